//! What a building must be for the simulator, beyond the file's syntax: floors 0..n, cars
//! whose doorways and panels fit their cabins, no floor wall inside a cabin, elevator ids left
//! to the elevator, a start clear of walls, a goal with its office's sign.

use super::{
    BUTTON_SPACING, Building, MAX_CARS, MAX_FLOORS, MIN_FLOORS, START_CLEARANCE, clearance,
    is_reserved,
};
use crate::world::{Rect, Segment};

/// What is wrong with a building, file aside.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Problem {
    /// The levels are not `0..n` with n in range.
    #[error("floors must be levels 0..n with {MIN_FLOORS} <= n <= {MAX_FLOORS}, got {levels:?}")]
    Floors {
        /// The levels found.
        levels: Vec<i32>,
    },
    /// The start or goal is on a floor that is not there.
    #[error("the {what} is on floor {floor}, which does not exist")]
    NoSuchFloor {
        /// "start" or "goal".
        what: &'static str,
        /// Its floor.
        floor: i32,
    },
    /// An elevator time is not positive.
    #[error("elevator.{name} must be positive and finite, got {value}")]
    Timing {
        /// The field.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// Too few or too many cars.
    #[error("the elevator needs 1..={MAX_CARS} cars, got {count}")]
    Cars {
        /// Cars given.
        count: usize,
    },
    /// A doorway is not on its cabin's edge.
    #[error("car {car}: the door must be an axis-aligned segment on an edge of the cabin")]
    Doorway {
        /// The car (1-based).
        car: usize,
    },
    /// The panel buttons do not fit the cabin.
    #[error(
        "car {car}: {floors} panel buttons {BUTTON_SPACING} m apart do not fit its {length:.2} m back wall"
    )]
    Panel {
        /// The car (1-based).
        car: usize,
        /// Buttons needed.
        floors: usize,
        /// The back wall's length (m).
        length: f64,
    },
    /// A floor uses an elevator's barcode id.
    #[error("floor {floor}: barcode {id} is reserved for the elevator")]
    ReservedId {
        /// The floor.
        floor: i32,
        /// The id.
        id: u16,
    },
    /// A floor's wall or box reaches into a cabin.
    #[error("floor {floor}: a wall or box reaches into car {car}'s cabin")]
    WallInCabin {
        /// The floor.
        floor: i32,
        /// The car (1-based).
        car: usize,
    },
    /// The start is too near a wall.
    #[error("the start is {clearance:.2} m from the nearest wall, needs {START_CLEARANCE:.2}")]
    StartBlocked {
        /// Its clearance (m).
        clearance: f64,
    },
    /// A jitter is negative or not finite.
    #[error("start_jitter must be non-negative and finite, got {jitter:?}")]
    Jitter {
        /// The jitter.
        jitter: [f64; 3],
    },
    /// The goal radius is not positive.
    #[error("goal.radius must be positive, got {radius}")]
    GoalRadius {
        /// The radius.
        radius: f64,
    },
    /// The office has no sign.
    #[error("goal room {room} has no sign on floor {floor}")]
    NoGoalSign {
        /// The room.
        room: u16,
        /// The goal floor.
        floor: i32,
    },
}

/// What is wrong with `b`, if anything: what the simulator relies on beyond the file's syntax.
pub(super) fn check(b: &Building) -> Result<(), Problem> {
    let levels: Vec<i32> = b.floors.iter().map(|f| f.level).collect();
    let contiguous = levels.iter().zip(0..).all(|(l, i)| *l == i);
    if !contiguous || !(MIN_FLOORS..=MAX_FLOORS).contains(&levels.len()) {
        return Err(Problem::Floors { levels });
    }
    for (what, floor) in [("start", b.start_floor), ("goal", b.goal.floor)] {
        if b.floor(floor).is_none() {
            return Err(Problem::NoSuchFloor { what, floor });
        }
    }
    let e = &b.elevator;
    for (name, value) in [
        ("travel_s", e.travel_s),
        ("door_s", e.door_s),
        ("dwell_s", e.dwell_s),
        ("traffic_s", e.traffic_s),
    ] {
        if !(value > 0.0 && value.is_finite()) {
            return Err(Problem::Timing { name, value });
        }
    }
    if !(1..=MAX_CARS).contains(&e.cars.len()) {
        return Err(Problem::Cars {
            count: e.cars.len(),
        });
    }
    for (i, shaft) in e.cars.iter().enumerate() {
        shaft.layout(i + 1, b.floors.len())?;
    }
    for f in &b.floors {
        if let Some(code) = f.barcode.iter().find(|c| is_reserved(c.id)) {
            return Err(Problem::ReservedId {
                floor: f.level,
                id: code.id,
            });
        }
        let segments = f.world(String::new(), b.start).segments();
        for (i, shaft) in e.cars.iter().enumerate() {
            let inner = Rect {
                min: [shaft.cabin.min[0] + 0.01, shaft.cabin.min[1] + 0.01],
                max: [shaft.cabin.max[0] - 0.01, shaft.cabin.max[1] - 0.01],
            };
            if segments.iter().any(|s| crosses(s, &inner)) {
                return Err(Problem::WallInCabin {
                    floor: f.level,
                    car: i + 1,
                });
            }
        }
    }
    let jitter = b.start_jitter;
    if !jitter.iter().all(|j| *j >= 0.0 && j.is_finite()) {
        return Err(Problem::Jitter { jitter });
    }
    let clearance = clearance(&b.segments(b.start_floor), [b.start[0], b.start[1]]);
    if clearance < START_CLEARANCE {
        return Err(Problem::StartBlocked { clearance });
    }
    let radius = b.goal.radius;
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(Problem::GoalRadius { radius });
    }
    let signed = b
        .floor(b.goal.floor)
        .is_some_and(|f| f.barcode.iter().any(|c| c.id == b.goal.room));
    if !signed {
        return Err(Problem::NoGoalSign {
            room: b.goal.room,
            floor: b.goal.floor,
        });
    }
    Ok(())
}

/// Whether segment `s` has a point inside rectangle `r` (Liang–Barsky clipping).
fn crosses(s: &Segment, r: &Rect) -> bool {
    let d = [s.to[0] - s.from[0], s.to[1] - s.from[1]];
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    let bounds = (0..2).flat_map(|a| [(-d[a], s.from[a] - r.min[a]), (d[a], r.max[a] - s.from[a])]);
    for (p, q) in bounds {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    t0 <= t1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::P;
    use std::path::Path;

    #[test]
    fn malformed_buildings_are_refused_with_the_file_name() {
        let good = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("buildings/building-a.toml"),
        )
        .unwrap();
        assert!(Building::parse(&good, "good.toml").is_ok());
        let cases = [
            good.replacen("name =", "nme =", 1),
            good.replacen("level = 3", "level = 7", 1),
            good.replacen("travel_s = 2.5", "travel_s = -1.0", 1),
            good.replacen("id = 405", "id = 850", 1),
            good.replacen("room = 405", "room = 499", 1),
            good.replacen("start = [2.0, 2.0, 0.0]", "start = [4.2, 1.5, 0.0]", 1),
            "name = 'x'\n".to_string(),
        ];
        for (i, text) in cases.iter().enumerate() {
            let e = Building::parse(text, "bad.toml").unwrap_err();
            assert!(e.to_string().contains("bad.toml"), "case {i}: {e}");
        }
        let e = Building::load(Path::new("/nonexistent/b.toml")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/b.toml"), "{e}");
    }

    #[test]
    fn segments_crossing_a_rectangle_are_found() {
        let r = Rect {
            min: [0.0, 0.0],
            max: [1.0, 1.0],
        };
        let s = |a: P, b: P| Segment { from: a, to: b };
        assert!(crosses(&s([-1.0, 0.5], [2.0, 0.5]), &r));
        assert!(crosses(&s([0.5, 0.5], [0.6, 0.6]), &r));
        assert!(!crosses(&s([-1.0, 1.5], [2.0, 1.5]), &r));
        assert!(!crosses(&s([1.5, -1.0], [3.0, 2.0]), &r));
    }
}
