//! Building files (TOML; see `buildings/*.toml` and `buildings/README.md`): floors stacked in
//! one x, y frame, each laid out like a [`World`] (walls, boxes, doors, barcodes), and a bank
//! of elevator cars that serves every floor. [`crate::elevator`] moves the cars,
//! [`crate::site`] puts the robot among them.
//!
//! ```toml
//! name = "building-a"
//! start = [2.0, 2.0, 0.0]          # x, y (m), heading (rad) on floor `start_floor`
//! start_floor = 0                  # default 0
//! start_jitter = [0.4, 0.4, 0.6]   # seeds move the start within ± these (default none)
//! # SAY delivers the message on `floor` within `radius` of `at` (in front of the office door)
//! goal = { floor = 4, room = 405, at = [9.5, 21.2], radius = 2.0 }
//! [[floor]]
//! level = 0
//! outside = { min = [10.5, -20.0], max = [60.0, 60.0] }   # "out of the lab" (optional)
//! [[floor.wall]]
//! from = [0.0, 0.0]
//! to = [10.0, 0.0]
//! # [[floor.box]], [[floor.door]], [[floor.barcode]] as in a world file
//! [elevator]
//! travel_s = 2.5     # seconds per floor
//! door_s = 1.5       # opening or closing
//! dwell_s = 8.0      # doors held open
//! traffic_s = 60.0   # mean idle time before another passenger sends an idle car elsewhere
//! call = [27.45, 21.4]   # the hall call button, the same on every floor
//! [[elevator.car]]
//! door = { from = [27.5, 23.55], to = [27.5, 24.65] }   # its doorway in the bank wall
//! cabin = { min = [27.5, 23.25], max = [29.2, 24.95] }  # the cabin's inside
//! ```
//!
//! Floors are levels `0..n` (5 ≤ n ≤ 10), all served by every car. A floor's walls leave a
//! gap at each car's doorway: the car's doors (and, when it is there, its cabin) close it.
//!
//! # Conventions
//!
//! Barcode ids (the skills rely on them):
//! - [`LAB_DOOR`] (7): beside the lab door, floor 0.
//! - [`CALL`] (850): the hall call button, on the bank wall midway between cars 2 and 3,
//!   [`INSET`] in front of it, on every floor. A barcode and a button.
//! - [`PANEL`] + f (860 + f): the car's button for floor f, on the cabin's back wall (opposite
//!   the doorway), [`INSET`] in front of it, [`BUTTON_SPACING`] apart, centred, floor 0 on the
//!   left as seen facing the panel. Barcodes and buttons.
//! - [`LANTERN`] + k (811..=814): the hall lantern of car k (1-based), at the doorway centre,
//!   [`INSET`] into the lobby; seen only while car k is at this floor with its doors not
//!   fully closed.
//! - [`INDICATOR`] + f (900 + f): the floor indicator inside each cabin above its door
//!   (doorway centre, [`INSET`] into the cabin), showing the floor the car is at (nearest
//!   while it moves).
//! - floor · 100 + n: room signs, on the corridor wall 0.3 m beside a side door's edge.
//!
//! Cars are numbered 1.. from the left as seen from the lobby facing the bank wall.

use crate::sim::RADIUS;
use crate::world::{Barcode, P, Rect, Segment, World, point_segment};
use serde::Deserialize;
use std::path::Path;

mod check;
pub use check::Problem;

/// The lab door's barcode (floor 0).
pub const LAB_DOOR: u16 = 7;
/// Hall lantern of car k (1-based): `LANTERN + k`.
pub const LANTERN: u16 = 810;
/// The hall call button.
pub const CALL: u16 = 850;
/// Car panel button for floor f: `PANEL + f`.
pub const PANEL: u16 = 860;
/// Floor indicator inside a cabin showing floor f: `INDICATOR + f`.
pub const INDICATOR: u16 = 900;
/// How far barcodes and buttons stand in front of their wall (m).
pub const INSET: f64 = 0.05;
/// Distance between neighbouring panel buttons (m).
pub const BUTTON_SPACING: f64 = 0.3;
/// Fewest floors: the delivery mission goes from floor 0 to floor 4.
pub const MIN_FLOORS: usize = 5;
/// Most floors: panel ids 860 + f and indicator ids 900 + f stay in their decade.
pub const MAX_FLOORS: usize = 10;
/// Most cars: lantern ids 810 + k stay in their decade.
pub const MAX_CARS: usize = 9;
/// Clearance the start (and every jittered start) keeps from walls (m).
pub const START_CLEARANCE: f64 = RADIUS + 0.1;

/// A building.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Building {
    /// Name.
    pub name: String,
    /// Robot start: x, y, heading, on `start_floor`.
    pub start: [f64; 3],
    /// The floor the robot starts on.
    #[serde(default)]
    pub start_floor: i32,
    /// Seeds move the start uniformly within ± these (m, m, rad).
    #[serde(default)]
    pub start_jitter: [f64; 3],
    /// Where the message is to be delivered.
    pub goal: Goal,
    /// The floors, in level order once loaded.
    #[serde(rename = "floor")]
    pub floors: Vec<Floor>,
    /// The elevator bank.
    pub elevator: Elevator,
}

/// Where the message counts as delivered.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Goal {
    /// The floor.
    pub floor: i32,
    /// The office's room number (its sign's barcode on that floor).
    pub room: u16,
    /// A point in the corridor in front of the office door.
    pub at: P,
    /// How near `at` the robot must be (m).
    pub radius: f64,
}

/// Where the robot counts as back at the lab ([`Building::lab_goal`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabGoal {
    /// The lab's floor.
    pub floor: i32,
    /// A point in the corridor in front of the lab's door.
    pub at: P,
    /// How near `at` the robot must be (m).
    pub radius: f64,
}

/// How far into the corridor from the lab door's middle the lab's goal is (m): the corridor's
/// centre line, as the office goals are in front of their doors.
pub const LAB_GOAL_INTO_THE_CORRIDOR: f64 = 1.2;

/// One floor: its fixed layout, as in a world file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Floor {
    /// Level: 0 is the basement with the lab.
    pub level: i32,
    /// Region that counts as out of the lab.
    pub outside: Option<Rect>,
    /// Walls.
    #[serde(default)]
    pub wall: Vec<Segment>,
    /// Boxes.
    #[serde(default, rename = "box")]
    pub boxes: Vec<Rect>,
    /// Door openings (documentation and ground truth only).
    #[serde(default)]
    pub door: Vec<Segment>,
    /// Barcodes: the lab door's, room signs.
    #[serde(default)]
    pub barcode: Vec<Barcode>,
}

/// The elevator bank.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Elevator {
    /// Seconds per floor.
    pub travel_s: f64,
    /// Seconds to open or to close the doors.
    pub door_s: f64,
    /// Seconds the doors stay open.
    pub dwell_s: f64,
    /// Mean idle time before another passenger sends an idle car elsewhere (s).
    pub traffic_s: f64,
    /// The hall call button, the same on every floor.
    pub call: P,
    /// The cars, numbered 1.. in this order.
    #[serde(rename = "car")]
    pub cars: Vec<Shaft>,
}

/// Where a car runs: its doorway (the same on every floor) and its cabin's inside.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shaft {
    /// The doorway, in the lobby's bank wall.
    pub door: Segment,
    /// The cabin's inside.
    pub cabin: Rect,
}

/// A car's fixtures, derived from its [`Shaft`].
#[derive(Debug, Clone, PartialEq)]
pub struct CarLayout {
    /// The doorway (from post to post).
    pub door: Segment,
    /// The cabin's inside.
    pub cabin: Rect,
    /// The cabin's walls: the three sides without the doorway and the jambs beside it.
    pub walls: Vec<Segment>,
    /// Its hall lantern (in the lobby).
    pub lantern: P,
    /// Its floor indicator (in the cabin).
    pub indicator: P,
    /// Its panel buttons, by floor.
    pub panel: Vec<P>,
}

/// What is wrong with a building file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BuildingError {
    /// Unreadable.
    #[error("cannot read building {path}")]
    Read {
        /// File.
        path: String,
        /// OS error.
        #[source]
        source: std::io::Error,
    },
    /// Not a building.
    #[error("building {path}: {message}")]
    Parse {
        /// File.
        path: String,
        /// Parser message.
        message: String,
    },
    /// A building that cannot be simulated.
    #[error("building {path}: {problem}")]
    Invalid {
        /// File.
        path: String,
        /// What is wrong.
        problem: Problem,
    },
}

/// Whether `id` is one of the elevator's ids.
pub fn is_reserved(id: u16) -> bool {
    id == CALL
        || (LANTERN..LANTERN + 10).contains(&id)
        || (PANEL..PANEL + 10).contains(&id)
        || (INDICATOR..INDICATOR + 10).contains(&id)
}

impl Building {
    /// Reads a building file.
    pub fn load(path: &Path) -> Result<Building, BuildingError> {
        let text = std::fs::read_to_string(path).map_err(|source| BuildingError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Building::parse(&text, &path.display().to_string())
    }

    /// Parses and checks building text.
    pub fn parse(text: &str, path: &str) -> Result<Building, BuildingError> {
        let mut b: Building = toml::from_str(text).map_err(|e| BuildingError::Parse {
            path: path.to_string(),
            message: e.to_string(),
        })?;
        b.floors.sort_by_key(|f| f.level);
        check::check(&b).map_err(|problem| BuildingError::Invalid {
            path: path.to_string(),
            problem,
        })?;
        Ok(b)
    }

    /// Where the robot counts as back at the lab: a point in the corridor in front of the lab's
    /// door (the floor-0 door nearest the [`LAB_DOOR`] barcode, [`LAB_GOAL_INTO_THE_CORRIDOR`]
    /// from its middle on the side away from the barcode, which is inside the lab), within
    /// the office goal's radius. `None` without a barcode 7 or a door on floor 0.
    pub fn lab_goal(&self) -> Option<LabGoal> {
        let f = self.floor(0)?;
        let sign = f.barcode.iter().find(|b| b.id == LAB_DOOR)?;
        // The corridor is on the side away from the sign, which is inside the lab.
        let at = f.before_door(sign.at, -LAB_GOAL_INTO_THE_CORRIDOR)?;
        Some(LabGoal {
            floor: 0,
            at,
            radius: self.goal.radius,
        })
    }

    /// The floor at `level`.
    pub fn floor(&self, level: i32) -> Option<&Floor> {
        usize::try_from(level).ok().and_then(|i| self.floors.get(i))
    }

    /// The floor at `level` as a world (named after the building, with its start).
    pub fn world(&self, level: i32) -> Option<World> {
        let f = self.floor(level)?;
        Some(f.world(format!("{} floor {}", self.name, f.level), self.start))
    }

    /// What blocks the robot on floor `level` with every car's doors closed: the floor's walls
    /// and boxes and the doorways.
    pub fn segments(&self, level: i32) -> Vec<Segment> {
        let mut s = self.world(level).map(|w| w.segments()).unwrap_or_default();
        s.extend(self.elevator.cars.iter().map(|c| c.door));
        s
    }

    /// The cars' fixtures, in car order (the building is checked: every shaft has them).
    pub fn layouts(&self) -> Vec<CarLayout> {
        let n = self.floors.len();
        self.elevator
            .cars
            .iter()
            .enumerate()
            .filter_map(|(i, s)| s.layout(i + 1, n).ok())
            .collect()
    }
}

impl Floor {
    /// The point `d` m from the middle of the door nearest `sign` (by the door's nearest
    /// point), square to the door: on the sign's side for `d` > 0, on the other for `d` < 0.
    /// `None` without a door. How a room's sign tells its door (the goal in front of an
    /// office, the lab's goal in its corridor).
    pub fn before_door(&self, sign: P, d: f64) -> Option<P> {
        let near = |s: &Segment| point_segment(sign, s).0;
        let door = self
            .door
            .iter()
            .min_by(|a, b| near(a).total_cmp(&near(b)))?;
        let mid = [
            (door.from[0] + door.to[0]) / 2.0,
            (door.from[1] + door.to[1]) / 2.0,
        ];
        let (ax, ay) = (door.to[0] - door.from[0], door.to[1] - door.from[1]);
        let len = ax.hypot(ay);
        let (mut nx, mut ny) = (-ay / len, ax / len);
        if (sign[0] - mid[0]) * nx + (sign[1] - mid[1]) * ny < 0.0 {
            (nx, ny) = (-nx, -ny);
        }
        Some([mid[0] + nx * d, mid[1] + ny * d])
    }

    /// The floor as a world called `name` starting at `start`.
    pub fn world(&self, name: String, start: [f64; 3]) -> World {
        World {
            name,
            start,
            outside: self.outside,
            wall: self.wall.clone(),
            boxes: self.boxes.clone(),
            door: self.door.clone(),
            barcode: self.barcode.clone(),
        }
    }
}

/// Distance from `p` to the nearest of `segments`.
pub fn clearance(segments: &[Segment], p: P) -> f64 {
    segments
        .iter()
        .map(|s| point_segment(p, s).0)
        .fold(f64::INFINITY, f64::min)
}

impl Shaft {
    /// The car's fixtures, or why its doorway or panel does not fit (`car` is 1-based, for
    /// the message; `floors` is the number of panel buttons).
    pub fn layout(&self, car: usize, floors: usize) -> Result<CarLayout, Problem> {
        const EPS: f64 = 1e-6;
        let (c, d) = (self.cabin, self.door);
        let bad = Problem::Doorway { car };
        if !(c.min[0] < c.max[0] && c.min[1] < c.max[1]) {
            return Err(bad);
        }
        // The axis the doorway lies across (0: a wall of constant x), and the inward normal.
        let axis = if (d.from[0] - d.to[0]).abs() < EPS {
            0
        } else if (d.from[1] - d.to[1]).abs() < EPS {
            1
        } else {
            return Err(bad);
        };
        let along = 1 - axis;
        let at = d.from[axis];
        let inward = if (at - c.min[axis]).abs() < EPS {
            1.0
        } else if (at - c.max[axis]).abs() < EPS {
            -1.0
        } else {
            return Err(bad);
        };
        let (lo, hi) = (
            d.from[along].min(d.to[along]),
            d.from[along].max(d.to[along]),
        );
        if hi - lo < EPS || lo < c.min[along] - EPS || hi > c.max[along] + EPS {
            return Err(bad);
        }
        let length = c.max[along] - c.min[along];
        let span = (floors.saturating_sub(1)) as f64 * BUTTON_SPACING;
        if span > length - 0.2 {
            return Err(Problem::Panel {
                car,
                floors,
                length,
            });
        }
        let depth = c.max[axis] - c.min[axis];
        let point = |a: f64, l: f64| {
            let mut p = [0.0; 2];
            p[axis] = a;
            p[along] = l;
            p
        };
        let seg = |a: P, b: P| Segment { from: a, to: b };
        let back = at + inward * depth;
        let mid = (lo + hi) / 2.0;
        let corners = [c.min[along], c.max[along]];
        let mut walls = vec![
            seg(point(back, corners[0]), point(back, corners[1])),
            seg(point(at, corners[0]), point(back, corners[0])),
            seg(point(at, corners[1]), point(back, corners[1])),
        ];
        // The jambs beside the doorway: the bank wall covers them on a floor, but a moving
        // cabin is all the robot has around it.
        for (a, b) in [(corners[0], lo), (hi, corners[1])] {
            if b - a > EPS {
                walls.push(seg(point(at, a), point(at, b)));
            }
        }
        // Facing the panel (looking along `inward`), "left" is the inward normal turned
        // counter-clockwise.
        let left = if axis == 0 { inward } else { -inward };
        let panel = (0..floors)
            .map(|f| {
                let off = (f as f64 - (floors as f64 - 1.0) / 2.0) * BUTTON_SPACING;
                point(back - inward * INSET, mid - left * off)
            })
            .collect();
        Ok(CarLayout {
            door: seg(d.from, d.to),
            cabin: c,
            walls,
            lantern: point(at - inward * INSET, mid),
            indicator: point(at + inward * INSET, mid),
            panel,
        })
    }
}

impl CarLayout {
    /// The door leaves at `open` (0 closed, 1 open): centre-opening, each from its post toward
    /// the middle; none when fully open.
    pub fn leaves(&self, open: f64) -> impl Iterator<Item = Segment> + '_ {
        let f = (1.0 - open.clamp(0.0, 1.0)) / 2.0;
        let (a, b) = (self.door.from, self.door.to);
        let toward = move |p: P, q: P| Segment {
            from: p,
            to: [p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1])],
        };
        [toward(a, b), toward(b, a)]
            .into_iter()
            .filter(move |_| f > 1e-9)
    }

    /// Whether `p` is inside the cabin.
    pub fn contains(&self, p: P) -> bool {
        let c = &self.cabin;
        p[0] >= c.min[0] && p[0] <= c.max[0] && p[1] >= c.min[1] && p[1] <= c.max[1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped() -> Vec<(String, Building)> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("buildings");
        [
            "building-a.toml",
            "building-b.toml",
            "heldout/building-c.toml",
            "heldout/building-d.toml",
            "heldout/building-e.toml",
        ]
        .iter()
        .map(|f| {
            let path = dir.join(f);
            let b = Building::load(&path).unwrap_or_else(|e| panic!("{e}"));
            (f.to_string(), b)
        })
        .collect()
    }

    /// The lab's goal is in the corridor in front of its door: 1.2 m from the door's middle,
    /// on the side away from the lab's sign (which is inside), clear of the walls.
    #[test]
    fn the_labs_goal_is_in_the_corridor_in_front_of_its_door() {
        for (f, b) in shipped() {
            let g = b.lab_goal().unwrap_or_else(|| panic!("{f}: no lab goal"));
            assert_eq!(g.floor, 0, "{f}");
            let floor = b.floor(0).unwrap();
            let sign = floor.barcode.iter().find(|c| c.id == LAB_DOOR).unwrap();
            let door = floor
                .door
                .iter()
                .min_by(|a, c| {
                    point_segment(sign.at, a)
                        .0
                        .total_cmp(&point_segment(sign.at, c).0)
                })
                .unwrap();
            let (d, _) = point_segment(g.at, door);
            assert!((d - LAB_GOAL_INTO_THE_CORRIDOR).abs() < 1e-9, "{f}: {d}");
            let to_sign = (g.at[0] - sign.at[0]).hypot(g.at[1] - sign.at[1]);
            assert!(to_sign > LAB_GOAL_INTO_THE_CORRIDOR, "{f}: the sign's side");
            assert!(clearance(&b.segments(0), g.at) > 0.9, "{f}: {:?}", g.at);
        }
    }

    /// Length of a polyline, and its least clearance on `level` with the doors closed.
    fn walk(b: &Building, level: i32, path: &[P]) -> (f64, f64) {
        let segs = b.segments(level);
        let mut len = 0.0;
        let mut least = f64::INFINITY;
        for w in path.windows(2) {
            let d = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
            len += d;
            let n = (d / 0.05).ceil() as usize;
            for i in 0..=n {
                let t = i as f64 / n as f64;
                let p = [
                    w[0][0] + t * (w[1][0] - w[0][0]),
                    w[0][1] + t * (w[1][1] - w[0][1]),
                ];
                least = least.min(clearance(&segs, p));
            }
        }
        (len, least)
    }

    #[test]
    fn shipped_buildings_follow_the_conventions() {
        for (file, b) in shipped() {
            let floors = b.floors.len();
            assert!(
                (MIN_FLOORS..=MAX_FLOORS).contains(&floors),
                "{file}: {floors} floors"
            );
            assert_eq!(b.elevator.cars.len(), 4, "{file}");
            assert_eq!(b.goal.floor, 4, "{file}");
            let f0 = b.floor(0).unwrap();
            assert!(f0.outside.is_some(), "{file}");
            assert!(f0.barcode.iter().any(|c| c.id == LAB_DOOR), "{file}");
            let layouts = b.layouts();
            assert_eq!(layouts.len(), 4);
            // The call button midway between cars 2 and 3, in front of the bank wall.
            let (m2, m3) = (mid(&layouts[1].door), mid(&layouts[2].door));
            let between = [(m2[0] + m3[0]) / 2.0, (m2[1] + m3[1]) / 2.0];
            let d = (between[0] - b.elevator.call[0]).hypot(between[1] - b.elevator.call[1]);
            assert!((d - INSET).abs() < 1e-6, "{file}: call button {d} m off");
            for l in &layouts {
                let w = (l.door.to[0] - l.door.from[0]).hypot(l.door.to[1] - l.door.from[1]);
                assert!((w - 1.1).abs() < 1e-6, "{file}: doorway {w}");
                let c = l.cabin;
                assert!((c.max[0] - c.min[0] - 1.7).abs() < 1e-6, "{file}");
                assert!((c.max[1] - c.min[1] - 1.7).abs() < 1e-6, "{file}");
            }
            for w in layouts.windows(2) {
                let (a, c) = (mid(&w[0].door), mid(&w[1].door));
                assert!(
                    ((a[0] - c[0]).hypot(a[1] - c[1]) - 1.8).abs() < 1e-6,
                    "{file}"
                );
            }
            // Car 1 is on the left facing the bank wall: the lantern-to-doorway direction
            // turned counter-clockwise points from car 2 toward car 1.
            let facing = [m2[0] - layouts[1].lantern[0], m2[1] - layouts[1].lantern[1]];
            let left = [-facing[1], facing[0]];
            let m1 = mid(&layouts[0].door);
            assert!(
                left[0] * (m1[0] - m2[0]) + left[1] * (m1[1] - m2[1]) > 0.0,
                "{file}"
            );
        }
    }

    fn mid(s: &Segment) -> P {
        [(s.from[0] + s.to[0]) / 2.0, (s.from[1] + s.to[1]) / 2.0]
    }

    /// The routes the header comments describe, as waypoints: from the lab door to the call
    /// button on floor 0; from car 2's doorway to the goal on floor 4.
    fn routes(file: &str) -> (Vec<P>, Vec<P>) {
        match file {
            "building-a.toml" => (
                vec![[9.6, 4.0], [11.2, 4.0], [11.2, 18.2], [26.8, 18.2]],
                vec![[26.9, 19.1], [24.0, 18.2], [9.5, 18.2]],
            ),
            "building-b.toml" => (
                vec![[9.6, 4.0], [19.2, 4.0], [19.2, -10.8]],
                vec![[20.1, -10.9], [19.2, -6.0], [19.2, 1.2], [10.5, 1.2]],
            ),
            "heldout/building-c.toml" => (
                vec![
                    [9.6, 4.0],
                    [11.2, 4.0],
                    [11.2, -4.8],
                    [28.0, -4.8],
                    [30.2, -2.2],
                ],
                vec![[29.3, -2.1], [32.0, -4.8], [44.0, -4.8]],
            ),
            "heldout/building-d.toml" => (
                vec![
                    [6.0, -14.4],
                    [6.0, -12.8],
                    [-1.2, -12.8],
                    [-1.2, 4.2],
                    [3.9, 4.2],
                ],
                vec![[4.0, 5.1], [3.4, 6.5], [3.4, 21.3]],
            ),
            "heldout/building-e.toml" => (
                vec![[0.4, 5.4], [-1.2, 5.4], [-1.2, -6.0], [-18.8, -6.0]],
                vec![[-18.9, -6.9], [-16.0, -6.0], [-7.2, -6.0], [-7.2, 3.9]],
            ),
            _ => panic!("{file}: no route"),
        }
    }

    #[test]
    fn shipped_routes_are_passable_and_of_the_promised_length() {
        for (file, b) in shipped() {
            let (down, up) = routes(&file);
            let (len, least) = walk(&b, 0, &down);
            assert!((15.0..=35.0).contains(&len), "{file}: lab to lobby {len} m");
            assert!(
                least >= START_CLEARANCE,
                "{file}: floor 0 clearance {least}"
            );
            let (len, least) = walk(&b, 4, &up);
            assert!(
                (8.0..=25.0).contains(&len),
                "{file}: lobby to office {len} m"
            );
            assert!(
                least >= START_CLEARANCE,
                "{file}: floor 4 clearance {least}"
            );
            let end = up[up.len() - 1];
            let g = b.goal.at;
            assert!((end[0] - g[0]).hypot(end[1] - g[1]) < 0.01, "{file}");
            // The office's sign is by the goal, no other door's centre within its radius.
            let f4 = b.floor(4).unwrap();
            let sign = f4.barcode.iter().find(|c| c.id == b.goal.room).unwrap();
            assert!((sign.at[0] - g[0]).hypot(sign.at[1] - g[1]) < 2.5, "{file}");
            let near = f4
                .door
                .iter()
                .filter(|d| {
                    let m = mid(d);
                    (m[0] - g[0]).hypot(m[1] - g[1]) < b.goal.radius + 0.5
                })
                .count();
            assert_eq!(near, 1, "{file}: doors near the goal");
        }
    }

    #[test]
    fn door_leaves_shrink_toward_the_posts() {
        let b = &shipped()[0].1;
        let l = &b.layouts()[0];
        let closed: Vec<_> = l.leaves(0.0).collect();
        assert_eq!(closed.len(), 2);
        assert!((closed[0].to[0] - closed[1].to[0]).abs() < 1e-9);
        assert!(
            (closed[0].to[1] - closed[1].to[1]).abs() < 1e-9,
            "they meet"
        );
        let half: Vec<_> = l.leaves(0.5).collect();
        let len = |s: &Segment| (s.to[0] - s.from[0]).hypot(s.to[1] - s.from[1]);
        assert!((len(&half[0]) - 1.1 / 4.0).abs() < 1e-9);
        assert_eq!(l.leaves(1.0).count(), 0);
    }
}
