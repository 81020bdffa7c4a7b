//! `door_detect`: side doors passed along a corridor, from the sonar ring.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`DoorDetect`].
#[derive(Params, Debug, Clone)]
pub struct DoorDetectParams {
    /// A side reading nearer than this is the corridor's wall (m, from the ring).
    #[param(default = 2.0, min = 0.3, max = 5.0)]
    pub wall: f64,
    /// A reading this much beyond the wall looks through an opening (m).
    #[param(default = 0.8, min = 0.1, max = 5.0)]
    pub margin: f64,
    /// Narrowest opening that counts as a door (m).
    #[param(default = 0.7, min = 0.1, max = 5.0)]
    pub min_width: f64,
    /// Widest opening that counts as a door (m); wider ones are intersections.
    #[param(default = 1.6, min = 0.1, max = 10.0)]
    pub max_width: f64,
}

/// Inputs of [`DoorDetect`].
#[derive(Inputs)]
pub struct DoorDetectIn<'a> {
    /// The ring.
    pub sonar: Input<'a, Sonar>,
    /// Odometry (the length of an opening is the distance driven past it).
    pub odometry: Input<'a, Odometry>,
}

/// Output of [`DoorDetect`].
#[derive(Outputs)]
pub struct DoorsOut<'a> {
    /// Doors passed on each side, and an opening beside now.
    pub doors: Output<'a, Doors>,
}

/// An opening beside the robot, from where it began.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Opening {
    /// Pose where the side sonar first saw through it.
    x: f64,
    y: f64,
    theta: f64,
    /// The wall's range before it (m, from the ring).
    wall: f64,
}

/// What one side has seen.
#[derive(Debug, Default, Clone, Copy, Serialize, Deserialize)]
struct Side {
    /// The wall's last range (m); `None` until a wall has been seen.
    wall: Option<f64>,
    opening: Option<Opening>,
    doors: u32,
}

/// An opening whose heading changed more than this (rad) was not passed along a wall (the
/// robot turned, and the side sonar swept): it is not measured.
const STRAIGHT: f64 = 0.35;

impl Side {
    /// A new reading `r` of this side's sonar from pose `od`.
    fn reading(&mut self, r: f64, od: &Odometry, p: &DoorDetectParams) {
        if let Some(op) = self.opening {
            if r >= op.wall + p.margin {
                return;
            }
            // The wall is back: the opening's length is the distance driven along it, plus
            // the cone's width at the wall, which hid the opening's ends from the sonar.
            self.opening = None;
            self.wall = Some(r);
            let driven = (od.x - op.x) * op.theta.cos() + (od.y - op.y) * op.theta.sin();
            let width = driven + 2.0 * op.wall * CONE.tan();
            let straight = wrap(od.theta - op.theta).abs() < STRAIGHT;
            if straight && (p.min_width..=p.max_width).contains(&width) {
                self.doors += 1;
            }
        } else if r < p.wall {
            self.wall = Some(r);
        } else if let Some(w) = self.wall
            && r > w + p.margin
        {
            self.opening = Some(Opening {
                x: od.x,
                y: od.y,
                theta: od.theta,
                wall: w,
            });
        }
    }
}

/// Side doors along a corridor. Each side's sonar (at ±90°) ranges the wall beside; when it
/// reads `margin` beyond the wall, an opening begins there (by odometry); when the wall is
/// back, the opening's width is the distance driven along it, corrected for the cone (the
/// sonar sees through only once its whole cone is in the opening). A width within
/// `min_width..=max_width` is a door on that side; wider openings are intersections, and
/// openings passed while turning are not measured. Each reading is used once (a new reading
/// is younger than the last one seen).
///
/// For a sequencer: `doors.left >= n`, `doors.right >= n` (doors passed on each side since
/// activation), `doors.beside` (1 left, −1 right, 0 none: an opening beside now; left if both).
#[derive(Default, Serialize, Deserialize)]
pub struct DoorDetect {
    activation: Activation,
    /// Left, right.
    sides: [Side; 2],
    /// Age of each side sonar's reading in the last cycle.
    ages: [f64; 2],
}

/// The side sonars: left (90°), right (−90°).
const SIDE_SONARS: [usize; 2] = [SONARS / 4, 3 * SONARS / 4];

impl Skill for DoorDetect {
    type Params = DoorDetectParams;
    type Inputs<'a> = DoorDetectIn<'a>;
    type Outputs<'a> = DoorsOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(
        &mut self,
        ctx: &Ctx<DoorDetectParams>,
        i: DoorDetectIn,
        o: &mut DoorsOut,
    ) -> SkillResult {
        let (s, od, p) = (&*i.sonar, &*i.odometry, ctx.params);
        if self.activation.begins(ctx) {
            self.sides = [Side::default(); 2];
            self.ages = [f64::INFINITY; 2];
        }
        for (k, side) in self.sides.iter_mut().enumerate() {
            let n = SIDE_SONARS[k];
            let fresh = s.age_ms[n] < self.ages[k];
            self.ages[k] = s.age_ms[n];
            if let (true, Some(r)) = (fresh, range(s, n)) {
                side.reading(r, od, p);
            }
        }
        let [left, right] = self.sides;
        o.doors.set(Doors {
            left: left.doors,
            right: right.doors,
            beside: if left.opening.is_some() {
                1
            } else if right.opening.is_some() {
                -1
            } else {
                0
            },
        });
        Ok(())
    }
}
