//! `push_button`: pressing a button with the pusher.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`PushButton`].
#[derive(Params, Debug, Clone)]
pub struct PushButtonParams {
    /// Approach speed (m/s).
    #[param(default = 0.15, min = 0.0, max = 0.5)]
    pub speed: f64,
    /// Steering gain (rad/s per rad).
    #[param(default = 1.5, min = 0.0, max = 10.0)]
    pub gain: f64,
    /// Stop approaching at this range from the button (m, from the robot's centre): within
    /// the pusher's 0.75 m with room for the stop and the estimate's error.
    #[param(default = 0.62, min = 0.4, max = 0.75)]
    pub reach: f64,
    /// Stroke when the button's bearing is within this (rad): the pusher presses a button
    /// within ±12° (0.21 rad) of the heading.
    #[param(default = 0.04, min = 0.005, max = 0.2)]
    pub align: f64,
    /// Strokes tried before giving up.
    #[param(default = 3, min = 1, max = 20)]
    pub tries: u32,
    /// After a miss, back off this far before trying again (m).
    #[param(default = 0.3, min = 0.0, max = 2.0)]
    pub back: f64,
    /// A stroke with no report from the pusher after this long counts as a miss (ms of
    /// fabric time).
    #[param(default = 3000.0, min = 100.0, max = 60000.0)]
    pub stroke_ms: f64,
    /// After the press, back straight away this far before it is done (m; 0: done at once).
    /// A robot that called a car waits where it sees all the cars' lanterns.
    #[param(default = 0.0, min = 0.0, max = 6.0)]
    pub retreat: f64,
    /// After the press, before the retreat, look along the button's wall each way: turn this
    /// far off its normal to the left, then to the right, then back (rad; 0: no look). From
    /// the button the lanterns of the cars beside it are 55° and 77° off (the camera sees
    /// ±30°), and a car already at the floor opens at once and closes 9.5 s later: from the
    /// retreat's end, 4.6 m out, it would be seen only after it closed.
    #[param(default = 0.0, min = 0.0, max = 1.6)]
    pub look: f64,
    /// Turn rate looking for a button not seen yet (rad/s; 0: wait for it). A button beside
    /// the camera's field of view (a panel's end button, seen from the middle) comes into view.
    #[param(default = 0.4, min = 0.0, max = 1.5)]
    pub search: f64,
    /// 0: only go to the button and face it (then retreat, if set): a landmark to line up
    /// on, not a button to press.
    #[param(default = 1, min = 0, max = 1)]
    pub press: i64,
}

/// Inputs of [`PushButton`].
#[derive(Inputs)]
pub struct PushButtonIn<'a> {
    /// The button (barcode_track on its barcode).
    pub target: Input<'a, Target>,
    /// Odometry.
    pub odometry: Input<'a, Odometry>,
    /// The pusher's report.
    pub arm: Input<'a, Arm>,
    /// The ring: the button's wall (the approach keeps square enough to it) and what is
    /// behind when backing away.
    pub sonar: Input<'a, Sonar>,
}

/// Outputs of [`PushButton`].
#[derive(Outputs)]
pub struct PushButtonOut<'a> {
    /// The drive proposal.
    pub drive: Proposal<'a, Drive>,
    /// The pusher proposal.
    pub push: Proposal<'a, Push>,
    /// How far the job is.
    pub progress: Output<'a, Progress>,
}

/// Phases of [`PushButton`] (its `progress.phase`).
pub mod push_phase {
    /// Turning toward the button and driving to `reach` of it.
    pub const APPROACH: u32 = 0;
    /// Turning on the spot until the button is straight ahead.
    pub const ALIGN: u32 = 1;
    /// Pusher out, waiting for the stroke's report.
    pub const STROKE: u32 = 2;
    /// The button was pressed.
    pub const DONE: u32 = 3;
    /// A miss: backing off before the next try.
    pub const BACKING: u32 = 4;
    /// `tries` strokes missed: given up.
    pub const FAILED: u32 = 5;
    /// Pressed; backing away `retreat` before it is done.
    pub const RETREAT: u32 = 6;
    /// Pressed; looking along the wall each way (`look`) before the retreat.
    pub const LOOK: u32 = 7;
}
use push_phase::*;

/// Speed backing off after a miss (m/s).
const BACK_SPEED: f64 = 0.15;
/// Speed backing away after the press (m/s): a car called may come meanwhile.
const RETREAT_SPEED: f64 = 0.35;
/// Backing ends where something is this near behind (m, from the ring).
const BEHIND: f64 = 0.25;
/// The final approach comes at most this far off the button wall's normal (rad): from
/// further aside, the robot's flank would meet the wall before the pusher reaches the
/// button (at 0.62 m, 40° leaves 16 cm).
const APPROACH_CONE: f64 = 40.0 * PI / 180.0;
/// Lining up on a landmark (`press` 0), the approach comes at most this far off the normal.
const LANDMARK_CONE: f64 = 4.0 * PI / 180.0;
/// From outside the cone it first drives to the cone's edge this far from the button (m).
const LINE_UP_RANGE: f64 = 1.0;
/// The button stands this far in front of its wall (m; the building's convention).
const INSET: f64 = 0.05;
/// Beyond this bearing (rad) the approach turns on the spot before driving.
const FACING: f64 = 0.2;
/// Turn rate looking along the wall (rad/s, at most; the robot turns up to 3.1 rad/s and
/// accelerates at 1.75 rad/s²): the whole look (4 × `look`) takes some 4 s at 0.95 rad, and a
/// lantern stays in the camera's ±30° for half a second of a sweep, five camera frames.
const LOOK_RATE: f64 = 2.0;
/// A look's heading is reached within this (rad).
const LOOKED: f64 = 0.05;

/// Presses the tracked button: turns toward it, drives to `reach` of it (coming from within
/// 40° of square to the button's wall, once the ring fits that wall: from further aside it
/// first drives to the edge of that cone, 1 m out), turns until it is within `align` of
/// straight ahead, and proposes `push.press` until the pusher reports a new
/// stroke, then releases. The stroke pressed the button when the report names the button's
/// id (then it backs away `retreat`, if set, before it is done); a miss backs off `back` and
/// tries again, up to `tries` strokes. With `look` set, the press is followed by a look along
/// the wall: turning on the spot to `look` left of the wall's normal (the way it faces once
/// the ring fits the wall; else the way it faced pressing), then as far right, then back,
/// before the retreat. Backing ends early where the sonars behind see
/// something within 0.25 m. A target not seen yet is looked for by turning on the
/// spot at `search` (with `search` 0: no drive proposal, another skill may be bringing it
/// near).
///
/// For a sequencer: `push_button.progress.done == 1` (pressed), `push_button.progress.phase
/// == 5` (failed); `progress.value` is the number of strokes made. Everything starts again
/// when reactivated.
#[derive(Default, Serialize, Deserialize)]
pub struct PushButton {
    activation: Activation,
    phase: u32,
    /// Strokes reported since activation, and those that missed.
    strokes: u32,
    misses: u32,
    /// The pusher's stroke count when this stroke began, and the cycle it began.
    stroke_from: Option<(u32, u64)>,
    /// Where backing off began.
    back_from: (f64, f64),
    /// The normal of the button's wall, toward it (odometry frame), once the ring fits it.
    normal: Option<f64>,
    /// Looking along the wall: the heading looked from (the wall's normal), and the looks
    /// done (left, right, back).
    look_from: f64,
    looks_done: usize,
}

impl PushButton {
    /// The button pressed (or, with `press` 0, faced): look along the wall, back away or be
    /// done, as the parameters say.
    fn pressed(&mut self, p: &PushButtonParams, od: &Odometry) {
        self.phase = if p.look > 0.0 {
            LOOK
        } else if p.retreat > 0.0 {
            RETREAT
        } else {
            DONE
        };
        self.look_from = self.normal.unwrap_or(od.theta);
        self.looks_done = 0;
        self.back_from = (od.x, od.y);
    }

    /// Fits the button's wall: of the walls the ring fits, the one whose distance puts the
    /// button `INSET` in front of it (seen from aside, the sonars facing the button meet its
    /// wall too obliquely to fit it). Its normal is kept (blended: each fit is a few
    /// hundredths of a radian off).
    fn fit_wall(&mut self, t: &Target, od: &Odometry, s: &Sonar) {
        let mismatch =
            |w: &Wall| (t.range * wrap(t.bearing - w.normal).cos() + INSET - w.distance).abs();
        let Some(w) = (0..SONARS)
            .filter_map(|k| wall_toward(s, crate::nav::sonar_angle(k)))
            .filter(|w| mismatch(w) < 0.15)
            .min_by(|a, b| mismatch(a).total_cmp(&mismatch(b)))
        else {
            return;
        };
        let n = wrap(od.theta + w.normal);
        self.normal = Some(match self.normal {
            Some(old) => wrap(old + 0.1 * wrap(n - old)),
            None => n,
        });
    }

    /// Where to go before the final approach, if the robot is outside the cone square to the
    /// button's wall: the cone's edge on its side, `LINE_UP_RANGE` from the button.
    fn line_up(&self, t: &Target, od: &Odometry, cone: f64) -> Option<(f64, f64)> {
        let n = self.normal?;
        // The robot's direction from the button, against the wall's outward normal.
        let from = (od.y - t.y).atan2(od.x - t.x);
        let out = wrap(n + PI);
        let off = wrap(from - out);
        (off.abs() > cone && t.range > 0.3).then(|| {
            let a = out + cone.copysign(off) * 0.9;
            (t.x + LINE_UP_RANGE * a.cos(), t.y + LINE_UP_RANGE * a.sin())
        })
    }
}

impl Skill for PushButton {
    type Params = PushButtonParams;
    type Inputs<'a> = PushButtonIn<'a>;
    type Outputs<'a> = PushButtonOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(
        &mut self,
        ctx: &Ctx<PushButtonParams>,
        i: PushButtonIn,
        o: &mut PushButtonOut,
    ) -> SkillResult {
        let (t, od, arm, s, p) = (&*i.target, &*i.odometry, &*i.arm, &*i.sonar, ctx.params);
        if self.activation.begins(ctx) {
            *self = PushButton {
                activation: self.activation,
                ..PushButton::default()
            };
        }
        let period_ms = period_ms(ctx);
        if self.phase == APPROACH && t.visible {
            self.fit_wall(t, od, s);
        }
        let stop = Drive::default();
        let mut press = false;
        let mut drive = Some(stop);
        if self.phase == APPROACH && t.seen && t.range <= p.reach {
            self.phase = ALIGN;
        }
        if self.phase == ALIGN && t.range > p.reach + 0.1 {
            // Pushed away (or a better estimate of the button): approach again.
            self.phase = APPROACH;
        }
        if self.phase == ALIGN && t.bearing.abs() < p.align {
            if p.press == 0 {
                self.pressed(p, od);
            } else {
                self.phase = STROKE;
                self.stroke_from = Some((arm.strokes, ctx.cycle));
            }
        }
        if self.phase == STROKE
            && let Some((from, began)) = self.stroke_from
        {
            let reported = arm.strokes != from;
            let overdue = ctx.cycle.saturating_sub(began) as f64 * period_ms > p.stroke_ms;
            if reported || overdue {
                self.stroke_from = None;
                self.strokes += u32::from(reported);
                if reported && arm.pressed == t.id {
                    self.pressed(p, od);
                } else {
                    self.misses += 1;
                    self.phase = if self.misses >= p.tries {
                        FAILED
                    } else {
                        BACKING
                    };
                    self.back_from = (od.x, od.y);
                }
            } else {
                press = true;
            }
        }
        let look = [
            self.look_from + p.look,
            self.look_from - p.look,
            self.look_from,
        ];
        if self.phase == LOOK {
            while look
                .get(self.looks_done)
                .is_some_and(|&h| wrap(h - od.theta).abs() < LOOKED)
            {
                self.looks_done += 1;
            }
            if self.looks_done >= look.len() {
                self.phase = if p.retreat > 0.0 { RETREAT } else { DONE };
                self.back_from = (od.x, od.y);
            }
        }
        let backed = (od.x - self.back_from.0).hypot(od.y - self.back_from.1);
        // Something near behind ends the backing where it is.
        let blocked = arc(s, 150.0, 210.0).is_none_or(|(near, _)| near <= BEHIND);
        if self.phase == BACKING && (backed >= p.back || blocked) {
            self.phase = APPROACH;
        }
        if self.phase == RETREAT && (backed >= p.retreat || blocked) {
            self.phase = DONE;
        }
        match self.phase {
            APPROACH if !t.seen && p.search == 0.0 => drive = None,
            APPROACH if !t.seen => {
                drive = Some(Drive {
                    translate: 0.0,
                    rotate: p.search,
                });
            }
            APPROACH => {
                // Lining up on a landmark (no press): square to its wall, so that backing away
                // leaves the robot on the line through it.
                let cone = if p.press == 0 {
                    LANDMARK_CONE
                } else {
                    APPROACH_CONE
                };
                drive = Some(match self.line_up(t, od, cone) {
                    // To the cone's edge first.
                    Some((gx, gy)) => {
                        let err = wrap((gy - od.y).atan2(gx - od.x) - od.theta);
                        Drive {
                            translate: if err.abs() < FACING {
                                p.speed * err.cos()
                            } else {
                                0.0
                            },
                            rotate: (p.gain * err).clamp(-0.6, 0.6),
                        }
                    }
                    None => {
                        let b = t.bearing;
                        Drive {
                            translate: if b.abs() < FACING {
                                p.speed.min(0.05 + (t.range - p.reach)) * b.cos()
                            } else {
                                0.0
                            },
                            rotate: (p.gain * b).clamp(-0.6, 0.6),
                        }
                    }
                });
            }
            ALIGN => {
                drive = Some(Drive {
                    translate: 0.0,
                    rotate: turn_toward(t.bearing, p.gain, 0.3, 0.05, 0.0),
                });
            }
            LOOK => {
                let err = look
                    .get(self.looks_done)
                    .map_or(0.0, |&h| wrap(h - od.theta));
                drive = Some(Drive {
                    translate: 0.0,
                    rotate: turn_toward(err, 2.0 * p.gain, LOOK_RATE, 0.05, 0.0),
                });
            }
            BACKING | RETREAT => {
                drive = Some(Drive {
                    translate: if self.phase == RETREAT {
                        -RETREAT_SPEED
                    } else {
                        -BACK_SPEED
                    },
                    rotate: 0.0,
                });
            }
            _ => {}
        }
        if let Some(d) = drive {
            o.drive.set(d);
        }
        o.push.set(Push { press });
        o.progress.set(Progress {
            done: self.phase == DONE,
            phase: self.phase,
            value: f64::from(self.strokes),
        });
        Ok(())
    }
}
