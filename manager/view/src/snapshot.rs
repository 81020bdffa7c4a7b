//! `skillfab view --snapshot FILE.svg`: one moment of what a viewer is sent, drawn from above.
//!
//! The snapshot is a viewer of its own hub, in the same process: it subscribes to `/scene`,
//! `/robot`, `/tf` and `/plan` as any viewer does, takes the messages it is sent for a moment,
//! and draws them — the floor the robot is on (walls, doors, boxes, barcodes, cabins), the
//! robot and its sonar cones placed by the transforms, the true pose when the hub reads a
//! ground-truth file, and the plan's running branch beside the map.

use crate::conn::Outbox;
use crate::hub::{FromViewer, Hub, HubOptions};
use crate::protocol::{ClientMessage, Subscription};
use crate::scene::{FLOOR_HEIGHT, Scene};
use serde_json::Value as Json;
use skillfab_proto::domain::Domain;
use std::collections::HashMap;
use std::fmt::Write;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::channel;
use std::time::{Duration, Instant};
use tungstenite::Message;

/// How long the snapshot waits for the robot's pose and sonar.
const WAIT: Duration = Duration::from_secs(5);
/// Pixels per metre.
const SCALE: f64 = 50.0;
/// Margin (px).
const MARGIN: f64 = 30.0;
/// Width of the plan panel (px).
const PANEL: f64 = 360.0;

/// Why no snapshot was written.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// Nothing to draw the robot with.
    #[error(
        "no odometry and sonar sample (and ground-truth record, with --truth) within {0:?}: is a fabric with the denning device (and the simulator writing that file) running in this domain?"
    )]
    NoRobot(Duration),
    /// The hub.
    #[error(transparent)]
    Fabric(#[from] skillfab_proto::Error),
    /// The file.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
}

/// A 2-D rigid transform: x, y, yaw, and z for the floor.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Tf {
    x: f64,
    y: f64,
    z: f64,
    yaw: f64,
}

impl Tf {
    fn of(t: &Json) -> Tf {
        let n = |v: &Json| v.as_f64().unwrap_or(0.0);
        let (qz, qw) = (n(&t["rotation"]["z"]), n(&t["rotation"]["w"]));
        Tf {
            x: n(&t["translation"]["x"]),
            y: n(&t["translation"]["y"]),
            z: n(&t["translation"]["z"]),
            yaw: 2.0 * qz.atan2(qw),
        }
    }

    fn then(self, b: Tf) -> Tf {
        let (s, c) = self.yaw.sin_cos();
        Tf {
            x: self.x + c * b.x - s * b.y,
            y: self.y + s * b.x + c * b.y,
            z: self.z + b.z,
            yaw: self.yaw + b.yaw,
        }
    }

    fn apply(self, p: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.yaw.sin_cos();
        [self.x + c * p[0] - s * p[1], self.y + s * p[0] + c * p[1]]
    }
}

/// What the snapshot was sent.
#[derive(Default)]
struct Seen {
    scene: Option<Json>,
    robot: Option<Json>,
    plan: Option<Json>,
    frames: HashMap<String, Tf>,
}

impl Seen {
    fn take(&mut self, topic: &str, msg: Json) {
        match topic {
            "/scene" => self.scene = Some(msg),
            "/robot" => self.robot = Some(msg),
            "/plan" => self.plan = Some(msg),
            "/tf" => {
                for t in msg["transforms"].as_array().into_iter().flatten() {
                    if let Some(child) = t["child_frame_id"].as_str() {
                        self.frames.insert(child.to_string(), Tf::of(t));
                    }
                }
            }
            _ => {}
        }
    }

    fn complete(&self, wants_scene: bool, wants_truth: bool) -> bool {
        self.robot.is_some()
            && self.frames.contains_key("base_link")
            && (!wants_scene || self.scene.is_some())
            && (!wants_truth || self.frames.contains_key("truth"))
    }
}

/// Runs a hub over `domain`, watches it as a viewer for a moment, and writes the SVG.
pub fn take(
    domain: &Domain,
    scene: Option<Scene>,
    truth: Option<&Path>,
    out: &Path,
) -> Result<(), SnapshotError> {
    let (wants_scene, wants_truth) = (scene.is_some(), truth.is_some());
    let title = scene.as_ref().map_or_else(String::new, |s| s.name.clone());
    let (to_hub, from_viewers) = channel();
    let stop = Arc::new(AtomicBool::new(false));
    let thread = Hub::spawn(
        HubOptions {
            domain: domain.clone(),
            scene,
            truth: truth.map(Path::to_path_buf),
            max_hz: None,
        },
        from_viewers,
        stop.clone(),
    )?;
    let outbox = Arc::new(Outbox::default());
    let _ = to_hub.send(FromViewer::Joined {
        id: 1,
        outbox: outbox.clone(),
        wishes: crate::conn::Wishes::default(),
    });
    let mut topics: HashMap<u32, String> = HashMap::new();
    let mut seen = Seen::default();
    let started = Instant::now();
    while started.elapsed() < WAIT && !seen.complete(wants_scene, wants_truth) {
        std::thread::sleep(Duration::from_millis(50));
        let (control, data) = outbox.take();
        let mut subscribe = Vec::new();
        for m in control {
            let Message::Text(t) = m else { continue };
            let Ok(j) = serde_json::from_str::<Json>(&t) else {
                continue;
            };
            if j["op"] != "advertise" {
                continue;
            }
            for c in j["channels"].as_array().into_iter().flatten() {
                let (Some(id), Some(topic)) = (c["id"].as_u64(), c["topic"].as_str()) else {
                    continue;
                };
                if ["/scene", "/robot", "/tf", "/plan"].contains(&topic) {
                    let id = id as u32;
                    topics.insert(id, topic.to_string());
                    subscribe.push(Subscription { id, channel_id: id });
                }
            }
        }
        if !subscribe.is_empty() {
            let _ = to_hub.send(FromViewer::Message {
                id: 1,
                message: ClientMessage::Subscribe {
                    subscriptions: subscribe,
                },
            });
        }
        for frame in data {
            let Some(sub) = frame.get(1..5).and_then(|b| b.try_into().ok()) else {
                continue;
            };
            let (Some(topic), Some(payload)) =
                (topics.get(&u32::from_le_bytes(sub)), frame.get(13..))
            else {
                continue;
            };
            if let Ok(j) = serde_json::from_slice::<Json>(payload) {
                seen.take(topic, j);
            }
        }
    }
    // The plan may come a little after the robot: take what is queued.
    stop.store(true, Ordering::Relaxed);
    drop(to_hub);
    let _ = thread.join();
    if !seen.complete(wants_scene, wants_truth) {
        return Err(SnapshotError::NoRobot(WAIT));
    }
    let svg = draw(&seen, &title);
    std::fs::write(out, svg).map_err(|source| SnapshotError::Write {
        path: out.display().to_string(),
        source,
    })
}

/// Where things go on the page.
struct Page {
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Page {
    fn px(&self, p: [f64; 2]) -> (f64, f64) {
        (
            MARGIN + (p[0] - self.lo[0]) * SCALE,
            MARGIN + (self.hi[1] - p[1]) * SCALE,
        )
    }
}

fn rgba(c: &Json) -> String {
    let n = |k: &str| c[k].as_f64().unwrap_or(0.0);
    format!(
        "rgba({:.0},{:.0},{:.0},{:.2})",
        n("r") * 255.0,
        n("g") * 255.0,
        n("b") * 255.0,
        n("a")
    )
}

fn xyz(p: &Json) -> [f64; 3] {
    let n = |k: &str| p[k].as_f64().unwrap_or(0.0);
    [n("x"), n("y"), n("z")]
}

/// Draws one entity's primitives, placed by `tf`, keeping those between `z0` and `z1`.
fn entity(svg: &mut String, page: &Page, e: &Json, tf: Tf, (z0, z1): (f64, f64)) {
    let on_floor = |z: f64| z + tf.z >= z0 && z + tf.z < z1;
    let poly = |svg: &mut String, pts: &[[f64; 2]], fill: &str, stroke: &str| {
        let pts: Vec<String> = pts
            .iter()
            .map(|p| {
                let (x, y) = page.px(tf.apply(*p));
                format!("{x:.1},{y:.1}")
            })
            .collect();
        let _ = writeln!(
            svg,
            r#"<polygon points="{}" fill="{fill}" stroke="{stroke}" stroke-width="0.5"/>"#,
            pts.join(" ")
        );
    };
    for c in e["cubes"].as_array().into_iter().flatten() {
        let at = xyz(&c["pose"]["position"]);
        if !on_floor(at[2]) {
            continue;
        }
        let yaw = Tf::of(&serde_json::json!({"rotation": c["pose"]["orientation"]})).yaw;
        let (hx, hy) = (
            c["size"]["x"].as_f64().unwrap_or(0.0) / 2.0,
            c["size"]["y"].as_f64().unwrap_or(0.0) / 2.0,
        );
        let (s, co) = yaw.sin_cos();
        let corner = |dx: f64, dy: f64| [at[0] + co * dx - s * dy, at[1] + s * dx + co * dy];
        let pts = [
            corner(-hx, -hy),
            corner(hx, -hy),
            corner(hx, hy),
            corner(-hx, hy),
        ];
        poly(svg, &pts, &rgba(&c["color"]), "none");
    }
    for t in e["triangles"].as_array().into_iter().flatten() {
        let pts: Vec<[f64; 3]> = t["points"]
            .as_array()
            .into_iter()
            .flatten()
            .map(xyz)
            .collect();
        let colors = t["colors"].as_array();
        for (i, tri) in pts.chunks_exact(3).enumerate() {
            if !on_floor(tri[0][2]) {
                continue;
            }
            let c = colors.and_then(|c| c.get(i * 3)).unwrap_or(&t["color"]);
            let flat: Vec<[f64; 2]> = tri.iter().map(|p| [p[0], p[1]]).collect();
            poly(svg, &flat, &rgba(c), "none");
        }
    }
    for l in e["lines"].as_array().into_iter().flatten() {
        let pts: Vec<[f64; 3]> = l["points"]
            .as_array()
            .into_iter()
            .flatten()
            .map(xyz)
            .collect();
        let scale_invariant = l["scale_invariant"].as_bool().unwrap_or(false);
        let thick = l["thickness"].as_f64().unwrap_or(0.05);
        let width = if scale_invariant {
            thick
        } else {
            (thick * SCALE).max(0.8)
        };
        for seg in pts.chunks_exact(2) {
            if !on_floor(seg[0][2]) {
                continue;
            }
            let (a, b) = (
                page.px(tf.apply([seg[0][0], seg[0][1]])),
                page.px(tf.apply([seg[1][0], seg[1][1]])),
            );
            let _ = writeln!(
                svg,
                r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{}" stroke-width="{width:.1}" stroke-linecap="round"/>"#,
                a.0,
                a.1,
                b.0,
                b.1,
                rgba(&l["color"])
            );
        }
    }
    for c in e["cylinders"]
        .as_array()
        .into_iter()
        .chain(e["spheres"].as_array())
        .flatten()
    {
        let at = xyz(&c["pose"]["position"]);
        if !on_floor(at[2]) && !on_floor(0.0) {
            continue;
        }
        let (x, y) = page.px(tf.apply([at[0], at[1]]));
        let r = c["size"]["x"].as_f64().unwrap_or(0.1) / 2.0 * SCALE;
        let _ = writeln!(
            svg,
            r#"<circle cx="{x:.1}" cy="{y:.1}" r="{r:.1}" fill="{}"/>"#,
            rgba(&c["color"])
        );
    }
    for a in e["arrows"].as_array().into_iter().flatten() {
        let len =
            a["shaft_length"].as_f64().unwrap_or(0.3) + a["head_length"].as_f64().unwrap_or(0.1);
        let (p, q) = (page.px(tf.apply([0.0, 0.0])), page.px(tf.apply([len, 0.0])));
        let _ = writeln!(
            svg,
            r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{}" stroke-width="3"/>"#,
            p.0,
            p.1,
            q.0,
            q.1,
            rgba(&a["color"])
        );
    }
    for t in e["texts"].as_array().into_iter().flatten() {
        let at = xyz(&t["pose"]["position"]);
        if !on_floor(at[2]) {
            continue;
        }
        let (x, y) = page.px(tf.apply([at[0], at[1]]));
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" font-size="11" fill="{}">{}</text>"#,
            x + 4.0,
            y - 4.0,
            rgba(&t["color"]),
            escape(t["text"].as_str().unwrap_or_default())
        );
    }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn status_color(s: &str) -> &'static str {
    match s {
        "running" => "#d98c00",
        "success" => "#2a8a3a",
        "failure" => "#c0392b",
        _ => "#888",
    }
}

fn draw(seen: &Seen, title: &str) -> String {
    let tf = |f: &str| seen.frames.get(f).copied().unwrap_or_default();
    let robot = tf("odom").then(tf("base_link"));
    let truth = seen.frames.get("truth").copied();
    let floor_z = truth.map_or(robot.z, |t| t.z);
    let band = (floor_z - 0.5, floor_z + FLOOR_HEIGHT - 0.5);
    // The page: the floor's scene, or around the robot without one.
    let mut lo = [robot.x - 6.0, robot.y - 6.0];
    let mut hi = [robot.x + 6.0, robot.y + 6.0];
    if let Some(scene) = &seen.scene {
        let (mut l, mut h) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for e in scene["entities"].as_array().into_iter().flatten() {
            for c in e["cubes"].as_array().into_iter().flatten() {
                let p = xyz(&c["pose"]["position"]);
                if p[2] >= band.0 && p[2] < band.1 {
                    l = [l[0].min(p[0]), l[1].min(p[1])];
                    h = [h[0].max(p[0]), h[1].max(p[1])];
                }
            }
        }
        if l[0].is_finite() {
            (lo, hi) = ([l[0] - 1.0, l[1] - 1.0], [h[0] + 1.0, h[1] + 1.0]);
        }
    }
    let page = Page { lo, hi };
    let (w, h) = (
        (hi[0] - lo[0]) * SCALE + 2.0 * MARGIN,
        (hi[1] - lo[1]) * SCALE + 2.0 * MARGIN,
    );
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{:.0}" height="{:.0}" font-family="sans-serif">"#,
        w + PANEL,
        h.max(300.0)
    );
    let _ = writeln!(
        svg,
        r##"<rect width="100%" height="100%" fill="#fbfbf8"/>"##
    );
    if let Some(scene) = &seen.scene {
        for e in scene["entities"].as_array().into_iter().flatten() {
            entity(&mut svg, &page, e, Tf::default(), band);
        }
    }
    if let Some(t) = truth {
        let (x, y) = page.px([t.x, t.y]);
        let _ = writeln!(
            svg,
            r#"<circle cx="{x:.1}" cy="{y:.1}" r="{:.1}" fill="none" stroke="black" stroke-dasharray="4 3"/>"#,
            denning_sim::sim::RADIUS * SCALE
        );
    }
    if let Some(r) = &seen.robot {
        for e in r["entities"].as_array().into_iter().flatten() {
            entity(
                &mut svg,
                &page,
                e,
                robot,
                (f64::NEG_INFINITY, f64::INFINITY),
            );
        }
    }
    // The panel: title, pose, the plan's running branch and its nodes by status.
    let x0 = w + 10.0;
    let mut y = 30.0;
    let mut line = |svg: &mut String, text: &str, color: &str, size: u32, indent: f64| {
        let _ = writeln!(
            svg,
            r#"<text x="{:.0}" y="{y:.0}" font-size="{size}" fill="{color}">{}</text>"#,
            x0 + indent,
            escape(text)
        );
        y += f64::from(size) + 6.0;
    };
    line(
        &mut svg,
        &format!("skillfab view — {title}"),
        "#222",
        16,
        0.0,
    );
    line(
        &mut svg,
        &format!(
            "odometry pose x {:.2} m, y {:.2} m, heading {:.0}°",
            robot.x,
            robot.y,
            robot.yaw.to_degrees()
        ),
        "#222",
        12,
        0.0,
    );
    if truth.is_some() {
        line(&mut svg, "dashed circle: the true pose", "#222", 12, 0.0);
    }
    match &seen.plan {
        Some(p) => {
            line(
                &mut svg,
                &format!(
                    "plan {} at cycle {}",
                    p["plan"].as_str().unwrap_or("?"),
                    p["cycle"]
                ),
                "#222",
                14,
                0.0,
            );
            line(&mut svg, "running branch:", "#222", 12, 0.0);
            for n in p["running_branch"].as_array().into_iter().flatten() {
                line(
                    &mut svg,
                    n["node"].as_str().unwrap_or_default(),
                    status_color("running"),
                    12,
                    10.0 + 12.0 * n["depth"].as_f64().unwrap_or(0.0),
                );
            }
            let mut counts: HashMap<&str, usize> = HashMap::new();
            for n in p["nodes"].as_array().into_iter().flatten() {
                *counts
                    .entry(n["status"].as_str().unwrap_or("idle"))
                    .or_default() += 1;
            }
            for s in ["running", "success", "failure", "idle"] {
                line(
                    &mut svg,
                    &format!("{s}: {} nodes", counts.get(s).copied().unwrap_or(0)),
                    status_color(s),
                    12,
                    0.0,
                );
            }
        }
        None => line(&mut svg, "no plan running", "#888", 12, 0.0),
    }
    svg.push_str("</svg>\n");
    svg
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn transforms_compose_as_frames_do() {
        let odom = Tf {
            x: 1.0,
            y: 2.0,
            z: 3.0,
            yaw: std::f64::consts::FRAC_PI_2,
        };
        let base = Tf {
            x: 1.0,
            y: 0.0,
            z: 0.0,
            yaw: 0.0,
        };
        let r = odom.then(base);
        assert!(
            (r.x - 1.0).abs() < 1e-9 && (r.y - 3.0).abs() < 1e-9,
            "{r:?}"
        );
        let t = Tf::of(&json!({"translation": {"x": 1.0, "y": 2.0, "z": 0.0},
                               "rotation": crate::scene::quaternion(0.5)}));
        assert!((t.yaw - 0.5).abs() < 1e-9);
    }

    #[test]
    fn the_picture_holds_the_floor_the_robot_and_the_running_branch() {
        let scene = Scene::of_world(&denning_sim::world::World {
            name: "box".into(),
            start: [1.0, 1.0, 0.0],
            outside: None,
            wall: vec![denning_sim::world::Segment {
                from: [0.0, 0.0],
                to: [4.0, 0.0],
            }],
            boxes: vec![],
            door: vec![],
            barcode: vec![],
        });
        let mut seen = Seen::default();
        let stamp = json!({"sec": 0, "nsec": 0});
        seen.take("/scene", scene.update(stamp.clone()));
        let mut ranges = vec![f64::INFINITY; 24];
        ranges[0] = 1.0;
        seen.take(
            "/robot",
            crate::scene::robot_update("base_link", &ranges, &stamp),
        );
        seen.take(
            "/tf",
            json!({"transforms": [{"child_frame_id": "base_link",
                "translation": {"x": 0.5, "y": 0.0, "z": 0.0}, "rotation": crate::scene::quaternion(0.0)}]}),
        );
        seen.take(
            "/plan",
            json!({"plan": "exit-lab", "cycle": 7, "nodes": [{"status": "running"}],
                   "running_branch": [{"depth": 0, "node": "Sequence"},
                                      {"depth": 1, "node": "Action explore"}]}),
        );
        assert!(seen.complete(true, false));
        let svg = draw(&seen, "box");
        assert!(svg.starts_with("<svg"), "{svg}");
        assert_eq!(
            svg.matches("<polygon").count(),
            1 + 1,
            "the wall and one sonar cone"
        );
        assert!(svg.contains("Action explore") && svg.contains("cycle 7"));
        assert!(svg.contains("<circle"), "the robot's body");
        assert!(svg.trim_end().ends_with("</svg>"));
    }
}
