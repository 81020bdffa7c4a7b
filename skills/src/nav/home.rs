//! `home`: homing on the tracked target.

use super::*;

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
    /// The ring (going round what holds the approach).
    pub sonar: Input<'a, Sonar>,
}

/// Homing: drive toward the tracked target, stop at `stop_distance`. Held short of it with
/// something in the way, it goes round ([`Detour`]). With the target behind (more than 90°
/// off), it turns on the spot the short way; when that turn gets no nearer the target's
/// bearing for [`TURN_HELD_S`] (`avoid` turning it back from what is on that side, the two
/// taking turns for as long as the run lasts), it turns the other way round.
#[derive(Default, Serialize, Deserialize)]
pub struct Home {
    detour: Detour,
    activation: Activation,
    #[serde(default)]
    turn: Turn,
}

/// How long (s) a turn on the spot may get no nearer the target's bearing before it goes
/// the other way round: `avoid` pushes a blocked turn back within a few seconds.
pub const TURN_HELD_S: f64 = 4.0;
/// Nearer the target's bearing by this much (rad) counts as getting nearer.
const TURN_PROGRESS: f64 = 0.2;

/// A turn on the spot toward a target behind the robot.
#[derive(Debug, Default, Clone, Copy, Serialize, Deserialize)]
struct Turn {
    /// The way it turns (+1 counter-clockwise, −1 clockwise); 0: not turning on the spot.
    side: f64,
    /// The least turn left to the target's bearing since it last got nearer (rad).
    best: f64,
    /// Cycles since it last got nearer.
    since: u32,
}

impl Turn {
    /// The turn (rad, signed) to make toward a target at `bearing` (rad, the robot's frame):
    /// `bearing` itself within 90° of the heading, beyond that the turn this one goes round,
    /// the other way after it has been held `TURN_HELD_S` (`held`, in cycles).
    fn toward(&mut self, bearing: f64, held: u32) -> f64 {
        if bearing.abs() <= PI / 2.0 {
            *self = Turn::default();
            return bearing;
        }
        // The turn left going round on `side`: in (0, 2π).
        let left = |side: f64| (side * bearing).rem_euclid(2.0 * PI);
        if self.side == 0.0 {
            self.side = bearing.signum();
            self.best = left(self.side);
            self.since = 0;
        } else if left(self.side) < self.best - TURN_PROGRESS {
            self.best = left(self.side);
            self.since = 0;
        } else {
            self.since += 1;
            if self.since >= held {
                self.side = -self.side;
                self.best = left(self.side);
                self.since = 0;
            }
        }
        self.side * left(self.side)
    }
}

impl Skill for Home {
    type Params = HomeParams;
    type Inputs<'a> = HomeIn<'a>;
    type Outputs<'a> = DriveOut<'a>;
    const STATE: State<Self> = State::kept(1);
    const PRIORITY: i32 = 4;
    fn compute(&mut self, ctx: &Ctx<HomeParams>, i: HomeIn, o: &mut DriveOut) -> SkillResult {
        let p = ctx.params;
        let t = *i.target;
        if self.activation.begins(ctx) {
            self.detour.reset();
            self.turn = Turn::default();
        }
        if !t.seen {
            return Ok(());
        }
        let period = period_ms(ctx);
        let bearing = if t.range > p.stop_distance {
            self.detour
                .steer(&i.sonar, t.bearing, t.range, period, Watch::Line)
        } else {
            self.detour.reset();
            t.bearing
        };
        let bearing = self
            .turn
            .toward(bearing, (TURN_HELD_S * 1000.0 / period.max(1.0)) as u32);
        let rotate = (p.gain * bearing).clamp(-1.0, 1.0);
        let translate = if t.range > p.stop_distance {
            p.speed * bearing.cos().max(0.0)
        } else {
            0.0
        };
        o.drive.set(Drive { translate, rotate });
        Ok(())
    }
}
