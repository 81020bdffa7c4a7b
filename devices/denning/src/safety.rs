//! The safety layer at the device: whatever the skills propose and whatever the link does, the
//! translation the robot is commanded is limited by the nearest fresh sonar echo in the
//! direction of travel and by the link's health. It sits between arbitration and the serial
//! port, so no skill can override it (anchor: Nav2's collision monitor, its "approach" model).
//!
//! How it decides, each cycle (pure code; the device calls [`Guard::observe`] for each new
//! reading and [`Guard::limit`] for the command):
//! - Each reading is placed in the odometry frame when it arrives, so the robot's motion since
//!   it was taken is accounted for. An echo is a 30° cone: it is kept as three points, its
//!   axis and both edges, because the obstacle may be anywhere across it. Echoes are kept
//!   while fresh (`fresh_ms`), all of them, not only each sonar's newest: one reading that a
//!   corrupted frame made far cannot erase a near one (the protocol's 16-bit sum misses
//!   flips that cancel, see `PROTOCOL.md`).
//! - The free distance ahead (behind, when backing) is how far the body (radius + `margin_m`)
//!   can go straight before it touches one of those points. A reading at the sonar's
//!   shortest range (0.15 m) says only "this close or closer": it is placed at the ring, so
//!   the robot never creeps on into what its sonar can no longer see. The speed allowed is the one
//!   that can still stop `stop_m` short of it, braking at `decel` after `react_s`:
//!   `v ≤ √((a·t)² + 2·a·d) − a·t`.
//! - **Passage:** where the sonar along the direction of travel sees an opening (fresh, at
//!   least `opening_m`), the other echoes count by their axis only, so the robot can pass a
//!   doorway with posts beside its cones' edges; where it does not, the whole cones count.
//!   A false door estimate that points between two obstacles therefore stops the robot in
//!   front of them.
//! - **Blind:** no fresh reading (echo or no echo) from the sonars within 30° of the direction
//!   of travel, or a link that drops more than `bad_share` of its frames: at most
//!   `blind_speed`. No good frame at all for the device's `blind_ms`: stop (the device's
//!   older rule, kept).
//! - Rotation is never limited: a synchro-drive turns on the spot, its round body sweeps
//!   nothing.

use crate::codec::SONARS;
use crate::driver::{Echo, SonarReading};
use std::collections::VecDeque;
use std::f64::consts::TAU;
use std::time::{Duration, Instant};

/// The robot's radius (m): the sonars sit on a ring of this radius and ranges start there.
pub const RADIUS: f64 = 0.36;
/// Half the width of a sonar's cone (rad).
pub const CONE_HALF: f64 = 15.0 * std::f64::consts::PI / 180.0;
/// The sonars that must have fresh readings for the way ahead to count as seen: those within
/// this many places of the one along the direction of travel (two: ±30°).
const COVER: usize = 2;
/// Most echo points kept (a ring read every 300 ms for the longest `fresh_ms`: far more).
const MAX_POINTS: usize = 4096;

/// The layer's settings (the device's `safety_*` parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Whether the layer acts (off: tests of the skills' own behaviour; the blind stop stays).
    pub on: bool,
    /// Gap kept between the body and an echo along the direction of travel (m). With
    /// `margin_m` it must exceed the sonar's shortest range, or the robot could come closer
    /// than it can see.
    pub stop_m: f64,
    /// The sonar's shortest range (m): a reading this short (within 1 cm) means "this close
    /// or closer", and is placed at the ring itself.
    pub min_range_m: f64,
    /// Braking assumed (m/s², below the robot's 0.5).
    pub decel: f64,
    /// Reaction time assumed (s): sonar age, the cycle, the link.
    pub react_s: f64,
    /// Age past which a reading is forgotten (ms).
    pub fresh_ms: f64,
    /// Lateral margin added to the body's radius for the swept corridor (m).
    pub margin_m: f64,
    /// Free range along the direction of travel that counts as an opening (m).
    pub opening_m: f64,
    /// Speed allowed while the way ahead is not seen or the link is bad (m/s).
    pub blind_speed: f64,
    /// Share of frames dropped over the last second past which the link counts as bad.
    pub bad_share: f64,
}

impl Default for Limits {
    fn default() -> Limits {
        Limits {
            on: true,
            stop_m: 0.14,
            min_range_m: 0.15,
            decel: 0.4,
            react_s: 0.25,
            fresh_ms: 1200.0,
            margin_m: 0.04,
            opening_m: 1.0,
            blind_speed: 0.12,
            bad_share: 0.5,
        }
    }
}

/// What the layer did to one command (the numbers are the `Safety` message's `action`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Action {
    /// Passed as proposed.
    Passed = 0,
    /// Translation slowed for an echo ahead.
    Slowed = 1,
    /// Translation stopped for an echo ahead.
    Stopped = 2,
    /// Translation capped: the way ahead is not seen, or the link is bad.
    Blind = 3,
}

/// The command after the layer, and why.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Verdict {
    /// Translate velocity allowed (m/s).
    pub translate: f64,
    /// Rotate velocity (rad/s), never limited.
    pub rotate: f64,
    /// The highest translate speed allowed in the direction asked (m/s; ∞: no limit).
    pub limit: f64,
    /// Free distance along the direction of travel (m; ∞: nothing seen).
    pub clear: f64,
    /// What was done.
    pub action: Action,
}

/// The link's health as the device sees it this cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkHealth {
    /// Good frames received so far.
    pub frames: u64,
    /// Frames dropped so far (bad checksum or COUNT).
    pub bad: u64,
}

/// One echo point in the odometry frame.
#[derive(Debug, Clone, Copy)]
struct Point {
    at: Instant,
    x: f64,
    y: f64,
    /// On the sonar's axis (not a cone edge).
    axis: bool,
}

/// Cycles the layer acted in, by kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Interventions {
    /// Slowed for an echo ahead.
    pub slowed: u64,
    /// Stopped for an echo ahead.
    pub stopped: u64,
    /// Capped for a way ahead not seen or a bad link.
    pub blind: u64,
}

/// The layer's memory: fresh echo points, each sonar's last reading, the link's recent counts.
#[derive(Debug, Default)]
pub struct Guard {
    points: VecDeque<Point>,
    /// Per sonar: its newest reading.
    last: [Option<SonarReading>; SONARS],
    /// (when, good frames, dropped frames) about a second ago and now, for the drop share.
    window: VecDeque<(Instant, u64, u64)>,
    /// What it did so far.
    pub counts: Interventions,
}

/// The axis of sonar `i` relative to the heading (rad).
fn sonar_axis(i: usize) -> f64 {
    i as f64 * TAU / SONARS as f64
}

impl Guard {
    /// A reading of sonar `i`, taken when the robot stood at `pose` (odometry frame: x, y,
    /// heading). A reading already seen (read at the same time) changes nothing.
    pub fn observe(&mut self, i: usize, reading: SonarReading, pose: (f64, f64, f64), p: &Limits) {
        let Some(last) = self.last.get_mut(i) else {
            return;
        };
        if last.is_some_and(|l| l.read_at == reading.read_at) {
            return;
        }
        *last = Some(reading);
        let (Echo::Range(r), at) = (reading.echo, reading.read_at) else {
            return;
        };
        let r = if r <= p.min_range_m + 0.01 { 0.0 } else { r };
        let axis = pose.2 + sonar_axis(i);
        let (ox, oy) = (pose.0 + RADIUS * axis.cos(), pose.1 + RADIUS * axis.sin());
        for k in [-1.0, 0.0, 1.0] {
            let a = axis + k * CONE_HALF;
            self.points.push_back(Point {
                at,
                x: ox + r * a.cos(),
                y: oy + r * a.sin(),
                axis: k == 0.0,
            });
        }
        while self.points.len() > MAX_POINTS {
            self.points.pop_front();
        }
    }

    /// The command `(translate, rotate)` allowed at `now` with the robot at `pose`.
    pub fn limit(
        &mut self,
        translate: f64,
        rotate: f64,
        now: Instant,
        pose: (f64, f64, f64),
        link: LinkHealth,
        p: &Limits,
    ) -> Verdict {
        let fresh = Duration::from_secs_f64(p.fresh_ms.max(0.0) / 1000.0);
        let is_fresh = |at: Instant| now.saturating_duration_since(at) <= fresh;
        while self.points.front().is_some_and(|q| !is_fresh(q.at)) {
            self.points.pop_front();
        }
        let bad_link = self.bad_link(now, link, p);
        let passed = Verdict {
            translate,
            rotate,
            limit: f64::INFINITY,
            clear: f64::INFINITY,
            action: Action::Passed,
        };
        if !p.on || translate == 0.0 {
            return passed;
        }
        let ahead = if translate > 0.0 { 0 } else { SONARS / 2 };
        let sonar = |d: isize| self.last[(ahead as isize + d).rem_euclid(SONARS as isize) as usize];
        let seen = (-(COVER as isize)..=COVER as isize)
            .any(|d| sonar(d).is_some_and(|s| is_fresh(s.read_at)));
        let opening = sonar(0).is_some_and(|s| is_fresh(s.read_at) && s.echo.clear_to(p.opening_m));
        let clear = self.clear(translate.signum(), pose, opening, p.margin_m);
        let d = clear - p.stop_m;
        let (a, t) = (p.decel.max(1e-3), p.react_s.max(0.0));
        let mut limit = if d <= 0.0 {
            0.0
        } else {
            ((a * t).powi(2) + 2.0 * a * d).sqrt() - a * t
        };
        let blind = !seen || bad_link;
        if blind {
            limit = limit.min(p.blind_speed);
        }
        let allowed = translate.abs().min(limit);
        let action = if allowed >= translate.abs() {
            Action::Passed
        } else if allowed <= 0.0 {
            self.counts.stopped += 1;
            Action::Stopped
        } else if blind && allowed >= p.blind_speed {
            self.counts.blind += 1;
            Action::Blind
        } else {
            self.counts.slowed += 1;
            Action::Slowed
        };
        Verdict {
            translate: allowed * translate.signum(),
            rotate,
            limit,
            clear,
            action,
        }
    }

    /// How far the body, widened by `margin`, can go straight along `dir` (+1 ahead, −1
    /// back) from `pose` before it touches a fresh echo point (axis points only where the
    /// way ahead is open).
    fn clear(&self, dir: f64, pose: (f64, f64, f64), opening: bool, margin: f64) -> f64 {
        let (c, s) = (pose.2.cos(), pose.2.sin());
        let reach = RADIUS + margin;
        self.points
            .iter()
            .filter(|q| q.axis || !opening)
            .filter_map(|q| {
                let (dx, dy) = (q.x - pose.0, q.y - pose.1);
                let along = dir * (dx * c + dy * s);
                let across = -dx * s + dy * c;
                (along > 0.0 && across.abs() < reach)
                    .then(|| (along - (reach * reach - across * across).sqrt()).max(0.0))
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Whether more than `bad_share` of the frames of about the last second were dropped.
    fn bad_link(&mut self, now: Instant, link: LinkHealth, p: &Limits) -> bool {
        self.window.push_back((now, link.frames, link.bad));
        while self.window.len() > 2
            && self.window.get(1).is_some_and(|(t, _, _)| {
                now.saturating_duration_since(*t) >= Duration::from_secs(1)
            })
        {
            self.window.pop_front();
        }
        let Some(&(_, f0, b0)) = self.window.front() else {
            return false;
        };
        let (good, bad) = (
            link.frames.saturating_sub(f0) as f64,
            link.bad.saturating_sub(b0) as f64,
        );
        good + bad >= 4.0 && bad > p.bad_share * (good + bad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const AT: (f64, f64, f64) = (0.0, 0.0, 0.0);

    /// Sonar read at `t`: an echo from `range` (`None`: no echo).
    fn read(range: Option<f64>, t: Instant) -> SonarReading {
        SonarReading {
            echo: range.map_or(Echo::Silent, Echo::Range),
            read_at: t,
        }
    }

    /// Every sonar read at `t`: `range(i)` (None: no echo).
    fn ring(
        g: &mut Guard,
        t: Instant,
        pose: (f64, f64, f64),
        range: impl Fn(usize) -> Option<f64>,
    ) {
        for i in 0..SONARS {
            g.observe(i, read(range(i), t), pose, &Limits::default());
        }
    }

    fn limit(g: &mut Guard, v: f64, now: Instant) -> Verdict {
        g.limit(v, 0.3, now, AT, LinkHealth::default(), &Limits::default())
    }

    #[test]
    fn a_wall_ahead_slows_then_stops_the_robot_and_never_its_turn() {
        let t = Instant::now();
        let mut g = Guard::default();
        // A wall 2 m ahead of the ring: full speed passes.
        ring(&mut g, t, AT, |i| (i == 0).then_some(2.0));
        let v = limit(&mut g, 0.4, t);
        assert_eq!(v.action, Action::Passed, "{v:?}");
        // 0.4 m: slowed; 0.17 m: stopped; the turn always passes.
        let t = t + Duration::from_millis(300);
        let mut g = Guard::default();
        ring(&mut g, t, AT, |i| (i == 0).then_some(0.4));
        let v = limit(&mut g, 0.4, t);
        assert_eq!(v.action, Action::Slowed, "{v:?}");
        assert!(v.translate > 0.0 && v.translate < 0.4 && v.rotate == 0.3);
        let mut g = Guard::default();
        ring(&mut g, t, AT, |i| (i == 0).then_some(0.17));
        let v = limit(&mut g, 0.4, t);
        assert_eq!(
            (v.action, v.translate, v.rotate),
            (Action::Stopped, 0.0, 0.3)
        );
        // Backing away from it is free.
        let v = limit(&mut g, -0.3, t);
        assert_eq!(v.action, Action::Passed, "{v:?}");
        assert_eq!(g.counts.stopped, 1);
    }

    #[test]
    fn the_robots_own_motion_brings_an_old_echo_closer() {
        let t = Instant::now();
        let mut g = Guard::default();
        ring(&mut g, t, AT, |i| (i == 0).then_some(1.0));
        // 0.9 m further on, the same echo is 0.1 m ahead: stopped.
        let v = g.limit(
            0.3,
            0.0,
            t + Duration::from_millis(200),
            (0.9, 0.0, 0.0),
            LinkHealth::default(),
            &Limits::default(),
        );
        assert_eq!(v.action, Action::Stopped, "{v:?}");
    }

    #[test]
    fn a_far_reading_does_not_erase_a_near_one_while_it_is_fresh() {
        let t = Instant::now();
        let mut g = Guard::default();
        ring(&mut g, t, AT, |i| (i == 0).then_some(0.17));
        // A corrupted frame says the way is free.
        let t2 = t + Duration::from_millis(100);
        ring(&mut g, t2, AT, |_| None);
        assert_eq!(limit(&mut g, 0.3, t2).action, Action::Stopped);
        // Once the near echo is old, the newer readings decide.
        let t3 = t + Duration::from_millis(1300);
        ring(&mut g, t3, AT, |_| None);
        assert_eq!(limit(&mut g, 0.3, t3).action, Action::Passed);
    }

    #[test]
    fn posts_beside_a_doorway_pass_where_the_way_ahead_is_open_but_not_an_obstacle_ahead() {
        let t = Instant::now();
        // Door posts 0.5 m either side of the axis, 0.6 m ahead: the sonars at ±30° and ±45°
        // read them, the one ahead reads through the doorway (3 m).
        let posts = |i: usize| match i {
            0 => Some(3.0),
            2 | 22 => Some(0.45),
            3 | 21 => Some(0.5),
            _ => None,
        };
        let mut g = Guard::default();
        ring(&mut g, t, AT, posts);
        let v = limit(&mut g, 0.3, t);
        assert_ne!(v.action, Action::Stopped, "through the doorway: {v:?}");
        // The same posts with an obstacle in the doorway (a false door): the cones count.
        let mut g = Guard::default();
        ring(&mut g, t, AT, |i| if i == 0 { Some(0.1) } else { posts(i) });
        assert_eq!(limit(&mut g, 0.3, t).action, Action::Stopped);
    }

    #[test]
    fn a_way_ahead_not_seen_or_a_bad_link_caps_the_speed() {
        let t = Instant::now();
        let mut g = Guard::default();
        // Only the rear sonars read: the way ahead is not seen.
        ring(&mut g, t, AT, |_| None);
        let later = t + Duration::from_millis(1500);
        for i in 10..14 {
            g.observe(i, read(None, later), AT, &Limits::default());
        }
        let v = limit(&mut g, 0.4, later);
        assert_eq!(v.action, Action::Blind);
        assert_eq!(v.translate, Limits::default().blind_speed);
        // Seen, but three frames in four dropped over a second.
        let mut g = Guard::default();
        let p = Limits::default();
        for k in 0..=10u64 {
            let now = t + Duration::from_millis(100 * k);
            ring(&mut g, now, AT, |_| None);
            let link = LinkHealth {
                frames: k,
                bad: 3 * k,
            };
            let v = g.limit(0.4, 0.0, now, AT, link, &p);
            if k == 10 {
                assert_eq!(v.action, Action::Blind, "{v:?}");
            }
        }
    }

    #[test]
    fn a_reading_at_the_sonars_shortest_range_stops_the_robot_however_it_moved() {
        let t = Instant::now();
        let mut g = Guard::default();
        // 0.15 m is all the sonar can say of a wall 0.1 m away; a step on, it says 0.15 again.
        ring(&mut g, t, AT, |i| (i == 0).then_some(0.15));
        let t2 = t + Duration::from_millis(300);
        ring(&mut g, t2, (0.05, 0.0, 0.0), |i| (i == 0).then_some(0.15));
        let v = g.limit(
            0.3,
            0.0,
            t2,
            (0.05, 0.0, 0.0),
            LinkHealth::default(),
            &Limits::default(),
        );
        assert_eq!(v.action, Action::Stopped, "{v:?}");
    }

    #[test]
    fn off_it_passes_everything() {
        let t = Instant::now();
        let mut g = Guard::default();
        ring(&mut g, t, AT, |_| Some(0.15));
        let off = Limits {
            on: false,
            ..Limits::default()
        };
        let v = g.limit(0.4, 0.1, t, AT, LinkHealth::default(), &off);
        assert_eq!((v.translate, v.action), (0.4, Action::Passed));
    }
}
