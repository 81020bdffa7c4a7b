//! A route map: a building in the terms a person gives directions in (docs/maps.md), read
//! from TOML and checked. [`Map::parse`] refuses a map that contradicts itself, each problem
//! one sentence naming the place ([`Problem`]); a [`Map`] that exists is sound.

use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt;

/// A compass direction: the way a leg runs, the way an arm leaves a junction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Heading {
    /// North.
    North,
    /// East.
    East,
    /// South.
    South,
    /// West.
    West,
}

impl Heading {
    /// Quarter turns clockwise from north.
    fn quarters(self) -> u8 {
        match self {
            Heading::North => 0,
            Heading::East => 1,
            Heading::South => 2,
            Heading::West => 3,
        }
    }

    fn from_quarters(q: u8) -> Heading {
        match q % 4 {
            0 => Heading::North,
            1 => Heading::East,
            2 => Heading::South,
            _ => Heading::West,
        }
    }

    /// The other way.
    pub fn opposite(self) -> Heading {
        Heading::from_quarters(self.quarters() + 2)
    }

    /// The heading after `turn`.
    pub fn after(self, turn: Turn) -> Heading {
        match turn {
            Turn::Straight => self,
            Turn::Right => Heading::from_quarters(self.quarters() + 1),
            Turn::Left => Heading::from_quarters(self.quarters() + 3),
        }
    }

    /// The turn from this heading to `to`; `None` for turning back.
    pub fn turn_to(self, to: Heading) -> Option<Turn> {
        [Turn::Straight, Turn::Left, Turn::Right]
            .into_iter()
            .find(|t| self.after(*t) == to)
    }
}

impl fmt::Display for Heading {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Heading::North => "north",
            Heading::East => "east",
            Heading::South => "south",
            Heading::West => "west",
        })
    }
}

/// A turn, as a person says it and as `hall_follow.turn` takes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Turn {
    /// Left.
    Left,
    /// Straight on.
    Straight,
    /// Right.
    Right,
}

impl Turn {
    /// The value of `hall_follow.turn`: 1 left, −1 right, 0 straight on.
    pub fn hall_follow(self) -> i8 {
        match self {
            Turn::Left => 1,
            Turn::Straight => 0,
            Turn::Right => -1,
        }
    }

    /// The other way round (what is on the left going one way is on the right going back).
    pub fn mirrored(self) -> Turn {
        match self {
            Turn::Left => Turn::Right,
            Turn::Straight => Turn::Straight,
            Turn::Right => Turn::Left,
        }
    }
}

impl fmt::Display for Turn {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Turn::Left => "left",
            Turn::Straight => "straight on",
            Turn::Right => "right",
        })
    }
}

/// A side of a leg, seen travelling along it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// On the left.
    Left,
    /// On the right.
    Right,
}

impl Side {
    /// The other side.
    pub fn other(self) -> Side {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
}

impl fmt::Display for Side {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Side::Left => "left",
            Side::Right => "right",
        })
    }
}

/// What is at one end of a leg.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum End {
    /// The lab's door (the leg starts or ends at it).
    Lab,
    /// The floor's elevator lobby.
    Lobby,
    /// A room's door at the end of the corridor.
    Room(u32),
    /// A junction, by its index in [`Map::junctions`].
    Junction(usize),
    /// The corridor ends (or goes on where the map does not say).
    DeadEnd,
}

/// A door on a side of a leg.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Door {
    /// The lab's door.
    Lab,
    /// A room, by its number (floor · 100 + n).
    Room(u32),
    /// A door whose number the map does not know.
    Unnumbered,
}

/// A stretch of corridor between two places, with the doors on each side.
#[derive(Debug, Clone, PartialEq)]
pub struct Leg {
    /// Its name (what the map and the plan call it).
    pub name: String,
    /// Its floor.
    pub floor: i32,
    /// What is at its start.
    pub from: End,
    /// What is at its end.
    pub to: End,
    /// The way it runs from `from` to `to`.
    pub heading: Heading,
    /// Doors on the left, seen from `from` going to `to`, in the order met.
    pub left: Vec<Door>,
    /// Doors on the right, likewise.
    pub right: Vec<Door>,
    /// Rooms whose doors face each other across the corridor, in pairs.
    pub facing: Vec<[u32; 2]>,
}

impl Leg {
    /// The doors on `side`, seen from `from` going to `to`.
    pub fn doors(&self, side: Side) -> &[Door] {
        match side {
            Side::Left => &self.left,
            Side::Right => &self.right,
        }
    }

    /// Whether another door faces `room`'s across the corridor.
    pub fn faced(&self, room: u32) -> bool {
        self.facing.iter().any(|pair| pair.contains(&room))
    }
}

/// Where legs meet: each arm is a leg and the way it leaves the junction.
#[derive(Debug, Clone, PartialEq)]
pub struct Junction {
    /// Its name.
    pub name: String,
    /// Its floor.
    pub floor: i32,
    /// Its arms: (leg, the heading that leg leaves the junction in).
    pub arms: Vec<(usize, Heading)>,
}

/// Which wall of a lobby an opening is in, seen standing in the lobby facing the bank wall
/// (as cars are numbered).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Wall {
    /// The wall facing the bank wall.
    Opposite,
    /// The side wall on the left.
    Left,
    /// The side wall on the right.
    Right,
}

/// A corridor's way into a lobby.
#[derive(Debug, Clone, PartialEq)]
pub struct Opening {
    /// The leg (one of its ends is the lobby).
    pub leg: usize,
    /// The wall it is in.
    pub wall: Wall,
    /// In a side wall, right beside the bank wall.
    pub beside_bank: bool,
}

/// A floor's elevator lobby.
#[derive(Debug, Clone, PartialEq)]
pub struct Lobby {
    /// The floor.
    pub floor: i32,
    /// Its openings into corridors.
    pub openings: Vec<Opening>,
}

/// A checked route map.
#[derive(Debug, Clone, PartialEq)]
pub struct Map {
    /// The building it is of.
    pub building: String,
    /// The default destination (the department head's office).
    pub office: Option<u32>,
    /// The floors the elevator bank serves, in order.
    pub floors: Vec<i32>,
    /// Corridor legs.
    pub legs: Vec<Leg>,
    /// Junctions.
    pub junctions: Vec<Junction>,
    /// One lobby per floor, in floor order.
    pub lobbies: Vec<Lobby>,
}

/// Why a map is refused: each one sentence that names the place.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Problem {
    /// The file is not the map format (TOML, or a field the format does not have).
    #[error("{0}")]
    Format(String),
    /// The map lists no floor.
    #[error("the map lists no floors")]
    NoFloors,
    /// A floor listed twice.
    #[error("floor {0} is listed twice")]
    FloorTwice(i32),
    /// A place on a floor the map's floors do not list.
    #[error("{what} is on floor {floor}, which `floors` does not list")]
    UnknownFloor {
        /// The place.
        what: String,
        /// Its floor.
        floor: i32,
    },
    /// Two places of a kind with one name on a floor.
    #[error("two {kind}s on floor {floor} are called '{name}'")]
    NameTwice {
        /// "leg" or "junction".
        kind: &'static str,
        /// The name.
        name: String,
        /// The floor.
        floor: i32,
    },
    /// A junction named as a word the map reserves.
    #[error("junction '{0}': lab, lobby, end and room N name other places; call it otherwise")]
    ReservedName(String),
    /// A leg's end names no place of the map.
    #[error(
        "leg '{leg}' leads to '{to}', which is no place of the map (a junction's name, lab, lobby, room N or end)"
    )]
    LeadsNowhere {
        /// The leg.
        leg: String,
        /// What it names.
        to: String,
    },
    /// A leg's end is a junction on another floor.
    #[error("leg '{leg}' (floor {floor}) leads to junction '{junction}' on floor {other}")]
    OtherFloor {
        /// The leg.
        leg: String,
        /// Its floor.
        floor: i32,
        /// The junction.
        junction: String,
        /// The junction's floor.
        other: i32,
    },
    /// A leg that starts and ends at one place that is not a dead end.
    #[error("leg '{leg}' starts and ends at '{at}'")]
    Loop {
        /// The leg.
        leg: String,
        /// The place.
        at: String,
    },
    /// A door entry that is no door.
    #[error(
        "leg '{leg}': '{entry}' on its {side} is not a door (a room number, \"door\" or \"lab\")"
    )]
    NotADoor {
        /// The leg.
        leg: String,
        /// Which side.
        side: Side,
        /// What is written.
        entry: String,
    },
    /// A room on two doors.
    #[error("room {room} is listed on two doors: {first} and {second}")]
    RoomTwice {
        /// The room.
        room: u32,
        /// Where first.
        first: String,
        /// Where again.
        second: String,
    },
    /// A room on a floor its number does not say.
    #[error("room {room} is on {at} (floor {floor}), but its number says floor {}", room / 100)]
    RoomOnWrongFloor {
        /// The room.
        room: u32,
        /// Where it is listed.
        at: String,
        /// That leg's floor.
        floor: i32,
    },
    /// A pair of facing doors that are not one on each side of the leg.
    #[error("leg '{leg}': rooms {} and {} face each other, so each must be on one of its sides", pair[0], pair[1])]
    NotFacing {
        /// The leg.
        leg: String,
        /// The pair.
        pair: [u32; 2],
    },
    /// No lab door anywhere.
    #[error("the map has no lab: name it on a leg's side (\"lab\") or at a leg's end (lab)")]
    NoLab,
    /// The lab's door twice.
    #[error("the lab's door is listed twice: {first} and {second}")]
    LabTwice {
        /// Where first.
        first: String,
        /// Where again.
        second: String,
    },
    /// A junction that names a leg that does not end at it.
    #[error("junction '{junction}': leg '{leg}' does not end there")]
    NotAnArm {
        /// The junction.
        junction: String,
        /// The leg.
        leg: String,
    },
    /// A junction or lobby that names a leg its floor does not have.
    #[error("{at}: there is no leg '{leg}' on its floor")]
    UnknownLeg {
        /// The junction or lobby.
        at: String,
        /// The name.
        leg: String,
    },
    /// A leg that ends at a junction which does not list it.
    #[error(
        "junction '{junction}': leg '{leg}' ends there but the junction does not say on which side"
    )]
    ArmMissing {
        /// The junction.
        junction: String,
        /// The leg.
        leg: String,
    },
    /// A leg listed twice at a junction.
    #[error("junction '{junction}' lists leg '{leg}' twice")]
    ArmTwice {
        /// The junction.
        junction: String,
        /// The leg.
        leg: String,
    },
    /// A junction with too few arms.
    #[error(
        "junction '{junction}' joins {arms} legs: a junction joins 3 or 4 (a bend is part of a leg)"
    )]
    TooFewArms {
        /// The junction.
        junction: String,
        /// How many.
        arms: usize,
    },
    /// A side of a junction that disagrees with the way its leg runs.
    #[error(
        "junction '{junction}': its {side}, seen arriving along '{arriving}' (heading {heading}), is {expected}, but leg '{leg}' leaves it heading {actual}"
    )]
    SideDisagrees {
        /// The junction.
        junction: String,
        /// Which side (left, right, straight on).
        side: Turn,
        /// The leg it is seen from.
        arriving: String,
        /// The heading arriving.
        heading: Heading,
        /// The leg on that side.
        leg: String,
        /// The heading that side is.
        expected: Heading,
        /// The heading the leg leaves in.
        actual: Heading,
    },
    /// A floor without a lobby.
    #[error("floor {0} has no lobby: the elevator bank serves every floor the map lists")]
    NoLobby(i32),
    /// Two lobbies on a floor.
    #[error("floor {0} has two lobbies")]
    LobbyTwice(i32),
    /// A lobby's opening that is not a leg to it.
    #[error("the lobby of floor {floor}: leg '{leg}' does not lead to the lobby")]
    NotAnOpening {
        /// The floor.
        floor: i32,
        /// The leg.
        leg: String,
    },
    /// A leg to a lobby that the lobby does not list.
    #[error(
        "leg '{leg}' leads to the lobby of floor {floor}, but the lobby does not say in which wall it opens"
    )]
    OpeningMissing {
        /// The leg.
        leg: String,
        /// The floor.
        floor: i32,
    },
    /// `beside_bank` on the opposite wall.
    #[error(
        "the lobby of floor {floor}: the opening of '{leg}' is in the opposite wall, so it cannot be beside the bank wall"
    )]
    BesideBankOpposite {
        /// The floor.
        floor: i32,
        /// The leg.
        leg: String,
    },
    /// The office is no room of the map.
    #[error("the office, room {0}, is on no door of the map")]
    NoOffice(u32),
    /// A place that cannot be reached from the lab.
    #[error("{0} cannot be reached from the lab")]
    Unreachable(String),
}

/// A map refused, with every problem found.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}: {}", problems.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "))]
pub struct MapError {
    /// The file (or what names the text).
    pub file: String,
    /// What is wrong, each one sentence.
    pub problems: Vec<Problem>,
}

/// The file as written (`deny_unknown_fields`: a misspelt key is refused, not ignored).
mod raw {
    use super::{Heading, Wall};
    use serde::Deserialize;

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct Map {
        pub building: String,
        pub office: Option<u32>,
        pub floors: Vec<i32>,
        #[serde(default, rename = "lobby")]
        pub lobbies: Vec<Lobby>,
        #[serde(default, rename = "leg")]
        pub legs: Vec<Leg>,
        #[serde(default, rename = "junction")]
        pub junctions: Vec<Junction>,
    }

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct Lobby {
        pub floor: i32,
        #[serde(default)]
        pub openings: Vec<Opening>,
    }

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct Opening {
        pub leg: String,
        pub wall: Wall,
        #[serde(default)]
        pub beside_bank: bool,
    }

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct Leg {
        pub name: String,
        pub floor: i32,
        pub from: String,
        pub to: String,
        pub heading: Heading,
        #[serde(default)]
        pub left: Vec<DoorEntry>,
        #[serde(default)]
        pub right: Vec<DoorEntry>,
        #[serde(default)]
        pub facing: Vec<[u32; 2]>,
    }

    /// A room number, or a word ("door", "lab").
    #[derive(Debug, Deserialize)]
    #[serde(untagged)]
    pub enum DoorEntry {
        Room(u32),
        Word(String),
    }

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    pub struct Junction {
        pub name: String,
        pub floor: i32,
        pub arriving: String,
        pub straight: Option<String>,
        pub left: Option<String>,
        pub right: Option<String>,
    }
}

/// A room number written as a leg's end: `room 407`.
fn room_end(text: &str) -> Option<u32> {
    text.strip_prefix("room ")?.trim().parse().ok()
}

impl Map {
    /// Reads and checks a map; `file` names it in the error.
    pub fn parse(text: &str, file: &str) -> Result<Map, MapError> {
        let refuse = |problems: Vec<Problem>| MapError {
            file: file.to_string(),
            problems,
        };
        let raw: raw::Map =
            toml::from_str(text).map_err(|e| refuse(vec![Problem::Format(e.to_string())]))?;
        let mut problems = Vec::new();
        let map = resolve(raw, &mut problems);
        if problems.is_empty() {
            map.check_reachable(&mut problems);
        }
        if problems.is_empty() {
            Ok(map)
        } else {
            Err(refuse(problems))
        }
    }

    /// Reads and checks the map in `path`.
    pub fn load(path: &std::path::Path) -> Result<Map, LoadError> {
        let text = std::fs::read_to_string(path).map_err(|source| LoadError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(Map::parse(&text, &path.display().to_string())?)
    }

    /// The leg called `name`.
    pub fn leg(&self, name: &str) -> Option<usize> {
        self.legs.iter().position(|l| l.name == name)
    }

    /// The lobby of `floor`.
    pub fn lobby(&self, floor: i32) -> Option<&Lobby> {
        self.lobbies.iter().find(|l| l.floor == floor)
    }

    /// Where room `room`'s door is: (leg, where on it).
    pub fn room(&self, room: u32) -> Option<(usize, DoorAt)> {
        self.doors()
            .find_map(|(leg, at, door)| (door == Door::Room(room)).then_some((leg, at)))
    }

    /// Every room with a number, in the map's order.
    pub fn rooms(&self) -> Vec<u32> {
        self.doors()
            .filter_map(|(_, _, d)| match d {
                Door::Room(r) => Some(r),
                _ => None,
            })
            .collect()
    }

    /// Where the lab's door is.
    pub fn lab(&self) -> Option<(usize, DoorAt)> {
        self.doors()
            .find_map(|(leg, at, door)| (door == Door::Lab).then_some((leg, at)))
    }

    /// Every door: on the legs' sides, then at their ends.
    fn doors(&self) -> impl Iterator<Item = (usize, DoorAt, Door)> + '_ {
        let sides = self.legs.iter().enumerate().flat_map(|(i, leg)| {
            [Side::Left, Side::Right].into_iter().flat_map(move |side| {
                leg.doors(side)
                    .iter()
                    .enumerate()
                    .map(move |(n, d)| (i, DoorAt::Side { side, index: n }, *d))
            })
        });
        let ends = self.legs.iter().enumerate().flat_map(|(i, leg)| {
            [(&leg.from, false), (&leg.to, true)]
                .into_iter()
                .filter_map(move |(end, at_to)| {
                    let door = match end {
                        End::Lab => Door::Lab,
                        End::Room(r) => Door::Room(*r),
                        _ => return None,
                    };
                    Some((i, DoorAt::End { at_to }, door))
                })
        });
        sides.chain(ends)
    }

    /// Refuses places the lab cannot reach (legs walked both ways; the elevator joins every
    /// lobby).
    fn check_reachable(&self, problems: &mut Vec<Problem>) {
        let Some((lab_leg, _)) = self.lab() else {
            return;
        };
        let mut legs = vec![false; self.legs.len()];
        let mut junctions = vec![false; self.junctions.len()];
        let mut lobbies = false;
        let mut todo = vec![lab_leg];
        while let Some(l) = todo.pop() {
            if std::mem::replace(&mut legs[l], true) {
                continue;
            }
            for end in [&self.legs[l].from, &self.legs[l].to] {
                match end {
                    End::Junction(j) if !junctions[*j] => {
                        junctions[*j] = true;
                        todo.extend(self.junctions[*j].arms.iter().map(|(leg, _)| *leg));
                    }
                    End::Lobby if !lobbies => {
                        lobbies = true;
                        for lobby in &self.lobbies {
                            todo.extend(lobby.openings.iter().map(|o| o.leg));
                        }
                    }
                    _ => {}
                }
            }
        }
        for (j, seen) in junctions.iter().enumerate() {
            if !seen {
                let name = &self.junctions[j].name;
                problems.push(Problem::Unreachable(format!("junction '{name}'")));
            }
        }
        for (l, seen) in legs.iter().enumerate() {
            if !seen {
                problems.push(Problem::Unreachable(format!("leg '{}'", self.legs[l].name)));
            }
        }
        if !lobbies {
            problems.push(Problem::Unreachable("the elevator lobby".into()));
        }
    }
}

/// Where a door is on its leg.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DoorAt {
    /// On a side, the `index`-th (from 0) seen from the leg's `from`.
    Side {
        /// Which side.
        side: Side,
        /// Its place in that side's list.
        index: usize,
    },
    /// At one end: `to` (else `from`).
    End {
        /// At the leg's `to`.
        at_to: bool,
    },
}

/// A map that could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LoadError {
    /// The file could not be read.
    #[error("reading {}", path.display())]
    Read {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The map was refused.
    #[error(transparent)]
    Refused(#[from] MapError),
}

/// A place's index by its floor and name (names are a floor's own).
type Names<'a> = BTreeMap<(i32, &'a str), usize>;

/// From the file as written to a [`Map`]; every problem found is pushed.
fn resolve(raw: raw::Map, problems: &mut Vec<Problem>) -> Map {
    let floors = check_floors(&raw.floors, problems);
    let junction_at = name_junctions(&raw, &floors, problems);
    let (legs, leg_at) = resolve_legs(&raw, &floors, &junction_at, problems);
    let junctions = raw
        .junctions
        .iter()
        .enumerate()
        .map(|(j, raw_j)| resolve_junction(j, raw_j, &legs, &leg_at, problems))
        .collect();
    let lobbies = resolve_lobbies(&raw, &floors, &legs, &leg_at, problems);
    let map = Map {
        building: raw.building,
        office: raw.office,
        floors,
        legs,
        junctions,
        lobbies,
    };
    map.check_doors(problems);
    map
}

/// The floors in order, each once.
fn check_floors(listed: &[i32], problems: &mut Vec<Problem>) -> Vec<i32> {
    let mut floors = listed.to_vec();
    floors.sort_unstable();
    if floors.is_empty() {
        problems.push(Problem::NoFloors);
    }
    for w in floors.windows(2) {
        if w[0] == w[1] {
            problems.push(Problem::FloorTwice(w[0]));
        }
    }
    floors.dedup();
    floors
}

/// Refuses a place on a floor the map does not list.
fn on_floor(floors: &[i32], what: String, floor: i32, problems: &mut Vec<Problem>) {
    if !floors.contains(&floor) {
        problems.push(Problem::UnknownFloor { what, floor });
    }
}

/// The junctions by name: each name once a floor, none a word that names another place.
fn name_junctions<'a>(raw: &'a raw::Map, floors: &[i32], problems: &mut Vec<Problem>) -> Names<'a> {
    let mut junction_at = Names::new();
    for (i, j) in raw.junctions.iter().enumerate() {
        on_floor(floors, format!("junction '{}'", j.name), j.floor, problems);
        if matches!(j.name.as_str(), "lab" | "lobby" | "end") || room_end(&j.name).is_some() {
            problems.push(Problem::ReservedName(j.name.clone()));
        }
        if junction_at.insert((j.floor, &j.name), i).is_some() {
            problems.push(Problem::NameTwice {
                kind: "junction",
                name: j.name.clone(),
                floor: j.floor,
            });
        }
    }

    junction_at
}

/// The legs, their ends resolved to places on their floor and their doors read.
fn resolve_legs<'a>(
    raw: &'a raw::Map,
    floors: &[i32],
    junction_at: &Names<'_>,
    problems: &mut Vec<Problem>,
) -> (Vec<Leg>, Names<'a>) {
    let mut leg_at = Names::new();
    let mut legs = Vec::new();
    for (i, l) in raw.legs.iter().enumerate() {
        on_floor(floors, format!("leg '{}'", l.name), l.floor, problems);
        if leg_at.insert((l.floor, &l.name), i).is_some() {
            problems.push(Problem::NameTwice {
                kind: "leg",
                name: l.name.clone(),
                floor: l.floor,
            });
        }
        let end = |text: &str, problems: &mut Vec<Problem>| match text {
            "lab" => End::Lab,
            "lobby" => End::Lobby,
            "end" => End::DeadEnd,
            t => {
                if let Some(r) = room_end(t) {
                    End::Room(r)
                } else if let Some(&j) = junction_at.get(&(l.floor, t)) {
                    End::Junction(j)
                } else if let Some(j) = raw.junctions.iter().find(|j| j.name == t) {
                    problems.push(Problem::OtherFloor {
                        leg: l.name.clone(),
                        floor: l.floor,
                        junction: t.to_string(),
                        other: j.floor,
                    });
                    End::DeadEnd
                } else {
                    problems.push(Problem::LeadsNowhere {
                        leg: l.name.clone(),
                        to: t.to_string(),
                    });
                    End::DeadEnd
                }
            }
        };
        let (from, to) = (end(&l.from, problems), end(&l.to, problems));
        if from == to && from != End::DeadEnd {
            problems.push(Problem::Loop {
                leg: l.name.clone(),
                at: l.from.clone(),
            });
        }
        let doors = |side: Side, entries: &[raw::DoorEntry], problems: &mut Vec<Problem>| {
            entries
                .iter()
                .filter_map(|e| match e {
                    raw::DoorEntry::Room(r) => Some(Door::Room(*r)),
                    raw::DoorEntry::Word(w) if w == "door" => Some(Door::Unnumbered),
                    raw::DoorEntry::Word(w) if w == "lab" => Some(Door::Lab),
                    raw::DoorEntry::Word(w) => {
                        problems.push(Problem::NotADoor {
                            leg: l.name.clone(),
                            side,
                            entry: w.clone(),
                        });
                        None
                    }
                })
                .collect::<Vec<_>>()
        };
        legs.push(Leg {
            name: l.name.clone(),
            floor: l.floor,
            from,
            to,
            heading: l.heading,
            left: doors(Side::Left, &l.left, problems),
            right: doors(Side::Right, &l.right, problems),
            facing: l.facing.clone(),
        });
        let leg = &legs[legs.len() - 1];
        for pair in &leg.facing {
            let side = |room: u32| {
                [Side::Left, Side::Right]
                    .into_iter()
                    .find(|s| leg.doors(*s).contains(&Door::Room(room)))
            };
            match (side(pair[0]), side(pair[1])) {
                (Some(a), Some(b)) if a != b => {}
                _ => problems.push(Problem::NotFacing {
                    leg: leg.name.clone(),
                    pair: *pair,
                }),
            }
        }
    }

    (legs, leg_at)
}

/// A junction's arms: each side turned into the heading it leaves in, checked against the
/// way its leg runs; every leg that ends there named, and only those.
fn resolve_junction(
    j: usize,
    raw_j: &raw::Junction,
    legs: &[Leg],
    leg_at: &Names<'_>,
    problems: &mut Vec<Problem>,
) -> Junction {
    let name = &raw_j.name;
    let leaving = |leg: usize| -> Option<Heading> {
        let l: &Leg = &legs[leg];
        if l.from == End::Junction(j) {
            Some(l.heading)
        } else if l.to == End::Junction(j) {
            Some(l.heading.opposite())
        } else {
            None
        }
    };
    let mut arms: Vec<(usize, Heading)> = Vec::new();
    let mut named = |leg_name: &str, problems: &mut Vec<Problem>| -> Option<usize> {
        let Some(&leg) = leg_at.get(&(raw_j.floor, leg_name)) else {
            problems.push(Problem::UnknownLeg {
                at: format!("junction '{name}' (floor {})", raw_j.floor),
                leg: leg_name.to_string(),
            });
            return None;
        };
        if arms.iter().any(|(l, _)| *l == leg) {
            problems.push(Problem::ArmTwice {
                junction: name.clone(),
                leg: leg_name.to_string(),
            });
            return None;
        }
        match leaving(leg) {
            Some(h) => {
                arms.push((leg, h));
                Some(leg)
            }
            None => {
                problems.push(Problem::NotAnArm {
                    junction: name.clone(),
                    leg: leg_name.to_string(),
                });
                None
            }
        }
    };
    let arriving = named(&raw_j.arriving, problems);
    let sides = [
        (Turn::Straight, &raw_j.straight),
        (Turn::Left, &raw_j.left),
        (Turn::Right, &raw_j.right),
    ];
    let mut seen = Vec::new();
    for (turn, leg_name) in sides {
        if let Some(leg_name) = leg_name
            && let Some(leg) = named(leg_name, problems)
        {
            seen.push((turn, leg));
        }
    }
    if let Some(a) = arriving {
        // Arriving along a leg is heading against the way it leaves.
        let heading = arms[0].1.opposite();
        for (turn, leg) in seen {
            let expected = heading.after(turn);
            let actual = arms.iter().find(|(l, _)| *l == leg).map(|(_, h)| *h);
            if let Some(actual) = actual
                && actual != expected
            {
                problems.push(Problem::SideDisagrees {
                    junction: name.clone(),
                    side: turn,
                    arriving: legs[a].name.clone(),
                    heading,
                    leg: legs[leg].name.clone(),
                    expected,
                    actual,
                });
            }
        }
    }
    for (l, leg) in legs.iter().enumerate() {
        let ends_here = leg.from == End::Junction(j) || leg.to == End::Junction(j);
        if ends_here && !arms.iter().any(|(a, _)| *a == l) {
            problems.push(Problem::ArmMissing {
                junction: name.clone(),
                leg: leg.name.clone(),
            });
        }
    }
    let count = legs
        .iter()
        .filter(|l| l.from == End::Junction(j) || l.to == End::Junction(j))
        .count();
    if count < 3 {
        problems.push(Problem::TooFewArms {
            junction: name.clone(),
            arms: count,
        });
    }
    Junction {
        name: name.clone(),
        floor: raw_j.floor,
        arms,
    }
}

/// The lobbies: one a floor; each opening a leg to it, each leg to it an opening.
fn resolve_lobbies(
    raw: &raw::Map,
    floors: &[i32],
    legs: &[Leg],
    leg_at: &Names<'_>,
    problems: &mut Vec<Problem>,
) -> Vec<Lobby> {
    let mut lobbies: Vec<Lobby> = Vec::new();
    for raw_l in &raw.lobbies {
        on_floor(floors, "a lobby".to_string(), raw_l.floor, problems);
        if lobbies.iter().any(|l| l.floor == raw_l.floor) {
            problems.push(Problem::LobbyTwice(raw_l.floor));
            continue;
        }
        let mut openings = Vec::new();
        for o in &raw_l.openings {
            let Some(&leg) = leg_at.get(&(raw_l.floor, o.leg.as_str())) else {
                problems.push(Problem::UnknownLeg {
                    at: format!("the lobby of floor {}", raw_l.floor),
                    leg: o.leg.clone(),
                });
                continue;
            };
            let l = &legs[leg];
            if l.from != End::Lobby && l.to != End::Lobby {
                problems.push(Problem::NotAnOpening {
                    floor: raw_l.floor,
                    leg: o.leg.clone(),
                });
                continue;
            }
            if o.beside_bank && o.wall == Wall::Opposite {
                problems.push(Problem::BesideBankOpposite {
                    floor: raw_l.floor,
                    leg: o.leg.clone(),
                });
            }
            openings.push(Opening {
                leg,
                wall: o.wall,
                beside_bank: o.beside_bank,
            });
        }
        lobbies.push(Lobby {
            floor: raw_l.floor,
            openings,
        });
    }
    lobbies.sort_by_key(|l| l.floor);
    for f in floors {
        if !lobbies.iter().any(|l| l.floor == *f) {
            problems.push(Problem::NoLobby(*f));
        }
    }
    for (i, leg) in legs.iter().enumerate() {
        let to_lobby = leg.from == End::Lobby || leg.to == End::Lobby;
        let listed = lobbies
            .iter()
            .any(|l| l.floor == leg.floor && l.openings.iter().any(|o| o.leg == i));
        if to_lobby && !listed {
            problems.push(Problem::OpeningMissing {
                leg: leg.name.clone(),
                floor: leg.floor,
            });
        }
    }

    lobbies
}

impl Map {
    /// Doors: a room once, on the floor its number says; the lab once; the office a room.
    fn check_doors(&self, problems: &mut Vec<Problem>) {
        let mut rooms: BTreeMap<u32, String> = BTreeMap::new();
        let mut lab: Option<String> = None;
        for (leg, at, door) in self.doors() {
            let l = &self.legs[leg];
            let place = match at {
                DoorAt::Side { side, index } => {
                    format!("the {side} of leg '{}' (door {})", l.name, index + 1)
                }
                DoorAt::End { .. } => format!("the end of leg '{}'", l.name),
            };
            match door {
                Door::Room(room) => {
                    if i64::from(room / 100) != i64::from(l.floor) {
                        problems.push(Problem::RoomOnWrongFloor {
                            room,
                            at: place.clone(),
                            floor: l.floor,
                        });
                    }
                    if let Some(first) = rooms.get(&room) {
                        problems.push(Problem::RoomTwice {
                            room,
                            first: first.clone(),
                            second: place,
                        });
                    } else {
                        rooms.insert(room, place);
                    }
                }
                Door::Lab => match &lab {
                    Some(first) => problems.push(Problem::LabTwice {
                        first: first.clone(),
                        second: place,
                    }),
                    None => lab = Some(place),
                },
                Door::Unnumbered => {}
            }
        }
        if lab.is_none() {
            problems.push(Problem::NoLab);
        }
        if let Some(office) = self.office
            && !rooms.contains_key(&office)
        {
            problems.push(Problem::NoOffice(office));
        }
    }
}
