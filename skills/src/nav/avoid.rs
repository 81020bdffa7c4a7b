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
    /// An echo that can only come from this far beyond the robot's side or more (m), or
    /// from behind its centre, is beside the way ahead and does not make it take over: the
    /// robot drives through a gap twice this wider than itself. At [`EVERY_ECHO`] (the
    /// default) every echo in the arcs counts, wherever it may come from, as before the
    /// parameter: the corridor skills turn in lobbies with avoid turning at what is beside
    /// them. The lab plans lower it to 0.15 while `explore` and `home` drive, not along the
    /// wall (docs/measurements.md, "Gaps 1.4 m wide" and "The lab search by cost").
    #[param(default = 10.0, min = 0.0, max = 10.0)]
    pub beside: f64,
}

/// `beside` at which every echo in avoid's arcs counts (its largest value).
pub const EVERY_ECHO: f64 = 10.0;

/// Input of sonar-driven skills.
#[derive(Inputs)]
pub struct SonarIn<'a> {
    /// The ring.
    pub sonar: Input<'a, Sonar>,
}

/// Obstacle avoidance from the sonar ring: when something is closer than `safe_distance`
/// in the front arc (±46°), or than half of it on the flanks (46°–80°), turn toward the freer
/// side; otherwise propose nothing. With `beside` lowered, an echo counts only if it may come
/// from the way ahead ([`echo_places`]): one `beside` or more beyond the robot's side does
/// not. A box's corner passed 0.34 m off, in a gap 1.4 m wide, is seen by the sonars 45°–75°
/// off the front well inside their arcs: with every echo counted the robot is held there.
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
        let ahead = |from, to| min_ahead(&i.sonar, from, to, p.beside);
        let front = ahead(-0.8, 0.8)
            .min(2.0 * ahead(-1.4, -0.8))
            .min(2.0 * ahead(0.8, 1.4));
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

/// The smallest range among sonars whose angle lies within `[from, to]` (rad) and whose
/// echo may come from the way ahead: not only from `beside` (m) or more beyond the robot's
/// side, or from behind its centre (at [`EVERY_ECHO`], every sonar's).
fn min_ahead(s: &Sonar, from: f64, to: f64, beside: f64) -> f64 {
    if beside >= EVERY_ECHO {
        return min_in(s, from, to);
    }
    (0..SONARS)
        .filter(|&i| (from..=to).contains(&sonar_angle(i)))
        .filter(|&i| {
            let mut ahead = false;
            echo_places(s, i, |x, y| ahead |= x > 0.0 && y.abs() < RING + beside);
            ahead
        })
        .filter_map(|i| range(s, i))
        .fold(f64::INFINITY, f64::min)
}
