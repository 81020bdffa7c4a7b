//! World files (TOML; see `worlds/*.toml`): walls, boxes, doors, barcodes, the robot's start,
//! and the region that counts as outside the lab.
//!
//! ```toml
//! name = "exit-lab"
//! start = [2.0, 2.0, 0.0]            # x, y (m), heading (rad)
//! outside = { min = [10.4, -50.0], max = [60.0, 50.0] }
//! [[wall]]                            # a segment
//! from = [0.0, 0.0]
//! to = [10.0, 0.0]
//! [[box]]                             # an axis-aligned obstacle
//! min = [3.0, 3.0]
//! max = [4.0, 3.6]
//! [[door]]                            # an opening (documentation and ground truth only)
//! from = [10.0, 3.5]
//! to = [10.0, 4.5]
//! [[barcode]]
//! id = 7
//! at = [9.9, 5.0]
//! ```

use serde::Deserialize;
use std::path::Path;

/// A point (m).
pub type P = [f64; 2];

/// A wall segment.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    /// One end.
    pub from: P,
    /// The other end.
    pub to: P,
}

/// A box obstacle.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rect {
    /// Lower-left corner.
    pub min: P,
    /// Upper-right corner.
    pub max: P,
}

/// A barcode on a wall.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Barcode {
    /// Its id.
    pub id: u16,
    /// Where.
    pub at: P,
}

/// A world.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct World {
    /// Name.
    pub name: String,
    /// Robot start: x, y, heading.
    pub start: [f64; 3],
    /// Region that counts as outside the lab.
    pub outside: Option<Rect>,
    /// Walls.
    #[serde(default)]
    pub wall: Vec<Segment>,
    /// Boxes.
    #[serde(default, rename = "box")]
    pub boxes: Vec<Rect>,
    /// Door openings.
    #[serde(default)]
    pub door: Vec<Segment>,
    /// Barcodes.
    #[serde(default)]
    pub barcode: Vec<Barcode>,
}

/// What is wrong with a world file.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// Unreadable.
    #[error("cannot read world {path}: {source}")]
    Read {
        /// File.
        path: String,
        /// OS error.
        source: std::io::Error,
    },
    /// Not a world.
    #[error("world {path}: {message}")]
    Parse {
        /// File.
        path: String,
        /// Parser message.
        message: String,
    },
}

impl World {
    /// Reads a world file.
    pub fn load(path: &Path) -> Result<World, WorldError> {
        let text = std::fs::read_to_string(path).map_err(|source| WorldError::Read {
            path: path.display().to_string(),
            source,
        })?;
        World::parse(&text, &path.display().to_string())
    }

    /// Parses world text.
    pub fn parse(text: &str, path: &str) -> Result<World, WorldError> {
        toml::from_str(text).map_err(|e| WorldError::Parse {
            path: path.to_string(),
            message: e.to_string(),
        })
    }

    /// Every segment that blocks motion, sound and sight.
    pub fn segments(&self) -> Vec<Segment> {
        let mut s = self.wall.clone();
        for b in &self.boxes {
            let [x0, y0] = b.min;
            let [x1, y1] = b.max;
            for (a, c) in [
                ([x0, y0], [x1, y0]),
                ([x1, y0], [x1, y1]),
                ([x1, y1], [x0, y1]),
                ([x0, y1], [x0, y0]),
            ] {
                s.push(Segment { from: a, to: c });
            }
        }
        s
    }

    /// Whether a point is outside the lab.
    pub fn is_outside(&self, p: P) -> bool {
        self.outside.is_some_and(|r| {
            p[0] >= r.min[0] && p[0] <= r.max[0] && p[1] >= r.min[1] && p[1] <= r.max[1]
        })
    }
}

/// Distance along a ray from `o` in direction `d` (unit) to segment `s`, and the cosine of
/// the angle between the ray and the segment's normal.
pub fn ray_hit(o: P, d: P, s: &Segment) -> Option<(f64, f64)> {
    let e = [s.to[0] - s.from[0], s.to[1] - s.from[1]];
    let denom = d[0] * e[1] - d[1] * e[0];
    if denom.abs() < 1e-12 {
        return None;
    }
    let w = [s.from[0] - o[0], s.from[1] - o[1]];
    let t = (w[0] * e[1] - w[1] * e[0]) / denom;
    let u = (w[0] * d[1] - w[1] * d[0]) / denom;
    if t < 0.0 || !(0.0..=1.0).contains(&u) {
        return None;
    }
    let len = e[0].hypot(e[1]);
    // |cos| between the ray and the normal = |cross(d, e)| / |e|
    Some((t, (denom / len).abs()))
}

/// Distance from point `p` to segment `s`, and the closest point.
pub fn point_segment(p: P, s: &Segment) -> (f64, P) {
    let e = [s.to[0] - s.from[0], s.to[1] - s.from[1]];
    let l2 = e[0] * e[0] + e[1] * e[1];
    let t = if l2 == 0.0 {
        0.0
    } else {
        (((p[0] - s.from[0]) * e[0] + (p[1] - s.from[1]) * e[1]) / l2).clamp(0.0, 1.0)
    };
    let c = [s.from[0] + t * e[0], s.from[1] + t * e[1]];
    ((p[0] - c[0]).hypot(p[1] - c[1]), c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_hit_walls_with_their_incidence() {
        let wall = Segment {
            from: [2.0, -3.0],
            to: [2.0, 3.0],
        };
        let (t, c) = ray_hit([0.0, 0.0], [1.0, 0.0], &wall).unwrap();
        assert!((t - 2.0).abs() < 1e-12 && (c - 1.0).abs() < 1e-12);
        let d = [
            std::f64::consts::FRAC_1_SQRT_2,
            std::f64::consts::FRAC_1_SQRT_2,
        ];
        let (t, c) = ray_hit([0.0, 0.0], d, &wall).unwrap();
        assert!((t - 2.0f64.sqrt() * 2.0).abs() < 1e-9);
        assert!((c - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-9);
        assert!(ray_hit([0.0, 0.0], [-1.0, 0.0], &wall).is_none());
    }

    #[test]
    fn shipped_worlds_parse() {
        for w in [
            "exit-lab",
            "exit-lab-north",
            "exit-lab-clutter",
            "heldout/partition",
            "heldout/south-tall",
            "heldout/west-long",
            "heldout/row-gaps",
            "heldout/south-detour",
            "heldout/north-maze",
        ] {
            let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("worlds/{w}.toml"));
            let world = World::load(&path).unwrap();
            assert!(!world.segments().is_empty());
            assert!(world.outside.is_some());
            assert!(!world.barcode.is_empty());
        }
        assert!(World::parse("name = 'x'\nstart = [0,0,0]\nwal = []\n", "t").is_err());
    }
}
