//! The demos' pictures: the trajectory over the map, with the sequencer's steps marked. A
//! world is one map; a building is one map per floor the robot was on, side by side, in the
//! order it first came to them.

use super::RunOutcome;
use denning_sim::building::Building;
use denning_sim::truth::TruthRecord;
use denning_sim::world::{Barcode, Rect, Segment, World};
use std::fmt::Write;

/// Pixels per metre.
const SCALE: f64 = 50.0;
/// Margin around and between maps (px).
const MARGIN: f64 = 50.0;
/// Height of a line of the step list (px).
const LINE: f64 = 16.0;

/// One floor's map and what the robot did on it.
struct Map<'a> {
    title: String,
    walls: Vec<Segment>,
    doors: Vec<Segment>,
    boxes: Vec<Rect>,
    barcodes: Vec<Barcode>,
    /// The trajectory's records on this map, in runs (a new run each time the robot came
    /// back to it).
    runs: Vec<Vec<&'a TruthRecord>>,
    /// Which floor of the ground truth this map is (none: a world, every record).
    floor: Option<i32>,
}

impl Map<'_> {
    /// The map's extent (m): min and max corners.
    fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        let pts = self.walls.iter().flat_map(|s| [s.from, s.to]);
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
}

/// The trajectory over the world map, with the sequencer's switches marked.
pub fn svg(w: &World, r: &RunOutcome) -> String {
    let map = Map {
        title: String::new(),
        walls: w.wall.clone(),
        doors: w.door.clone(),
        boxes: w.boxes.clone(),
        barcodes: w.barcode.clone(),
        runs: vec![r.trajectory.iter().collect()],
        floor: None,
    };
    draw(&[map], r)
}

/// One map per floor the robot was on (with the elevator cabins), the trajectory on each.
pub fn building_svg(b: &Building, r: &RunOutcome) -> String {
    let mut order: Vec<i32> = Vec::new();
    for p in &r.trajectory {
        if !order.contains(&p.floor) {
            order.push(p.floor);
        }
    }
    if order.is_empty() {
        order.push(b.start_floor);
    }
    let maps: Vec<Map> = order
        .iter()
        .filter_map(|&level| {
            let f = b.floor(level)?;
            let mut walls = f.wall.clone();
            for car in &b.elevator.cars {
                let c = car.cabin;
                walls.extend([
                    Segment {
                        from: c.min,
                        to: [c.max[0], c.min[1]],
                    },
                    Segment {
                        from: [c.max[0], c.min[1]],
                        to: c.max,
                    },
                    Segment {
                        from: c.max,
                        to: [c.min[0], c.max[1]],
                    },
                    Segment {
                        from: [c.min[0], c.max[1]],
                        to: c.min,
                    },
                ]);
            }
            let mut runs: Vec<Vec<&TruthRecord>> = Vec::new();
            let mut last_on = false;
            for p in &r.trajectory {
                let on = p.floor == level;
                if on && !last_on {
                    runs.push(Vec::new());
                }
                if let (true, Some(run)) = (on, runs.last_mut()) {
                    run.push(p);
                }
                last_on = on;
            }
            let goal = (b.goal.floor == level).then_some(b.goal.room);
            Some(Map {
                title: match goal {
                    Some(room) => format!("floor {level} (the office: room {room})"),
                    None => format!("floor {level}"),
                },
                walls,
                doors: f.door.clone(),
                boxes: f.boxes.clone(),
                barcodes: f.barcode.clone(),
                runs,
                floor: Some(level),
            })
        })
        .collect();
    draw(&maps, r)
}

/// The maps side by side, the trajectory on each, the steps marked where they happened and
/// listed below.
fn draw(maps: &[Map], r: &RunOutcome) -> String {
    let bounds: Vec<_> = maps.iter().map(Map::bounds).collect();
    let height = bounds
        .iter()
        .map(|(lo, hi)| hi[1] - lo[1])
        .fold(0.0f64, f64::max);
    // Each map's left edge (px).
    let mut lefts = Vec::new();
    let mut x = MARGIN;
    for (lo, hi) in &bounds {
        lefts.push(x);
        x += (hi[0] - lo[0]) * SCALE + MARGIN;
    }
    let width = x.max(14.0 * SCALE);
    let list_top = MARGIN + height * SCALE + 2.0 * MARGIN;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width:.0}\" height=\"{:.0}\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>",
        list_top + LINE * (r.steps.len() as f64 + 1.0)
    );
    for ((m, (lo, hi)), left) in maps.iter().zip(&bounds).zip(&lefts) {
        // Maps share a top edge; y grows upward in the world.
        let px = |x: f64| left + (x - lo[0]) * SCALE;
        let py = |y: f64| MARGIN + (hi[1] - y) * SCALE;
        let _ = writeln!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"14\">{}</text>",
            px(lo[0]),
            MARGIN - 8.0,
            m.title
        );
        let walls = m
            .walls
            .iter()
            .map(|seg| (seg, "stroke=\"black\" stroke-width=\"4\""));
        let doors = m.doors.iter().map(|seg| {
            (
                seg,
                "stroke=\"#2a2\" stroke-width=\"2\" stroke-dasharray=\"4 3\"",
            )
        });
        for (seg, style) in walls.chain(doors) {
            let _ = writeln!(
                s,
                "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" {style}/>",
                px(seg.from[0]),
                py(seg.from[1]),
                px(seg.to[0]),
                py(seg.to[1])
            );
        }
        for b in &m.boxes {
            let _ = writeln!(
                s,
                "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#bbb\" stroke=\"#555\"/>",
                px(b.min[0]),
                py(b.max[1]),
                (b.max[0] - b.min[0]) * SCALE,
                (b.max[1] - b.min[1]) * SCALE
            );
        }
        for c in &m.barcodes {
            let _ = writeln!(
                s,
                "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"8\" height=\"8\" fill=\"#d22\"/><text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
                px(c.at[0]) - 4.0,
                py(c.at[1]) - 4.0,
                px(c.at[0]) + 8.0,
                py(c.at[1]) - 6.0,
                c.id
            );
        }
        for run in &m.runs {
            let pts: Vec<String> = run
                .iter()
                .map(|p| format!("{:.1},{:.1}", px(p.x), py(p.y)))
                .collect();
            let _ = writeln!(
                s,
                "<polyline points=\"{}\" fill=\"none\" stroke=\"#15c\" stroke-width=\"2\"/>",
                pts.join(" ")
            );
        }
        for (i, (_, _, t)) in r.steps.iter().enumerate() {
            let at = r.trajectory.iter().find(|p| p.t >= *t);
            if let Some(p) = at.filter(|p| m.floor.is_none_or(|f| f == p.floor)) {
                let _ = writeln!(
                    s,
                    "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"5\" fill=\"#f80\"/><text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
                    px(p.x),
                    py(p.y),
                    px(p.x) + 7.0,
                    py(p.y) + 4.0,
                    i + 1
                );
            }
        }
    }
    let _ = writeln!(
        s,
        "<text x=\"{MARGIN:.1}\" y=\"{:.1}\" font-size=\"16\">{} — {} in {:.1} s (seed {})</text>",
        list_top - LINE,
        r.world,
        if r.success { "success" } else { "failure" },
        r.time_s,
        r.seed
    );
    for (i, (what, _, t)) in r.steps.iter().enumerate() {
        let _ = writeln!(
            s,
            "<text x=\"{MARGIN:.1}\" y=\"{:.1}\">{}. t={:.1}s {}</text>",
            list_top + LINE * (i as f64 + 0.5),
            i + 1,
            t,
            what.replace('&', "&amp;")
                .replace('<', "&lt;")
                .replace('>', "&gt;")
        );
    }
    s.push_str("</svg>\n");
    s
}
