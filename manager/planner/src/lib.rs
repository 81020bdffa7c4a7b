//! The deliberative tier: a building's route map in a person's terms, and a planner that
//! turns a destination into the plan the sequencer runs.
//!
//! Layout: [`map`] reads a route map (TOML, docs/maps.md) and refuses one that contradicts
//! itself, each problem one sentence naming the place; [`route`] finds the way from the lab to
//! a room, from a room back to the lab, or both (corridor legs, junctions and their turns, the
//! lobbies, the elevator); [`replan`] says where a failed step leaves the robot and plans
//! on from there; [`tree`] writes
//! that route as a BehaviorTree.CPP v4 plan built from the delivery library's subtrees
//! (`skills/plans/deliver.xml`). Pure code: no fabric, no files but what [`Map::load`] reads.
//!
//! ```no_run
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! use skillfab_planner::{From, Library, Map, plan};
//! let map = Map::load("devices/denning-sim/buildings/building-a.map.toml".as_ref())?;
//! let route = plan(&map, Some(405), From::Lab)?;
//! println!("{route}");
//! let library = std::fs::read_to_string("skills/plans/deliver.xml")?;
//! let xml = route.plan_xml(&Library::parse(&library, "deliver.xml")?, "building-a.map.toml")?;
//! # let _ = xml;
//! # Ok(())
//! # }
//! ```

#![warn(missing_docs)]

pub mod map;
pub mod replan;
pub mod route;
pub mod tree;

pub use map::{LoadError, Map, MapError, Problem};
pub use replan::Believed;
pub use route::{
    From, PlanError, Route, Step, Trip, plan, plan_back, plan_back_from, plan_round_trip,
    plan_round_trip_from,
};
pub use tree::{Library, TreeError};

/// Where the map of a building file is by convention: beside it, `NAME.map.toml` for
/// `NAME.toml`.
pub fn map_beside(building: &std::path::Path) -> std::path::PathBuf {
    let stem = building
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    building.with_file_name(format!("{stem}.map.toml"))
}
