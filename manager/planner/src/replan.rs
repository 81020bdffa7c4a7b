//! Planning again: where a failed step of a route leaves the robot ([`Believed`], said by
//! [`Route::believed`] for each node of the route's tree) and the route that goes on from
//! there ([`Route::replanned`]).

use crate::map::Map;
use crate::route::{From, PlanError, Route, Trip, plan, plan_back_from, plan_round_trip_from};
use std::fmt;

/// Where the robot is believed to be when a step of a route failed, as the plan that goes on
/// from there needs it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Believed {
    /// The place.
    pub at: From,
    /// On the way back to the lab (the message said).
    pub back: bool,
}

impl fmt::Display for Believed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let on = match self.at {
            From::DeadEnd { .. } => "at",
            _ => "in",
        };
        write!(f, "{on} {}", self.at.place())?;
        if self.back {
            write!(f, ", on the way back")?;
        }
        Ok(())
    }
}

impl Route {
    /// The route that goes on from where `at` says the robot is: the same destination, and
    /// the way back too if this route has it.
    pub fn replanned(&self, map: &Map, at: Believed) -> Result<Route, PlanError> {
        match (at.back, at.at, self.trip) {
            (true, From::Lab, _) => Err(PlanError::NotFrom("lab".into())),
            (true, from, _) => plan_back_from(map, self.room, from),
            (false, from, Trip::RoundTrip) => plan_round_trip_from(map, Some(self.room), from),
            (false, from, _) => plan(map, Some(self.room), from),
        }
    }
}
