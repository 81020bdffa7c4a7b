//! `denning`: the Denning robot's device process. It owns the serial port (`--port`, a real
//! tty or the simulator's link; `--baud`), publishes the latest buffered sample at the start
//! of every cycle without waiting for the robot, and forwards the arbitrated `drive` command.

use denning::codec::{Command as Wire, Text};
use denning::driver::{Driver, Odometer, SONARS};
use denning::transport::{Serial, Transport};
use skill_sdk::prelude::*;
use skillfab_msgs::{
    Arm, Barcodes, Battery, Bumpers, Drive, Link, Odometry, Push, Say, Sonar, Voice,
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
}

/// Channels served.
#[derive(Inputs)]
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
        let sonar = out.sonar.get_mut();
        for i in 0..SONARS {
            match s.sonar[i] {
                Some((r, at)) => {
                    sonar.range[i] = r.unwrap_or(f64::INFINITY);
                    sonar.age_ms[i] = ms(at);
                }
                None => {
                    sonar.range[i] = f64::NAN;
                    sonar.age_ms[i] = f64::INFINITY;
                }
            }
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
            (c.drive.translate, c.drive.rotate)
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
