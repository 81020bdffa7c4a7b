//! `avoid`: obstacle avoidance from the sonar ring.

use super::*;
use serde::{Deserialize, Serialize};

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
#[derive(Default, Serialize, Deserialize)]
pub struct Avoid {
    /// Side chosen while an obstacle persists (stops dithering): +1 left, −1 right.
    side: f64,
}

impl Skill for Avoid {
    type Params = AvoidParams;
    type Inputs<'a> = SonarIn<'a>;
    type Outputs<'a> = DriveOut<'a>;
    const STATE: State<Self> = State::kept(1);
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
