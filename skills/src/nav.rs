//! The standard navigation skills of the exit-lab experiment. Movement skills propose on the
//! `drive` channel; default priorities: stop 10, avoid 8, go_through 6, home 4, wall_follow 3,
//! wander 2 (higher wins).

use skill_sdk::prelude::*;
use skillfab_msgs::{Barcodes, Door, Drive, Odometry, SONARS, Sonar, Target};
use std::f64::consts::{PI, TAU};

/// Angle of sonar `i` from the front (rad, counter-clockwise).
pub fn sonar_angle(i: usize) -> f64 {
    wrap(i as f64 * TAU / SONARS as f64)
}

/// Wraps an angle into −π..π.
pub fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

/// A usable range: no echo counts as far, never-read as unknown.
fn range(s: &Sonar, i: usize) -> Option<f64> {
    let r = s.range[i % SONARS];
    if r.is_nan() { None } else { Some(r.min(10.0)) }
}

/// The smallest range among sonars whose angle lies within `[from, to]` (rad).
fn min_in(s: &Sonar, from: f64, to: f64) -> f64 {
    (0..SONARS)
        .filter(|&i| {
            let a = sonar_angle(i);
            a >= from && a <= to
        })
        .filter_map(|i| range(s, i))
        .fold(f64::INFINITY, f64::min)
}

/// Output of every movement skill.
#[derive(Outputs)]
pub struct DriveOut<'a> {
    /// The proposal.
    pub drive: Proposal<'a, Drive>,
}

/// Parameters of [`Avoid`].
#[derive(Params, Debug, Clone)]
pub struct AvoidParams {
    /// Obstacles closer than this in front (m, from the ring) make it take over.
    #[param(default = 0.6, min = 0.05, max = 3.0)]
    pub safe_distance: f64,
    /// Turn rate when avoiding (rad/s).
    #[param(default = 0.9, min = 0.0, max = 3.0)]
    pub turn: f64,
    /// Forward speed while turning away (m/s).
    #[param(default = 0.05, min = -0.3, max = 0.5)]
    pub creep: f64,
}

/// Input of sonar-driven skills.
#[derive(Inputs)]
pub struct SonarIn<'a> {
    /// The ring.
    pub sonar: Input<'a, Sonar>,
}

/// Obstacle avoidance from the sonar ring: when something is closer than `safe_distance`
/// in the front arc, turn toward the freer side; otherwise propose nothing.
#[derive(Default)]
pub struct Avoid {
    /// Side chosen while an obstacle persists (stops dithering): +1 left, −1 right.
    side: f64,
}

impl Skill for Avoid {
    type Params = AvoidParams;
    type Inputs<'a> = SonarIn<'a>;
    type Outputs<'a> = DriveOut<'a>;
    const PRIORITY: i32 = 8;
    fn compute(&mut self, ctx: &Ctx<AvoidParams>, i: SonarIn, o: &mut DriveOut) -> SkillResult {
        let p = ctx.params;
        // The front arc at the safe distance, the flanks at half of it.
        let front = min_in(&i.sonar, -0.8, 0.8)
            .min(2.0 * min_in(&i.sonar, -1.4, -0.8))
            .min(2.0 * min_in(&i.sonar, 0.8, 1.4));
        if front >= p.safe_distance {
            self.side = 0.0;
            return Ok(());
        }
        if self.side == 0.0 {
            let left = min_in(&i.sonar, 0.3, 1.9);
            let right = min_in(&i.sonar, -1.9, -0.3);
            self.side = if left >= right { 1.0 } else { -1.0 };
        }
        let creep = if front < p.safe_distance * 0.5 {
            -0.05
        } else {
            p.creep
        };
        o.drive.set(Drive {
            translate: creep,
            rotate: self.side * p.turn,
        });
        Ok(())
    }
}

/// Parameters of [`Wander`].
#[derive(Params, Debug, Clone)]
pub struct WanderParams {
    /// Forward speed (m/s).
    #[param(default = 0.35, min = 0.0, max = 1.0)]
    pub speed: f64,
    /// Largest turn rate toward the chosen heading (rad/s).
    #[param(default = 0.8, min = 0.0, max = 2.0)]
    pub turn: f64,
    /// Mean length of a straight leg before a new heading is drawn (cycles).
    #[param(default = 1500, min = 10)]
    pub leg: u64,
    /// Something closer than this ahead ends the leg: a new heading is drawn among the open
    /// directions (m, from the ring).
    #[param(default = 1.0, min = 0.2, max = 5.0)]
    pub blocked: f64,
    /// A direction is open when its sonar sees at least this far (m).
    #[param(default = 2.5, min = 0.5, max = 10.0)]
    pub open: f64,
    /// After driving this far since the last look around, turn once on the spot to look
    /// around (m; 0: never).
    #[param(default = 4.0, min = 0.0, max = 100.0)]
    pub look: f64,
    /// Seed of the random choices.
    #[param(default = 1, min = 0)]
    pub seed: u64,
}

/// Inputs of [`Wander`].
#[derive(Inputs)]
pub struct WanderIn<'a> {
    /// The ring.
    pub sonar: Input<'a, Sonar>,
    /// Odometry (the heading of a leg is held in its frame).
    pub odometry: Input<'a, Odometry>,
}

/// Wandering that covers the room: straight legs; a leg ends after a random number of cycles
/// or when something is near ahead. The next heading is the open direction (the ring sees far
/// along it) that leads through the least visited ground, from a coarse map of where the robot
/// has been (odometry frame, 0.5 m cells), with a little randomness. Close obstacles are
/// `avoid`'s.
#[derive(Default)]
pub struct Wander {
    rng: u64,
    heading: Option<f64>,
    leg_ends: u64,
    /// Cycles spent in each cell.
    visits: std::collections::HashMap<(i32, i32), u32>,
    /// Distance driven since the last look around, and the last position.
    driven: f64,
    last: Option<(f64, f64, f64)>,
    /// Angle still to turn in the current look around (rad).
    turning: f64,
}

/// Cell size of the visit map (m).
const CELL: f64 = 0.5;

fn cell(x: f64, y: f64) -> (i32, i32) {
    ((x / CELL).floor() as i32, (y / CELL).floor() as i32)
}

impl Wander {
    /// Uniform in [0, 1) (xorshift).
    fn uniform(&mut self) -> f64 {
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        (self.rng >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A new leg from the pose: the open direction through the least visited cells (the
    /// farthest-seeing direction if none is open).
    fn new_leg(&mut self, p: &WanderParams, s: &Sonar, od: &Odometry, cycle: u64) {
        let mut best: Option<(f64, f64)> = None;
        for k in 0..SONARS {
            let Some(r) = range(s, k) else { continue };
            let a = wrap(od.theta + sonar_angle(k));
            let score = if r >= p.open {
                let steps = (r.min(5.0) / CELL) as usize;
                let seen: u32 = (1..=steps)
                    .map(|j| {
                        let d = j as f64 * CELL;
                        let c = cell(od.x + d * a.cos(), od.y + d * a.sin());
                        self.visits.get(&c).copied().unwrap_or(0).min(400)
                    })
                    .sum();
                f64::from(seen) / steps.max(1) as f64 + 40.0 * self.uniform()
            } else {
                // Not open: only if nothing is, the farthest.
                1e6 - r
            };
            if best.is_none_or(|b| score < b.0) {
                best = Some((score, a));
            }
        }
        let a = best.map_or(od.theta + PI, |b| b.1);
        self.heading = Some(wrap(a + 0.1 * (2.0 * self.uniform() - 1.0)));
        self.leg_ends = cycle + ((0.5 + self.uniform()) * p.leg as f64) as u64;
    }
}

impl Skill for Wander {
    type Params = WanderParams;
    type Inputs<'a> = WanderIn<'a>;
    type Outputs<'a> = DriveOut<'a>;
    const PRIORITY: i32 = 2;
    fn compute(&mut self, ctx: &Ctx<WanderParams>, i: WanderIn, o: &mut DriveOut) -> SkillResult {
        let (p, s, od) = (ctx.params, &*i.sonar, &*i.odometry);
        if self.rng == 0 {
            self.rng = p.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        }
        *self.visits.entry(cell(od.x, od.y)).or_insert(0) += 1;
        if let Some((x, y, th)) = self.last.replace((od.x, od.y, od.theta)) {
            self.driven += (od.x - x).hypot(od.y - y);
            self.turning -= wrap(od.theta - th).abs();
        }
        if p.look > 0.0 && self.driven > p.look {
            self.driven = 0.0;
            self.turning = TAU;
        }
        if self.turning > 0.0 {
            // Looking around; the next leg starts from what the ring sees after it.
            self.heading = None;
            o.drive.set(Drive {
                translate: 0.0,
                rotate: p.turn.max(0.3),
            });
            return Ok(());
        }
        let heading = match self.heading {
            Some(h) if ctx.cycle < self.leg_ends => h,
            _ => {
                self.new_leg(p, s, od, ctx.cycle);
                self.heading.unwrap_or(od.theta)
            }
        };
        let err = wrap(heading - od.theta);
        // Blocked ahead while facing the leg's way: bounce.
        if err.abs() < 0.5 && min_in(s, -0.4, 0.4) < p.blocked {
            self.new_leg(p, s, od, ctx.cycle);
        }
        o.drive.set(Drive {
            translate: p.speed * err.cos().max(0.0).powi(2),
            rotate: (2.0 * err).clamp(-p.turn, p.turn),
        });
        Ok(())
    }
}

/// Parameters of [`WallFollow`].
#[derive(Params, Debug, Clone)]
pub struct WallFollowParams {
    /// Distance to keep from the wall (m, from the ring).
    #[param(default = 0.5, min = 0.1, max = 3.0)]
    pub distance: f64,
    /// Forward speed (m/s).
    #[param(default = 0.3, min = 0.0, max = 1.0)]
    pub speed: f64,
    /// Steering gain (rad/s per rad of heading error).
    #[param(default = 1.5, min = 0.0, max = 10.0)]
    pub gain: f64,
    /// Which side the wall is on: 1 right, -1 left.
    #[param(default = 1, min = -1, max = 1)]
    pub side: i32,
    /// Cycles to hold the heading where the wall beside stops.
    #[param(default = 600, min = 0)]
    pub gap: u64,
}

/// Hallway following: keeps `distance` from the wall on the right (or left). The sonars 60°
/// and 120° off the heading on the wall's side give the heading relative to the wall (equal
/// ranges: parallel); the nearest side reading gives the distance, corrected by approaching
/// or leaving the wall at up to 30°. A wall ahead turns it away. Where the wall beside stops,
/// it holds its heading for `gap` cycles (past an open door), then curves toward the side
/// (around a corner).
#[derive(Default)]
pub struct WallFollow {
    /// Cycles since the wall was last beside.
    lost: u64,
}

impl Skill for WallFollow {
    type Params = WallFollowParams;
    type Inputs<'a> = SonarIn<'a>;
    type Outputs<'a> = DriveOut<'a>;
    const PRIORITY: i32 = 3;
    fn compute(
        &mut self,
        ctx: &Ctx<WallFollowParams>,
        i: SonarIn,
        o: &mut DriveOut,
    ) -> SkillResult {
        let p = ctx.params;
        // Work as if the wall were on the right; mirror for the left.
        let side = if p.side < 0 { -1.0 } else { 1.0 };
        let at = |deg: f64| {
            let a = -side * deg.to_radians();
            min_in(&i.sonar, a - 0.01, a + 0.01)
        };
        let (front, back) = (at(60.0).min(5.0), at(120.0).min(5.0));
        let beside = at(60.0)
            .min(at(75.0))
            .min(at(90.0))
            .min(at(105.0))
            .min(at(120.0));
        let ahead = min_in(&i.sonar, -0.5, 0.5);
        self.lost = if beside > 2.0 { self.lost + 1 } else { 0 };
        let (translate, turn_left) = if ahead < p.distance + 0.3 {
            // A wall ahead: turn away from the wall's side on the spot.
            (0.0, 1.0)
        } else if beside > 2.0 && self.lost <= p.gap {
            // A gap in the wall: straight on.
            (p.speed, 0.0)
        } else if beside > 2.0 {
            // No wall: curve toward the side.
            (p.speed, -0.3 / p.gain.max(0.1))
        } else {
            // Heading toward the wall (positive) from the front/back imbalance.
            let toward = ((1.0 - front / back) / 0.54).clamp(-0.6, 0.6);
            let approach = (0.8 * (beside - p.distance)).clamp(-0.5, 0.5);
            (p.speed, toward - approach)
        };
        o.drive.set(Drive {
            translate,
            rotate: (side * p.gain * turn_left).clamp(-1.2, 1.2),
        });
        Ok(())
    }
}

/// Parameters of [`BarcodeTrack`].
#[derive(Params, Debug, Clone)]
pub struct TrackParams {
    /// The barcode id to track.
    #[param(default = 7, min = 0, max = 65535)]
    pub id: u32,
}

/// Inputs of [`BarcodeTrack`].
#[derive(Inputs)]
pub struct TrackIn<'a> {
    /// Camera sightings.
    pub barcodes: Input<'a, Barcodes>,
    /// Odometry.
    pub odometry: Input<'a, Odometry>,
}

/// Output of [`BarcodeTrack`].
#[derive(Outputs)]
pub struct TrackOut<'a> {
    /// The tracked barcode.
    pub target: Output<'a, Target>,
}

/// Barcode tracking: keeps the latest sighting of the wanted id, placed in the odometry
/// frame (a running average over sightings that forgets old ones, as odometry drifts), and
/// its range and bearing from the robot now. Each sighting is used once: the camera's report
/// stays in the input until the next one, and placing it again from a pose that moved on
/// would smear the estimate.
#[derive(Default)]
pub struct BarcodeTrack {
    sum: (f64, f64, f64),
    /// Age of the report seen in the last cycle (a younger one is a new report).
    last_age_ms: Option<f64>,
}

/// Weight kept by the older sightings when a new one arrives.
const TRACK_FORGET: f64 = 0.9;

impl Skill for BarcodeTrack {
    type Params = TrackParams;
    type Inputs<'a> = TrackIn<'a>;
    type Outputs<'a> = TrackOut<'a>;
    fn compute(&mut self, ctx: &Ctx<TrackParams>, i: TrackIn, o: &mut TrackOut) -> SkillResult {
        let od = *i.odometry;
        let b = *i.barcodes;
        let new = self.last_age_ms.is_none_or(|last| b.age_ms < last);
        self.last_age_ms = Some(b.age_ms);
        let mut visible = false;
        for k in 0..(b.count as usize).min(8) {
            if b.id[k] == ctx.params.id && b.age_ms < 500.0 {
                visible = true;
                if !new {
                    continue;
                }
                let a = od.theta + b.bearing[k];
                let (x, y) = (od.x + b.range[k] * a.cos(), od.y + b.range[k] * a.sin());
                // Near sightings are better: weight by 1/range.
                let w = 1.0 / b.range[k].max(0.3);
                let f = TRACK_FORGET;
                self.sum = (
                    f * self.sum.0 + w * x,
                    f * self.sum.1 + w * y,
                    f * self.sum.2 + w,
                );
            }
        }
        let mut t = Target {
            id: ctx.params.id,
            visible,
            ..Target::default()
        };
        if self.sum.2 > 0.0 {
            t.seen = true;
            t.x = self.sum.0 / self.sum.2;
            t.y = self.sum.1 / self.sum.2;
            t.range = (t.x - od.x).hypot(t.y - od.y);
            t.bearing = wrap((t.y - od.y).atan2(t.x - od.x) - od.theta);
        }
        o.target.set(t);
        Ok(())
    }
}

/// Parameters of [`Home`].
#[derive(Params, Debug, Clone)]
pub struct HomeParams {
    /// Forward speed (m/s).
    #[param(default = 0.35, min = 0.0, max = 1.0)]
    pub speed: f64,
    /// Stop this far from the target (m).
    #[param(default = 1.4, min = 0.0, max = 5.0)]
    pub stop_distance: f64,
    /// Steering gain (rad/s per rad).
    #[param(default = 1.5, min = 0.0, max = 10.0)]
    pub gain: f64,
}

/// Inputs of [`Home`].
#[derive(Inputs)]
pub struct HomeIn<'a> {
    /// The target.
    pub target: Input<'a, Target>,
}

/// Homing: drive toward the tracked target, stop at `stop_distance`.
#[derive(Default)]
pub struct Home;

impl Skill for Home {
    type Params = HomeParams;
    type Inputs<'a> = HomeIn<'a>;
    type Outputs<'a> = DriveOut<'a>;
    const PRIORITY: i32 = 4;
    fn compute(&mut self, ctx: &Ctx<HomeParams>, i: HomeIn, o: &mut DriveOut) -> SkillResult {
        let p = ctx.params;
        let t = *i.target;
        if !t.seen {
            return Ok(());
        }
        let rotate = (p.gain * t.bearing).clamp(-1.0, 1.0);
        let translate = if t.range > p.stop_distance {
            p.speed * t.bearing.cos().max(0.0)
        } else {
            0.0
        };
        o.drive.set(Drive { translate, rotate });
        Ok(())
    }
}

/// Parameters of [`DoorLocate`].
#[derive(Params, Debug, Clone)]
pub struct DoorParams {
    /// Start looking when the barcode is closer than this (m).
    #[param(default = 3.0, min = 0.5, max = 10.0)]
    pub near: f64,
    /// A reading this much longer than the wall along its whole cone looks through it (m).
    #[param(default = 1.0, min = 0.2, max = 5.0)]
    pub margin: f64,
    /// Narrowest opening that counts as the door (m).
    #[param(default = 0.6, min = 0.2, max = 3.0)]
    pub min_width: f64,
    /// How far along the wall, either side of the barcode, the door may be (m).
    #[param(default = 3.0, min = 0.5, max = 10.0)]
    pub span: f64,
}

/// Inputs of [`DoorLocate`].
#[derive(Inputs)]
pub struct DoorIn<'a> {
    /// The ring.
    pub sonar: Input<'a, Sonar>,
    /// Odometry.
    pub odometry: Input<'a, Odometry>,
    /// The door's barcode.
    pub target: Input<'a, Target>,
}

/// Output of [`DoorLocate`].
#[derive(Outputs)]
pub struct DoorOut<'a> {
    /// The opening.
    pub door: Output<'a, Door>,
}

/// Radius of the sonar ring (m): ranges are measured from it.
pub const RING: f64 = 0.36;
/// Half the sonar cone (rad).
const CONE: f64 = 15.0 * PI / 180.0;
/// Incidence beyond which a ping reflects away from a wall instead of echoing (rad).
const GRAZING: f64 = 65.0 * PI / 180.0;
/// Width of an evidence bin along the wall (m).
const BIN: f64 = 0.05;

/// One sonar reading placed in the odometry frame: ring point, direction, range (∞: no echo).
#[derive(Debug, Clone, Copy)]
struct Ray {
    o: (f64, f64),
    a: f64,
    r: f64,
}

/// A wall line `x cos φ + y sin φ = ρ`, its normal pointing from the robot's side into it;
/// positions along it are measured from the barcode's foot on it.
#[derive(Debug, Clone, Copy)]
struct Wall {
    phi: f64,
    rho: f64,
    anchor: (f64, f64),
}

impl Wall {
    fn n(&self) -> (f64, f64) {
        (self.phi.cos(), self.phi.sin())
    }
    /// Distance from `o` to the wall along the normal (positive: the wall is ahead).
    fn gap(&self, o: (f64, f64)) -> f64 {
        let (nx, ny) = self.n();
        self.rho - (o.0 * nx + o.1 * ny)
    }
    /// Coordinate along the wall of a point.
    fn along(&self, p: (f64, f64)) -> f64 {
        let (nx, ny) = self.n();
        -(p.0 - self.anchor.0) * ny + (p.1 - self.anchor.1) * nx
    }
    /// The point on the wall at coordinate `s`.
    fn at(&self, s: f64) -> (f64, f64) {
        let (nx, ny) = self.n();
        let g = self.gap(self.anchor);
        (
            self.anchor.0 + g * nx - s * ny,
            self.anchor.1 + g * ny + s * nx,
        )
    }
    /// The range a sonar cone sees when the whole cone meets the wall: its ray nearest to the
    /// normal hits first. `None` when the cone does not face the wall.
    fn expected(&self, ray: &Ray) -> Option<f64> {
        let inc = wrap(ray.a - self.phi).abs();
        let gap = self.gap(ray.o);
        (inc < 60f64.to_radians() && gap > 0.05).then(|| gap / (inc - CONE).max(0.0).cos())
    }
    /// Where the ray at angle `a` from `o` crosses the wall (coordinate along it).
    fn crossing(&self, o: (f64, f64), a: f64) -> Option<f64> {
        let c = wrap(a - self.phi).cos();
        let gap = self.gap(o);
        (c > 0.1 && gap > 0.05).then(|| {
            let t = gap / c;
            self.along((o.0 + t * a.cos(), o.1 + t * a.sin()))
        })
    }
}

/// Door location, the paper's example of a perception skill. Near the door's barcode it fits
/// the barcode's wall: the line through the barcode that best explains the ring's echoes
/// (a cone's range is the distance along its ray nearest to the wall's normal). Then every
/// new sonar reading is evidence along that wall: a cone that sees well past the wall shows
/// its whole footprint open; an echo at the wall's distance shows wall where the cone meets it
/// first. The door is the widest open run next to the barcode with wall on both sides, its
/// edges halfway between the last open and the first wall evidence; the way through is the
/// wall's normal. Each reading is used once, placed from the pose it was taken at.
#[derive(Default)]
pub struct DoorLocate {
    /// Age of each sonar's reading in the last cycle (a younger one is a new reading).
    ages: Vec<f64>,
    /// Every reading since the search began, oldest first (bounded).
    history: std::collections::VecDeque<Ray>,
    wall: Option<Wall>,
    /// Along-wall evidence around the barcode, from `-span`: (open, wall) counts per bin.
    bins: Vec<(u32, u32)>,
    /// Cycle of the last refit of the wall.
    fitted: u64,
    /// The newest estimate.
    found: Door,
}

/// Readings kept for refitting the wall and rebuilding the evidence.
const HISTORY: usize = 6000;
/// Readings the wall is refitted on (the newest).
const FIT_RAYS: usize = 400;
/// The wall is fitted on readings that meet it this close to the barcode (m).
const FIT_WINDOW: f64 = 1.2;
/// ... and meet it this close to square (rad).
const FIT_INCIDENCE: f64 = 40.0 * PI / 180.0;

impl DoorLocate {
    /// The wall that explains most readings, among normals `phis` and offsets that put the
    /// barcode on the wall or a little in front of it. A reading agrees with a wall when its
    /// range is what the cone sees of it (within 8 cm); for one normal, the readings that
    /// agree at each offset are found in one sweep over the offsets each reading allows.
    /// Only readings that meet the wall near the barcode count: it hangs on that wall, while
    /// other surfaces (a box's face) may line up with it farther away.
    fn fit(rays: &[Ray], anchor: (f64, f64), phis: impl Iterator<Item = f64>) -> Option<Wall> {
        let mut best: Option<(usize, Wall)> = None;
        let mut ends: Vec<(f64, i32)> = Vec::with_capacity(2 * rays.len());
        for phi in phis {
            let (nx, ny) = (phi.cos(), phi.sin());
            let at_code = anchor.0 * nx + anchor.1 * ny;
            let (lo, hi) = (at_code - 0.05, at_code + 0.3);
            let probe = Wall {
                phi,
                rho: at_code,
                anchor,
            };
            ends.clear();
            for ray in rays.iter().filter(|r| r.r.is_finite()) {
                let inc = wrap(ray.a - phi).abs();
                if inc > FIT_INCIDENCE
                    || probe
                        .crossing(ray.o, ray.a)
                        .is_none_or(|s| s.abs() > FIT_WINDOW)
                {
                    continue;
                }
                let c = (inc - CONE).max(0.0).cos();
                let base = ray.o.0 * nx + ray.o.1 * ny;
                let (a, b) = (base + (ray.r - 0.08) * c, base + (ray.r + 0.08) * c);
                if b >= lo && a <= hi {
                    ends.push((a.max(lo), 1));
                    ends.push((b.min(hi), -1));
                }
            }
            ends.sort_by(|x, y| x.0.total_cmp(&y.0).then(y.1.cmp(&x.1)));
            let (mut n, mut top, mut at) = (0i32, 0i32, at_code);
            for (k, &(rho, step)) in ends.iter().enumerate() {
                n += step;
                if n > top {
                    top = n;
                    // The middle of the stretch where this many agree.
                    let next = ends.get(k + 1).map_or(rho, |e| e.0);
                    at = (rho + next) / 2.0;
                }
            }
            let count = top.max(0) as usize;
            if best.as_ref().is_none_or(|b| count > b.0) {
                best = Some((
                    count,
                    Wall {
                        phi,
                        rho: at,
                        anchor,
                    },
                ));
            }
        }
        best.filter(|b| b.0 >= 3).map(|b| b.1)
    }

    /// Evidence from every reading kept, along the current wall.
    fn rebuild(&mut self, span: f64, margin: f64) {
        let Some(wall) = self.wall else { return };
        self.bins = vec![(0, 0); (2.0 * span / BIN).ceil() as usize];
        let rays: Vec<Ray> = self.history.iter().copied().collect();
        for ray in rays {
            self.observe(wall, ray, margin, span);
        }
    }

    fn mark(&mut self, from: f64, to: f64, open: bool, span: f64) {
        let n = self.bins.len() as f64;
        let lo = ((from + span) / BIN).floor().max(0.0);
        let hi = ((to + span) / BIN).ceil().min(n);
        let (lo, hi) = (lo as usize, hi as usize);
        for b in self.bins.iter_mut().take(hi).skip(lo) {
            if open {
                b.0 += 1;
            } else {
                b.1 += 1;
            }
        }
    }

    /// Evidence from one new reading.
    fn observe(&mut self, wall: Wall, ray: Ray, margin: f64, span: f64) {
        let inc = wrap(ray.a - wall.phi);
        if inc.abs() > 55f64.to_radians() {
            return;
        }
        // The cone's edges, clipped to the rays that would echo off a wall: steeper ones
        // reflect away and tell nothing.
        let steep = GRAZING - 0.05;
        let clip = |a: f64| wall.phi + wrap(a - wall.phi).clamp(-steep, steep);
        let edges = [clip(ray.a - CONE), clip(ray.a + CONE)];
        let [Some(s1), Some(s2)] = edges.map(|a| wall.crossing(ray.o, a)) else {
            return;
        };
        let far = edges
            .iter()
            .map(|a| wall.gap(ray.o) / wrap(a - wall.phi).cos())
            .fold(0.0, f64::max);
        if ray.r > far + margin {
            self.mark(s1.min(s2), s1.max(s2), true, span);
        } else if let Some(e) = wall.expected(&ray)
            && (ray.r - e).abs() < 0.15
        {
            // The first echo: where the ray nearest to the normal meets the wall.
            let a = if inc.abs() <= CONE {
                wall.phi
            } else {
                ray.a - CONE * inc.signum()
            };
            if let Some(s) = wall.crossing(ray.o, a) {
                self.mark(s - BIN / 2.0, s + BIN / 2.0, false, span);
            }
        }
    }

    /// The door from the evidence: (centre along the wall, width).
    fn door(&self, min_width: f64, span: f64) -> Option<(f64, f64)> {
        let open = |b: &(u32, u32)| b.0 >= 2 && b.0 > 2 * b.1;
        let wall = |b: &(u32, u32)| b.1 >= 2 && b.1 > b.0;
        let mut best: Option<(f64, f64)> = None;
        let mut i = 0;
        while i < self.bins.len() {
            if !open(&self.bins[i]) {
                i += 1;
                continue;
            }
            let mut j = i;
            while j + 1 < self.bins.len()
                && (open(&self.bins[j + 1])
                    || (j + 2 < self.bins.len()
                        && !wall(&self.bins[j + 1])
                        && open(&self.bins[j + 2])))
            {
                j += 1;
            }
            // Wall evidence within 0.5 m on both sides brackets the opening.
            let reach = (0.5 / BIN) as usize;
            let left = (i.saturating_sub(reach)..i)
                .rev()
                .find(|&k| wall(&self.bins[k]));
            let right =
                (j + 1..(j + 1 + reach).min(self.bins.len())).find(|&k| wall(&self.bins[k]));
            if let (Some(l), Some(r)) = (left, right) {
                let lo = BIN * (i as f64 + l as f64 + 1.0) / 2.0 - span;
                let hi = BIN * (j as f64 + 1.0 + r as f64) / 2.0 - span;
                if hi - lo >= min_width && best.is_none_or(|b| hi - lo > b.1) {
                    best = Some(((lo + hi) / 2.0, hi - lo));
                }
            }
            i = j + 1;
        }
        best
    }
}

impl Skill for DoorLocate {
    type Params = DoorParams;
    type Inputs<'a> = DoorIn<'a>;
    type Outputs<'a> = DoorOut<'a>;
    fn compute(&mut self, ctx: &Ctx<DoorParams>, i: DoorIn, o: &mut DoorOut) -> SkillResult {
        let (od, t, s, p) = (*i.odometry, *i.target, *i.sonar, ctx.params);
        if self.ages.is_empty() {
            self.ages = vec![f64::INFINITY; SONARS];
        }
        let mut fresh = Vec::new();
        for k in 0..SONARS {
            let new = s.age_ms[k] < self.ages[k];
            self.ages[k] = s.age_ms[k];
            if new && !s.range[k].is_nan() {
                let a = wrap(od.theta + sonar_angle(k));
                let ray = Ray {
                    o: (od.x + RING * a.cos(), od.y + RING * a.sin()),
                    a,
                    r: s.range[k],
                };
                fresh.push(ray);
                if self.history.len() == HISTORY {
                    self.history.pop_front();
                }
                self.history.push_back(ray);
            }
        }
        let newest = |h: &std::collections::VecDeque<Ray>| -> Vec<Ray> {
            h.iter().rev().take(FIT_RAYS).copied().collect()
        };
        if self.wall.is_none() && t.seen && t.range < p.near {
            // First fit: any normal within 70° of the way to the barcode, through it.
            let beta = (t.y - od.y).atan2(t.x - od.x);
            let phis = (-70..=70).map(|d| wrap(beta + f64::from(d).to_radians()));
            self.wall = Self::fit(&newest(&self.history), (t.x, t.y), phis);
            self.fitted = ctx.cycle;
            self.rebuild(p.span, p.margin);
        } else if let Some(w) = self.wall
            && ctx.cycle >= self.fitted + 20
            && !fresh.is_empty()
        {
            // Refit on the newest readings, near the current line, from the barcode's newest
            // estimate: the evidence is rebuilt along the refined wall.
            let anchor = if t.seen { (t.x, t.y) } else { w.anchor };
            let cands = (-24..=24).map(|d| wrap(w.phi + f64::from(d) * 0.25f64.to_radians()));
            if let Some(better) = Self::fit(&newest(&self.history), anchor, cands) {
                self.wall = Some(better);
            }
            self.fitted = ctx.cycle;
            self.rebuild(p.span, p.margin);
        } else if let Some(wall) = self.wall {
            for ray in fresh {
                self.observe(wall, ray, p.margin, p.span);
            }
        }
        if let Some(wall) = self.wall {
            // Once found, the door stays found; new evidence only moves it.
            if let Some((s, width)) = self.door(p.min_width, p.span) {
                let (x, y) = wall.at(s);
                self.found = Door {
                    found: true,
                    x,
                    y,
                    heading: wall.phi,
                    width,
                };
            }
        }
        o.door.set(self.found);
        Ok(())
    }
}

/// Parameters of [`GoThrough`].
#[derive(Params, Debug, Clone)]
pub struct GoThroughParams {
    /// Forward speed (m/s).
    #[param(default = 0.3, min = 0.0, max = 1.0)]
    pub speed: f64,
    /// Steering gain (rad/s per rad).
    #[param(default = 1.5, min = 0.0, max = 10.0)]
    pub gain: f64,
    /// Line up on the door's axis this far before the opening (m).
    #[param(default = 1.0, min = 0.3, max = 3.0)]
    pub approach: f64,
    /// Centring gain between the door posts (rad per m of imbalance).
    #[param(default = 0.8, min = 0.0, max = 10.0)]
    pub centre: f64,
}

/// Inputs of [`GoThrough`].
#[derive(Inputs)]
pub struct GoIn<'a> {
    /// The opening.
    pub door: Input<'a, Door>,
    /// Odometry.
    pub odometry: Input<'a, Odometry>,
    /// The ring (centring between the posts).
    pub sonar: Input<'a, Sonar>,
}

/// Drive through a located opening: to a point `approach` before it on its axis, then along
/// the axis (a carrot 0.6 m ahead on it), centred between the posts by the side sonars, and
/// on. Pushing without moving (a post) backs it off to line up again.
#[derive(Default)]
pub struct GoThrough {
    lined_up: bool,
    /// Cycles spent commanding forward motion without moving.
    stuck: u32,
    /// Cycles of backing off left.
    backing: u32,
}

impl Skill for GoThrough {
    type Params = GoThroughParams;
    type Inputs<'a> = GoIn<'a>;
    type Outputs<'a> = DriveOut<'a>;
    const PRIORITY: i32 = 6;
    fn compute(&mut self, ctx: &Ctx<GoThroughParams>, i: GoIn, o: &mut DriveOut) -> SkillResult {
        let (d, od, s, p) = (*i.door, *i.odometry, *i.sonar, ctx.params);
        if !d.found {
            return Ok(());
        }
        if self.backing > 0 {
            self.backing -= 1;
            o.drive.set(Drive {
                translate: -0.15,
                rotate: 0.0,
            });
            return Ok(());
        }
        let (c, sn) = (d.heading.cos(), d.heading.sin());
        // Along-axis and cross-axis position relative to the door centre.
        let along = (od.x - d.x) * c + (od.y - d.y) * sn;
        let cross = -(od.x - d.x) * sn + (od.y - d.y) * c;
        let start = (d.x - p.approach * c, d.y - p.approach * sn);
        if !self.lined_up && (od.x - start.0).hypot(od.y - start.1) < 0.25 {
            self.lined_up = true;
        }
        // Off the axis before the wall: line up again.
        if self.lined_up && along < -0.2 && cross.abs() > 0.35 {
            self.lined_up = false;
        }
        let goal = if self.lined_up || along > 0.3 {
            let ahead = along + 0.6;
            (d.x + ahead * c, d.y + ahead * sn)
        } else {
            start
        };
        let want = (goal.1 - od.y).atan2(goal.0 - od.x);
        let mut err = wrap(want - od.theta);
        if self.lined_up && (-0.9..0.5).contains(&along) {
            // Between the posts: steer away from the nearer one.
            let left = min_in(&s, 0.5, 2.4).min(0.8);
            let right = min_in(&s, -2.4, -0.5).min(0.8);
            err += p.centre * (left - right) / 2.0;
        }
        let rotate = (p.gain * err).clamp(-1.0, 1.0);
        let translate = if err.abs() < 0.8 {
            p.speed * err.cos().powi(2)
        } else {
            0.0
        };
        if translate > 0.1 && od.v.abs() < 0.02 {
            self.stuck += 1;
        } else {
            self.stuck = 0;
        }
        if self.stuck > 80 {
            self.stuck = 0;
            self.backing = 100;
            self.lined_up = false;
        }
        o.drive.set(Drive { translate, rotate });
        Ok(())
    }
}

/// Stop: proposes standing still, with the highest default priority.
#[derive(Default)]
pub struct Stop;

impl Skill for Stop {
    type Params = NoParams;
    type Inputs<'a> = ();
    type Outputs<'a> = DriveOut<'a>;
    const PRIORITY: i32 = 10;
    fn compute(&mut self, _: &Ctx<NoParams>, _: (), o: &mut DriveOut) -> SkillResult {
        o.drive.set(Drive::default());
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skill_sdk::harness::Harness;

    fn ring(f: impl Fn(f64) -> f64) -> Sonar {
        let mut s = Sonar {
            range: [0.0; SONARS],
            age_ms: [10.0; SONARS],
        };
        for i in 0..SONARS {
            s.range[i] = f(sonar_angle(i));
        }
        s
    }

    #[test]
    fn avoid_turns_away_from_the_near_side_and_is_quiet_in_the_open() {
        let mut h = Harness::<Avoid>::new();
        h.input("sonar", ring(|_| 5.0));
        assert!(
            h.step().unwrap().output::<Drive>("drive").is_none(),
            "nothing near: no proposal"
        );
        // An obstacle ahead and to the right: turn left (positive rotate).
        let mut h = Harness::<Avoid>::new();
        h.input(
            "sonar",
            ring(|a| if (-1.0..0.3).contains(&a) { 0.3 } else { 4.0 }),
        );
        let d = *h.step().unwrap().output::<Drive>("drive").unwrap();
        assert!(d.rotate > 0.0, "{d:?}");
        let mut h = Harness::<Avoid>::new();
        h.input(
            "sonar",
            ring(|a| if (-0.3..1.0).contains(&a) { 0.3 } else { 4.0 }),
        );
        assert!(h.step().unwrap().output::<Drive>("drive").unwrap().rotate < 0.0);
        // A lowered safe distance lets it pass close obstacles.
        let mut h = Harness::<Avoid>::new();
        h.set_param("safe_distance=0.2").unwrap();
        h.input("sonar", ring(|_| 0.3));
        assert!(h.step().unwrap().output::<Drive>("drive").is_none());
    }

    #[test]
    fn home_converges_on_its_goal() {
        // Integrate the proposals with a unicycle: the robot ends near the goal.
        let mut h = Harness::<Home>::new();
        let (mut x, mut y, mut th) = (0.0f64, 0.0f64, 2.0f64);
        let goal = (4.0, 3.0);
        for _ in 0..2000 {
            let range = (goal.0 - x).hypot(goal.1 - y);
            let bearing = wrap((goal.1 - y).atan2(goal.0 - x) - th);
            h.input(
                "target",
                Target {
                    seen: true,
                    visible: true,
                    id: 7,
                    x: goal.0,
                    y: goal.1,
                    range,
                    bearing,
                },
            );
            let d = *h.step().unwrap().output::<Drive>("drive").unwrap();
            th += d.rotate * 0.05;
            x += d.translate * 0.05 * th.cos();
            y += d.translate * 0.05 * th.sin();
        }
        let left = (goal.0 - x).hypot(goal.1 - y);
        assert!(
            left < 1.5 && left > 1.2,
            "stops at its stop distance: {left}"
        );
    }

    #[test]
    fn barcode_track_places_the_sighting_in_the_odometry_frame() {
        let mut h = Harness::<BarcodeTrack>::new();
        let mut b = Barcodes {
            count: 1,
            ..Barcodes::default()
        };
        b.id[0] = 7;
        b.bearing[0] = PI / 2.0;
        b.range[0] = 2.0;
        h.input("barcodes", b);
        h.input(
            "odometry",
            Odometry {
                x: 1.0,
                y: 1.0,
                theta: 0.0,
                v: 0.0,
                w: 0.0,
            },
        );
        let t = *h.step().unwrap().output::<Target>("target").unwrap();
        assert!(t.seen && t.visible);
        assert!(
            (t.x - 1.0).abs() < 1e-9 && (t.y - 3.0).abs() < 1e-9,
            "{t:?}"
        );
        // Out of view, it is remembered and re-aimed from the new pose.
        h.input("barcodes", Barcodes::default());
        h.input(
            "odometry",
            Odometry {
                x: 1.0,
                y: 1.0,
                theta: PI / 2.0,
                v: 0.0,
                w: 0.0,
            },
        );
        let t = *h.step().unwrap().output::<Target>("target").unwrap();
        assert!(t.seen && !t.visible && t.bearing.abs() < 1e-9 && (t.range - 2.0).abs() < 1e-9);
    }

    /// A pass of the robot along `path` (x, y, heading per cycle) in `world`, with the
    /// simulator's sonar model read group by group as the device reports it; `each` gets
    /// the pose as odometry.
    fn pass<S: Skill>(
        h: &mut Harness<S>,
        world: &str,
        path: impl Iterator<Item = (f64, f64, f64)>,
        mut each: impl FnMut(&mut Harness<S>, &Odometry),
    ) {
        use denning_sim::sim::Sim;
        use denning_sim::world::World;
        let mut sim = Sim::new(World::parse(world, "test").unwrap(), 3);
        let mut s = Sonar {
            range: [f64::NAN; SONARS],
            age_ms: [f64::INFINITY; SONARS],
        };
        for (k, (x, y, th)) in path.enumerate() {
            sim.pose = [x, y, th];
            for i in 0..SONARS {
                s.age_ms[i] += 10.0;
                if i % 3 == k % 3 {
                    s.range[i] = sim.sonar(i).unwrap_or(f64::INFINITY);
                    s.age_ms[i] = 0.0;
                }
            }
            let od = Odometry {
                x,
                y,
                theta: th,
                v: 0.3,
                w: 0.0,
            };
            h.input("sonar", s);
            each(h, &od);
        }
    }

    /// A wall along x = 2 with a 1.2 m opening from y = 0.4 to 1.6, the barcode south of it.
    const DOOR_WORLD: &str = "name = 'door'\nstart = [0.0, 0.0, 0.0]\n\
        [[wall]]\nfrom = [2.0, -3.0]\nto = [2.0, 0.4]\n\
        [[wall]]\nfrom = [2.0, 1.6]\nto = [2.0, 4.0]\n\
        [[barcode]]\nid = 7\nat = [1.95, -0.4]\n";

    /// The door's barcode at `code`, seen before and out of view now, from pose `od`.
    fn remembered(code: (f64, f64), od: &Odometry) -> Target {
        let (dx, dy) = (code.0 - od.x, code.1 - od.y);
        Target {
            seen: true,
            visible: false,
            id: 7,
            x: code.0,
            y: code.1,
            range: dx.hypot(dy),
            bearing: wrap(dy.atan2(dx) - od.theta),
        }
    }

    #[test]
    fn door_locate_finds_the_opening_from_a_pass_along_the_wall() {
        let mut h = Harness::<DoorLocate>::new();
        let code = (1.95, -0.4);
        // Drive north 1 m from the wall, past the barcode and the opening.
        let path = (0..140).map(|k| (1.0, -1.5 + 0.03 * f64::from(k), PI / 2.0));
        let mut last = Door::default();
        pass(&mut h, DOOR_WORLD, path, |h, od| {
            h.input("odometry", *od);
            h.input("target", remembered(code, od));
            last = *h.step().unwrap().output::<Door>("door").unwrap();
        });
        assert!(last.found, "{last:?}");
        assert!(
            (last.x - 2.0).abs() < 0.1 && (last.y - 1.0).abs() < 0.15,
            "the opening's centre: {last:?}"
        );
        assert!(last.heading.abs() < 0.05, "through the wall: {last:?}");
        assert!((last.width - 1.2).abs() < 0.3, "its width: {last:?}");
    }

    #[test]
    fn door_locate_sees_no_door_in_a_plain_wall() {
        let mut h = Harness::<DoorLocate>::new();
        let world = "name = 'wall'\nstart = [0.0, 0.0, 0.0]\n\
            [[wall]]\nfrom = [2.0, -3.0]\nto = [2.0, 4.0]\n";
        let path = (0..140).map(|k| (1.0, -1.5 + 0.03 * f64::from(k), PI / 2.0));
        pass(&mut h, world, path, |h, od| {
            h.input("odometry", *od);
            h.input("target", remembered((1.95, -0.4), od));
            let d = *h.step().unwrap().output::<Door>("door").unwrap();
            assert!(!d.found, "no opening, no door: {d:?}");
        });
    }

    #[test]
    fn wall_follow_keeps_its_distance_and_turns_away_from_a_wall_ahead() {
        // Parallel to a wall 1 m away on the right: turn right toward 0.5 m.
        let mut h = Harness::<WallFollow>::new();
        let world = "name = 'wall'\nstart = [0.0, 0.0, 0.0]\n\
            [[wall]]\nfrom = [-5.0, -1.36]\nto = [5.0, -1.36]\n\
            [[wall]]\nfrom = [3.0, -5.0]\nto = [3.0, 5.0]\n";
        let mut d = Drive::default();
        pass(&mut h, world, (0..3).map(|_| (0.0, 0.0, 0.0)), |h, _| {
            d = *h.step().unwrap().output::<Drive>("drive").unwrap();
        });
        assert!(
            d.translate > 0.0 && d.rotate < 0.0,
            "toward the wall: {d:?}"
        );
        // Heading into the wall at 40°: turn away (left).
        pass(&mut h, world, (0..3).map(|_| (0.0, -0.5, -0.7)), |h, _| {
            d = *h.step().unwrap().output::<Drive>("drive").unwrap();
        });
        assert!(d.rotate > 0.0, "away from the wall: {d:?}");
        // The wall ahead (x = 3) close: turn left on the spot.
        pass(&mut h, world, (0..3).map(|_| (2.2, -0.5, 0.0)), |h, _| {
            d = *h.step().unwrap().output::<Drive>("drive").unwrap();
        });
        assert!(d.translate == 0.0 && d.rotate > 0.0, "{d:?}");
        // The same on the left side, mirrored.
        h.set_param("side=-1").unwrap();
        let mirrored = "name = 'wall'\nstart = [0.0, 0.0, 0.0]\n\
            [[wall]]\nfrom = [-5.0, 1.36]\nto = [5.0, 1.36]\n";
        pass(&mut h, mirrored, (0..3).map(|_| (0.0, 0.0, 0.0)), |h, _| {
            d = *h.step().unwrap().output::<Drive>("drive").unwrap();
        });
        assert!(d.rotate > 0.0, "toward the wall on the left: {d:?}");
    }

    #[test]
    fn wander_drives_on_and_bounces_off_what_is_ahead() {
        let mut h = Harness::<Wander>::new();
        h.input("sonar", ring(|_| 5.0));
        h.input("odometry", Odometry::default());
        let d = *h.step().unwrap().output::<Drive>("drive").unwrap();
        assert!(d.translate >= 0.0);
        // Something close ahead: the next heading is the open side (here: behind).
        let mut h = Harness::<Wander>::new();
        h.set_param("look=0").unwrap();
        h.input("sonar", ring(|a| if a.abs() < 2.0 { 0.5 } else { 5.0 }));
        h.input("odometry", Odometry::default());
        let d = *h.step().unwrap().output::<Drive>("drive").unwrap();
        assert!(
            d.translate == 0.0 && d.rotate.abs() > 0.5,
            "turns around: {d:?}"
        );
    }

    #[test]
    fn stop_proposes_standing_still() {
        let mut h = Harness::<Stop>::new();
        assert_eq!(
            *h.step().unwrap().output::<Drive>("drive").unwrap(),
            Drive::default()
        );
    }

    #[test]
    fn go_through_heads_for_the_axis_then_through() {
        let mut h = Harness::<GoThrough>::new();
        let door = Door {
            found: true,
            x: 3.0,
            y: 0.0,
            heading: 0.0,
            width: 1.2,
        };
        h.input("door", door);
        h.input("sonar", ring(|_| 5.0));
        h.input(
            "odometry",
            Odometry {
                x: 0.0,
                y: 1.0,
                theta: 0.0,
                v: 0.0,
                w: 0.0,
            },
        );
        let d = *h.step().unwrap().output::<Drive>("drive").unwrap();
        assert!(
            d.rotate < 0.0,
            "turns toward the approach point below: {d:?}"
        );
    }
}
