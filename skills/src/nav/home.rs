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
/// something in the way, it goes round ([`Detour`]).
#[derive(Default, Serialize, Deserialize)]
pub struct Home {
    detour: Detour,
    activation: Activation,
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
        }
        if !t.seen {
            return Ok(());
        }
        let bearing = if t.range > p.stop_distance {
            self.detour
                .steer(&i.sonar, t.bearing, t.range, period_ms(ctx))
        } else {
            self.detour.reset();
            t.bearing
        };
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
