//! `intersection`: corridor intersections from the sonar ring.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`Intersection`].
#[derive(Params, Debug, Clone)]
pub struct IntersectionParams {
    /// A way is open when its arc reads farther than this (m, from the ring). Not more than
    /// 2.2: from the middle of a crossing 2.4 m corridor, the cones of the sonars at ±75° and
    /// ±105° reach that corridor's far walls 2.2 m away, so a larger value never opens a side.
    /// A 1 m door beside never opens all three cones of a side, whatever this is.
    #[param(default = 1.7, min = 0.5, max = 10.0)]
    pub open: f64,
    /// Cycles a change must persist before `inside` follows it.
    #[param(default = 10, min = 1, max = 10000)]
    pub hold: u64,
    /// Walls on both sides end an intersection only once the robot has moved this far with
    /// them there (m): turning on the spot in a crossing or a doorway's exit, the side cones
    /// can find walls on both sides for longer than `hold`, and an intersection that ended
    /// there would count again when the turn is over.
    #[param(default = 0.3, min = 0.0, max = 5.0)]
    pub leave: f64,
    /// Once the robot has had a wall beside, a side opens an intersection only after it has
    /// been open over this much travel (m), or with a wall across the way (the sonar straight
    /// ahead within `open`: a T's bar): a 1 m door beside a robot 0.2 to 0.4 m off the
    /// centre line toward it opens all three cones of that side for 0.03 to 0.25 m of
    /// travel, a 2.4 m corridor's mouth for 0.45 to 0.55 m, wherever the robot is across
    /// the corridor.
    #[param(default = 0.3, min = 0.0, max = 5.0)]
    pub width: f64,
}

/// Inputs of [`Intersection`].
#[derive(Inputs)]
pub struct IntersectionIn<'a> {
    /// The ring.
    pub sonar: Input<'a, Sonar>,
    /// Odometry (how far it has moved with walls beside).
    pub odometry: Input<'a, Odometry>,
}

/// Output of [`Intersection`].
#[derive(Outputs)]
pub struct JunctionOut<'a> {
    /// Whether it is in an intersection, and how many it has entered.
    pub junction: Output<'a, Junction>,
}

/// Corridor intersections. A side is open when the whole arc 60°..120° (−120°..−60° for the
/// right) reads farther than `open`: the sonars at 75°, 90° and 105°, whose cones fill that
/// arc. Ahead is open when the sonars within ±20° (cones over ±30°) read farther than `open`.
///
/// `inside` turns true when a side has been open for `hold` cycles (and, once the robot has
/// had a wall beside since activation, over `width` metres of travel or with a wall across
/// the way: a door beside is not a junction), and false only when both
/// sides are closed along their whole arcs (60°..120°, −120°..−60°: walls beside again) for
/// `hold` cycles and over `leave` metres of travel: turning on the spot in a crossing, the
/// side sonars look into its corners, which must not end the intersection (and count it
/// twice). `count` is the
/// number of times `inside` turned true since the skill was last activated, so an
/// intersection the robot is in at activation counts at once.
///
/// For a sequencer: `junction.count >= n` (the n-th intersection entered), `junction.inside`,
/// `junction.left`/`right`/`ahead` (which ways are open now).
#[derive(Default, Serialize, Deserialize)]
pub struct Intersection {
    activation: Activation,
    inside: bool,
    count: u32,
    /// Consecutive cycles the raw reading has disagreed with `inside`.
    differs: u64,
    /// Where the raw reading began to disagree with `inside` (odometry).
    since: Option<(f64, f64)>,
    /// A wall beside seen since activation (from then on a side must open over `width`):
    /// activated in the open (a lobby, a doorway's exit) an open side counts at once.
    #[serde(default)]
    walled_once: bool,
}

impl Skill for Intersection {
    type Params = IntersectionParams;
    type Inputs<'a> = IntersectionIn<'a>;
    type Outputs<'a> = JunctionOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(
        &mut self,
        ctx: &Ctx<IntersectionParams>,
        i: IntersectionIn,
        o: &mut JunctionOut,
    ) -> SkillResult {
        let (s, od, p) = (&*i.sonar, &*i.odometry, ctx.params);
        if self.activation.begins(ctx) {
            self.inside = false;
            self.count = 0;
            self.differs = 0;
            self.since = None;
            self.walled_once = false;
        }
        // Open: every reading of the arc beyond `open`; closed: every reading within it.
        let open = |a: Option<(f64, f64)>| a.is_some_and(|(near, _)| near > p.open);
        let closed = |a: Option<(f64, f64)>| a.is_some_and(|(_, far)| far <= p.open);
        let left = open(arc(s, 60.0 + 15.0, 120.0 - 15.0));
        let right = open(arc(s, -120.0 + 15.0, -60.0 - 15.0));
        let ahead = open(arc(s, -20.0, 20.0));
        let (wall_left, wall_right) = (closed(arc(s, 60.0, 120.0)), closed(arc(s, -120.0, -60.0)));
        let walled = wall_left && wall_right;
        self.walled_once |= wall_left || wall_right;
        let wall_across = at(s, 0.0).is_some_and(|r| r <= p.open);
        let raw = if self.inside { !walled } else { left || right };
        if raw == self.inside {
            self.differs = 0;
            self.since = None;
        } else {
            self.differs += 1;
            let (x0, y0) = *self.since.get_or_insert((od.x, od.y));
            let moved = (od.x - x0).hypot(od.y - y0);
            let far_enough = if raw {
                !self.walled_once || moved >= p.width || wall_across
            } else {
                moved >= p.leave
            };
            if self.differs >= p.hold && far_enough {
                self.differs = 0;
                self.since = None;
                self.inside = raw;
                self.count += u32::from(raw);
            }
        }
        o.junction.set(Junction {
            count: self.count,
            inside: self.inside,
            left,
            right,
            ahead,
        });
        Ok(())
    }
}
