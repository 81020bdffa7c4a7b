//! The standard navigation skills of the exit-lab experiment. Movement skills propose on the
//! `drive` channel; default priorities: stop 10, avoid 8, go_through 6, home 4, wall_follow 3,
//! wander 2 (higher wins).
//!
//! One file per skill; the helpers they share (sonar geometry, the drive output) are here.

mod avoid;
mod barcode_track;
mod door_locate;
mod go_through;
mod home;
mod stop;
#[cfg(test)]
mod tests;
mod wall_follow;
mod wander;

pub use avoid::*;
pub use barcode_track::*;
pub use door_locate::*;
pub use go_through::*;
pub use home::*;
pub use stop::*;
pub use wall_follow::*;
pub use wander::*;

use skill_sdk::prelude::*;
use skillfab_msgs::{Barcodes, Door, Drive, Odometry, SONARS, Sonar, Target};
use std::f64::consts::{PI, TAU};

/// Angle of sonar `i` from the front (rad, counter-clockwise).
pub fn sonar_angle(i: usize) -> f64 {
    wrap(i as f64 * TAU / SONARS as f64)
}

/// Wraps an angle into −π..π.
pub fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

/// A usable range: no echo counts as far, never-read as unknown.
fn range(s: &Sonar, i: usize) -> Option<f64> {
    let r = s.range[i % SONARS];
    if r.is_nan() { None } else { Some(r.min(10.0)) }
}

/// The smallest range among sonars whose angle lies within `[from, to]` (rad).
fn min_in(s: &Sonar, from: f64, to: f64) -> f64 {
    (0..SONARS)
        .filter(|&i| {
            let a = sonar_angle(i);
            a >= from && a <= to
        })
        .filter_map(|i| range(s, i))
        .fold(f64::INFINITY, f64::min)
}

/// Output of every movement skill.
#[derive(Outputs)]
pub struct DriveOut<'a> {
    /// The proposal.
    pub drive: Proposal<'a, Drive>,
}
