//! What the view draws, in the `map` frame: the simulated world's walls, boxes, doors and
//! barcodes — one floor, or every floor of a building stacked [`FLOOR_HEIGHT`] apart with its
//! elevator cabins and call button — and, in the robot's frame, its body and sonar ring.
//!
//! The same [`Scene`] is sent as `foxglove.SceneUpdate` (JSON) and drawn by the SVG
//! [`snapshot`](crate::snapshot), so the picture is what a viewer is sent.

use denning_sim::building::Building;
use denning_sim::sim::{CONE_HALF, RADIUS, SONAR_MAX};
use denning_sim::world::{Barcode, Rect, Segment, World};
use serde_json::{Value as Json, json};
use std::f64::consts::TAU;
use std::path::Path;

/// Height between two floors of a building in the 3-D scene (m).
pub const FLOOR_HEIGHT: f64 = 3.0;
/// Height of a wall in the 3-D scene (m).
const WALL_HEIGHT: f64 = 0.8;
/// Thickness of a wall in the 3-D scene (m).
const WALL_THICKNESS: f64 = 0.08;

/// One floor's fixed layout.
#[derive(Debug, Clone, PartialEq)]
pub struct Level {
    /// Its level (0 in a plain world).
    pub level: i32,
    /// Walls.
    pub walls: Vec<Segment>,
    /// Door openings.
    pub doors: Vec<Segment>,
    /// Boxes.
    pub boxes: Vec<Rect>,
    /// Barcodes.
    pub barcodes: Vec<Barcode>,
    /// Elevator cabins (a building's).
    pub cabins: Vec<Rect>,
    /// Cabin walls.
    pub cabin_walls: Vec<Segment>,
}

/// The world as the view shows it.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The world's or building's name.
    pub name: String,
    /// Where the robot starts (x, y, heading) and on which level: the odometry frame's origin.
    pub start: [f64; 3],
    /// The level it starts on.
    pub start_level: i32,
    /// The floors.
    pub levels: Vec<Level>,
    /// The elevators' hall call button (a building's).
    pub call: Option<[f64; 2]>,
}

/// Why a world or building file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A world file's error.
    #[error(transparent)]
    World(#[from] denning_sim::world::WorldError),
    /// A building file's error.
    #[error(transparent)]
    Building(#[from] denning_sim::building::BuildingError),
}

impl Scene {
    /// The scene of a world file.
    pub fn of_world(w: &World) -> Scene {
        Scene {
            name: w.name.clone(),
            start: w.start,
            start_level: 0,
            levels: vec![Level {
                level: 0,
                walls: w.wall.clone(),
                doors: w.door.clone(),
                boxes: w.boxes.clone(),
                barcodes: w.barcode.clone(),
                cabins: Vec::new(),
                cabin_walls: Vec::new(),
            }],
            call: None,
        }
    }

    /// The scene of a building file: every floor, with the cars' cabins on each.
    pub fn of_building(b: &Building) -> Scene {
        let cars = b.layouts();
        Scene {
            name: b.name.clone(),
            start: b.start,
            start_level: b.start_floor,
            levels: b
                .floors
                .iter()
                .map(|f| Level {
                    level: f.level,
                    walls: f.wall.clone(),
                    doors: f.door.clone(),
                    boxes: f.boxes.clone(),
                    barcodes: f.barcode.clone(),
                    cabins: cars.iter().map(|c| c.cabin).collect(),
                    cabin_walls: cars.iter().flat_map(|c| c.walls.clone()).collect(),
                })
                .collect(),
            call: Some(b.elevator.call),
        }
    }

    /// A world file (`[[wall]]` …) or a building file (`[[floor]]` …), told apart by what
    /// it holds.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| {
            denning_sim::world::WorldError::Read {
                path: path.display().to_string(),
                source,
            }
        })?;
        if text.lines().any(|l| l.trim() == "[[floor]]") {
            Ok(Scene::of_building(&Building::parse(
                &text,
                &path.display().to_string(),
            )?))
        } else {
            Ok(Scene::of_world(&World::parse(
                &text,
                &path.display().to_string(),
            )?))
        }
    }

    /// The odometry frame's origin in the map: the start pose, at its floor's height.
    pub fn odom_origin(&self) -> ([f64; 3], f64) {
        let [x, y, th] = self.start;
        ([x, y, f64::from(self.start_level) * FLOOR_HEIGHT], th)
    }

    /// The map's extent over every level (m): min and max corners.
    pub fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        let pts = self
            .levels
            .iter()
            .flat_map(|l| l.walls.iter().flat_map(|s| [s.from, s.to]));
        pts.fold(
            ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
            |(lo, hi), p| {
                (
                    [lo[0].min(p[0]), lo[1].min(p[1])],
                    [hi[0].max(p[0]), hi[1].max(p[1])],
                )
            },
        )
    }

    /// The scene as a `foxglove.SceneUpdate`: one entity per level (`level-<n>`), in `map`.
    pub fn update(&self, stamp: Json) -> Json {
        let entities: Vec<Json> = self
            .levels
            .iter()
            .map(|l| level_entity(l, &stamp, self.call))
            .collect();
        json!({"deletions": [], "entities": entities})
    }
}

fn point(x: f64, y: f64, z: f64) -> Json {
    json!({"x": x, "y": y, "z": z})
}

fn color(r: f64, g: f64, b: f64, a: f64) -> Json {
    json!({"r": r, "g": g, "b": b, "a": a})
}

/// A pose at (x, y, z) turned `yaw` about z.
pub(crate) fn pose(x: f64, y: f64, z: f64, yaw: f64) -> Json {
    json!({"position": point(x, y, z), "orientation": quaternion(yaw)})
}

/// The rotation by `yaw` about z.
pub(crate) fn quaternion(yaw: f64) -> Json {
    json!({"x": 0.0, "y": 0.0, "z": (yaw / 2.0).sin(), "w": (yaw / 2.0).cos()})
}

fn cube(at: [f64; 3], size: [f64; 3], yaw: f64, c: Json) -> Json {
    json!({"pose": pose(at[0], at[1], at[2], yaw),
           "size": {"x": size[0], "y": size[1], "z": size[2]}, "color": c})
}

fn wall_cube(s: &Segment, z: f64, height: f64, c: &Json) -> Json {
    let (dx, dy) = (s.to[0] - s.from[0], s.to[1] - s.from[1]);
    let mid = [(s.from[0] + s.to[0]) / 2.0, (s.from[1] + s.to[1]) / 2.0];
    cube(
        [mid[0], mid[1], z + height / 2.0],
        [dx.hypot(dy) + WALL_THICKNESS, WALL_THICKNESS, height],
        dy.atan2(dx),
        c.clone(),
    )
}

fn text(at: [f64; 3], t: String, c: Json) -> Json {
    json!({"pose": pose(at[0], at[1], at[2], 0.0), "billboard": true, "font_size": 14.0,
           "scale_invariant": true, "color": c, "text": t})
}

fn entity(id: &str, frame: &str, stamp: &Json) -> serde_json::Map<String, Json> {
    let e = json!({"timestamp": stamp, "frame_id": frame, "id": id,
                   "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": true, "metadata": [],
                   "arrows": [], "cubes": [], "spheres": [], "cylinders": [], "lines": [],
                   "triangles": [], "texts": [], "models": []});
    match e {
        Json::Object(m) => m,
        _ => serde_json::Map::new(),
    }
}

fn level_entity(l: &Level, stamp: &Json, call: Option<[f64; 2]>) -> Json {
    let z = f64::from(l.level) * FLOOR_HEIGHT;
    let mut e = entity(&format!("level-{}", l.level), "map", stamp);
    let wall = color(0.55, 0.57, 0.62, 0.9);
    let cabin = color(0.25, 0.45, 0.85, 0.5);
    let mut cubes: Vec<Json> = l
        .walls
        .iter()
        .map(|s| wall_cube(s, z, WALL_HEIGHT, &wall))
        .collect();
    cubes.extend(
        l.cabin_walls
            .iter()
            .map(|s| wall_cube(s, z, WALL_HEIGHT, &cabin)),
    );
    cubes.extend(l.boxes.iter().map(|b| {
        cube(
            [
                (b.min[0] + b.max[0]) / 2.0,
                (b.min[1] + b.max[1]) / 2.0,
                z + 0.3,
            ],
            [b.max[0] - b.min[0], b.max[1] - b.min[1], 0.6],
            0.0,
            color(0.6, 0.4, 0.2, 0.9),
        )
    }));
    cubes.extend(l.cabins.iter().map(|b| {
        cube(
            [
                (b.min[0] + b.max[0]) / 2.0,
                (b.min[1] + b.max[1]) / 2.0,
                z + 0.01,
            ],
            [b.max[0] - b.min[0], b.max[1] - b.min[1], 0.02],
            0.0,
            cabin.clone(),
        )
    }));
    cubes.extend(l.barcodes.iter().map(|b| {
        cube(
            [b.at[0], b.at[1], z + 0.5],
            [0.12, 0.12, 0.3],
            0.0,
            color(0.95, 0.8, 0.1, 1.0),
        )
    }));
    let doors: Vec<Json> = l
        .doors
        .iter()
        .flat_map(|s| [point(s.from[0], s.from[1], z), point(s.to[0], s.to[1], z)])
        .collect();
    let mut texts: Vec<Json> = l
        .barcodes
        .iter()
        .map(|b| {
            text(
                [b.at[0], b.at[1], z + 0.9],
                format!("#{}", b.id),
                color(0.95, 0.8, 0.1, 1.0),
            )
        })
        .collect();
    let mut spheres = Vec::new();
    if let Some(c) = call {
        spheres.push(json!({"pose": pose(c[0], c[1], z + 1.0, 0.0),
                            "size": {"x": 0.15, "y": 0.15, "z": 0.15},
                            "color": color(0.9, 0.2, 0.9, 1.0)}));
        texts.push(text(
            [c[0], c[1], z + 1.3],
            "call".into(),
            color(0.9, 0.2, 0.9, 1.0),
        ));
    }
    e.insert("cubes".into(), Json::Array(cubes));
    e.insert("spheres".into(), Json::Array(spheres));
    e.insert("texts".into(), Json::Array(texts));
    e.insert(
        "lines".into(),
        json!([{"type": 2, "pose": pose(0.0, 0.0, 0.0, 0.0), "thickness": 0.06,
                "scale_invariant": false, "points": doors,
                "color": color(0.2, 0.8, 0.3, 1.0), "colors": [], "indices": []}]),
    );
    Json::Object(e)
}

/// The angle of sonar `i` from the robot's heading: 24 sonars 15° apart, counter-clockwise.
pub fn sonar_axis(i: usize, n: usize) -> f64 {
    i as f64 * (TAU / n as f64)
}

/// The robot's body and its sonar ring, in `frame` (the robot's): a cylinder with an arrow
/// along its heading, and for each sonar a cone out to its echo — red when near, green when
/// far — with a point at the echo; a sonar with no echo shows a faint outline out to
/// [`SONAR_MAX`], one never read shows nothing.
pub fn robot_update(frame: &str, ranges: &[f64], stamp: &Json) -> Json {
    let mut body = entity("robot", frame, stamp);
    body.insert(
        "cylinders".into(),
        json!([{"pose": pose(0.0, 0.0, 0.25, 0.0),
                "size": {"x": 2.0 * RADIUS, "y": 2.0 * RADIUS, "z": 0.5},
                "bottom_scale": 1.0, "top_scale": 1.0, "color": color(0.1, 0.4, 0.9, 0.8)}]),
    );
    body.insert(
        "arrows".into(),
        json!([{"pose": pose(0.0, 0.0, 0.55, 0.0), "shaft_length": 0.35,
                "shaft_diameter": 0.06, "head_length": 0.15, "head_diameter": 0.15,
                "color": color(1.0, 1.0, 1.0, 1.0)}]),
    );
    let mut sonar = entity("sonar", frame, stamp);
    let (mut tri, mut tri_colors, mut outline, mut echoes) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (i, &r) in ranges.iter().enumerate() {
        let axis = sonar_axis(i, ranges.len());
        let o = [RADIUS * axis.cos(), RADIUS * axis.sin()];
        let edge = |reach: f64, side: f64| {
            let a = axis + side * CONE_HALF;
            point(o[0] + reach * a.cos(), o[1] + reach * a.sin(), 0.3)
        };
        if r.is_finite() {
            let near = (1.0 - r / 3.0).clamp(0.0, 1.0);
            let c = color(near, 1.0 - near, 0.1, 0.35);
            tri.extend([point(o[0], o[1], 0.3), edge(r, -1.0), edge(r, 1.0)]);
            tri_colors.extend([c.clone(), c.clone(), c]);
            let hit = [o[0] + (r + 0.0) * axis.cos(), o[1] + r * axis.sin()];
            echoes.push(point(hit[0], hit[1], 0.3));
        } else if r.is_infinite() {
            outline.extend([point(o[0], o[1], 0.3), edge(SONAR_MAX, 0.0)]);
        }
    }
    sonar.insert(
        "triangles".into(),
        json!([{"pose": pose(0.0, 0.0, 0.0, 0.0), "points": tri, "color": color(0.0, 1.0, 0.0, 0.3),
                "colors": tri_colors, "indices": []}]),
    );
    sonar.insert(
        "lines".into(),
        json!([{"type": 2, "pose": pose(0.0, 0.0, 0.0, 0.0), "thickness": 0.01,
                "scale_invariant": false, "points": outline,
                "color": color(0.6, 0.6, 0.6, 0.25), "colors": [], "indices": []},
               {"type": 2, "pose": pose(0.0, 0.0, 0.0, 0.0), "thickness": 4.0,
                "scale_invariant": true, "points": echoes.iter().flat_map(|p| [p.clone(), p.clone()]).collect::<Vec<_>>(),
                "color": color(1.0, 0.2, 0.2, 1.0), "colors": [], "indices": []}]),
    );
    json!({"deletions": [], "entities": [Json::Object(body), Json::Object(sonar)]})
}

#[cfg(test)]
mod tests {
    use super::*;

    fn repo(p: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(p)
    }

    #[test]
    fn a_world_file_is_one_level_and_a_building_one_per_floor_with_its_cabins() {
        let w = Scene::load(&repo("devices/denning-sim/worlds/exit-lab.toml")).unwrap();
        assert_eq!(w.levels.len(), 1);
        assert!(!w.levels[0].walls.is_empty() && !w.levels[0].barcodes.is_empty());
        assert!(w.call.is_none());
        let b = Scene::load(&repo("devices/denning-sim/buildings/building-a.toml")).unwrap();
        assert!(b.levels.len() >= 2, "{}", b.levels.len());
        assert!(b.levels.iter().all(|l| !l.cabins.is_empty()));
        assert!(b.call.is_some());
        let u = b.update(json!({"sec": 0, "nsec": 0}));
        let ents = u["entities"].as_array().unwrap();
        assert_eq!(ents.len(), b.levels.len());
        // A wall per wall and cabin wall, a cube per box, cabin and barcode.
        let l = &b.levels[1];
        assert_eq!(
            ents[1]["cubes"].as_array().unwrap().len(),
            l.walls.len() + l.cabin_walls.len() + l.boxes.len() + l.cabins.len() + l.barcodes.len()
        );
        assert_eq!(
            ents[1]["cubes"][0]["pose"]["position"]["z"],
            json!(FLOOR_HEIGHT + 0.4)
        );
    }

    #[test]
    fn a_missing_or_broken_file_says_which_and_why() {
        let e = Scene::load(Path::new("/nonexistent/w.toml")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/w.toml"), "{e}");
        let dir = std::env::temp_dir().join(format!("view-scene-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("bad.toml");
        std::fs::write(&f, "name = 3\n").unwrap();
        assert!(Scene::load(&f).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_sonar_ring_draws_a_cone_per_echo_an_outline_per_silence_and_nothing_unread() {
        let mut ranges = vec![f64::NAN; 24];
        ranges[0] = 1.0;
        ranges[6] = f64::INFINITY;
        let u = robot_update("base_link", &ranges, &json!({"sec": 0, "nsec": 0}));
        let sonar = &u["entities"][1];
        assert_eq!(sonar["triangles"][0]["points"].as_array().unwrap().len(), 3);
        assert_eq!(sonar["lines"][0]["points"].as_array().unwrap().len(), 2);
        assert_eq!(sonar["lines"][1]["points"].as_array().unwrap().len(), 2);
        // Sonar 0 faces forward: its echo is straight ahead, 1 m from the ring.
        let echo = &sonar["lines"][1]["points"][0];
        assert!((echo["x"].as_f64().unwrap() - (RADIUS + 1.0)).abs() < 1e-9);
        assert!(echo["y"].as_f64().unwrap().abs() < 1e-9);
    }
}
