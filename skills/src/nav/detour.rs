//! Going round what holds a straight approach: `home` to the barcode, `go_through` to the
//! door's axis.
//!
//! Both drive straight for a goal, with `avoid` above them. A box between the robot and the
//! goal stops the approach for good: `avoid` turns the robot away, the approach turns it
//! back, and it stands at the box. The first batches of the held-out lab south-detour (four
//! runs at box A's corner, `home`) and building F (five runs behind a box on the door's axis,
//! `go_through`) ended so.
//!
//! A [`Detour`] watches the approach: held [`HELD_S`] without getting [`PROGRESS`] nearer,
//! with something on the line to the goal (a sonar within [`ON_LINE`] of the goal's bearing
//! reads nearer than [`NEAR`], and nearer than the goal), it takes a side and steers for the
//! clear way nearest the goal on that side, until nothing is near within [`OFF_LINE`] of the
//! goal's bearing. A way round is clear when the ring sees nothing in a lane as wide as the
//! robot and a margin ([`HALF_WIDTH`] each side), each echo placed at the edge of its cone
//! nearest the lane. An approach that is not held, or held with its line clear, is not
//! changed.
//!
//! The line is judged from the sonars facing the goal and only near: a lane test out to the
//! goal sees a wall the goal is on (a barcode approached at a shallow angle) or runs beside
//! (each cone spans 30°) as blocking.

use super::range as range_of;
use super::*;

/// Held this long (s) without getting nearer, with the way to the goal blocked, the approach
/// goes round. `avoid` turns away from a box and the approach turns back in a few seconds.
pub const HELD_S: f64 = 8.0;
/// Nearer the goal by this much (m) counts as getting nearer.
pub const PROGRESS: f64 = 0.25;
/// Going round gives up after this long (s); the next try takes the other side.
pub const ROUND_S: f64 = 30.0;
/// Something this near (m, from the ring) on the line to the goal holds the approach ...
pub const NEAR: f64 = 1.0;
/// ... on the line: a sonar facing within this of the goal's bearing (rad, 15°) ...
pub const ON_LINE: f64 = PI / 12.0;
/// ... and round it when nothing is near within this of it (rad, 20°).
pub const OFF_LINE: f64 = PI / 9.0;
/// Half the lane a way round needs (m, from its centre line): the robot's radius (0.36 m)
/// and a margin.
pub const HALF_WIDTH: f64 = 0.55;
/// The way the robot takes round must be clear this far (m, from its centre).
const WAY: f64 = 1.2;
/// Ways tried round, from the goal's bearing outward (rad, 10°).
const STEP: f64 = PI / 18.0;
/// Half a sonar's cone (rad).
const CONE: f64 = PI / 12.0;

/// The watch on one straight approach (see the module's doc). Kept with its skill's state.
#[derive(Debug, Default, Clone, Copy, Serialize, Deserialize)]
pub struct Detour {
    /// Nearest the goal has been since the last progress (m); `None` before the first cycle.
    best: Option<f64>,
    /// Cycles since the approach last got nearer.
    since: u32,
    /// The side it is going round (+1 left, −1 right); 0: not going round.
    side: f64,
    /// Cycles left to go round before giving up.
    left: u32,
    /// The side of the last try that gave up (the next takes the other); 0: none.
    gave_up: f64,
}

impl Detour {
    /// Starts afresh: a new activation, or the approach stopped wanting to get nearer (at its
    /// stop distance).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// True while going round.
    pub fn going_round(&self) -> bool {
        self.side != 0.0
    }

    /// The bearing (rad, the robot's frame) to steer for this cycle, approaching a goal at
    /// `bearing` and `range` (m, from the robot's centre) with the ring `s`: the goal's own
    /// bearing, or going round, the clear way nearest it on the side taken. Counts a cycle of
    /// `period_ms`.
    pub fn steer(&mut self, s: &Sonar, bearing: f64, range: f64, period_ms: f64) -> f64 {
        match self.best {
            Some(best) if range > best - PROGRESS => self.since += 1,
            _ => {
                self.best = Some(range);
                self.since = 0;
            }
        }
        let cycles = |secs: f64| (secs * 1000.0 / period_ms.max(1.0)) as u32;
        if self.side == 0.0 {
            if !on_the_line(s, bearing, range, ON_LINE) || self.since < cycles(HELD_S) {
                return bearing;
            }
            self.side = if self.gave_up != 0.0 {
                -self.gave_up
            } else {
                nearer_side(s, bearing)
            };
            self.left = cycles(ROUND_S);
        } else if self.left == 0 || !on_the_line(s, bearing, range, OFF_LINE) {
            // Given up, or round: straight again, counting afresh.
            self.gave_up = if self.left == 0 { self.side } else { 0.0 };
            self.side = 0.0;
            self.best = Some(range);
            self.since = 0;
            return bearing;
        }
        self.left -= 1;
        way_round(s, bearing, self.side).unwrap_or(bearing)
    }
}

/// Whether something is near on the line to a goal at `bearing` (rad, the robot's frame) and
/// `range` (m, from the robot's centre): a sonar facing within `within` of it reads nearer
/// than [`NEAR`] and short of the goal.
fn on_the_line(s: &Sonar, bearing: f64, range: f64, within: f64) -> bool {
    let near = NEAR.min(range - RING - 0.5);
    (0..SONARS).any(|i| {
        wrap(sonar_angle(i) - bearing).abs() <= within && range_of(s, i).is_some_and(|r| r < near)
    })
}

/// Whether the lane toward `heading` (rad, the robot's frame) is clear for `length` (m from
/// the robot's centre): no echo of the ring, placed at the edge of its cone nearest the lane,
/// within [`HALF_WIDTH`] of its centre line before `length`. Unread sonars see nothing.
pub fn clear(s: &Sonar, heading: f64, length: f64) -> bool {
    (0..SONARS).all(|i| {
        let Some(r) = range_of(s, i) else {
            return true;
        };
        let off = (wrap(sonar_angle(i) - heading).abs() - CONE).max(0.0);
        // From the robot's centre: a sonar's range is from the ring.
        let d = r + RING;
        off >= PI / 2.0 || d * off.cos() >= length || d * off.sin() >= HALF_WIDTH
    })
}

/// The clear way nearest `bearing` on `side` (+1 left, −1 right), short of turning back.
fn way_round(s: &Sonar, bearing: f64, side: f64) -> Option<f64> {
    (1..18)
        .map(|k| wrap(bearing + side * f64::from(k) * STEP))
        .find(|&h| clear(s, h, WAY))
}

/// The side whose clear way is nearer the goal's bearing (left on a tie or when neither has
/// one).
fn nearer_side(s: &Sonar, bearing: f64) -> f64 {
    let turn = |side: f64| way_round(s, bearing, side).map(|h| wrap(h - bearing).abs());
    match (turn(1.0), turn(-1.0)) {
        (Some(l), Some(r)) if r < l => -1.0,
        (None, Some(_)) => -1.0,
        _ => 1.0,
    }
}
