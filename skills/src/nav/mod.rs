//! The standard navigation skills of the exit-lab experiment. Movement skills propose on the
//! `drive` channel; default priorities: stop 10, avoid 8, go_through 6, home 4, wall_follow 3,
//! wander 2, explore 2 (higher wins).
//!
//! One file per skill; the helpers they share (sonar geometry, the drive output) are here.

mod avoid;
mod barcode_track;
mod detour;
mod door_locate;
mod explore;
mod go_through;
mod home;
mod stop;
#[cfg(test)]
pub(crate) mod tests;
mod wall_follow;
mod wander;

pub use avoid::*;
pub use barcode_track::*;
pub use detour::{Detour, Watch};
pub use door_locate::*;
pub use explore::*;
pub use go_through::*;
pub use home::*;
pub use stop::*;
pub use wall_follow::*;
pub use wander::*;

use serde::{Deserialize, Serialize};
use skill_sdk::prelude::*;
use skillfab_msgs::{Barcodes, Door, Drive, Odometry, Progress, SONARS, Sonar, Target};
use std::f64::consts::{PI, TAU};

/// Angle of sonar `i` from the front (rad, counter-clockwise).
pub fn sonar_angle(i: usize) -> f64 {
    wrap(i as f64 * TAU / SONARS as f64)
}

/// Wraps an angle into −π..π.
pub fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

/// Radius of the sonar ring (m): ranges are measured from it.
pub const RING: f64 = 0.36;
/// Half a sonar's cone (rad): a reading is the nearest echo within it.
pub const CONE: f64 = 15.0 * PI / 180.0;

/// How far a sonar reaches (m): a longer range, or no echo, counts as this.
const SONAR_REACH: f64 = 10.0;

/// A usable range (m): no echo counts as far (the sonar's reach), never-read as unknown.
pub(crate) fn range(s: &Sonar, i: usize) -> Option<f64> {
    s.echo(i % SONARS)
        .map(|e| e.range_or(SONAR_REACH).min(SONAR_REACH))
}

/// The smallest range among sonars whose angle lies within `[from, to]` (rad).
pub(crate) fn min_in(s: &Sonar, from: f64, to: f64) -> f64 {
    (0..SONARS)
        .filter(|&i| {
            let a = sonar_angle(i);
            a >= from && a <= to
        })
        .filter_map(|i| range(s, i))
        .fold(f64::INFINITY, f64::min)
}

/// Rays per side of a sonar's axis an echo is placed on (the cone sampled every 5°).
const RAYS: i32 = 3;
/// A place nearer than another sonar's reading by this much (m), inside its cone, is clear:
/// the reading's noise and a margin.
const CARVE: f64 = 0.1;

/// Where sonar `i`'s echo may come from, each place given to `f` (m, the robot's frame, from
/// its centre). A reading is the nearest echo somewhere in the cone: any of its rays (every
/// 5°) at the range read — unless another sonar that heard an echo reads farther there (the
/// place is inside its cone and nearer than its reading by [`CARVE`]), for then nothing is
/// there. A side wall seen by a sonar 45° off the front comes from its cone's outer rays:
/// the inner ones fall in the cone of the sonar 15° nearer the front, which reads farther.
/// When every ray is ruled out (the readings disagree) the cone's axis is kept. No place
/// for a sonar not read or with no echo.
pub(crate) fn echo_places(s: &Sonar, i: usize, mut f: impl FnMut(f64, f64)) {
    let Some(r) = heard(s, i) else {
        return;
    };
    let axis = sonar_angle(i);
    let place = |k: i32| {
        let a = axis + f64::from(k) * CONE / f64::from(RAYS);
        (
            RING * axis.cos() + r * a.cos(),
            RING * axis.sin() + r * a.sin(),
        )
    };
    let clear = |(x, y): (f64, f64)| {
        (0..SONARS).any(|j| {
            let Some(rj) = heard(s, j).filter(|_| j != i % SONARS) else {
                return false;
            };
            let aj = sonar_angle(j);
            let (dx, dy) = (x - RING * aj.cos(), y - RING * aj.sin());
            wrap(dy.atan2(dx) - aj).abs() <= CONE && dx.hypot(dy) < rj - CARVE
        })
    };
    let mut any = false;
    for k in -RAYS..=RAYS {
        let p = place(k);
        if !clear(p) {
            any = true;
            f(p.0, p.1);
        }
    }
    if !any {
        let (x, y) = place(0);
        f(x, y);
    }
}

/// Sonar `i`'s range when it heard an echo (m, from the ring).
fn heard(s: &Sonar, i: usize) -> Option<f64> {
    match s.echo(i % SONARS)? {
        skillfab_msgs::Echo::Range(r) if r < SONAR_REACH => Some(r),
        _ => None,
    }
}

/// The cycle period (ms) a skill times things in, counting cycles: the manager's nominal
/// period, or its default (10 ms) when it free-runs without one.
pub(crate) fn period_ms<P>(ctx: &Ctx<'_, P>) -> f64 {
    ctx.clock
        .period
        .map_or(FREE_RUN_PERIOD_MS, |d| d.as_secs_f64() * 1000.0)
}

/// The period assumed when the manager free-runs (no nominal period): its default.
const FREE_RUN_PERIOD_MS: f64 = 10.0;

/// Output of every movement skill.
#[derive(Outputs)]
pub struct DriveOut<'a> {
    /// The proposal.
    pub drive: Proposal<'a, Drive>,
}

/// When a skill begins an activation: skills that count or remember "since activated" start
/// afresh there (a sequencer reuses them from step to step of a plan). The manager numbers
/// activations ([`Ctx::activation`]); a restarted process keeps its number, so a restart in
/// the middle of an activation goes on with the state it kept.
#[derive(Debug, Default, Clone, Copy, Serialize, Deserialize)]
pub struct Activation {
    /// The activation of the last run.
    last: Option<u32>,
}

impl Activation {
    /// Notes a run of activation `ctx.activation`; true when it begins one (the first run, or
    /// the first of a new activation).
    pub fn begins<P>(&mut self, ctx: &Ctx<'_, P>) -> bool {
        let fresh = self.last != Some(ctx.activation);
        self.last = Some(ctx.activation);
        fresh
    }
}
