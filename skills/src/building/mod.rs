//! The building skills of the delivery experiment: from the basement lab's door along
//! corridors, up in an elevator and along a corridor to an office. Movement skills propose on
//! the `drive` channel (default priorities: enter_car 6, leave_car 6, push_button 5,
//! hall_follow 3; `avoid` 8 and `stop` 10 run beside them), `push_button` also on `push`,
//! `deliver` only on `say` (priority 1). Perception skills (`intersection`, `door_detect`,
//! `sign_read`, `car_watch`) only write outputs.
//!
//! Every skill's outputs carry what a sequencer waits on: a count, a flag, or a [`Progress`]
//! whose phases each skill documents. Counts and progress start afresh whenever a skill is
//! (re)activated ([`Activation`]): a plan reuses the same instances step after step.
//!
//! One file per skill; the geometry they share (side walls from the ring) is here.

mod car_watch;
mod deliver;
mod door_detect;
mod enter_car;
mod hall_follow;
mod intersection;
mod leave_car;
mod push_button;
mod sign_read;
#[cfg(test)]
mod tests;

pub use car_watch::*;
pub use deliver::*;
pub use door_detect::*;
pub use enter_car::*;
pub use hall_follow::*;
pub use intersection::*;
pub use leave_car::*;
pub use push_button::*;
pub use sign_read::*;

use crate::nav::{Activation, CONE, DriveOut, RING, min_in, period_ms, range, wrap};
use skill_sdk::prelude::*;
use skillfab_msgs::{
    Arm, Barcodes, Car, Doors, Drive, Junction, Odometry, Progress, Push, SONARS, Say, Signs,
    Sonar, Target, Voice,
};
use std::f64::consts::{FRAC_PI_2, PI};

/// Camera reports older than this are not "in view" (ms), as in `barcode_track`.
const IN_VIEW_MS: f64 = 500.0;

/// The reading of the sonar whose axis is at `deg` degrees (counter-clockwise from the
/// front; rounded to the nearest sonar); `None` if it was never read.
fn at(s: &Sonar, deg: f64) -> Option<f64> {
    let i = (deg / 15.0).round().rem_euclid(SONARS as f64) as usize;
    range(s, i)
}

/// The nearest and the farthest reading among the sonars whose axes lie within `from..=to`
/// degrees; `None` while one of them was never read (an unread ring opens nothing).
fn arc(s: &Sonar, from: f64, to: f64) -> Option<(f64, f64)> {
    let first = (from / 15.0).ceil() as i32;
    let last = (to / 15.0).floor() as i32;
    (first..=last).try_fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), k| {
        at(s, f64::from(k) * 15.0).map(|r| (lo.min(r), hi.max(r)))
    })
}

/// A straight wall seen by three sonars 30° apart.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Wall {
    /// Direction of its normal, from the robot toward it, relative to the heading (rad).
    normal: f64,
    /// Distance from the robot's centre to the wall (m).
    distance: f64,
}

/// A straight wall beside the robot, from the sonars at 60°, 90° and 120° on one side.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SideWall {
    /// The wall's direction relative to the heading (rad, counter-clockwise): the heading
    /// plus this is the corridor's axis.
    tilt: f64,
    /// Distance from the robot's centre to the wall (m).
    distance: f64,
}

/// Readings beyond this are not a wall near the robot (m, from the ring).
const WALL_MAX: f64 = 2.2;
/// A fitted wall's normal is within this of the middle sonar's axis (rad).
const WALL_TILT_MAX: f64 = 0.5;

/// The wall the sonars at `beta` and `beta` ± 30° (rad) see, if they agree on one straight
/// wall. A cone's reading is the range along its ray nearest to the wall's normal, so for a
/// trial normal each reading implies a distance to the wall; the normal is the one at which
/// the outer two readings imply the same distance, and the middle one must agree with it (an
/// opening, or the end of the wall, breaks the agreement: no wall then).
fn wall_toward(s: &Sonar, beta: f64) -> Option<Wall> {
    let side = 30f64.to_radians();
    let read = |b: f64| at(s, b.to_degrees()).filter(|&r| r < WALL_MAX);
    let (r0, r1, r2) = (read(beta - side)?, read(beta)?, read(beta + side)?);
    // Distance from the centre to the wall implied by reading `r` of the sonar at `b`, for
    // a wall whose normal (toward it) is at `normal`.
    let implied = |r: f64, b: f64, normal: f64| {
        let inc = wrap(b - normal).abs();
        r * (inc - CONE).max(0.0).cos() + RING * (b - normal).cos()
    };
    let steps = 100;
    let mut best: Option<(f64, f64)> = None;
    for k in -steps..=steps {
        let normal = beta + f64::from(k) * WALL_TILT_MAX / f64::from(steps);
        let miss = (implied(r0, beta - side, normal) - implied(r2, beta + side, normal)).abs();
        if best.is_none_or(|b| miss < b.1) {
            best = Some((normal, miss));
        }
    }
    let (normal, miss) = best?;
    let (d0, d1, d2) = (
        implied(r0, beta - side, normal),
        implied(r1, beta, normal),
        implied(r2, beta + side, normal),
    );
    (miss < 0.1 && (d1 - (d0 + d2) / 2.0).abs() < 0.12).then_some(Wall {
        normal: wrap(normal),
        distance: (d0 + d1 + d2) / 3.0,
    })
}

/// The wall on `side` (+1 left, −1 right), if the three side sonars agree on one straight
/// wall ([`wall_toward`] at ±90°).
fn side_wall(s: &Sonar, side: f64) -> Option<SideWall> {
    wall_toward(s, side * FRAC_PI_2).map(|w| SideWall {
        tilt: wrap(w.normal - side * FRAC_PI_2),
        distance: w.distance,
    })
}

/// The orientation of the walls around the robot, modulo a quarter turn, relative to its
/// heading (rad, −π/4..π/4): the straight walls the ring fits, in a room whose walls are
/// square to each other (a car's cabin). Three sonars that straddle a corner can fit a wall
/// that is not there, so the orientation is the one most fits agree on (within 3°), averaged
/// over those; `None` unless three agree.
fn box_axis(s: &Sonar) -> Option<f64> {
    // Square walls: their normals agree modulo a quarter turn, so they are compared as
    // angles four times over.
    let quads: Vec<f64> = (0..SONARS)
        .filter_map(|k| wall_toward(s, crate::nav::sonar_angle(k)))
        .map(|w| wrap(4.0 * w.normal))
        .collect();
    let near = |a: f64, b: f64| wrap(a - b).abs() < 4.0 * BOX_AGREE;
    let best = quads
        .iter()
        .max_by_key(|&&a| quads.iter().filter(|&&b| near(a, b)).count())?;
    let (c, sn, n) = quads
        .iter()
        .filter(|&&b| near(*best, b))
        .fold((0.0, 0.0, 0), |(c, s, n), &b| {
            (c + b.cos(), s + b.sin(), n + 1)
        });
    (n >= 3).then(|| sn.atan2(c) / 4.0)
}

/// Wall fits within this of each other (rad, modulo a quarter turn) agree on a room's
/// orientation.
const BOX_AGREE: f64 = 0.05;

/// The direction of the walls on both sides (odometry frame), when both are fitted and run
/// within 0.25 rad of `near`: in a car's cabin, the way in and out, free of the odometry's
/// turning error and of the estimate the robot came in by.
fn walls_axis(s: &Sonar, theta: f64, near: f64) -> Option<f64> {
    let l = side_wall(s, 1.0)?;
    let r = side_wall(s, -1.0)?;
    let a = wrap(theta + (l.tilt + r.tilt) / 2.0);
    // The walls run both ways: the one near `near`.
    [a, wrap(a + PI)]
        .into_iter()
        .find(|&a| wrap(a - near).abs() < 0.25)
}

/// A turn rate toward `err` (rad) with gain `gain`, at most `max`, and at least `min` while
/// the error is above `deadband`: the robot's rotate command has a resolution, and a turn
/// that slows to nothing never ends.
fn turn_toward(err: f64, gain: f64, max: f64, min: f64, deadband: f64) -> f64 {
    let w = (gain * err).clamp(-max, max);
    if err.abs() > deadband && w.abs() < min {
        min.copysign(err)
    } else {
        w
    }
}
