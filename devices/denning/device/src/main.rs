//! `denning`: the Denning robot's device process. It owns the serial port (`--port`, a real
//! tty or the simulator's link; `--baud`), publishes the latest buffered sample at the start
//! of every cycle without waiting for the robot, and forwards the arbitrated `drive` command.

use denning::codec::{Command as Wire, Text};
use denning::driver::{Driver, Echo, Odometer, SONARS};
use denning::safety::{Action, Guard, Limits, LinkHealth};
use denning::transport::{Serial, Transport};
use skill_sdk::prelude::*;
use skillfab_msgs::{
    Arm, Barcodes, Battery, Bumpers, Drive, Link, Odometry, Push, Safety, Say, Sonar, Voice,
};
use std::time::{Duration, Instant};

/// How long a lock-step cycle waits for the robot to connect or to acknowledge its step.
const STEP_WAIT: Duration = Duration::from_secs(5);

// The fabric's sonar message has one reading per sonar of the protocol's ring.
const _: () = assert!(skillfab_msgs::SONARS == SONARS);

/// Sensor outputs.
#[derive(Outputs)]
pub struct Sensors<'a> {
    /// The sonar ring.
    pub sonar: Output<'a, Sonar>,
    /// Odometry.
    pub odometry: Output<'a, Odometry>,
    /// Bumpers and stall.
    pub bumpers: Output<'a, Bumpers>,
    /// Barcode sightings.
    pub barcodes: Output<'a, Barcodes>,
    /// Battery.
    pub battery: Output<'a, Battery>,
    /// The serial link.
    pub link: Output<'a, Link>,
    /// The button pusher.
    pub arm: Output<'a, Arm>,
    /// The speaker and display.
    pub voice: Output<'a, Voice>,
    /// What the safety layer did to the last drive command.
    pub safety: Output<'a, Safety>,
}

/// Channels served.
#[derive(Channels)]
pub struct Channels<'a> {
    /// Translate and rotate velocity; safe command: stop.
    pub drive: Command<'a, Drive>,
    /// The button pusher: a stroke each time `press` turns true; safe command: retracted.
    pub push: Command<'a, Push>,
    /// Messages to say: each new non-zero `seq` is said once; safe command: silent.
    pub say: Command<'a, Say>,
}

/// Parameters of the device.
#[derive(Params, Debug, Clone)]
pub struct DenningParams {
    /// The robot is driven only while it is seen: when no good status frame came for this
    /// long, the device commands stop whatever was proposed (the sonar ring is as old as
    /// that, and obstacles come closer unseen). In the robot's time (a simulator faster
    /// than real time needs it divided by its time factor).
    #[param(default = 500.0, min = 1.0, max = 10000.0)]
    pub blind_ms: f64,
    /// The safety layer (`denning::safety`): translation limited by the nearest fresh sonar
    /// echo along the direction of travel and by the link's health. Off only for tests of
    /// the skills' own behaviour.
    #[param(default = true)]
    pub safety: bool,
    /// Gap kept between the body and an echo along the direction of travel (m; with the
    /// margin, more than the sonar's shortest range).
    #[param(default = 0.14, min = 0.0, max = 2.0)]
    pub safety_stop_m: f64,
    /// Braking assumed (m/s²).
    #[param(default = 0.4, min = 0.05, max = 5.0)]
    pub safety_decel: f64,
    /// Reaction time assumed: sonar age, the cycle, the link (s).
    #[param(default = 0.25, min = 0.0, max = 5.0)]
    pub safety_react_s: f64,
    /// Age past which a sonar reading is forgotten (ms, in the robot's time).
    #[param(default = 1200.0, min = 100.0, max = 10000.0)]
    pub safety_fresh_ms: f64,
    /// Lateral margin added to the body's radius (m).
    #[param(default = 0.04, min = 0.0, max = 1.0)]
    pub safety_margin_m: f64,
    /// Free range along the direction of travel that makes a passage: the other echoes then
    /// count by their sonar's axis, not their whole cone (m).
    #[param(default = 1.0, min = 0.2, max = 10.0)]
    pub safety_opening_m: f64,
    /// Speed allowed while the way ahead is not seen or the link is bad (m/s).
    #[param(default = 0.12, min = 0.0, max = 2.0)]
    pub safety_blind_speed: f64,
    /// Share of frames dropped over a second past which the link is bad.
    #[param(default = 0.5, min = 0.0, max = 1.0)]
    pub safety_bad_share: f64,
}

impl DenningParams {
    /// The safety layer's settings.
    fn limits(&self) -> Limits {
        Limits {
            on: self.safety,
            stop_m: self.safety_stop_m,
            min_range_m: denning::safety::Limits::default().min_range_m,
            decel: self.safety_decel,
            react_s: self.safety_react_s,
            fresh_ms: self.safety_fresh_ms,
            margin_m: self.safety_margin_m,
            opening_m: self.safety_opening_m,
            blind_speed: self.safety_blind_speed,
            bad_share: self.safety_bad_share,
        }
    }
}

/// The device.
#[derive(Default)]
pub struct Denning {
    driver: Option<Driver>,
    /// When the newest good status frame arrived (read at each cycle's sample).
    seen: Option<Instant>,
    /// Whether the last command was replaced by stop (said once per blind spell).
    blind: bool,
    /// Whether the pusher was commanded out last cycle (a stroke is made on the rising edge).
    pressing: bool,
    /// The `seq` of the last message sent to be said (0: none).
    said_seq: u32,
    /// Strokes of the last pusher report counted, and the strokes that pressed a button.
    strokes_seen: u16,
    hits: u32,
    /// The safety layer's memory (fresh echoes, the link's recent counts).
    guard: Guard,
    /// The pose and link counts of the newest sample (what the safety layer judges with).
    pose: (f64, f64, f64),
    link: LinkHealth,
    /// The safety layer's last verdict, published with the next sample.
    verdict: Option<denning::safety::Verdict>,
}

impl Device for Denning {
    type Params = DenningParams;
    type Outputs<'a> = Sensors<'a>;
    type Commands<'a> = Channels<'a>;

    fn init(&mut self, options: &DeviceOptions) -> SkillResult {
        let port = options.port.clone().ok_or_else(|| {
            SkillError::msg("--port PATH is required (a tty or the simulator's link)")
        })?;
        let baud = options.baud.unwrap_or(38_400);
        tracing::info!(%port, baud, "opening the robot's port");
        // The odometry frame outlives this process: a restarted or hot-swapped device
        // continues it, so positions skills hold in it stay valid.
        let store = options.state_dir.as_ref().and_then(|dir| {
            std::fs::create_dir_all(dir)
                .map_err(|e| tracing::warn!(dir = %dir.display(), error = %e, "no odometry store"))
                .ok()
                .map(|()| dir.join("odometry"))
        });
        self.driver = Some(Driver::start_with(
            Box::new(move || Serial::open(&port, baud).map(|s| Box::new(s) as Box<dyn Transport>)),
            Odometer::new(store),
        ));
        Ok(())
    }

    fn sample(&mut self, ctx: &Ctx<DenningParams>, out: &mut Sensors) -> SkillResult {
        let Some(d) = &self.driver else {
            return Ok(());
        };
        // Lock-step: what the first cycles see must not depend on how fast the handshake was
        // or how long ago it was.
        if ctx.clock.lockstep {
            d.enter_lockstep();
            if !d.wait_connected(STEP_WAIT) {
                tracing::warn!(cycle = ctx.cycle, "lock-step: the robot is not connected");
            }
        }
        let s = d.latest();
        self.seen = s.received;
        // The driver's clock: the host's, or the robot's in lock-step.
        let now = d.now();
        let ms = |t: Instant| now.duration_since(t).as_secs_f64() * 1000.0;
        self.pose = s.pose;
        self.link = LinkHealth {
            frames: s.stats.frames,
            bad: s.stats.bad_checksum + s.stats.bad_count,
        };
        let sonar = out.sonar.get_mut();
        for (i, reading) in s.sonar.iter().enumerate() {
            let Some(reading) = *reading else {
                sonar.set_unread(i);
                continue;
            };
            self.guard.observe(i, reading, s.pose, &ctx.params.limits());
            let echo = match reading.echo {
                Echo::Range(r) => skillfab_msgs::Echo::Range(r),
                Echo::Silent => skillfab_msgs::Echo::Silent,
            };
            sonar.set_reading(i, echo, ms(reading.read_at));
        }
        out.odometry.set(Odometry {
            x: s.pose.0,
            y: s.pose.1,
            theta: s.pose.2,
            v: s.vel.0,
            w: s.vel.1,
        });
        out.bumpers.set(Bumpers {
            hit: u32::from(s.flags >> 1) & 0xff,
            stall: s.flags & 1 != 0,
        });
        let mut b = Barcodes {
            age_ms: s.barcodes.1.map_or(f64::INFINITY, ms),
            ..Barcodes::default()
        };
        for (i, sight) in s.barcodes.0.iter().take(8).enumerate() {
            b.id[i] = u32::from(sight.id);
            b.bearing[i] = (f64::from(sight.bearing) / 10.0).to_radians();
            b.range[i] = f64::from(sight.range) / 1000.0;
            b.count += 1;
        }
        out.barcodes.set(b);
        out.battery.set(Battery { volts: s.battery });
        let mut arm = Arm {
            age_ms: f64::INFINITY,
            ..Arm::default()
        };
        if let Some((strokes, pressed, at)) = s.arm {
            if strokes != self.strokes_seen {
                self.strokes_seen = strokes;
                self.hits += u32::from(pressed != 0);
            }
            arm = Arm {
                strokes: u32::from(strokes),
                pressed: u32::from(pressed),
                hits: self.hits,
                age_ms: ms(at),
            };
        }
        out.arm.set(arm);
        out.voice.set(Voice {
            said: u32::from(s.said),
            seq: self.said_seq,
        });
        let counts = self.guard.counts;
        let v = self.verdict.take();
        out.safety.set(Safety {
            limit: v.map_or(f64::INFINITY, |v| v.limit),
            clear_m: v.map_or(f64::INFINITY, |v| v.clear),
            action: v.map_or(0, |v| v.action as u32),
            slowed: counts.slowed,
            stopped: counts.stopped,
            blind: counts.blind,
        });
        out.link.set(Link {
            connected: s.connected,
            age_ms: s.received.map_or(f64::INFINITY, ms),
            frames: s.stats.frames,
            bad_frames: s.stats.bad_checksum + s.stats.bad_count,
            garbage: s.stats.garbage,
            connects: s.connects,
        });
        Ok(())
    }

    fn command(&mut self, ctx: &Ctx<DenningParams>, c: Channels) -> SkillResult {
        let Some(d) = &self.driver else {
            return Ok(());
        };
        let limit = Duration::from_secs_f64(ctx.params.blind_ms / 1000.0);
        let seen = self
            .seen
            .is_some_and(|t| d.now().saturating_duration_since(t) < limit);
        let (v, w) = if seen {
            let verdict = self.guard.limit(
                c.drive.translate,
                c.drive.rotate,
                d.now(),
                self.pose,
                self.link,
                &ctx.params.limits(),
            );
            if verdict.action != Action::Passed
                && self.verdict.is_none_or(|v| v.action != verdict.action)
            {
                tracing::debug!(?verdict, "safety layer acted");
            }
            self.verdict = Some(verdict);
            (verdict.translate, verdict.rotate)
        } else {
            (0.0, 0.0)
        };
        // One-off commands go out before the cycle's drive command (and, in lock-step, its
        // step): the robot acts on them in this cycle.
        // (A stroke that cannot go out is tried again next cycle.)
        if !c.push.press {
            self.pressing = false;
        } else if !self.pressing {
            self.pressing = d.send(Wire::Push);
        }
        // (A message not sent — the robot is not connected — is tried again next cycle.)
        if c.say.seq != 0
            && c.say.seq != self.said_seq
            && d.send(Wire::Say(Text::from_bytes(c.say.text())))
        {
            self.said_seq = c.say.seq;
            tracing::info!(seq = c.say.seq, "message sent to be said");
        }
        if ctx.clock.lockstep {
            // The robot advances one period with this command; the next cycle's sample is
            // what it saw meanwhile.
            let period = ctx.clock.period.unwrap_or(Duration::from_millis(10));
            let ms = u16::try_from(period.as_millis()).unwrap_or(u16::MAX);
            if let Err(e) = d.step(v, w, ms, STEP_WAIT) {
                tracing::warn!(cycle = ctx.cycle, error = %e, "lock-step: step failed");
            }
        } else {
            d.command(v, w);
        }
        if seen == self.blind {
            self.blind = !seen;
            if self.blind {
                tracing::warn!(
                    blind_ms = ctx.params.blind_ms,
                    "no good frame from the robot: stopped"
                );
            } else {
                tracing::info!("the robot is seen again: driving");
            }
        }
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    skill_sdk::device_main::<Denning>()
}
