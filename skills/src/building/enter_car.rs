//! `enter_car`: driving into an open elevator car.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`EnterCar`].
#[derive(Params, Debug, Clone)]
pub struct EnterCarParams {
    /// Forward speed across the lobby (m/s): a car's doors start closing 9.5 s after its
    /// lantern lights, and the robot waits some 5 m away to see all the lanterns.
    #[param(default = 0.7, min = 0.0, max = 1.0)]
    pub speed: f64,
    /// Forward speed between the door posts (m/s; from 0.6 m before the doorway line).
    #[param(default = 0.35, min = 0.0, max = 1.0)]
    pub through: f64,
    /// Steering gain (rad/s per rad).
    #[param(default = 1.5, min = 0.0, max = 10.0)]
    pub gain: f64,
    /// Line up on the doorway's axis this far before it (m).
    #[param(default = 1.2, min = 0.3, max = 5.0)]
    pub approach: f64,
    /// Stop this far past the doorway line (m): inside, clear of the doors.
    #[param(default = 0.95, min = 0.3, max = 3.0)]
    pub depth: f64,
    /// Centring gain between the door posts (rad per m of imbalance).
    #[param(default = 0.8, min = 0.0, max = 10.0)]
    pub centre: f64,
    /// Give up on a car whose doorway's light curtain is not reached this long after the car
    /// was first seen open (ms of fabric time): its doors start closing 9.5 s after its
    /// lantern lights (1.5 s opening, 8 s open), and closing doors meet a robot that comes
    /// into the curtain too late to hold them.
    #[param(default = 9000.0, min = 0.0, max = 600000.0)]
    pub open_ms: f64,
}

/// Inputs of [`EnterCar`].
#[derive(Inputs)]
pub struct EnterCarIn<'a> {
    /// The open car (car_watch).
    pub car: Input<'a, Car>,
    /// Odometry.
    pub odometry: Input<'a, Odometry>,
    /// The ring (centring between the door posts, and what is ahead).
    pub sonar: Input<'a, Sonar>,
}

/// Outputs of movement skills with one job.
#[derive(Outputs)]
pub struct DriveJobOut<'a> {
    /// The proposal.
    pub drive: Proposal<'a, Drive>,
    /// How far the job is.
    pub progress: Output<'a, Progress>,
}

/// Phases of [`EnterCar`] (its `progress.phase`).
pub mod enter_phase {
    /// Lining up before the doorway (or waiting for a car to be open).
    pub const LINING_UP: u32 = 0;
    /// Driving in along the doorway's axis.
    pub const ENTERING: u32 = 1;
    /// Inside: turning to face the back wall; `done` once it does.
    pub const INSIDE: u32 = 2;
    /// The doors closed before it reached the doorway: stopped, backed away to `approach`
    /// before them (activate it again to retry).
    pub const LOST: u32 = 3;
    /// The doors closed before it reached the doorway: backing away from them (then lost).
    pub const BACKING_OUT: u32 = 4;
}
use enter_phase::*;

/// Something this near ahead (m, from the ring) stops the drive in: not the back wall it
/// expects, or the doors.
const BLOCKED: f64 = 0.15;
/// Weight of one cycle's fit of the cabin's walls in the way to face.
const WALL_BLEND: f64 = 0.05;
/// Cycles for the device to bring a reading of every sonar (300 ms).
const RING_REFRESH: u32 = 30;
/// Cycles of wall fits before facing them counts ...
const WALLS_SETTLED: u32 = 40;
/// ... or cycles inside without them (a cabin whose walls the sonars do not fit).
const NO_WALLS: u32 = 300;
/// Within this of the approach point (m) it is lined up.
const LINED_UP: f64 = 0.3;
/// Closer than this to the doorway line (m), it drives at `through`.
const POSTS: f64 = 0.6;
/// Speed backing away from doors that closed (m/s).
const BACK_SPEED: f64 = 0.25;
/// Doors shut are looked for from this far before the doorway line (m) ...
const SHUT_FROM: f64 = 0.9;
/// ... to this far (nearer, the doors are in the light curtain's reach) ...
const SHUT_TO: f64 = 0.25;
/// ... within this of the axis (m) and of its heading (rad), where the straight-ahead cone
/// (±15°) lies within the 1.1 m doorway ...
const SHUT_CROSS: f64 = 0.15;
const SHUT_SQUARE: f64 = 0.15;
/// ... and read when the reading ends within this beyond the doorway's line (m; an open car
/// reads its cabin, 1.7 m deep).
const SHUT_MARGIN: f64 = 0.6;
/// Within this of the doorway line (m) the robot's centre is in the doors' light curtain
/// (0.51 m).
const CURTAIN: f64 = 0.45;
/// Deceleration the drive in counts on to stop short of what is ahead (m/s²; the robot's
/// limit is 0.5, and a sonar reading is up to 300 ms old).
const STOPPING: f64 = 0.35;

/// Drives into the open car. First to a point `approach` before the doorway on its axis,
/// then along the axis (a carrot 0.6 m ahead on it) centred between the door posts by the
/// side sonars, as go_through does; `depth` past the doorway line it stops and turns to face
/// the back wall (the way in, squared to the cabin's side walls when they are seen), where the
/// car's panel is. The doorway is taken from car_watch until the drive in begins, then held:
/// the lantern goes out of view as the robot passes under it. If no car is open (car.id 0:
/// the doors closed; or another car reported: car_watch keeps reporting a car while it is
/// open) before the robot's centre has passed the doorway line, it backs straight away to
/// `approach` before the doorway if it faces the doors (a retry starts in the open, not
/// against them; backing stops where something is near behind) and stops for good (`lost`);
/// past the line, the light curtain keeps the doors open. Doors seen shut by the sonar
/// straight ahead (lined up, 0.25–0.9 m before the doorway: it reads the doorway's line, not
/// the cabin) count as closed too, and so does a car whose light curtain it has not reached
/// `open_ms` after it first saw it open. The first car seen open since activation is the one it
/// enters.
///
/// For a sequencer: `enter_car.progress.done == 1` (inside, facing the back wall),
/// `enter_car.progress.phase == 3` (lost, backed away: call the car again and reactivate);
/// `progress.value` is the distance past the doorway line (m, negative before it).
#[derive(Default, Serialize, Deserialize)]
pub struct EnterCar {
    activation: Activation,
    phase: u32,
    /// The doorway (x, y, way in), held from the drive in on.
    doorway: Option<(f64, f64, f64)>,
    /// The car it is entering (the first open since activation), and its doorway when last
    /// reported open (what to back away from when its doors close).
    chosen: Option<u32>,
    last_car: Option<(f64, f64, f64)>,
    /// Whether a car has been seen open since activation (only then can it be lost), and the
    /// cycle it first was.
    saw_car: bool,
    first_seen: Option<u64>,
    /// Inside: the way to face, refined from the cabin's side walls, and the cycles they
    /// were seen in and spent inside.
    back: Option<f64>,
    walls_seen: u32,
    inside_for: u32,
    /// Cycles it has stood still (translation) inside.
    still_for: u32,
    /// Inside and facing the back wall (kept: a later wobble does not undo it).
    faced: bool,
}

impl Skill for EnterCar {
    type Params = EnterCarParams;
    type Inputs<'a> = EnterCarIn<'a>;
    type Outputs<'a> = DriveJobOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(
        &mut self,
        ctx: &Ctx<EnterCarParams>,
        i: EnterCarIn,
        o: &mut DriveJobOut,
    ) -> SkillResult {
        let (car, od, s, p) = (&*i.car, &*i.odometry, &*i.sonar, ctx.params);
        if self.activation.begins(ctx) {
            *self = EnterCar {
                activation: self.activation,
                ..EnterCar::default()
            };
        }
        if car.id != 0 && self.chosen.is_none() {
            self.chosen = Some(car.id);
        }
        // Another car reported: this one's lantern has not been seen for a while (car_watch
        // keeps reporting a car while it is open), its doors closed.
        let ours = car.id != 0 && self.chosen == Some(car.id);
        self.saw_car |= ours;
        if ours {
            self.last_car = Some((car.x, car.y, car.heading));
        }
        let stop = Drive::default();
        let closed = !ours && self.saw_car;
        let Some((dx, dy, h)) = self
            .doorway
            .or(ours.then_some((car.x, car.y, car.heading)))
            .or(self.last_car.filter(|_| closed))
        else {
            // No car seen open yet: wait.
            o.drive.set(stop);
            o.progress.set(Progress::default());
            return Ok(());
        };
        let (c, sn) = (h.cos(), h.sin());
        let along = (od.x - dx) * c + (od.y - dy) * sn;
        let cross = -(od.x - dx) * sn + (od.y - dy) * c;
        let period_ms = period_ms(ctx);
        let first = *self.first_seen.get_or_insert(ctx.cycle);
        let late =
            ctx.cycle.saturating_sub(first) as f64 * period_ms > p.open_ms && along < -CURTAIN;
        if (closed && along < 0.0 || late) && matches!(self.phase, LINING_UP | ENTERING) {
            self.phase = BACKING_OUT;
        }
        // Backing straight away from the doors only when it faces them, while nothing is
        // near behind.
        let facing = wrap(od.theta - h).abs() < 0.6;
        let clear_behind = arc(s, 150.0, 210.0).is_some_and(|(near, _)| near > BLOCKED + 0.1);
        if self.phase == BACKING_OUT && (along <= -p.approach || !facing || !clear_behind) {
            self.phase = LOST;
        }
        // Doors shut in front: on the axis short of the doorway and facing it, the cone of
        // the sonar straight ahead lies within the doorway and reads the doorway's line
        // instead of the cabin behind it. car_watch may still call the car open (its lantern
        // out of the camera's view on the way here).
        let square = wrap(od.theta - h).abs() < SHUT_SQUARE && cross.abs() < SHUT_CROSS;
        let shut = at(s, 0.0).is_some_and(|r| r < -along - RING + SHUT_MARGIN);
        if self.phase == ENTERING && (-SHUT_FROM..-SHUT_TO).contains(&along) && square && shut {
            self.phase = BACKING_OUT;
        }
        let ahead = min_in(s, -0.5, 0.5);
        let drive = match self.phase {
            LINING_UP => {
                let start = (dx - p.approach * c, dy - p.approach * sn);
                let to_start = (start.0 - od.x).hypot(start.1 - od.y);
                // On the axis already (a second try from inside the approach): go on.
                let on_axis = along > -p.approach && along < 0.0 && cross.abs() < 0.1;
                if to_start < LINED_UP || on_axis {
                    self.phase = ENTERING;
                    self.doorway = Some((dx, dy, h));
                }
                let want = (start.1 - od.y).atan2(start.0 - od.x);
                let err = wrap(want - od.theta);
                Drive {
                    // Slowing into the approach point, so as not to circle it.
                    translate: if err.abs() < 0.8 {
                        p.speed.min(p.through + to_start) * err.cos().powi(2)
                    } else {
                        0.0
                    },
                    rotate: (p.gain * err).clamp(-1.0, 1.0),
                }
            }
            ENTERING if along >= p.depth => {
                self.phase = INSIDE;
                stop
            }
            ENTERING => {
                let carrot = along + 0.6;
                let goal = (dx + carrot * c, dy + carrot * sn);
                let want = (goal.1 - od.y).atan2(goal.0 - od.x);
                let mut err = wrap(want - od.theta);
                if (-POSTS..POSTS).contains(&along) {
                    // Between the posts: steer away from the nearer one.
                    let left = min_in(s, 0.5, 2.4).min(0.8);
                    let right = min_in(s, -2.4, -0.5).min(0.8);
                    err += p.centre * (left - right) / 2.0;
                }
                let limit = if along > -POSTS { p.through } else { p.speed };
                let slow = 0.05 + 0.8 * (p.depth - along);
                // Able to stop short of what the ring sees ahead: doors that closed while
                // car_watch still reports the car (1.5 s after its lantern went out) stand
                // across the way, and coming in askew the shut test does not see them. An
                // open doorway reads the cabin behind it (1.7 m deep): no limit there.
                let stoppable = (2.0 * STOPPING * (ahead - BLOCKED).max(0.0)).sqrt();
                Drive {
                    translate: if err.abs() < 0.8 && ahead > BLOCKED {
                        limit.min(slow).min(stoppable) * err.cos().powi(2)
                    } else {
                        0.0
                    },
                    rotate: (p.gain * err).clamp(-1.0, 1.0),
                }
            }
            BACKING_OUT => Drive {
                translate: -BACK_SPEED,
                rotate: 0.0,
            },
            INSIDE => {
                // Square to the cabin's side walls (each fit a few hundredths of a radian
                // off: blended), the way in when they are not seen.
                let mut back = self.back.unwrap_or(h);
                // Only from readings all taken since it stopped: the ring refreshes each
                // sonar every 300 ms, and those taken in the doorway see its posts.
                self.still_for = if od.v.abs() < 0.01 {
                    self.still_for + 1
                } else {
                    0
                };
                if self.still_for > RING_REFRESH
                    && let Some(a) = walls_axis(s, od.theta, back)
                {
                    back = wrap(back + WALL_BLEND * wrap(a - back));
                    self.walls_seen += 1;
                }
                self.back = Some(back);
                self.inside_for += 1;
                let err = wrap(back - od.theta);
                let settled = self.walls_seen >= WALLS_SETTLED || self.inside_for >= NO_WALLS;
                self.faced |= settled && err.abs() < 0.04;
                Drive {
                    translate: 0.0,
                    rotate: if self.faced {
                        0.0
                    } else {
                        turn_toward(err, p.gain, 0.6, 0.08, 0.0)
                    },
                }
            }
            _ => stop,
        };
        o.drive.set(drive);
        o.progress.set(Progress {
            done: self.faced,
            phase: self.phase,
            value: along,
        });
        Ok(())
    }
}
