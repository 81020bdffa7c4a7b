//! `skillfab plan`: a route on a building's route map (docs/maps.md) written as a plan of the
//! delivery library's subtrees ([`skillfab_planner`]); `demo deliver` runs such a plan. The
//! judge's side of a destination is here too: a building file's goal moved to another room.

use anyhow::Context;
use skillfab_planner::{From, Library, Map, Route};
use std::path::{Path, PathBuf};

/// A place a route starts or ends at: the lab, a room, or (a start) a floor's lobby.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// The lab.
    Lab,
    /// A room, by its number.
    Room(u32),
    /// Where a route to a room may start besides the lab: a floor's lobby (`lobby:F`), a
    /// leg's dead end (`end:N`), a car boarded on a floor (`car:F`).
    At(From),
}

impl std::str::FromStr for Place {
    type Err = String;
    fn from_str(s: &str) -> Result<Place, String> {
        match s {
            "lab" => Ok(Place::Lab),
            n => n.parse().map(Place::Room).or_else(|_| {
                n.parse().map(Place::At).map_err(|_| {
                    format!(
                        "'{n}' is neither `lab`, a room's number, a lobby (`lobby:F`), a leg's dead end (`end:N`, the map's N-th leg) nor a car (`car:F`, boarded on floor F)"
                    )
                })
            }),
        }
    }
}

/// Which route: from, to (`None`: the map's office), and whether back again.
#[derive(Debug, Clone, Copy)]
pub struct Trip {
    /// Where it starts.
    pub from: Place,
    /// Where it goes.
    pub to: Option<Place>,
    /// To the room and back to the lab.
    pub and_back: bool,
}

/// A plan the planner wrote: its route and the file's text.
pub struct Planned {
    /// The route.
    pub route: Route,
    /// The plan (BehaviorTree.CPP v4 XML), read back as the sequencer reads it.
    pub xml: String,
}

/// Plans `trip` (to the map's office unless it says), as a tree of `library`'s subtrees.
pub fn plan(map: &Path, trip: Trip, library: &Path) -> anyhow::Result<Planned> {
    let m = Map::load(map)?;
    let route = match (trip.from, trip.to, trip.and_back) {
        (_, Some(Place::At(_)), _) => anyhow::bail!("a route ends at a room or the lab"),
        (Place::Lab, Some(Place::Lab), _) => anyhow::bail!("from the lab to the lab: no route"),
        (Place::At(from), Some(Place::Lab), _) => {
            anyhow::bail!("--from {from}: from there the planner plans to a room (--to ROOM)")
        }
        (Place::Lab, to, false) => skillfab_planner::plan(&m, room(to), From::Lab)?,
        (Place::Lab, to, true) => skillfab_planner::plan_round_trip(&m, room(to))?,
        (Place::Room(r), Some(Place::Lab), false) => skillfab_planner::plan_back(&m, Some(r))?,
        (Place::Room(r), _, false) => {
            anyhow::bail!("--from {r}: from a room the planner plans the way back (--to lab)")
        }
        (Place::Room(_), _, true) => anyhow::bail!("--and-back starts at the lab"),
        (Place::At(from), to, false) => skillfab_planner::plan(&m, room(to), from)?,
        (Place::At(from), to, true) => skillfab_planner::plan_round_trip_from(&m, room(to), from)?,
    };
    written(route, map, library)
}

/// `route` as a plan of `library`'s subtrees (`map` named in its comment), checked as the
/// sequencer reads it.
pub fn written(route: Route, map: &Path, library: &Path) -> anyhow::Result<Planned> {
    let text = std::fs::read_to_string(library)
        .with_context(|| format!("reading {}", library.display()))?;
    let lib = Library::parse(&text, &library.display().to_string())?;
    let xml = route.plan_xml(&lib, &map.display().to_string())?;
    // What the sequencer would refuse is refused here (a library it does not read).
    skillfab_sequence::Plan::parse(&xml, &format!("the plan {}", route.tree_id()))?;
    Ok(Planned { route, xml })
}

/// The room of a destination (`None`: the map's office).
fn room(to: Option<Place>) -> Option<u32> {
    match to {
        Some(Place::Room(r)) => Some(r),
        _ => None,
    }
}

/// `skillfab plan`: the plan on stdout (or the route in words, or only the map's check).
pub fn run(map: &Path, trip: Trip, library: &Path, words: bool, check: bool) -> anyhow::Result<()> {
    if check {
        let m = Map::load(map)?;
        println!(
            "{}: the map of {} is sound: {} legs, {} junctions, floors {:?}, rooms {:?}",
            map.display(),
            m.building,
            m.legs.len(),
            m.junctions.len(),
            m.floors,
            m.rooms()
        );
        return Ok(());
    }
    let p = plan(map, trip, library)?;
    if words {
        println!("{}", p.route);
    } else {
        print!("{}", p.xml);
    }
    Ok(())
}

/// In front of a door the goal is this far into the corridor (m): its centre line (the
/// buildings' corridors are 2.4 m wide), as the shipped goals are.
const GOAL_INTO_THE_CORRIDOR_M: f64 = 1.2;

/// The building file with its goal at room `room` (in front of the door beside its sign, as
/// the shipped goals are), written into `dir` under the same name; `None` when the goal is
/// that room already. The judge's ground truth: the robot is never told.
pub fn building_for_room(
    building: &Path,
    room: u32,
    dir: &Path,
) -> anyhow::Result<Option<PathBuf>> {
    use denning_sim::building::Building;
    let b = Building::load(building)?;
    if u32::from(b.goal.room) == room {
        return Ok(None);
    }
    let floor = i32::try_from(room / 100)?;
    let f = b
        .floor(floor)
        .with_context(|| format!("{}: no floor {floor} for room {room}", building.display()))?;
    let sign = f
        .barcode
        .iter()
        .find(|c| u32::from(c.id) == room)
        .with_context(|| format!("{}: room {room} has no sign", building.display()))?;
    // The sign is 0.3 m beside its door's edge, 0.05 m in front of the wall: the door whose
    // nearest point is nearest, and the corridor on the sign's side of it.
    let at = f
        .before_door(sign.at, GOAL_INTO_THE_CORRIDOR_M)
        .with_context(|| format!("{}: no door on floor {floor}", building.display()))?;
    // The file as a TOML table with its goal replaced (the simulator reads it as ever).
    let text = std::fs::read_to_string(building)?;
    let mut doc: toml::Table = toml::from_str(&text)?;
    let mut goal = toml::Table::new();
    goal.insert("floor".into(), toml::Value::Integer(floor.into()));
    goal.insert("room".into(), toml::Value::Integer(room.into()));
    goal.insert(
        "at".into(),
        toml::Value::Array(vec![at[0].into(), at[1].into()]),
    );
    goal.insert("radius".into(), toml::Value::Float(b.goal.radius));
    doc.insert("goal".into(), toml::Value::Table(goal));
    let out = dir.join(
        building
            .file_name()
            .context("the building file has no name")?,
    );
    std::fs::write(&out, toml::to_string(&doc)?)?;
    Ok(Some(out))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    /// The goal a room's sign gives is the one the building file has for its office: in
    /// front of the door, on the corridor's centre line.
    #[test]
    fn a_rooms_goal_is_where_the_buildings_own_goal_is_for_its_office() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let dir = std::env::temp_dir().join(format!("skillfab-goal-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (file, other) in [
            ("devices/denning-sim/buildings/building-a.toml", 404),
            ("devices/denning-sim/buildings/building-b.toml", 405),
            ("devices/denning-sim/buildings/heldout/building-c.toml", 403),
            ("devices/denning-sim/buildings/heldout/building-d.toml", 404),
        ] {
            let path = root.join(file);
            let b = denning_sim::building::Building::load(&path).unwrap();
            // Moved to another room and back: the file's own goal.
            let moved = building_for_room(&path, other, &dir).unwrap().unwrap();
            let again = building_for_room(&moved, u32::from(b.goal.room), &dir)
                .unwrap()
                .unwrap();
            let back = denning_sim::building::Building::load(&again).unwrap();
            assert_eq!(back.goal.room, b.goal.room, "{file}");
            let (g, h) = (back.goal.at, b.goal.at);
            assert!(
                (g[0] - h[0]).hypot(g[1] - h[1]) < 1e-9,
                "{file}: {g:?} vs {h:?}"
            );
            assert!(
                building_for_room(&path, u32::from(b.goal.room), &dir)
                    .unwrap()
                    .is_none()
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
