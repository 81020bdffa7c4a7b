//! The robot model: synchro-drive kinematics with acceleration limits, collisions and stall,
//! odometry with seeded drift, a 24-sonar ring with cones, noise and grazing-angle misses,
//! and a barcode camera; a button pusher and a speaker. In a plain [`World`] or in a
//! [`Building`] with elevators ([`crate::site`]). Deterministic for a given seed and command
//! sequence.

use crate::building::{Building, START_CLEARANCE, clearance};
use crate::site::{Mark, Site};
use crate::world::{Barcode, P, Segment, World, point_segment, ray_hit};
use denning::codec::{MAX_SIGHTINGS, Sighting, Status};
use std::f64::consts::{PI, TAU};

/// Robot radius (m).
pub const RADIUS: f64 = 0.36;
pub use denning::codec::SONARS;
/// Largest sonar range (m).
pub const SONAR_MAX: f64 = 10.0;
/// Smallest sonar range (m).
pub const SONAR_MIN: f64 = 0.15;
/// Half the sonar cone (rad): 15°.
pub const CONE_HALF: f64 = 15.0 * PI / 180.0;
/// Beyond this incidence angle from the normal a ping reflects away (specular miss).
pub const GRAZING: f64 = 65.0 * PI / 180.0;
/// Camera half field of view.
pub const CAMERA_HALF_FOV: f64 = 30.0 * PI / 180.0;
/// Camera range (m).
pub const CAMERA_RANGE: f64 = 6.0;
/// Translate acceleration limit (m/s²).
pub const ACCEL: f64 = 0.5;
/// Rotate acceleration limit (rad/s²).
pub const RACCEL: f64 = 100.0 * PI / 180.0;
/// How far ahead of the robot's centre the pusher's tip reaches (m).
pub const REACH: f64 = 0.75;
/// How far off the heading a button may be for the pusher to press it (rad): 12°.
pub const PUSH_ALIGN: f64 = 12.0 * PI / 180.0;

/// A seeded random source (splitmix64) with Gaussian samples.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// From a seed.
    pub fn new(seed: u64) -> Rng {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal.
    pub fn gauss(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-12);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
    }
}

/// The simulated robot in its world.
#[derive(Debug, Clone)]
pub struct Sim {
    /// The world: a plain world, or in a building the fixed layout of the robot's floor.
    pub world: World,
    /// What blocks motion, sound and sight.
    segments: Vec<Segment>,
    /// What the camera can see (the world's, or the floor's and the cars').
    barcodes: Vec<Barcode>,
    /// What each of `barcodes` is.
    marks: Vec<Mark>,
    /// The building and its cars (`None`: a plain world).
    site: Option<Box<Site>>,
    /// True pose (m, m, rad).
    pub pose: [f64; 3],
    /// Odometry pose (drifts).
    pub odom: [f64; 3],
    /// Current velocities.
    pub vel: [f64; 2],
    /// Commanded velocities.
    pub cmd: [f64; 2],
    /// Motors enabled.
    pub enabled: bool,
    /// Stalled in the last step.
    pub stall: bool,
    /// Bumper segments in contact (bit 0: front, clockwise, 8 segments).
    pub bumpers: u16,
    /// Collisions so far (steps that hit something).
    pub collisions: u64,
    /// Simulated time (s).
    pub time: f64,
    rng: Rng,
    /// Odometry scale errors (translate, rotate), fixed per seed.
    drift: [f64; 2],
    next_group: usize,
    /// Pusher strokes so far.
    pub strokes: u16,
    /// Buttons pressed so far.
    pub presses: u16,
    /// Messages spoken so far.
    pub said: u16,
    /// When a message was first spoken at the building's goal (s).
    pub delivered: Option<f64>,
    /// Fault injection: while the simulated time (s) is in this range no car moves with its
    /// doors closed and no hall call is answered (the button is pressed, none comes).
    pub cars_out: std::ops::Range<f64>,
}

/// What the robot keeps when the process that simulates its serial side restarts: its body
/// (pose, velocities, collisions so far) and its controller's odometry, at a simulated time.
/// A real robot does not jump back to its start because its link process crashed.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Physical {
    /// True pose (m, m, rad).
    pub pose: [f64; 3],
    /// Odometry pose.
    pub odom: [f64; 3],
    /// Velocities (m/s, rad/s).
    pub vel: [f64; 2],
    /// Collisions so far.
    pub collisions: u64,
    /// Simulated time (s).
    pub time: f64,
    /// The floor (0 in a plain world, and in a state file that does not say).
    #[serde(default)]
    pub floor: i32,
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

/// The building's start moved uniformly within its jitter, redrawn until it is clear of
/// walls (the unmoved start is: the building is checked).
fn jittered(b: &Building, rng: &mut Rng) -> [f64; 3] {
    let segments = b.segments(b.start_floor);
    for _ in 0..1000 {
        let p: [f64; 3] =
            std::array::from_fn(|i| b.start[i] + (2.0 * rng.uniform() - 1.0) * b.start_jitter[i]);
        if clearance(&segments, [p[0], p[1]]) >= START_CLEARANCE {
            return [p[0], p[1], wrap(p[2])];
        }
    }
    b.start
}

impl Sim {
    /// A robot at the world's start.
    pub fn new(world: World, seed: u64) -> Sim {
        let start = world.start;
        let (segments, barcodes) = (world.segments(), world.barcode.clone());
        Sim::with(world, start, segments, barcodes, None, seed)
    }

    /// A robot at the building's start (`building` checked by [`Building::parse`]), moved
    /// within its jitter by the seed, which also places the cars.
    pub fn in_building(building: Building, seed: u64) -> Sim {
        // A stream of its own: the robot's noise and drift are those of the same seed in a
        // world.
        let mut rng = Rng::new(seed ^ 0xB17D_1A6E_E1E7_A70E);
        let start = jittered(&building, &mut rng);
        let site = Site::new(building, rng);
        let world = site.world().unwrap_or_else(|| World {
            name: site.building().name.clone(),
            start,
            outside: None,
            wall: Vec::new(),
            boxes: Vec::new(),
            door: Vec::new(),
            barcode: Vec::new(),
        });
        let mut sim = Sim::with(world, start, Vec::new(), Vec::new(), Some(site), seed);
        sim.refresh();
        sim
    }

    fn with(
        world: World,
        start: [f64; 3],
        segments: Vec<Segment>,
        barcodes: Vec<Barcode>,
        site: Option<Site>,
        seed: u64,
    ) -> Sim {
        let mut rng = Rng::new(seed);
        let drift = [0.01 * rng.gauss(), 0.01 * rng.gauss()];
        Sim {
            marks: vec![Mark::Sign; barcodes.len()],
            segments,
            barcodes,
            site: site.map(Box::new),
            world,
            pose: start,
            odom: [0.0, 0.0, start[2]],
            vel: [0.0; 2],
            cmd: [0.0; 2],
            enabled: false,
            stall: false,
            bumpers: 0,
            collisions: 0,
            time: 0.0,
            rng,
            drift,
            next_group: 0,
            strokes: 0,
            presses: 0,
            said: 0,
            delivered: None,
            cars_out: 0.0..0.0,
        }
    }

    /// The building the robot is in (`None`: a plain world).
    pub fn site(&self) -> Option<&Site> {
        self.site.as_deref()
    }

    /// The robot's floor (0 in a plain world; riding between floors, the one it left).
    pub fn floor(&self) -> i32 {
        self.site.as_ref().map_or(0, |s| s.floor())
    }

    /// Whether the robot rides an elevator car between floors.
    pub fn in_transit(&self) -> bool {
        self.site.as_ref().is_some_and(|s| s.in_transit())
    }

    /// Whether the robot is in the world's (in a building: its floor's) outside region.
    pub fn outside(&self) -> bool {
        !self.in_transit() && self.world.is_outside([self.pose[0], self.pose[1]])
    }

    /// Whether the robot is back at the lab (a building's ground truth: [`Site::at_lab`]).
    pub fn at_lab(&self) -> bool {
        self.site
            .as_ref()
            .is_some_and(|s| s.at_lab([self.pose[0], self.pose[1]]))
    }

    /// Rebuilds the building's segments and barcodes if anything in sight changed, and the
    /// floor's world if the robot changed floors.
    fn refresh(&mut self) {
        let Some(site) = self.site.as_mut() else {
            return;
        };
        site.refresh(&mut self.segments, &mut self.barcodes, &mut self.marks);
        if let Some(w) = site.moved_floor() {
            self.world = w;
        }
    }

    /// The robot's physical state, to resume from.
    pub fn physical(&self) -> Physical {
        Physical {
            pose: self.pose,
            odom: self.odom,
            vel: self.vel,
            collisions: self.collisions,
            time: self.time,
            floor: self.floor(),
        }
    }

    /// Puts the robot back in `p` (motors off and no command, as after a power-on of the
    /// link: the device enables them again at its handshake).
    pub fn resume(&mut self, p: Physical) {
        self.pose = p.pose;
        self.odom = p.odom;
        self.vel = p.vel;
        self.collisions = p.collisions;
        self.time = p.time;
        if let Some(site) = self.site.as_mut() {
            site.place(p.floor, [p.pose[0], p.pose[1]]);
            self.refresh();
        }
    }

    fn clearance(&self, p: [f64; 2]) -> (f64, Option<[f64; 2]>) {
        self.segments.iter().map(|s| point_segment(p, s)).fold(
            (f64::INFINITY, None),
            |(d, c), (d2, c2)| {
                if d2 < d { (d2, Some(c2)) } else { (d, c) }
            },
        )
    }

    /// Advances `dt` seconds.
    pub fn step(&mut self, dt: f64) {
        let target = if self.enabled { self.cmd } else { [0.0, 0.0] };
        let approach = |v: f64, t: f64, a: f64| v + (t - v).clamp(-a * dt, a * dt);
        self.vel = [
            approach(self.vel[0], target[0], ACCEL),
            approach(self.vel[1], target[1], RACCEL),
        ];
        let [x, y, th] = self.pose;
        let nth = wrap(th + self.vel[1] * dt);
        let mid = th + self.vel[1] * dt / 2.0;
        let np = [
            x + self.vel[0] * dt * mid.cos(),
            y + self.vel[0] * dt * mid.sin(),
        ];
        let (clear, contact) = self.clearance(np);
        let (now_clear, _) = self.clearance([x, y]);
        self.bumpers = 0;
        // Blocked when the move would end inside an obstacle's reach and not away from it.
        if clear < RADIUS && clear <= now_clear && self.vel[0] != 0.0 {
            // Blocked: rotate in place only, flag stall and the bumper segment touched.
            self.stall = true;
            self.collisions += 1;
            if let Some(c) = contact {
                let bearing = wrap((c[1] - y).atan2(c[0] - x) - th);
                let seg = ((-bearing).rem_euclid(TAU) / (TAU / 8.0)).round() as u16 % 8;
                self.bumpers = 1 << seg;
            }
            self.vel[0] = 0.0;
            self.pose = [x, y, nth];
        } else {
            self.stall = false;
            self.pose = [np[0], np[1], nth];
        }
        // Odometry integrates the wheel motion with a per-seed scale error and a little noise.
        let dv = self.vel[0] * dt * (1.0 + self.drift[0]) + 0.0005 * dt * self.rng.gauss();
        let dw = self.vel[1] * dt * (1.0 + self.drift[1]);
        let om = self.odom[2] + dw / 2.0;
        self.odom = [
            self.odom[0] + dv * om.cos(),
            self.odom[1] + dv * om.sin(),
            wrap(self.odom[2] + dw),
        ];
        self.time += dt;
        let out = self.cars_out();
        if let Some(site) = self.site.as_mut() {
            site.out_of_service(out);
            site.step(dt, [self.pose[0], self.pose[1]]);
            self.refresh();
        }
    }

    /// Whether nothing stands between `from` and a barcode or button at `to`, `range` away
    /// (it hangs just in front of its wall: what is within 5 cm behind it does not hide it).
    fn in_sight(&self, from: P, to: P, range: f64) -> bool {
        let d = [(to[0] - from[0]) / range, (to[1] - from[1]) / range];
        !self
            .segments
            .iter()
            .filter_map(|s| ray_hit(from, d, s))
            .any(|(t, _)| t < range - 0.05)
    }

    /// One stroke of the button pusher. Its tip reaches [`REACH`] straight ahead: it presses
    /// the nearest button in sight within [`REACH`] of the robot's centre and [`PUSH_ALIGN`] of
    /// its heading. Returns the button's id, or 0 for a miss (always, in a plain world).
    pub fn push(&mut self) -> u16 {
        self.strokes = self.strokes.saturating_add(1);
        let [x, y, th] = self.pose;
        let hit = self
            .barcodes
            .iter()
            .zip(&self.marks)
            .filter(|(_, m)| m.is_button())
            .filter_map(|(b, m)| {
                let (dx, dy) = (b.at[0] - x, b.at[1] - y);
                let range = dx.hypot(dy);
                let reached = range <= REACH
                    && wrap(dy.atan2(dx) - th).abs() <= PUSH_ALIGN
                    && self.in_sight([x, y], b.at, range);
                reached.then_some((range, b.id, *m))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let Some((_, id, mark)) = hit else {
            tracing::debug!(strokes = self.strokes, "the pusher pressed nothing");
            return 0;
        };
        self.presses = self.presses.saturating_add(1);
        tracing::info!(button = id, floor = self.floor(), "button pressed");
        if matches!(mark, Mark::Call) && self.cars_out() {
            tracing::info!(
                until = self.cars_out.end,
                "hall call unanswered: the cars are out of service"
            );
        } else if let Some(site) = self.site.as_mut() {
            site.press(mark);
            self.refresh();
        }
        id
    }

    /// Whether the cars are out of service now (fault injection).
    fn cars_out(&self) -> bool {
        self.cars_out.contains(&self.time)
    }

    /// Speaks `text`; in a building, on the goal floor near the goal, that delivers the
    /// message (the first time is remembered). Returns the messages spoken so far.
    pub fn say(&mut self, text: &str) -> u16 {
        self.said = self.said.saturating_add(1);
        let at_goal = self
            .site
            .as_ref()
            .is_some_and(|s| s.at_goal([self.pose[0], self.pose[1]]));
        if at_goal && self.delivered.is_none() {
            self.delivered = Some(self.time);
        }
        tracing::info!(text, said = self.said, at_goal, "the robot says");
        self.said
    }

    /// Range seen by sonar `i` (m from the ring; `None`: no echo).
    pub fn sonar(&mut self, i: usize) -> Option<f64> {
        let [x, y, th] = self.pose;
        let axis = th + i as f64 * (TAU / SONARS as f64);
        let origin = [x + RADIUS * axis.cos(), y + RADIUS * axis.sin()];
        let mut best: Option<f64> = None;
        for k in -3..=3 {
            let a = axis + f64::from(k) * CONE_HALF / 3.0;
            let d = [a.cos(), a.sin()];
            let hit = self
                .segments
                .iter()
                .filter_map(|s| ray_hit(origin, d, s))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            if let Some((t, cos)) = hit
                && cos.acos() < GRAZING
            {
                best = Some(best.map_or(t, |b: f64| b.min(t)));
            }
        }
        let r = best?;
        let noisy = r + (0.01 + 0.01 * r) * self.rng.gauss();
        (noisy <= SONAR_MAX).then(|| noisy.max(SONAR_MIN))
    }

    /// Barcodes in the camera's view with a clear line of sight.
    pub fn camera(&mut self) -> Vec<Sighting> {
        let [x, y, th] = self.pose;
        let mut out = Vec::new();
        for i in 0..self.barcodes.len() {
            let b = self.barcodes[i];
            let (dx, dy) = (b.at[0] - x, b.at[1] - y);
            let range = dx.hypot(dy);
            let bearing = wrap(dy.atan2(dx) - th);
            if range > CAMERA_RANGE || bearing.abs() > CAMERA_HALF_FOV {
                continue;
            }
            if !self.in_sight([x, y], b.at, range) {
                continue;
            }
            let r = range + 0.02 * self.rng.gauss();
            let bear = bearing + 0.5f64.to_radians() * self.rng.gauss();
            out.push(Sighting {
                id: b.id,
                bearing: (bear.to_degrees() * 10.0).round() as i16,
                range: (r * 1000.0).round().clamp(0.0, 65535.0) as u16,
            });
        }
        // A packet holds MAX_SIGHTINGS: when more are in view (a lobby), the nearest are sent.
        if out.len() > MAX_SIGHTINGS {
            out.sort_by_key(|s| s.range);
        }
        out
    }

    /// A status packet with the next sonar group's fresh readings (3 groups of 8, interleaved).
    pub fn status(&mut self) -> Status {
        let group = self.next_group;
        self.next_group = (self.next_group + 1) % 3;
        let sonars = (0..SONARS)
            .filter(|i| i % 3 == group)
            .map(|i| {
                (
                    i as u8,
                    self.sonar(i).map_or(0, |r| (r * 1000.0).round() as u16),
                )
            })
            .collect();
        let to_mm = |v: f64| ((v * 1000.0).round() as i64).rem_euclid(32768) as u16;
        Status {
            moving: self.vel[0].abs() > 1e-3 || self.vel[1].abs() > 1e-3,
            // Odometry starts at (16384, 16384) mm so it wraps only after 16 m either way.
            x: to_mm(self.odom[0] + 16.384),
            y: to_mm(self.odom[1] + 16.384),
            th: ((self.odom[2].rem_euclid(TAU) / TAU * 4096.0).round() as u16) % 4096,
            vel: (self.vel[0] * 1000.0).round() as i16,
            rvel: (self.vel[1].to_degrees() * 10.0).round() as i16,
            battery: 128,
            flags: u16::from(self.stall) | (self.bumpers << 1),
            sonars,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn room() -> World {
        World::parse(
            "name = 'box'\nstart = [2.0, 2.0, 0.0]\n[[wall]]\nfrom = [0.0, 0.0]\nto = [4.0, 0.0]\n[[wall]]\nfrom = [4.0, 0.0]\nto = [4.0, 4.0]\n[[wall]]\nfrom = [4.0, 4.0]\nto = [0.0, 4.0]\n[[wall]]\nfrom = [0.0, 4.0]\nto = [0.0, 0.0]\n[[barcode]]\nid = 3\nat = [3.95, 2.0]\n",
            "t",
        )
        .unwrap()
    }

    #[test]
    fn sonars_see_the_walls_at_their_distance() {
        let mut s = Sim::new(room(), 1);
        // Sonar 0 faces +x: wall at x = 4, ring at 2.36: 1.64 m.
        let r0 = s.sonar(0).unwrap();
        assert!((r0 - 1.64).abs() < 0.1, "{r0}");
        // Sonar 6 faces +y (90°).
        let r6 = s.sonar(6).unwrap();
        assert!((r6 - 1.64).abs() < 0.1, "{r6}");
    }

    #[test]
    fn driving_moves_and_walls_stall() {
        let mut s = Sim::new(room(), 2);
        s.enabled = true;
        s.cmd = [0.5, 0.0];
        for _ in 0..200 {
            s.step(0.01);
        }
        assert!(s.pose[0] > 2.5, "{:?}", s.pose);
        for _ in 0..2000 {
            s.step(0.01);
        }
        assert!(s.stall, "the wall stops it");
        assert!(s.pose[0] <= 4.0 - RADIUS + 1e-6);
        assert!(s.bumpers & 1 != 0, "front bumper");
        assert!(s.collisions > 0);
    }

    #[test]
    fn the_camera_sees_a_barcode_ahead_only() {
        let mut s = Sim::new(room(), 3);
        let seen = s.camera();
        assert_eq!(seen.len(), 1);
        assert_eq!(seen[0].id, 3);
        assert!((f64::from(seen[0].range) / 1000.0 - 1.95).abs() < 0.1);
        s.pose[2] = PI;
        assert!(s.camera().is_empty(), "behind the robot");
    }

    #[test]
    fn same_seed_same_run() {
        let run = |seed| {
            let mut s = Sim::new(room(), seed);
            s.enabled = true;
            s.cmd = [0.3, 0.2];
            (0..300)
                .map(|_| {
                    s.step(0.01);
                    s.status()
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(5), run(5));
        assert_ne!(run(5), run(6));
    }
}
