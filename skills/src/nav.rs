//! The standard navigation skills of the exit-lab experiment. Movement skills propose on the
//! `drive` channel; default priorities: stop 10, avoid 8, go_through 6, home 4, wall_follow 3,
//! wander 2 (higher wins).

use skill_sdk::msg::{Barcodes, Door, Drive, Odometry, SONARS, Sonar, Target};
use skill_sdk::prelude::*;
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
    /// Largest turn rate of the random walk (rad/s).
    #[param(default = 0.4, min = 0.0, max = 2.0)]
    pub turn: f64,
    /// Seed of the random walk.
    #[param(default = 1, min = 0)]
    pub seed: u64,
}

/// Wandering: forward with a slowly drifting random turn.
#[derive(Default)]
pub struct Wander {
    state: u64,
    rotate: f64,
}

impl Skill for Wander {
    type Params = WanderParams;
    type Inputs<'a> = ();
    type Outputs<'a> = DriveOut<'a>;
    const PRIORITY: i32 = 2;
    fn compute(&mut self, ctx: &Ctx<WanderParams>, _: (), o: &mut DriveOut) -> SkillResult {
        if self.state == 0 {
            self.state = ctx.params.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        }
        // xorshift: every 25 cycles pick a new turn rate.
        if ctx.cycle % 25 == 1 {
            self.state ^= self.state << 13;
            self.state ^= self.state >> 7;
            self.state ^= self.state << 17;
            let u = (self.state >> 11) as f64 / (1u64 << 53) as f64;
            self.rotate = (2.0 * u - 1.0) * ctx.params.turn;
        }
        o.drive.set(Drive {
            translate: ctx.params.speed,
            rotate: self.rotate,
        });
        Ok(())
    }
}

/// Parameters of [`WallFollow`].
#[derive(Params, Debug, Clone)]
pub struct WallFollowParams {
    /// Distance to keep from the wall on the right (m, from the ring).
    #[param(default = 0.5, min = 0.1, max = 3.0)]
    pub distance: f64,
    /// Forward speed (m/s).
    #[param(default = 0.3, min = 0.0, max = 1.0)]
    pub speed: f64,
    /// Steering gain (rad/s per m).
    #[param(default = 1.5, min = 0.0, max = 10.0)]
    pub gain: f64,
    /// Which side the wall is on: 1 right, -1 left.
    #[param(default = 1, min = -1, max = 1)]
    pub side: i32,
}

/// Hallway following: keeps `distance` from the wall on the right (or left).
#[derive(Default)]
pub struct WallFollow;

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
        let side = if p.side < 0 { -1.0 } else { 1.0 };
        let (lo, hi) = if side > 0.0 { (-1.9, -1.2) } else { (1.2, 1.9) };
        let beside = min_in(&i.sonar, lo, hi);
        // A wall ahead: turn away from the wall side first.
        let ahead = min_in(&i.sonar, -0.5, 0.5);
        let err = if ahead < p.distance + 0.4 {
            -1.0
        } else if beside.is_finite() {
            (beside - p.distance).clamp(-1.0, 1.0)
        } else {
            1.0
        };
        o.drive.set(Drive {
            translate: if ahead < p.distance + 0.2 {
                0.0
            } else {
                p.speed
            },
            rotate: -side * p.gain * err,
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
/// frame (averaged over sightings), and its range and bearing from the robot now.
#[derive(Default)]
pub struct BarcodeTrack {
    sum: (f64, f64, f64),
}

impl Skill for BarcodeTrack {
    type Params = TrackParams;
    type Inputs<'a> = TrackIn<'a>;
    type Outputs<'a> = TrackOut<'a>;
    fn compute(&mut self, ctx: &Ctx<TrackParams>, i: TrackIn, o: &mut TrackOut) -> SkillResult {
        let od = *i.odometry;
        let b = *i.barcodes;
        let mut visible = false;
        for k in 0..(b.count as usize).min(8) {
            if b.id[k] == ctx.params.id && b.age_ms < 500.0 {
                let a = od.theta + b.bearing[k];
                let (x, y) = (od.x + b.range[k] * a.cos(), od.y + b.range[k] * a.sin());
                // Near sightings are better: weight by 1/range.
                let w = 1.0 / b.range[k].max(0.3);
                self.sum = (self.sum.0 + w * x, self.sum.1 + w * y, self.sum.2 + w);
                visible = true;
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
    /// Only look when the target is closer than this (m).
    #[param(default = 3.0, min = 0.5, max = 10.0)]
    pub near: f64,
    /// A reading this much longer than the wall counts as the opening (m).
    #[param(default = 1.5, min = 0.2, max = 5.0)]
    pub margin: f64,
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

/// Door location: near the door's barcode, the sonar echoes from the wall around the barcode
/// give the wall's line (least squares); the sonars that look through it (much longer than the
/// wall along their direction) mark the opening. The door is where those rays cross the wall
/// line, and the way through is the wall's normal, away from the robot. Estimates are averaged.
#[derive(Default)]
pub struct DoorLocate {
    best: Option<(f64, f64, f64, usize)>,
}

/// Fits a line through points: (centroid, unit direction).
fn fit_line(pts: &[(f64, f64)]) -> Option<((f64, f64), (f64, f64))> {
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) = pts
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in pts {
        let (dx, dy) = (p.0 - mx, p.1 - my);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    Some(((mx, my), (angle.cos(), angle.sin())))
}

impl Skill for DoorLocate {
    type Params = DoorParams;
    type Inputs<'a> = DoorIn<'a>;
    type Outputs<'a> = DoorOut<'a>;
    fn compute(&mut self, ctx: &Ctx<DoorParams>, i: DoorIn, o: &mut DoorOut) -> SkillResult {
        let (od, t, s) = (*i.odometry, *i.target, *i.sonar);
        if t.seen && t.range < ctx.params.near {
            let to_code = (t.y - od.y).atan2(t.x - od.x);
            // Sonars looking toward the barcode's wall: 75° either side.
            let looking: Vec<(f64, f64)> = (0..SONARS)
                .filter(|&k| s.age_ms[k] < 1000.0)
                .filter_map(|k| {
                    let a = od.theta + sonar_angle(k);
                    (wrap(a - to_code).abs() < 75f64.to_radians())
                        .then(|| range(&s, k).map(|r| (a, r)))?
                })
                .collect();
            // Echoes about as far as the wall is expected along that direction are the wall.
            let wall_d = t.range * 1.0;
            let wall_pts: Vec<(f64, f64)> = looking
                .iter()
                .filter(|(a, r)| {
                    let off = wrap(a - to_code);
                    let expect = wall_d / off.cos().max(0.3);
                    off.abs() < 55f64.to_radians() && (*r - expect).abs() < 0.8
                })
                .map(|(a, r)| (od.x + (r + 0.36) * a.cos(), od.y + (r + 0.36) * a.sin()))
                .collect();
            if let Some(((cx, cy), (dx, dy))) = fit_line(&wall_pts) {
                // The normal pointing away from the robot.
                let (mut nx, mut ny) = (-dy, dx);
                if (cx - od.x) * nx + (cy - od.y) * ny < 0.0 {
                    nx = -nx;
                    ny = -ny;
                }
                let dist = (cx - od.x) * nx + (cy - od.y) * ny;
                let mut crossings = Vec::new();
                for (a, r) in &looking {
                    let along = a.cos() * nx + a.sin() * ny;
                    if along < 0.3 {
                        continue;
                    }
                    let to_wall = dist / along;
                    if *r + 0.36 > to_wall + ctx.params.margin {
                        crossings.push((od.x + to_wall * a.cos(), od.y + to_wall * a.sin()));
                    }
                }
                if !crossings.is_empty() {
                    let n = crossings.len() as f64;
                    let (x, y) = crossings
                        .iter()
                        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
                    let h = ny.atan2(nx);
                    self.best = Some(match self.best {
                        None => (x, y, h, 1),
                        Some((bx, by, bh, k)) => {
                            let k1 = k as f64;
                            (
                                (bx * k1 + x) / (k1 + 1.0),
                                (by * k1 + y) / (k1 + 1.0),
                                wrap(bh + wrap(h - bh) / (k1 + 1.0)),
                                k + 1,
                            )
                        }
                    });
                }
            }
        }
        let mut d = Door::default();
        if let Some((x, y, h, n)) = self.best
            && n >= 5
        {
            d = Door {
                found: true,
                x,
                y,
                heading: h,
            };
        }
        o.door.set(d);
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
    /// Centring gain between the door posts (rad/s per m).
    #[param(default = 1.0, min = 0.0, max = 10.0)]
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

/// Drive through a located opening: aim at a point before it on its axis, then along the
/// axis, centred between the posts, and on.
#[derive(Default)]
pub struct GoThrough {
    lined_up: bool,
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
        let (c, sn) = (d.heading.cos(), d.heading.sin());
        // Along-axis and cross-axis position relative to the door centre.
        let along = (od.x - d.x) * c + (od.y - d.y) * sn;
        let cross = -(od.x - d.x) * sn + (od.y - d.y) * c;
        let goal = if !self.lined_up && along < -0.9 {
            // Approach a point 1 m before the opening.
            (d.x - c, d.y - sn)
        } else {
            self.lined_up = true;
            // Then a point 2 m past it, pulling toward the axis.
            (d.x + 2.0 * c, d.y + 2.0 * sn)
        };
        if !self.lined_up && (od.x - goal.0).hypot(od.y - goal.1) < 0.25 {
            self.lined_up = true;
        }
        let want = (goal.1 - od.y).atan2(goal.0 - od.x);
        let mut err = wrap(want - od.theta);
        if self.lined_up {
            let left = min_in(&s, 1.2, 1.9);
            let right = min_in(&s, -1.9, -1.2);
            if left < 1.0 && right < 1.0 {
                err += p.centre * (left - right) / 2.0;
            } else {
                err -= 0.5 * cross.clamp(-0.5, 0.5);
            }
        }
        let rotate = (p.gain * err).clamp(-1.0, 1.0);
        let translate = p.speed * err.cos().max(0.0).powi(2);
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

    #[test]
    fn door_locate_finds_the_long_readings_near_the_barcode() {
        let mut h = Harness::<DoorLocate>::new();
        // A wall along x = 1.86 (1.5 m from the ring), an opening around y = 0.4..1.1: sonars
        // whose rays cross the wall there see far.
        let s = ring(|a| {
            let y = 1.86 * a.tan();
            if a.cos() <= 0.05 {
                5.0
            } else if (0.4..1.1).contains(&y) {
                8.0
            } else {
                1.86 / a.cos() - 0.36
            }
        });
        let mut found = None;
        for _ in 0..6 {
            h.input("sonar", s);
            h.input("odometry", Odometry::default());
            h.input(
                "target",
                Target {
                    seen: true,
                    visible: true,
                    id: 7,
                    x: 1.86,
                    y: -0.5,
                    range: 1.93,
                    bearing: -0.26,
                },
            );
            found = Some(*h.step().unwrap().output::<Door>("door").unwrap());
        }
        let d = found.unwrap();
        assert!(d.found, "{d:?}");
        assert!(
            d.heading.abs() < 0.15,
            "through the wall, along its normal: {d:?}"
        );
        assert!((d.x - 1.86).abs() < 0.2 && d.y > 0.3 && d.y < 1.2, "{d:?}");
    }

    #[test]
    fn wander_and_stop_propose() {
        let mut h = Harness::<Wander>::new();
        assert!(
            h.step()
                .unwrap()
                .output::<Drive>("drive")
                .unwrap()
                .translate
                > 0.0
        );
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
