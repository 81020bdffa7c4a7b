//! Finding a route on a [`Map`]: from the lab to a room, through the elevator when the room
//! is on another floor. On each floor the route passes the fewest junctions (the map has no
//! lengths; a junction is what the robot counts, so fewer is also fewer chances to miscount);
//! ties go to the way written first in the map.

use crate::map::{Door, DoorAt, End, Heading, Map, Side, Turn, Wall};
use std::cmp::Reverse;
use std::collections::{BTreeSet, BinaryHeap};
use std::fmt;

/// One step of a route, in the terms the plan is built from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    /// Out through the lab's door.
    LeaveTheLab,
    /// Out of the lab's door, which is in a corridor's side: a turn into the corridor (the
    /// robot counts it as its first junction).
    IntoTheCorridor {
        /// Which way.
        turn: Turn,
    },
    /// Along a leg (in words only: nothing to do but follow it).
    Along {
        /// The leg.
        leg: String,
        /// The way it is travelled.
        heading: Heading,
    },
    /// At a junction.
    Junction {
        /// Its name.
        name: String,
        /// What to do there.
        turn: Turn,
    },
    /// Into a floor's lobby: straight in with the bank wall ahead, or turning to face it where
    /// the corridor opens into the lobby's side (counted as a junction).
    IntoTheLobby {
        /// The floor.
        floor: i32,
        /// The turn toward the bank wall.
        turn: Turn,
    },
    /// The elevator, from a floor to another.
    Ride {
        /// From.
        from: i32,
        /// To.
        to: i32,
    },
    /// Out of a car and out of the lobby: straight away from the bank wall, or turning to an
    /// opening in a side wall (counted as a junction).
    OutOfTheLobby {
        /// The floor.
        floor: i32,
        /// The turn, with the bank wall behind.
        turn: Turn,
        /// The opening is right beside the bank wall: taken from where the robot leaves its
        /// car, not from in front of the call button.
        beside_bank: bool,
    },
    /// At the room's door; the message is delivered.
    AtTheRoom {
        /// The room.
        room: u32,
        /// The side its door is on (`None`: ahead, at the corridor's end).
        side: Option<Side>,
        /// Another door faces it across the corridor.
        faced: bool,
    },
}

impl fmt::Display for Step {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Step::LeaveTheLab => write!(f, "out through the lab's door"),
            Step::IntoTheCorridor { turn } => write!(f, "{turn} into the corridor"),
            Step::Along { leg, heading } => write!(f, "along '{leg}' ({heading})"),
            Step::Junction { name, turn } => write!(f, "at '{name}': {turn}"),
            Step::IntoTheLobby { floor, turn } => match turn {
                Turn::Straight => write!(f, "into the lobby of floor {floor}, the bank wall ahead"),
                t => write!(
                    f,
                    "into the lobby of floor {floor}: {t}, to face the bank wall"
                ),
            },
            Step::Ride { from, to } => write!(f, "a car from floor {from} to floor {to}"),
            Step::OutOfTheLobby {
                floor,
                turn,
                beside_bank,
            } => match turn {
                Turn::Straight => write!(
                    f,
                    "out of the lobby of floor {floor}, straight away from the bank wall"
                ),
                t => write!(
                    f,
                    "out of the lobby of floor {floor}: {t} (the bank wall behind) to the opening in its side{}",
                    if *beside_bank {
                        ", right beside the bank wall"
                    } else {
                        ""
                    }
                ),
            },
            Step::AtTheRoom { room, side, faced } => match side {
                Some(s) => write!(
                    f,
                    "room {room}: its door on the {s}{}",
                    if *faced { ", a door facing it" } else { "" }
                ),
                None => write!(f, "room {room}: its door ahead, at the corridor's end"),
            },
        }
    }
}

/// A route to a room.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Route {
    /// The building.
    pub building: String,
    /// The room.
    pub room: u32,
    /// Its floor.
    pub floor: i32,
    /// The steps, in order.
    pub steps: Vec<Step>,
}

impl fmt::Display for Route {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: to room {} (floor {}) from the lab",
            self.building, self.room, self.floor
        )?;
        for (i, s) in self.steps.iter().enumerate() {
            write!(f, "\n{:>3}. {s}", i + 1)?;
        }
        Ok(())
    }
}

/// Where a route starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum From {
    /// The lab (the robot inside it).
    Lab,
}

impl std::str::FromStr for From {
    type Err = PlanError;
    fn from_str(s: &str) -> Result<From, PlanError> {
        match s {
            "lab" => Ok(From::Lab),
            other => Err(PlanError::NotFrom(other.to_string())),
        }
    }
}

/// Why no route.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum PlanError {
    /// The room is on no door of the map.
    #[error("room {room} is not on the map of {building} (its rooms: {rooms})")]
    UnknownRoom {
        /// The room.
        room: u32,
        /// The building.
        building: String,
        /// The rooms it has.
        rooms: String,
    },
    /// No destination given and the map names no office.
    #[error("the map of {0} names no office: say which room (--to)")]
    NoDestination(String),
    /// A start the planner does not plan from.
    #[error(
        "--from {0}: routes are planned from the lab only (the way back from a room is not done)"
    )]
    NotFrom(String),
    /// No way on a floor (a map that passed its checks always has one).
    #[error("no way from {from} to {to} on floor {floor}")]
    NoWay {
        /// From where.
        from: String,
        /// To where.
        to: String,
        /// The floor.
        floor: i32,
    },
}

/// Where the robot is on a leg: which leg, which way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
struct Pos {
    leg: usize,
    /// From the leg's `from` to its `to`.
    forward: bool,
}

impl Pos {
    fn heading(self, map: &Map) -> Heading {
        let h = map.legs[self.leg].heading;
        if self.forward { h } else { h.opposite() }
    }

    fn ahead(self, map: &Map) -> &End {
        let l = &map.legs[self.leg];
        if self.forward { &l.to } else { &l.from }
    }

    /// Travelling away from `end` along `leg`.
    fn leaving(map: &Map, leg: usize, end: &End) -> Pos {
        Pos {
            leg,
            forward: map.legs[leg].from == *end,
        }
    }

    fn along(self, map: &Map) -> Step {
        Step::Along {
            leg: map.legs[self.leg].name.clone(),
            heading: self.heading(map),
        }
    }
}

/// The door the robot came out of onto a leg: on its side only the doors after it are ahead.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct CameOut {
    /// The side of the leg it is on (seen from the leg's `from`).
    side: Side,
    /// Its place in that side's list.
    index: usize,
}

/// A place the search reached: where, how (the node before and the steps from it).
#[derive(Debug, Clone)]
struct Node {
    pos: Pos,
    parent: Option<usize>,
    steps: Vec<Step>,
    came_out: Option<CameOut>,
}

/// Whether the destination is reached from a position: its extra cost and steps.
type Goal<'a> = dyn Fn(Pos, Option<CameOut>) -> Option<(u32, Vec<Step>)> + 'a;

/// A start of a search: where, its cost, its steps, and the door it came out of on that leg
/// (doors before it are behind the robot).
struct Start {
    pos: Pos,
    cost: u32,
    steps: Vec<Step>,
    door: Option<CameOut>,
}

/// Uniform-cost search on one floor (a junction passed costs 1): from `starts` to a position
/// where `goal` says the destination is (its extra cost and steps).
fn search(map: &Map, starts: Vec<Start>, goal: &Goal<'_>) -> Option<Vec<Step>> {
    let mut nodes: Vec<Node> = Vec::new();
    // (cost, order, index, arrived): an index into `arrivals` when arrived, else into `nodes`.
    let mut heap: BinaryHeap<Reverse<(u32, usize, usize, bool)>> = BinaryHeap::new();
    let mut arrivals: Vec<Vec<Step>> = Vec::new();
    let mut order = 0;
    for s in starts {
        nodes.push(Node {
            pos: s.pos,
            parent: None,
            steps: s.steps,
            came_out: s.door,
        });
        heap.push(Reverse((s.cost, order, nodes.len() - 1, false)));
        order += 1;
    }
    let mut done: BTreeSet<Pos> = BTreeSet::new();
    while let Some(Reverse((cost, _, n, arrived))) = heap.pop() {
        if arrived {
            return Some(std::mem::take(&mut arrivals[n]));
        }
        let (pos, door) = (nodes[n].pos, nodes[n].came_out);
        if !done.insert(pos) {
            continue;
        }
        if let Some((extra, steps)) = goal(pos, door) {
            let mut path = path_to(&nodes, n);
            path.extend(steps);
            arrivals.push(path);
            heap.push(Reverse((cost + extra, order, arrivals.len() - 1, true)));
            order += 1;
        }
        if let End::Junction(j) = pos.ahead(map) {
            let junction = &map.junctions[*j];
            let heading = pos.heading(map);
            for &(leg, leaves) in &junction.arms {
                let Some(turn) = heading.turn_to(leaves) else {
                    continue;
                };
                if leg == pos.leg {
                    continue;
                }
                let next = Pos::leaving(map, leg, &End::Junction(*j));
                let steps = vec![
                    Step::Junction {
                        name: junction.name.clone(),
                        turn,
                    },
                    next.along(map),
                ];
                nodes.push(Node {
                    pos: next,
                    parent: Some(n),
                    steps,
                    came_out: None,
                });
                heap.push(Reverse((cost + 1, order, nodes.len() - 1, false)));
                order += 1;
            }
        }
    }
    None
}

/// The steps from a start to node `n`.
fn path_to(nodes: &[Node], n: usize) -> Vec<Step> {
    let mut chain = Vec::new();
    let mut at = Some(n);
    while let Some(i) = at {
        chain.push(nodes[i].steps.clone());
        at = nodes[i].parent;
    }
    chain.into_iter().rev().flatten().collect()
}

/// Whether `room`'s door is ahead on `pos`'s leg, and on which side (`Some(None)`: at its
/// end). `door`: the door the robot came out of on this leg — on its side only the doors
/// after it are ahead, and on the other side the order is not known, so none is taken.
fn room_ahead(map: &Map, pos: Pos, room: u32, door: Option<CameOut>) -> Option<Option<Side>> {
    let leg = &map.legs[pos.leg];
    for side in [Side::Left, Side::Right] {
        let Some(i) = leg.doors(side).iter().position(|d| *d == Door::Room(room)) else {
            continue;
        };
        if let Some(out) = door {
            let ahead = if pos.forward {
                i > out.index
            } else {
                i < out.index
            };
            if out.side != side || !ahead {
                continue;
            }
        }
        return Some(Some(if pos.forward { side } else { side.other() }));
    }
    (*pos.ahead(map) == End::Room(room)).then_some(None)
}

/// The route from the lab to `room` (default: the map's office).
pub fn plan(map: &Map, room: Option<u32>, from: From) -> Result<Route, PlanError> {
    let From::Lab = from;
    let room = room
        .or(map.office)
        .ok_or_else(|| PlanError::NoDestination(map.building.clone()))?;
    let Some((room_leg, _)) = map.room(room) else {
        return Err(PlanError::UnknownRoom {
            room,
            building: map.building.clone(),
            rooms: map
                .rooms()
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(", "),
        });
    };
    let floor = map.legs[room_leg].floor;
    // A checked map has its lab.
    let Some((lab_leg, lab_at)) = map.lab() else {
        return Err(PlanError::NoWay {
            from: "the lab".into(),
            to: format!("room {room}"),
            floor,
        });
    };
    let lab_floor = map.legs[lab_leg].floor;
    let out_of_the_lab = out_of_the_lab(map, lab_leg, lab_at);
    let to_room = |pos: Pos, door: Option<CameOut>| {
        room_ahead(map, pos, room, door).map(|side| {
            let faced = map.legs[pos.leg].faced(room);
            (0, vec![Step::AtTheRoom { room, side, faced }])
        })
    };
    let no_way = |from: &str, to: String, floor: i32| PlanError::NoWay {
        from: from.into(),
        to,
        floor,
    };
    let steps = if floor == lab_floor {
        search(map, out_of_the_lab, &to_room)
            .ok_or_else(|| no_way("the lab", format!("room {room}"), floor))?
    } else {
        let into_the_lobby = |pos: Pos, _: Option<CameOut>| {
            if *pos.ahead(map) != End::Lobby {
                return None;
            }
            let opening = map
                .lobby(lab_floor)?
                .openings
                .iter()
                .find(|o| o.leg == pos.leg)?;
            // Through a side wall the bank wall is on that side (seen facing it, the left
            // wall is on the left).
            let turn = match opening.wall {
                Wall::Opposite => Turn::Straight,
                Wall::Left => Turn::Left,
                Wall::Right => Turn::Right,
            };
            let cost = u32::from(turn != Turn::Straight);
            Some((
                cost,
                vec![Step::IntoTheLobby {
                    floor: lab_floor,
                    turn,
                }],
            ))
        };
        let mut steps = search(map, out_of_the_lab, &into_the_lobby)
            .ok_or_else(|| no_way("the lab", "the lobby".into(), lab_floor))?;
        steps.push(Step::Ride {
            from: lab_floor,
            to: floor,
        });
        let starts = map
            .lobby(floor)
            .map(|l| l.openings.as_slice())
            .unwrap_or_default()
            .iter()
            .map(|o| {
                // With the bank wall behind, the left wall (seen facing it) is on the right.
                let turn = match o.wall {
                    Wall::Opposite => Turn::Straight,
                    Wall::Left => Turn::Right,
                    Wall::Right => Turn::Left,
                };
                let pos = Pos::leaving(map, o.leg, &End::Lobby);
                Start {
                    pos,
                    cost: u32::from(turn != Turn::Straight),
                    steps: vec![
                        Step::OutOfTheLobby {
                            floor,
                            turn,
                            beside_bank: o.beside_bank,
                        },
                        pos.along(map),
                    ],
                    door: None,
                }
            })
            .collect();
        steps.extend(
            search(map, starts, &to_room)
                .ok_or_else(|| no_way("the lobby", format!("room {room}"), floor))?,
        );
        steps
    };
    Ok(Route {
        building: map.building.clone(),
        room,
        floor,
        steps,
    })
}

/// The ways out of the lab: into its corridor to the left and to the right (a door in the
/// corridor's side), or straight on (a door at the corridor's end).
fn out_of_the_lab(map: &Map, leg: usize, at: DoorAt) -> Vec<Start> {
    match at {
        DoorAt::Side { side, index } => [true, false]
            .into_iter()
            .map(|forward| {
                let pos = Pos { leg, forward };
                // Out of a door on the leg's left, its `to` is to the left.
                let turn = match side {
                    Side::Left => Turn::Left,
                    Side::Right => Turn::Right,
                };
                let turn = if forward { turn } else { turn.mirrored() };
                Start {
                    pos,
                    cost: 1,
                    steps: vec![
                        Step::LeaveTheLab,
                        Step::IntoTheCorridor { turn },
                        pos.along(map),
                    ],
                    door: Some(CameOut { side, index }),
                }
            })
            .collect(),
        DoorAt::End { at_to } => {
            let pos = Pos {
                leg,
                forward: !at_to,
            };
            vec![Start {
                pos,
                cost: 0,
                steps: vec![Step::LeaveTheLab, pos.along(map)],
                door: None,
            }]
        }
    }
}
