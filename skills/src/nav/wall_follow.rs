//! `wall_follow`: hallway (wall) following.

use super::*;
use serde::{Deserialize, Serialize};

/// A side cone reading farther than this sees no wall (m, from the ring).
const NO_WALL: f64 = 2.0;
/// A side cone reading this or nearer is on a wall the robot is beside (m, from the ring).
const BESIDE: f64 = 1.2;

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
/// or leaving the wall at up to 30°. Beside a wall, while the 60° or 120° cone looks through
/// an opening, the heading is held (steered by the distance alone): an open door ahead or
/// behind does not draw the robot in. A wall ahead turns it away. Where the wall beside
/// stops, it holds its heading for `gap` cycles (past an open door), then curves toward the
/// side (around a corner).
#[derive(Default, Serialize, Deserialize)]
pub struct WallFollow {
    /// Cycles since the wall was last beside.
    lost: u64,
}

impl Skill for WallFollow {
    type Params = WallFollowParams;
    type Inputs<'a> = SonarIn<'a>;
    type Outputs<'a> = DriveOut<'a>;
    const STATE: State<Self> = State::kept(1);
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
        let open = beside > NO_WALL;
        self.lost = if open { self.lost + 1 } else { 0 };
        let (translate, turn_left) = if ahead < p.distance + 0.3 {
            // A wall ahead: turn away from the wall's side on the spot.
            (0.0, 1.0)
        } else if open && self.lost <= p.gap {
            // A gap in the wall: straight on.
            (p.speed, 0.0)
        } else if open {
            // No wall: curve toward the side.
            (p.speed, -0.3 / p.gain.max(0.1))
        } else {
            // Heading toward the wall (positive) from the front/back imbalance. Beside a
            // wall (the 60° or 120° cone on it), the other cone seeing no wall looks through
            // an opening (a door, the wall's end): it tells nothing of the heading, which is
            // held.
            let toward = if front.min(back) <= BESIDE && front.max(back) > NO_WALL {
                0.0
            } else {
                ((1.0 - front / back) / 0.54).clamp(-0.6, 0.6)
            };
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
