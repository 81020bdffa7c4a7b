//! `wander`: wandering that covers the room.

use super::*;
use serde::{Deserialize, Serialize};

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
#[derive(Default, Serialize, Deserialize)]
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
    const STATE: State<Self> = State::kept(1);
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
