//! `leave_car`: turning to the car's doors and driving out when they open.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`LeaveCar`].
#[derive(Params, Debug, Clone)]
pub struct LeaveCarParams {
    /// 1: leave when the doors open (the sequencer sets it on the right floor); 0: hold.
    #[param(default = 0, min = 0, max = 1)]
    pub go: i64,
    /// The way out: the heading at activation turned this many quarter turns (counter-
    /// clockwise; 2: half round, out of a car's doors behind it; ±1: along a corridor from
    /// its side, out of an office's door), squared to the walls around.
    #[param(default = 2, min = -1, max = 2)]
    pub quarters: i64,
    /// Done this far from where it started (m, along the way out).
    #[param(default = 1.8, min = 0.3, max = 10.0)]
    pub distance: f64,
    /// Forward speed (m/s).
    #[param(default = 0.3, min = 0.0, max = 1.0)]
    pub speed: f64,
    /// Steering gain (rad/s per rad).
    #[param(default = 1.5, min = 0.0, max = 10.0)]
    pub gain: f64,
    /// The doors are open when the front sonar reads farther than this (m).
    #[param(default = 1.5, min = 0.3, max = 5.0)]
    pub clear: f64,
    /// Doors closing in front make it wait while it is less than this from its start (m):
    /// until its front is in the doorway, where the light curtain holds them open.
    #[param(default = 0.6, min = 0.0, max = 5.0)]
    pub doorway: f64,
    /// Past the cabin's walls, steering toward the middle of the gap the door posts leave
    /// ahead (rad per m off it, at most 0.5 rad).
    #[param(default = 2.0, min = 0.0, max = 10.0)]
    pub centre: f64,
}

/// Inputs of [`LeaveCar`].
#[derive(Inputs)]
pub struct LeaveCarIn<'a> {
    /// Odometry.
    pub odometry: Input<'a, Odometry>,
    /// The ring (the doors ahead, the posts beside).
    pub sonar: Input<'a, Sonar>,
}

/// Phases of [`LeaveCar`] (its `progress.phase`).
pub mod leave_phase {
    /// Turning on the spot to the way out.
    pub const TURNING: u32 = 0;
    /// Holding still until `go` is 1 and the doors ahead are open.
    pub const WAITING: u32 = 1;
    /// Driving out.
    pub const LEAVING: u32 = 2;
    /// Out: `distance` from the start, stopped.
    pub const OUT: u32 = 3;
}
use leave_phase::*;

/// Weight of one cycle's fit of the cabin's walls in the way out.
const WALL_BLEND: f64 = 0.05;
/// Cycles for the device to bring a reading of every sonar (300 ms).
const RING_REFRESH: u32 = 30;
/// Once squared, fits this far off the way out (rad) are ignored; nearer ones refine it.
const SNAP: f64 = 0.15;
/// Steering toward the cabin's centre line (rad per m off it).
const CABIN_CENTRING: f64 = 1.5;

/// Something this near ahead (m, from the ring) stops it at once, doors or not.
const BLOCKED: f64 = 0.3;

/// Echoes ahead nearer than this (m, along the heading from the robot's centre) bound the
/// gap it drives into.
const GAP_AHEAD: f64 = 1.0;
/// A side of the gap with no echo ahead within [`GAP_AHEAD`] is this far across (m).
const GAP_OPEN: f64 = 0.8;

/// Where the middle of the gap ahead is across the way (m, left of the robot's centre line
/// positive): half-way between the nearest echo on each side of the centre line among those
/// ahead within [`GAP_AHEAD`].
fn gap_middle(s: &Sonar) -> f64 {
    let (mut left, mut right) = (GAP_OPEN, -GAP_OPEN);
    for i in 0..SONARS {
        let Some(r) = range(s, i) else { continue };
        let (a, d) = (crate::nav::sonar_angle(i), RING + r);
        let (x, y) = (d * a.cos(), d * a.sin());
        if x <= 0.0 || x > GAP_AHEAD {
            continue;
        }
        if y >= 0.0 {
            left = left.min(y);
        } else {
            right = right.max(y);
        }
    }
    (left + right) / 2.0
}

/// The side (+1 left, −1 right) whose sonar square to the heading reads past `clear` while
/// the one behind and the one square on the other side read short of it: waiting in a cabin
/// squared to the wrong wall, the doors open beside the robot. `None` otherwise (an unread
/// sonar opens nothing and shuts nothing).
fn doors_beside(s: &Sonar, clear: f64) -> Option<f64> {
    let shut = |deg: f64| at(s, deg).is_some_and(|r| r < clear);
    let open = |deg: f64| at(s, deg).is_some_and(|r| r > clear);
    if !shut(180.0) {
        return None;
    }
    [1.0, -1.0]
        .into_iter()
        .find(|&side: &f64| open(side * 90.0) && shut(-side * 90.0))
}

/// Told to drive out and not moving this many cycles (0.5 s), it steers by the gap alone.
const PINNED: u32 = 50;
/// ... for this far along the way out (m): past the posts.
const BY_THE_GAP: f64 = 0.3;
/// Steering by the gap alone: toward its middle seen from this far back (m), at most 0.8 rad.
const GAP_LOOK: f64 = 0.3;

/// Leaves the car. At activation it faces the back wall, or the panel's button beside it; the
/// way out is that heading turned half round (or as many quarter turns as `quarters` says:
/// out of an office's door, facing its sign, along the corridor), squared to the walls around
/// (the nearest of their directions, when the ring fits them standing still), and it turns to
/// it on the spot. Then it holds still
/// until `go` is 1 and the way ahead is open (the front sonar reads farther than `clear`:
/// the doors are open), and drives out straight along the way out, toward the cabin's centre
/// line while its side walls are beside, then centred between the door posts by the side
/// sonars, until `distance` from where it started; there it stops. Doors
/// seen closing in front before it reached the doorway (`doorway` from the start) make it
/// wait again. Waiting with `go`, shut ahead and behind and on one side but open square to
/// the way on the other (doors opening beside it: the way out squared to the wrong wall), it
/// turns the way out a quarter toward them.
///
/// For a sequencer: `leave_car.progress.done == 1` (out of the car, stopped),
/// `leave_car.progress.phase == 1` (turned, waiting for `go` and the doors); `progress.value`
/// is the distance driven along the way out (m). Set `go` to 1 on the right floor (e.g. when
/// `sign_read.signs.floor == 4`).
#[derive(Default, Serialize, Deserialize)]
pub struct LeaveCar {
    activation: Activation,
    phase: u32,
    /// Where it started and the way out (odometry frame).
    start: (f64, f64),
    way: f64,
    /// Cycles it has stood still, and whether this is the activation's first run (it
    /// stood still before: the job before it ended standing).
    still_for: u32,
    fresh: bool,
    /// Whether the way out has been squared to the cabin's walls.
    squared: bool,
    /// Cycles it has been told to drive out and has not moved (the device's safety layer
    /// holds it at a post), and once that lasted [`PINNED`], how far along it steers by the
    /// gap alone.
    #[serde(default)]
    pinned_for: u32,
    #[serde(default)]
    by_the_gap_until: Option<f64>,
}

impl Skill for LeaveCar {
    type Params = LeaveCarParams;
    type Inputs<'a> = LeaveCarIn<'a>;
    type Outputs<'a> = DriveJobOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(
        &mut self,
        ctx: &Ctx<LeaveCarParams>,
        i: LeaveCarIn,
        o: &mut DriveJobOut,
    ) -> SkillResult {
        let (od, s, p) = (&*i.odometry, &*i.sonar, ctx.params);
        if self.activation.begins(ctx) {
            self.phase = TURNING;
            self.start = (od.x, od.y);
            self.way = wrap(od.theta + p.quarters as f64 * FRAC_PI_2);
            self.still_for = 0;
            self.fresh = true;
            self.squared = false;
            self.pinned_for = 0;
            self.by_the_gap_until = None;
        }
        // Fits only from readings all taken standing still: the ring refreshes each sonar
        // every 300 ms.
        self.still_for = if od.v.abs() < 0.02 && od.w.abs() < 0.02 {
            self.still_for + 1
        } else {
            0
        };
        if matches!(self.phase, TURNING | WAITING)
            && (self.still_for > RING_REFRESH || self.fresh)
            && let Some(a) = box_axis(s)
        {
            // Square to the cabin's walls: the robot may face the panel's end button rather
            // than the back wall, and the turn half round by odometry is off by its scale
            // error. The cabin's direction nearest the way out it has: taken at the first fit,
            // then refined (each fit is a few hundredths of a radian off).
            let box_dir = wrap(od.theta + a);
            let quarter = (wrap(self.way - box_dir) / FRAC_PI_2).round();
            let nearest = wrap(box_dir + quarter * FRAC_PI_2);
            let off = wrap(nearest - self.way);
            if !self.squared {
                // The first fit: the way out may be far off (facing the panel's end button).
                self.way = nearest;
                self.squared = true;
            } else if off.abs() < SNAP {
                self.way = wrap(self.way + WALL_BLEND * off);
            }
            // (A later fit far off is a bad one: some sonars straddled a corner.)
        }
        self.fresh = false;
        let (c, sn) = (self.way.cos(), self.way.sin());
        let along = (od.x - self.start.0) * c + (od.y - self.start.1) * sn;
        // The doors: the front sonar's cone alone, which fits through the doorway even from a
        // little off its axis (the panel is beside it); the side posts are the centring's.
        let ahead = arc(s, -5.0, 5.0).map_or(0.0, |(near, _)| near);
        let err = wrap(self.way - od.theta);
        if self.phase == TURNING && err.abs() < 0.04 {
            self.phase = WAITING;
        } else if self.phase == WAITING && err.abs() > 0.06 {
            // The way out moved (squared to the cabin): turn to it again.
            self.phase = TURNING;
        }
        if self.phase == WAITING && p.go == 1 && ahead > p.clear {
            self.phase = LEAVING;
        } else if self.phase == WAITING
            && p.go == 1
            && let Some(side) = doors_beside(s, p.clear)
        {
            // The doors opened beside it: the way out was squared to the wrong wall (turned
            // toward the panel's button at 45° to the walls, the half turn is as near one wall
            // as the other; building G seed 5 waited at the cabin's side wall for 890 s).
            self.way = wrap(self.way + side * FRAC_PI_2);
            self.phase = TURNING;
        }
        if self.phase == LEAVING {
            if along >= p.distance {
                self.phase = OUT;
            } else if ahead < p.clear && along < p.doorway {
                // The doors are closing in front: wait for them to open again.
                self.phase = WAITING;
            }
        }
        let drive = match self.phase {
            TURNING => Drive {
                translate: 0.0,
                rotate: turn_toward(err, p.gain, 0.8, 0.08, 0.0),
            },
            LEAVING => {
                let mut steer = err;
                if let (Some(l), Some(r)) = (side_wall(s, 1.0), side_wall(s, -1.0)) {
                    // Between the cabin's side walls: toward its centre line, which runs
                    // through the doorway's centre (the robot may stand off it, beside the
                    // panel's end button).
                    let left_of = (r.distance - l.distance) / 2.0;
                    steer -= (CABIN_CENTRING * left_of).clamp(-0.45, 0.45);
                } else if along > 0.2 && along < p.distance - 0.3 {
                    // Between the posts: toward the middle of the gap they leave ahead. Off
                    // the doorway's axis a post ahead may be in the front sonars' cones only
                    // (building D seed 4: 0.17 m off, the posts never in the side sonars'),
                    // so the echoes count by where they are across the way, not by sonar.
                    let middle = gap_middle(s);
                    steer = match self.by_the_gap_until {
                        // Held at a post: the way out itself is off (squared to a bad fit of
                        // the cabin), so the gap alone says where to go until past it.
                        Some(until) if along < until => (middle / GAP_LOOK).atan().clamp(-0.8, 0.8),
                        _ => steer + (p.centre * middle).clamp(-0.5, 0.5),
                    };
                }
                let slow = 0.05 + 0.8 * (p.distance - along);
                let translate = if steer.abs() < 0.8 && ahead > BLOCKED {
                    p.speed.min(slow) * steer.cos().powi(2)
                } else {
                    0.0
                };
                self.pinned_for = if translate > 0.05 && od.v.abs() < 0.02 {
                    self.pinned_for + 1
                } else {
                    0
                };
                if self.pinned_for > PINNED && self.by_the_gap_until.is_none_or(|u| along >= u) {
                    self.by_the_gap_until = Some(along + BY_THE_GAP);
                }
                Drive {
                    translate,
                    rotate: (p.gain * steer).clamp(-1.0, 1.0),
                }
            }
            _ => Drive::default(),
        };
        o.drive.set(drive);
        o.progress.set(Progress {
            done: self.phase == OUT,
            phase: self.phase,
            value: along,
        });
        Ok(())
    }
}
