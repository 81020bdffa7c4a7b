//! Going round what holds a straight approach: `home` to the barcode, `go_through` to the
//! point before the door on its axis.
//!
//! Both drive straight for a goal, with `avoid` above them. With a box between the robot and
//! the goal, `avoid` turns the robot away, the approach turns it back, and it stands at the
//! box for good.
//!
//! A [`Detour`] watches the approach: held [`HELD_S`] without getting [`PROGRESS`] nearer,
//! with something on the line to the goal (a sonar facing within [`ON_LINE`] of the goal's
//! bearing reads under [`NEAR`], and [`SHORT`] short of the goal), it takes a side and steers
//! for the clear lane nearest the goal on that side, until no sonar facing within
//! [`OFF_LINE`] of the goal reads so near. A lane is clear when the ring sees nothing in it:
//! [`HALF_WIDTH`] each side of its centre line for [`LANE_LENGTH`], each echo wherever in its
//! cone the other readings leave it room ([`echo_places`]: a gap 1.4 m wide is a lane).
//! Until a detour starts the approach's bearing is
//! returned as it is: an approach that is not held, or held with its line clear, is not
//! changed.
//!
//! The line is judged from the sonars facing the goal and only near: a lane test out to the
//! goal saw a wall the goal is on, or one the robot runs beside, as blocking (each cone spans
//! 30°). A wall near and nearly along the line can still count (a barcode approached within
//! 0.65 m of its wall at a shallow angle); a detour started there cannot end round, and gives
//! up after [`ROUND_S`], one side after the other.
//!
//! What holds the robot may also stand beside the line, not on it: a box's corner that the
//! body's own corridor toward the goal clips ([`BODY`] each side of the line, [`BODY_AHEAD`]
//! ahead), which the device's safety layer stops the robot for. No sonar facing the goal hears
//! it (building F seeds 5, 15 and 18: `go_through` lining up from 0.1 m above a box's top,
//! the approach point past the box's far corner, held there for 800 s). With
//! [`Watch::LineAndBody`] (`go_through`'s), held with the corridor not clear counts as held
//! with something on the line, and round is when the corridor is clear too. `home` watches
//! the line only ([`Watch::Line`]): with the corridor, the held-out lab north-maze lost 6
//! of its 9 exits (docs/measurements.md, "The body's corridor").

use super::*;

/// Held this long (s) without getting nearer, with something on the line to the goal, the
/// approach goes round. `avoid` turns away from a box and the approach turns back in a few
/// seconds.
pub const HELD_S: f64 = 8.0;
/// Nearer the goal by this much (m) counts as getting nearer.
pub const PROGRESS: f64 = 0.25;
/// Going round gives up after this long (s); the next try takes the other side.
pub const ROUND_S: f64 = 30.0;
/// Something this near (m, from the ring) on the line to the goal holds the approach ...
pub const NEAR: f64 = 1.0;
/// ... and this much short of the goal (m): the goal's own wall, seen through the cone's
/// edge, reads a little short of it ...
pub const SHORT: f64 = 0.5;
/// ... on the line: a sonar facing within this of the goal's bearing (rad, 15°) ...
pub const ON_LINE: f64 = PI / 12.0;
/// ... and round it when no sonar facing within this of it reads so near (rad, 20°).
pub const OFF_LINE: f64 = PI / 9.0;
/// Half a lane (m, from its centre line): the robot's radius (0.36 m) and a margin.
pub const HALF_WIDTH: f64 = 0.55;
/// Half the body's own corridor toward the goal (m, from its centre line): the robot's
/// radius and the safety layer's lateral margin (0.04 m), and a little.
pub const BODY: f64 = 0.45;
/// The body's corridor is judged this far toward the goal (m, from the robot's centre; the
/// radius, the safety layer's stop gap and braking), and no nearer than [`SHORT`] to it.
pub const BODY_AHEAD: f64 = 0.9;
/// The lane the robot takes round must be clear this far (m, from its centre).
const LANE_LENGTH: f64 = 1.2;
/// Lanes tried round, from the goal's bearing outward (rad, 10°).
const STEP: f64 = PI / 18.0;

/// The side a detour goes round on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
enum Side {
    Left,
    Right,
}

impl Side {
    /// The sign of a turn to this side (counter-clockwise positive).
    fn sign(self) -> f64 {
        match self {
            Side::Left => 1.0,
            Side::Right => -1.0,
        }
    }

    fn other(self) -> Side {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
}

/// What counts as something in the way of a held approach (see the module's doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Watch {
    /// Something near on the line, heard by a sonar facing the goal.
    Line,
    /// That, or something in the body's own corridor toward the goal.
    LineAndBody,
}

/// The watch on one straight approach (see the module's doc). Kept with its skill's state.
#[derive(Debug, Default, Clone, Copy, Serialize, Deserialize)]
pub struct Detour {
    /// Nearest the goal has been since the last progress (m); `None` before the first cycle.
    best: Option<f64>,
    /// Cycles since the approach last got nearer.
    since: u32,
    /// The side it is going round on; `None`: not going round.
    side: Option<Side>,
    /// Cycles of going round before it gives up.
    remaining: u32,
    /// The side of the last detour that gave up: the next takes the other.
    gave_up: Option<Side>,
}

impl Detour {
    /// Starts afresh: a new activation, or the approach stopped wanting to get nearer (at its
    /// stop distance).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// The bearing (rad, the robot's frame) to steer for this cycle, approaching a goal at
    /// `bearing` and `far` (m, from the robot's centre) with the ring `s`: the goal's own
    /// bearing, or going round, the clear lane nearest it on the side taken (the goal's
    /// bearing when no lane on that side is clear). Counts a cycle of `period_ms`; `watch`
    /// says what holds the way.
    pub fn steer(
        &mut self,
        s: &Sonar,
        bearing: f64,
        far: f64,
        period_ms: f64,
        watch: Watch,
    ) -> f64 {
        match self.best {
            Some(best) if far > best - PROGRESS => self.since += 1,
            _ => {
                self.best = Some(far);
                self.since = 0;
            }
        }
        let cycles = |secs: f64| (secs * 1000.0 / period_ms.max(1.0)) as u32;
        let side = match self.side {
            None => {
                if self.since < cycles(HELD_S) || !in_the_way(s, bearing, far, ON_LINE, watch) {
                    return bearing;
                }
                let side = self
                    .gave_up
                    .map_or_else(|| nearer_side(s, bearing), Side::other);
                self.remaining = cycles(ROUND_S);
                side
            }
            Some(side) if self.remaining == 0 || !in_the_way(s, bearing, far, OFF_LINE, watch) => {
                // Given up, or round: straight again, counting afresh.
                self.gave_up = (self.remaining == 0).then_some(side);
                self.side = None;
                self.best = Some(far);
                self.since = 0;
                return bearing;
            }
            Some(side) => side,
        };
        self.side = Some(side);
        self.remaining = self.remaining.saturating_sub(1);
        way_round(s, bearing, side).unwrap_or(bearing)
    }
}

/// Whether something is near on the line to a goal at `bearing` (rad, the robot's frame) and
/// `far` (m, from the robot's centre): a sonar facing within `within` of it reads under
/// [`NEAR`] and [`SHORT`] short of the goal.
fn on_the_line(s: &Sonar, bearing: f64, far: f64, within: f64) -> bool {
    let near = NEAR.min(far - RING - SHORT);
    (0..SONARS).any(|i| {
        wrap(sonar_angle(i) - bearing).abs() <= within && range(s, i).is_some_and(|r| r < near)
    })
}

/// Whether something holds the way to a goal at `bearing` and `far`: on the line
/// ([`on_the_line`] with `within`), or with [`Watch::LineAndBody`] in the body's corridor
/// toward it ([`BODY`], [`BODY_AHEAD`]).
fn in_the_way(s: &Sonar, bearing: f64, far: f64, within: f64, watch: Watch) -> bool {
    on_the_line(s, bearing, far, within)
        || (watch == Watch::LineAndBody && !clear(s, bearing, BODY_AHEAD.min(far - SHORT), BODY))
}

/// Whether the lane toward `heading` (rad, the robot's frame) is clear for `length` (m from
/// the robot's centre): no place an echo of the ring may come from ([`echo_places`]) within
/// `half` of its centre line before `length`. Unread sonars see nothing.
fn clear(s: &Sonar, heading: f64, length: f64, half: f64) -> bool {
    let (c, sn) = (heading.cos(), heading.sin());
    let mut clear = true;
    for i in 0..SONARS {
        echo_places(s, i, |x, y| {
            let along = x * c + y * sn;
            clear &= along <= 0.0 || along >= length || (y * c - x * sn).abs() >= half;
        });
    }
    clear
}

/// The clear lane nearest `bearing` on `side`, short of turning back.
fn way_round(s: &Sonar, bearing: f64, side: Side) -> Option<f64> {
    (1..18)
        .map(|k| wrap(bearing + side.sign() * f64::from(k) * STEP))
        .find(|&h| clear(s, h, LANE_LENGTH, HALF_WIDTH))
}

/// The side whose clear lane is nearer the goal's bearing (left on a tie or when neither has
/// one).
fn nearer_side(s: &Sonar, bearing: f64) -> Side {
    let turn = |side| way_round(s, bearing, side).map(|h| wrap(h - bearing).abs());
    match (turn(Side::Left), turn(Side::Right)) {
        (Some(l), Some(r)) if r < l => Side::Right,
        (None, Some(_)) => Side::Right,
        _ => Side::Left,
    }
}
