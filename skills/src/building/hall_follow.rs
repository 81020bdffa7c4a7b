//! `hall_follow`: driving along corridors and turning at intersections.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`HallFollow`].
#[derive(Params, Debug, Clone)]
pub struct HallFollowParams {
    /// Forward speed (m/s).
    #[param(default = 0.35, min = 0.0, max = 1.0)]
    pub speed: f64,
    /// Steering gain (rad/s per rad of heading error).
    #[param(default = 1.5, min = 0.0, max = 10.0)]
    pub gain: f64,
    /// At the next intersection entered: 1 turn left, −1 turn right, 0 go straight through.
    #[param(default = 0, min = -1, max = 1)]
    pub turn: i64,
    /// With no turn pending, a wall ahead nearer than this stops it (m, from the ring).
    #[param(default = 1.2, min = 0.3, max = 5.0)]
    pub stop: f64,
    /// Turn this far past where the side sonar saw the side open (m): it sees past the
    /// corner 0.2 m after it, so 1.0 m is the middle of a crossing 2.4 m corridor.
    #[param(default = 1.0, min = 0.0, max = 5.0)]
    pub after: f64,
    /// ... or where a wall ahead is this near (m, from the ring): the middle of a 2.4 m
    /// corridor crossing a T's stem, or entered from a door.
    #[param(default = 0.85, min = 0.3, max = 3.0)]
    pub middle: f64,
    /// Steering toward the corridor's centre line (rad per m off it, at most 0.3 rad).
    #[param(default = 0.6, min = 0.0, max = 5.0)]
    pub centring: f64,
}

/// Inputs of [`HallFollow`].
#[derive(Inputs)]
pub struct HallFollowIn<'a> {
    /// The ring.
    pub sonar: Input<'a, Sonar>,
    /// Odometry (the corridor's axis and the turns are held in its frame).
    pub odometry: Input<'a, Odometry>,
    /// Intersections (the intersection skill).
    pub junction: Input<'a, Junction>,
}

/// What it is doing.
#[derive(Debug, Default, Clone, Copy, PartialEq, Serialize, Deserialize)]
enum Mode {
    /// Along the corridor.
    #[default]
    Follow,
    /// In an intersection with a turn latched (+1 left, −1 right): on to its middle, counted
    /// from `from`, where that side opened (`None` while it has not: a staggered crossing
    /// may open the other side first).
    Cross { turn: f64, from: Option<(f64, f64)> },
    /// Turning on the spot to a heading; `slide`: turned along a wall that stopped it in
    /// Leave, to cross into the mouth that opens in it and turn this way (+1 left, −1 right)
    /// into it, as at a T.
    Turn { to: f64, slide: Option<f64> },
    /// Out of the intersection on the new heading, until walls are on both sides.
    Leave,
}

/// A side reading nearer than this is a wall beside (m, from the ring).
const SIDE_WALL: f64 = 2.0;
/// Weight of one cycle's wall measurement in the corridor's axis: walls are fitted from
/// readings refreshed every 300 ms with a few cm of noise, so the axis averages about two
/// seconds of them.
const AXIS_BLEND: f64 = 0.005;
/// Wall measurements farther than this from the held axis (rad) are not the corridor's —
/// unless both sides' walls agree within [`WALLS_AGREE`]: two parallel walls, one each side,
/// are the corridor, and it is the held axis that is wrong (taken facing a sign beside a
/// door, not square to it, and turned out of the door from there).
const AXIS_GATE: f64 = 0.3;
/// Both side walls' axes within this of each other (rad) are taken whatever the held axis.
const WALLS_AGREE: f64 = 0.1;
/// Nothing is driven into: a wall ahead this near stops translation in every mode (m).
const TOO_CLOSE: f64 = 0.4;
/// Most the centring turns the heading off the axis (rad).
const CENTRING_MAX: f64 = 0.3;

/// Corridor following for the building's axis-aligned corridors. It holds the corridor's
/// axis (a heading in the odometry frame, refined from the side walls: the 60°, 90° and 120°
/// sonars of each side fitted as one straight wall) and its centre line between the walls;
/// with one side open (a door, a side corridor) it keeps the distance it had to the other
/// wall; with none (a lobby, a crossing), it holds the axis, turned toward the middle of a
/// corridor's mouth ahead when its edges show in the front cones. A wall ahead nearer than `stop` stops it.
///
/// Turns: when `junction.count` increases (an intersection entered; also one it is in at
/// activation), it latches `turn`. Straight (0): on along the axis. Left or right: on to the
/// middle of the crossing corridor (`after` past where its side sonar saw that side open, or
/// a wall ahead at `middle`), a quarter turn on the spot (the axis ± 90°: the corridors are
/// square to each other), then out on the new heading until walls are on both sides again.
/// A wall ahead with a turn latched starts the turn at once; at a wall ahead with `turn` set
/// while in an intersection whose entry it has missed, it turns too. Stopped by a wall across
/// the way with the turn's side never seen to open by its side sonar (out of a door askew
/// toward that side, the sonar's cone reads the wall the door is in), another sonar on that
/// side reading open is the way: on to the middle square to the wall ahead, and turn. Out on
/// the new heading in a lobby, the corridor's mouth may be off the line it turned on: in open
/// space the front cones steer it into a mouth ahead; stopped square to a wall across the way with a mouth
/// opening in it to one side (that side's diagonal sonars read down it), it turns along the
/// wall and crosses into the mouth as into a T's stem.
///
/// For a sequencer: it reports nothing; wait on `intersection.junction.count` and set `turn`
/// before the intersection.
#[derive(Default, Serialize, Deserialize)]
pub struct HallFollow {
    activation: Activation,
    mode: Mode,
    /// The corridor's axis (odometry frame).
    axis: Option<f64>,
    /// The wall followed alone (+1 left, −1 right) and the distance kept to it (m).
    keep: Option<(f64, f64)>,
    /// The junction count seen last cycle.
    last_count: Option<u32>,
    /// Per side (left, right): whether the side sonar read a wall last time, and where the
    /// side was last seen to open.
    walled: [bool; 2],
    opened: [Option<(f64, f64)>; 2],
}

impl HallFollow {
    /// The heading to steer for along the axis: toward the centre line, or the kept distance
    /// to the one wall beside.
    fn steer(&mut self, axis: f64, walls: [Option<SideWall>; 2], centring: f64) -> f64 {
        let off = match walls {
            [Some(l), Some(r)] => {
                self.keep = None;
                // Left of the centre line by this much.
                (r.distance - l.distance) / 2.0
            }
            [Some(w), None] | [None, Some(w)] => {
                let side = if walls[0].is_some() { 1.0 } else { -1.0 };
                let keep = match self.keep {
                    Some((s, d)) if s == side => d,
                    _ => w.distance,
                };
                self.keep = Some((side, keep));
                side * (keep - w.distance)
            }
            [None, None] => 0.0,
        };
        axis - (centring * off).clamp(-CENTRING_MAX, CENTRING_MAX)
    }
}

/// The axis two side walls agree on (within [`WALLS_AGREE`]), from the axes measured on
/// each side; `None` unless both sides have a wall.
fn both_walls(measured: &[f64]) -> Option<f64> {
    match *measured {
        [l, r] if wrap(l - r).abs() < WALLS_AGREE => Some(wrap(l + wrap(r - l) / 2.0)),
        _ => None,
    }
}

/// Steering into a corridor's mouth from open space (rad, counter-clockwise, at most
/// [`CENTRING_MAX`]): off its centre line, the near edge of the mouth shows first in the cone
/// of the sonar at 15° on that side while the one at 15° on the other side still sees down the
/// corridor, so the robot turns toward the side that reads farther. Centred (or far from any
/// mouth, or before a flat wall) the two read alike and it holds the axis.
fn mouth_steer(s: &Sonar) -> f64 {
    let read = |deg: f64| at(s, deg).unwrap_or(MOUTH_CAP).min(MOUTH_CAP);
    (MOUTH_GAIN * (read(15.0) - read(-15.0))).clamp(-CENTRING_MAX, CENTRING_MAX)
}

/// With no wall beside on either side (a lobby, a crossing): the heading `want` turned toward
/// the middle of a corridor's mouth ahead ([`mouth_steer`]), and only the sonar straight ahead
/// as the distance ahead, so the wall beside the mouth, seen by the outer cones, does not stop
/// the robot. With a wall beside, `want` and `ahead` as they are.
fn into_a_mouth(s: &Sonar, walls: [Option<SideWall>; 2], want: f64, ahead: f64) -> (f64, f64) {
    if walls == [None, None] {
        (wrap(want + mouth_steer(s)), at(s, 0.0).unwrap_or(0.0))
    } else {
        (want, ahead)
    }
}

/// Stopped by a wall across the way `ahead` (m, from the ring): the side (+1 left, −1 right)
/// where a corridor's mouth opens in that wall beside the robot, or 0. Before a flat wall
/// the sonar at φ reads it first along its cone's inner edge, ahead / cos(φ − 15°); a side
/// opens where its sonar at 45° or at 60° reads [`MOUTH_MARGIN`] past that (a corner near on
/// that side reads nearer). Only one side may open.
fn mouth_beside(s: &Sonar, ahead: f64) -> f64 {
    let open = |k: f64| {
        [45.0f64, 60.0].into_iter().any(|deg| {
            let flat = ahead / (deg - 15.0).to_radians().cos();
            at(s, k * deg).is_some_and(|r| r > flat + MOUTH_MARGIN)
        })
    };
    match (open(1.0), open(-1.0)) {
        (true, false) => 1.0,
        (false, true) => -1.0,
        _ => 0.0,
    }
}

/// Whether a sonar on `side` (+1 left, −1 right), from 45° to 135° off the heading, reads
/// farther than [`SIDE_WALL`]: a way that side, whatever the one at 90° reads.
fn opens_beside(s: &Sonar, side: f64) -> bool {
    let (from, to) = if side > 0.0 {
        (45.0, 135.0)
    } else {
        (-135.0, -45.0)
    };
    arc(s, from, to).is_some_and(|(_, far)| far > SIDE_WALL)
}

/// How much farther than a flat wall a side's sonar must read for [`mouth_beside`] (m).
const MOUTH_MARGIN: f64 = 0.5;

/// Facing the axis within this (rad): a wall ahead then is across the way out.
const SQUARE: f64 = 0.15;

/// Readings farther than this count as open in [`mouth_steer`] (m, from the ring).
const MOUTH_CAP: f64 = 3.0;
/// [`mouth_steer`]'s gain (rad per m of difference).
const MOUTH_GAIN: f64 = 0.3;

impl Skill for HallFollow {
    type Params = HallFollowParams;
    type Inputs<'a> = HallFollowIn<'a>;
    type Outputs<'a> = DriveOut<'a>;
    const STATE: State<Self> = State::kept(1);
    const PRIORITY: i32 = 3;
    fn compute(
        &mut self,
        ctx: &Ctx<HallFollowParams>,
        i: HallFollowIn,
        o: &mut DriveOut,
    ) -> SkillResult {
        let (s, od, j, p) = (&*i.sonar, &*i.odometry, &*i.junction, ctx.params);
        if self.activation.begins(ctx) {
            *self = HallFollow {
                activation: self.activation,
                ..HallFollow::default()
            };
        }
        let pos = (od.x, od.y);
        let walls = [side_wall(s, 1.0), side_wall(s, -1.0)];
        // The axis: from the walls, held while turning.
        let measured: Vec<f64> = walls
            .iter()
            .flatten()
            .map(|w| wrap(od.theta + w.tilt))
            .collect();
        let axis = match self.axis {
            None => measured.first().copied().unwrap_or(od.theta),
            Some(a) if !matches!(self.mode, Mode::Turn { .. }) => match both_walls(&measured) {
                Some(m) if wrap(m - a).abs() >= AXIS_GATE => wrap(a + AXIS_BLEND * wrap(m - a)),
                _ => measured.iter().fold(a, |a, &m| {
                    let d = wrap(m - a);
                    if d.abs() < AXIS_GATE {
                        wrap(a + AXIS_BLEND * d)
                    } else {
                        a
                    }
                }),
            },
            Some(a) => a,
        };
        self.axis = Some(axis);
        // Where each side opened: its sonar's reading leaving the wall.
        for (k, n) in [(0, 90.0), (1, -90.0)] {
            let Some(r) = at(s, n) else { continue };
            let wall = r < SIDE_WALL;
            if wall {
                self.opened[k] = None;
            } else if self.walled[k] {
                self.opened[k] = Some(pos);
            }
            self.walled[k] = wall;
        }
        // An intersection entered: latch the turn. One it is in at activation counts.
        let entered = match self.last_count {
            Some(last) => j.count > last,
            None => j.inside && j.count > 0,
        };
        self.last_count = Some(j.count);
        let ahead = arc(s, -20.0, 20.0).map_or(0.0, |(near, _)| near);
        if self.mode == Mode::Follow && p.turn != 0 && (entered || (j.inside && ahead < p.stop)) {
            self.mode = Mode::Cross {
                turn: p.turn as f64,
                from: None,
            };
        }
        let stop = Drive::default();
        let cruise = |want: f64, limit: f64| {
            let err = wrap(want - od.theta);
            Drive {
                translate: if err.abs() < 0.8 && ahead > TOO_CLOSE {
                    limit.clamp(0.0, p.speed) * err.cos().powi(2)
                } else {
                    0.0
                },
                rotate: (p.gain * err).clamp(-0.8, 0.8),
            }
        };
        let drive = match self.mode {
            Mode::Follow => {
                let mut want = self.steer(axis, walls, p.centring);
                let mut ahead = ahead;
                if p.turn == 0 {
                    (want, ahead) = into_a_mouth(s, walls, want, ahead);
                }
                // With a turn pending and that side open beside, on to the middle of what
                // may be a crossing corridor (a T's bar ahead, a corridor entered from a
                // door): its sides open fully only there, and there the junction counts.
                let turn_side = match p.turn {
                    1 => Some(0),
                    -1 => Some(1),
                    _ => None,
                };
                let until = match turn_side {
                    Some(k) if !self.walled[k] => p.middle.min(p.stop),
                    _ => p.stop,
                };
                if ahead < until {
                    // Stopped, but still turning to the axis: come out of a door askew, the
                    // front cones see the side wall as a wall ahead.
                    cruise(want, 0.0)
                } else {
                    cruise(want, 0.05 + 0.5 * (ahead - until))
                }
            }
            Mode::Cross { turn, from } => {
                let side = if turn > 0.0 { 0 } else { 1 };
                // Open since before the robot saw a wall there (from a door, or at
                // activation): counted from here.
                let mut from = from
                    .or(self.opened[side])
                    .or((!self.walled[side]).then_some(pos));
                let mut axis = axis;
                // Stopped by a wall across the way with that side never seen to open: come
                // out of a door askew toward that side, its 90° sonar's cone reads the wall
                // the door is in (and the axis held is the heading it came out on). Another
                // sonar on that side reading open is a way there: counted from here, on
                // square to the wall ahead, to turn in the corridor's middle.
                if from.is_none() && ahead < p.stop && opens_beside(s, turn) {
                    from = Some(pos);
                    if let Some(w) = wall_toward(s, 0.0) {
                        axis = wrap(od.theta + w.normal);
                        self.axis = Some(axis);
                    }
                }
                self.mode = Mode::Cross { turn, from };
                let want = self.steer(axis, walls, p.centring);
                match from {
                    // Never turned toward a wall: the side it was to turn to never opened.
                    None if !j.inside => {
                        self.mode = Mode::Follow;
                        cruise(want, 0.05 + 0.5 * (ahead - p.stop))
                    }
                    None if ahead < p.stop => stop,
                    None => cruise(want, 0.05 + 0.5 * (ahead - p.stop)),
                    Some(from) => {
                        let (c, sn) = (axis.cos(), axis.sin());
                        let left = p.after - ((pos.0 - from.0) * c + (pos.1 - from.1) * sn);
                        if left <= 0.02 || ahead <= p.middle {
                            self.mode = Mode::Turn {
                                to: wrap(axis + turn * FRAC_PI_2),
                                slide: None,
                            };
                            stop
                        } else {
                            cruise(want, 0.05 + left.min(ahead - p.middle))
                        }
                    }
                }
            }
            Mode::Turn { to, slide } => {
                let err = wrap(to - od.theta);
                if err.abs() < 0.03 {
                    self.mode = match slide {
                        Some(turn) => Mode::Cross { turn, from: None },
                        None => Mode::Leave,
                    };
                    self.axis = Some(to);
                    self.keep = None;
                    stop
                } else {
                    Drive {
                        translate: 0.0,
                        rotate: turn_toward(err, 1.2, 0.8, 0.08, 0.0),
                    }
                }
            }
            Mode::Leave => {
                if self.walled == [true, true] {
                    self.mode = Mode::Follow;
                }
                // Turned in a lobby toward the corridor out of its side: the mouth may be
                // off the line the robot turned on. Near it, the front cones steer into it;
                // stopped by the wall it opens in, the robot turns along that wall toward
                // the side that reads open and crosses into the mouth as into a T's stem.
                let (want, near) = into_a_mouth(s, walls, axis, ahead);
                let side = mouth_beside(s, near);
                if near < p.stop && wrap(axis - od.theta).abs() < SQUARE && side != 0.0 {
                    self.mode = Mode::Turn {
                        to: wrap(axis + side * FRAC_PI_2),
                        slide: Some(-side),
                    };
                    stop
                } else if near < p.stop {
                    cruise(want, 0.0)
                } else {
                    cruise(want, 0.05 + 0.5 * (near - p.stop))
                }
            }
        };
        o.drive.set(drive);
        Ok(())
    }
}
