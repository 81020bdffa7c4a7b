//! The robot model: synchro-drive kinematics with acceleration limits, collisions and stall,
//! odometry with seeded drift, a 24-sonar ring with cones, noise and grazing-angle misses,
//! and a barcode camera. Deterministic for a given seed and command sequence.

use crate::world::{Segment, World, point_segment, ray_hit};
use denning::codec::{Sighting, Status};
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
    /// The world.
    pub world: World,
    segments: Vec<Segment>,
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
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

impl Sim {
    /// A robot at the world's start.
    pub fn new(world: World, seed: u64) -> Sim {
        let mut rng = Rng::new(seed);
        let drift = [0.01 * rng.gauss(), 0.01 * rng.gauss()];
        let start = world.start;
        Sim {
            segments: world.segments(),
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
        for b in self.world.barcode.clone() {
            let (dx, dy) = (b.at[0] - x, b.at[1] - y);
            let range = dx.hypot(dy);
            let bearing = wrap(dy.atan2(dx) - th);
            if range > CAMERA_RANGE || bearing.abs() > CAMERA_HALF_FOV {
                continue;
            }
            let d = [dx / range, dy / range];
            let blocked = self
                .segments
                .iter()
                .filter_map(|s| ray_hit([x, y], d, s))
                .any(|(t, _)| t < range - 0.05);
            if blocked {
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
