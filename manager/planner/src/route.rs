//! Finding a route on a [`Map`]: from the lab to a room, from a room back to the lab, or both
//! one after the other, through the elevator when the room is on another floor. On each floor the route passes the fewest junctions (the map has no
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
        /// The leg straight on, when it ends in a dead end (by its index in [`Map::legs`]):
        /// where a robot that missed this turn, or took it at a door before, stops.
        overshoot: Option<usize>,
    },
    /// Turned round at a leg's dead end (where a missed turn left the robot), square to the
    /// corridor: the leg is then travelled back.
    TurnRound {
        /// The leg.
        leg: String,
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
    /// Out of the room's door where the message was said (the robot facing it) into the
    /// corridor: a turn (the robot counts it as its first junction).
    OutOfTheRoom {
        /// The room.
        room: u32,
        /// Which way, from facing the door.
        turn: Turn,
    },
    /// At the lab's door, from the corridor: in the leg's side after `doors_before` other
    /// doors on that side, or ahead at the corridor's end (`side` `None`).
    AtTheLab {
        /// The side its door is on.
        side: Option<Side>,
        /// Doors on that side the robot passes before it.
        doors_before: usize,
        /// The dead end a robot that did not count the door comes to, straight on (the leg
        /// of it, by its index in [`Map::legs`]): this leg's, or past junctions ahead.
        missed: Option<usize>,
    },
    /// At the room's door; the message is delivered.
    AtTheRoom {
        /// The room.
        room: u32,
        /// The side its door is on (`None`: ahead, at the corridor's end).
        side: Option<Side>,
        /// Another door faces it across the corridor.
        faced: bool,
        /// The dead end a robot that did not find the door comes to, straight on (the leg of
        /// it, by its index in [`Map::legs`]): this leg's, or past junctions ahead.
        missed: Option<usize>,
    },
}

impl fmt::Display for Step {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Step::LeaveTheLab => write!(f, "out through the lab's door"),
            Step::IntoTheCorridor { turn } => write!(f, "{turn} into the corridor"),
            Step::Along { leg, heading } => write!(f, "along '{leg}' ({heading})"),
            Step::Junction { name, turn, .. } => write!(f, "at '{name}': {turn}"),
            Step::TurnRound { leg } => write!(f, "turned round at the end of '{leg}'"),
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
            Step::OutOfTheRoom { room, turn } => {
                write!(f, "out of room {room}'s door: {turn} into the corridor")
            }
            Step::AtTheLab {
                side, doors_before, ..
            } => match side {
                Some(s) => write!(
                    f,
                    "the lab: its door on the {s}, after {doors_before} other door{} on the {s}",
                    if *doors_before == 1 { "" } else { "s" }
                ),
                None => write!(f, "the lab: its door ahead, at the corridor's end"),
            },
            Step::AtTheRoom {
                room, side, faced, ..
            } => match side {
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

/// Which way a route goes between the lab and its room.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trip {
    /// From the lab to the room.
    ToTheRoom,
    /// From the room (the robot at its door, facing it) back to the lab.
    BackToTheLab,
    /// To the room and back to the lab.
    RoundTrip,
}

/// A route between the lab and a room.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Route {
    /// The building.
    pub building: String,
    /// The room.
    pub room: u32,
    /// Its floor.
    pub floor: i32,
    /// Which way.
    pub trip: Trip,
    /// Where the way to the room starts (the way back alone starts at the room).
    pub from: From,
    /// The steps, in order.
    pub steps: Vec<Step>,
}

impl fmt::Display for Route {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (b, r, fl) = (&self.building, self.room, self.floor);
        let from = self.from.place();
        match self.trip {
            Trip::ToTheRoom => write!(f, "{b}: to room {r} (floor {fl}) from {from}"),
            Trip::BackToTheLab => write!(f, "{b}: from room {r} (floor {fl}) back to the lab"),
            Trip::RoundTrip => write!(f, "{b}: to room {r} (floor {fl}) from {from}, and back"),
        }?;
        for (i, s) in self.steps.iter().enumerate() {
            write!(f, "\n{:>3}. {s}", i + 1)?;
        }
        Ok(())
    }
}

/// Where a route to a room starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum From {
    /// The lab (the robot inside it).
    Lab,
    /// A floor's lobby, the robot anywhere in it (where a car that did not come left it):
    /// the route calls a car there, or, on the room's floor, leaves the lobby.
    Lobby {
        /// The floor.
        floor: i32,
    },
    /// A leg's dead end, the robot stopped facing it (where a missed turn left it): the
    /// route turns round and goes back along the leg. Written `end:N`, N the leg's place
    /// among the map's `[[leg]]`s, from 1.
    DeadEnd {
        /// The leg, by its index in [`Map::legs`].
        leg: usize,
    },
    /// In a car boarded on a floor, its ride failed (the floor's button pressed and the
    /// indicator not saying that floor in time, try after try: a car that stopped, or a
    /// press missed): the route presses the button of the floor it goes to and rides, as
    /// after a boarding. Written `car:F`, F the floor the car was boarded on.
    Car {
        /// The floor the car was boarded on.
        floor: i32,
    },
}

impl std::str::FromStr for From {
    type Err = PlanError;
    /// `lab`, `lobby:F` (floor F's lobby), `end:N` (the dead end of the map's N-th leg) or
    /// `car:F` (in a car boarded on floor F).
    fn from_str(s: &str) -> Result<From, PlanError> {
        if s == "lab" {
            return Ok(From::Lab);
        }
        if let Some(Ok(floor)) = s.strip_prefix("lobby:").map(str::parse) {
            return Ok(From::Lobby { floor });
        }
        if let Some(Ok(floor)) = s.strip_prefix("car:").map(str::parse) {
            return Ok(From::Car { floor });
        }
        match s.strip_prefix("end:").map(str::parse::<usize>) {
            Some(Ok(n)) if n >= 1 => Ok(From::DeadEnd { leg: n - 1 }),
            _ => Err(PlanError::NotFrom(s.to_string())),
        }
    }
}

impl From {
    /// The place in words: "the lab", "the lobby of floor F".
    pub fn place(self) -> String {
        match self {
            From::Lab => "the lab".to_string(),
            From::Lobby { floor } => format!("the lobby of floor {floor}"),
            From::DeadEnd { leg } => format!("the dead end of the map's leg {}", leg + 1),
            From::Car { floor } => format!("a car boarded on floor {floor}"),
        }
    }
}

impl fmt::Display for From {
    /// As it is read: `lab`, `lobby:F`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            From::Lab => write!(f, "lab"),
            From::Lobby { floor } => write!(f, "lobby:{floor}"),
            From::DeadEnd { leg } => write!(f, "end:{}", leg + 1),
            From::Car { floor } => write!(f, "car:{floor}"),
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
        "--from {0}: a route starts at the lab, at a floor's lobby (`lobby:F`), at a leg's dead end (`end:N`, the map's N-th leg), in a car boarded on a floor (`car:F`) or, back to the lab, at a room (its number)"
    )]
    NotFrom(String),
    /// A lobby the map does not have.
    #[error("the map of {building} has no lobby on floor {floor}")]
    NoLobby {
        /// The building.
        building: String,
        /// The floor.
        floor: i32,
    },
    /// A dead end to start from that the map does not have.
    #[error("--from end:{n}: the map of {building} has {legs} legs{what}")]
    NoDeadEnd {
        /// The building.
        building: String,
        /// The leg asked for (from 1).
        n: usize,
        /// The legs it has.
        legs: usize,
        /// What that leg is, when it is one.
        what: String,
    },
    /// The way back from a door at a corridor's end: the robot would have to turn round.
    #[error(
        "room {0}'s door is at a corridor's end: the way back from it needs a turn round, which the library does not have"
    )]
    NoWayBack(u32),
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
                        overshoot: straight_on_to_a_dead_end(map, pos, *j),
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

/// The way straight on at junction `j` arriving on `pos`, if the junction has one.
fn straight_on(map: &Map, pos: Pos, j: usize) -> Option<Pos> {
    let heading = pos.heading(map);
    map.junctions[j]
        .arms
        .iter()
        .find(|&&(leg, leaves)| leg != pos.leg && heading.turn_to(leaves) == Some(Turn::Straight))
        .map(|&(leg, _)| Pos::leaving(map, leg, &End::Junction(j)))
}

/// The leg straight on at junction `j` arriving on `pos`, when it ends in a dead end.
fn straight_on_to_a_dead_end(map: &Map, pos: Pos, j: usize) -> Option<usize> {
    straight_on(map, pos, j)
        .filter(|next| *next.ahead(map) == End::DeadEnd)
        .map(|next| next.leg)
}

/// The dead end a robot on `pos` comes to going straight on, through the junctions ahead
/// that have a way straight on: where a robot that passes a door in the leg's side without
/// finding it stops. Nothing counts junctions while the door is awaited (`hall_follow`'s
/// turn is set back to straight before it), so a junction passed changes no step. `None`
/// where the way ends otherwise (a lobby, a room's or the lab's door, a junction with no
/// way straight on: a T's bar, where the sides are open and the robot is not at a dead end).
fn dead_end_ahead(map: &Map, pos: Pos) -> Option<usize> {
    let mut at = pos;
    // A way straight on passes each leg once; more is a loop of legs.
    for _ in 0..=map.legs.len() {
        match at.ahead(map) {
            End::DeadEnd => return Some(at.leg),
            End::Junction(j) => at = straight_on(map, at, *j)?,
            _ => return None,
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

/// The room asked for (default: the map's office) and its leg and door.
fn the_room(map: &Map, room: Option<u32>) -> Result<(u32, usize, DoorAt), PlanError> {
    let room = room
        .or(map.office)
        .ok_or_else(|| PlanError::NoDestination(map.building.clone()))?;
    match map.room(room) {
        Some((leg, at)) => Ok((room, leg, at)),
        None => Err(PlanError::UnknownRoom {
            room,
            building: map.building.clone(),
            rooms: map
                .rooms()
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(", "),
        }),
    }
}

/// The lab's leg, door and floor (a checked map has its lab).
fn the_lab(map: &Map, room: u32, floor: i32) -> Result<(usize, DoorAt, i32), PlanError> {
    match map.lab() {
        Some((leg, at)) => Ok((leg, at, map.legs[leg].floor)),
        None => Err(PlanError::NoWay {
            from: "the lab".into(),
            to: format!("room {room}"),
            floor,
        }),
    }
}

/// The route from `from` (the lab, a floor's lobby, a leg's dead end or a car) to `room`
/// (default: the map's office).
pub fn plan(map: &Map, room: Option<u32>, from: From) -> Result<Route, PlanError> {
    let (room, room_leg, _) = the_room(map, room)?;
    let floor = map.legs[room_leg].floor;
    let to_room = |pos: Pos, door: Option<CameOut>| {
        room_ahead(map, pos, room, door).map(|side| {
            let faced = map.legs[pos.leg].faced(room);
            let step = Step::AtTheRoom {
                room,
                side,
                faced,
                missed: side.and(dead_end_ahead(map, pos)),
            };
            (0u32, vec![step])
        })
    };
    let to = (format!("room {room}"), &to_room as &Goal<'_>, floor);
    let steps = match from {
        From::Lab => {
            let (lab_leg, lab_at, lab_floor) = the_lab(map, room, floor)?;
            between_floors(
                map,
                ("the lab", out_of_the_lab(map, lab_leg, lab_at), lab_floor),
                to,
            )?
        }
        From::Lobby { floor: lobby } => from_the_lobby(map, lobby, false, to)?,
        From::Car { floor: car } => from_the_lobby(map, car, true, to)?,
        From::DeadEnd { leg } => from_a_dead_end(map, leg, to)?,
    };
    Ok(Route {
        building: map.building.clone(),
        room,
        floor,
        trip: Trip::ToTheRoom,
        from,
        steps,
    })
}

/// The route back to the lab from `room`'s door (default: the map's office), the robot
/// standing at it facing it, as a route to the room leaves it.
pub fn plan_back(map: &Map, room: Option<u32>) -> Result<Route, PlanError> {
    back_to_the_lab(map, room, From::Lab)
}

/// The route back to the lab from `from` (a floor's lobby, where a car that did not come on
/// the way back left the robot, a leg's dead end, or a car whose ride failed), `room` being
/// the room the message was for. `From::Lab` is the room's door, as [`plan_back`].
pub fn plan_back_from(map: &Map, room: u32, from: From) -> Result<Route, PlanError> {
    back_to_the_lab(map, Some(room), from)
}

/// The way back to the lab from `room`'s door (`from` [`From::Lab`]), from a floor's lobby,
/// from a leg's dead end or from a car.
fn back_to_the_lab(map: &Map, room: Option<u32>, from: From) -> Result<Route, PlanError> {
    let (room, room_leg, room_at) = the_room(map, room)?;
    let floor = map.legs[room_leg].floor;
    let (lab_leg, lab_at, lab_floor) = the_lab(map, room, floor)?;
    let to_lab = |pos: Pos, door: Option<CameOut>| {
        lab_ahead(map, pos, lab_leg, lab_at, door).map(|(side, doors_before)| {
            let step = Step::AtTheLab {
                side,
                doors_before,
                missed: side.and(dead_end_ahead(map, pos)),
            };
            (0u32, vec![step])
        })
    };
    let to = ("the lab".to_string(), &to_lab as &Goal<'_>, lab_floor);
    let steps = match from {
        From::Lab => between_floors(
            map,
            (
                &format!("room {room}"),
                out_of_the_room(map, room, room_leg, room_at)?,
                floor,
            ),
            to,
        )?,
        From::Lobby { floor: lobby } => from_the_lobby(map, lobby, false, to)?,
        From::Car { floor: car } => from_the_lobby(map, car, true, to)?,
        From::DeadEnd { leg } => from_a_dead_end(map, leg, to)?,
    };
    Ok(Route {
        building: map.building.clone(),
        room,
        floor,
        trip: Trip::BackToTheLab,
        from,
        steps,
    })
}

/// The route from the lab to `room` (default: the map's office) and back: the message said,
/// the way back starts at its door.
pub fn plan_round_trip(map: &Map, room: Option<u32>) -> Result<Route, PlanError> {
    plan_round_trip_from(map, room, From::Lab)
}

/// The same from `from`: to the room, and back to the lab.
pub fn plan_round_trip_from(map: &Map, room: Option<u32>, from: From) -> Result<Route, PlanError> {
    let to = plan(map, room, from)?;
    let back = plan_back(map, Some(to.room))?;
    Ok(Route {
        trip: Trip::RoundTrip,
        steps: to.steps.into_iter().chain(back.steps).collect(),
        ..to
    })
}

/// The steps from `starts` on their floor to where `goal` says the destination is on its
/// floor: on one floor, or to the starts' floor's lobby, a car, and out of the goal floor's
/// lobby. The names say the places in errors.
fn between_floors(
    map: &Map,
    (from, starts, from_floor): (&str, Vec<Start>, i32),
    (to, goal, floor): (String, &Goal<'_>, i32),
) -> Result<Vec<Step>, PlanError> {
    let no_way = |from: &str, to: String, floor: i32| PlanError::NoWay {
        from: from.into(),
        to,
        floor,
    };
    if floor == from_floor {
        return search(map, starts, goal).ok_or_else(|| no_way(from, to, floor));
    }
    let into_the_lobby = |pos: Pos, _: Option<CameOut>| {
        if *pos.ahead(map) != End::Lobby {
            return None;
        }
        let opening = map
            .lobby(from_floor)?
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
                floor: from_floor,
                turn,
            }],
        ))
    };
    let mut steps = search(map, starts, &into_the_lobby)
        .ok_or_else(|| no_way(from, "the lobby".into(), from_floor))?;
    steps.push(Step::Ride {
        from: from_floor,
        to: floor,
    });
    steps.extend(
        search(map, out_of_the_lobby(map, floor), goal)
            .ok_or_else(|| no_way("the lobby", to, floor))?,
    );
    Ok(steps)
}

/// The steps from floor `lobby`'s lobby, or from a car boarded there (`in_a_car`), to where
/// `goal` says the destination is on its floor: a car to that floor first if it is another
/// (from a car, a ride always: the car may have gone anywhere).
fn from_the_lobby(
    map: &Map,
    lobby: i32,
    in_a_car: bool,
    (to, goal, floor): (String, &Goal<'_>, i32),
) -> Result<Vec<Step>, PlanError> {
    if map.lobby(lobby).is_none() {
        return Err(PlanError::NoLobby {
            building: map.building.clone(),
            floor: lobby,
        });
    }
    let mut steps = Vec::new();
    if in_a_car || lobby != floor {
        steps.push(Step::Ride {
            from: lobby,
            to: floor,
        });
    }
    steps.extend(
        search(map, out_of_the_lobby(map, floor), goal).ok_or_else(|| PlanError::NoWay {
            from: "the lobby".into(),
            to,
            floor,
        })?,
    );
    Ok(steps)
}

/// The steps from leg `leg`'s dead end, the robot facing it, to where `goal` says the
/// destination is: turned round, back along the leg (the leg's `to` end when both ends are
/// dead), and on, through a car if the destination is on another floor.
fn from_a_dead_end(
    map: &Map,
    leg: usize,
    to: (String, &Goal<'_>, i32),
) -> Result<Vec<Step>, PlanError> {
    let no = |what: String| PlanError::NoDeadEnd {
        building: map.building.clone(),
        n: leg + 1,
        legs: map.legs.len(),
        what,
    };
    let l = map.legs.get(leg).ok_or_else(|| no(String::new()))?;
    let forward = match (&l.from, &l.to) {
        (_, End::DeadEnd) => false,
        (End::DeadEnd, _) => true,
        _ => return Err(no(format!(": '{}' has no dead end", l.name))),
    };
    let pos = Pos { leg, forward };
    let start = Start {
        pos,
        cost: 0,
        steps: vec![
            Step::TurnRound {
                leg: l.name.clone(),
            },
            pos.along(map),
        ],
        door: None,
    };
    let place = From::DeadEnd { leg }.place();
    between_floors(map, (&place, vec![start], l.floor), to)
}

/// The ways out of `floor`'s lobby, the robot in it (out of a car, or where it waited for
/// one): through each opening.
fn out_of_the_lobby(map: &Map, floor: i32) -> Vec<Start> {
    map.lobby(floor)
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
        .collect()
}

/// Whether the lab's door (on `lab_leg`, at `lab_at`) is ahead on `pos`'s leg: its side
/// (`None`: at the leg's end) and how many doors on that side come before it. `door`: the
/// door the robot came out of on this leg — on its side only the doors after it are ahead;
/// on the other side the order is not known, so none is taken.
fn lab_ahead(
    map: &Map,
    pos: Pos,
    lab_leg: usize,
    lab_at: DoorAt,
    door: Option<CameOut>,
) -> Option<(Option<Side>, usize)> {
    if pos.leg != lab_leg {
        return None;
    }
    match lab_at {
        DoorAt::Side { side, index } => {
            let n = map.legs[lab_leg].doors(side).len();
            // Doors on its side between where the robot comes onto the leg and the lab.
            let (first, past) = match door {
                None => (0, 0),
                Some(out) if out.side == side => (out.index, 1),
                Some(_) => return None,
            };
            let before = if pos.forward {
                if door.is_some() && index <= first {
                    return None;
                }
                index - first - past
            } else {
                let first = if door.is_some() { first } else { n };
                if index >= first {
                    return None;
                }
                first - index - 1
            };
            Some((Some(if pos.forward { side } else { side.other() }), before))
        }
        DoorAt::End { .. } => (*pos.ahead(map) == End::Lab).then_some((None, 0)),
    }
}

/// Out of `room`'s door, the robot facing it: into the corridor both ways (cost 1, the turn
/// is counted as a junction). A door at a corridor's end is refused: that way back is a turn
/// round.
fn out_of_the_room(map: &Map, room: u32, leg: usize, at: DoorAt) -> Result<Vec<Start>, PlanError> {
    let DoorAt::Side { side, index } = at else {
        return Err(PlanError::NoWayBack(room));
    };
    Ok([true, false]
        .into_iter()
        .map(|forward| {
            let pos = Pos { leg, forward };
            // Facing a door on the leg's left, its `to` is to the right.
            let turn = match side {
                Side::Left => Turn::Right,
                Side::Right => Turn::Left,
            };
            let turn = if forward { turn } else { turn.mirrored() };
            Start {
                pos,
                cost: 1,
                steps: vec![Step::OutOfTheRoom { room, turn }, pos.along(map)],
                door: Some(CameOut { side, index }),
            }
        })
        .collect())
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
