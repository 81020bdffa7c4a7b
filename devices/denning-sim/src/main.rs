//! `denning-sim`: the robot at the other end of a pseudo-terminal.
//!
//! It opens a pty (keeping its own slave fd open so the device can come and go), sets raw
//! mode, optionally links the slave to a stable path (`--link`), and speaks the robot side of
//! `devices/denning/PROTOCOL.md`: handshake, status packets every period, barcode packets,
//! commands, the 2 s watchdog; the button pusher (PUSH) and the speaker (SAY), which matter in
//! a building (`--building`: floors and elevators) rather than a one-room world (`--world`).
//! Bytes are paced at the baud rate; `--time-factor` runs faster than real time;
//! `--corrupt-rate`/`--drop-rate` inject faults into the robot's output.

use anyhow::{Context, bail};
use clap::Parser;
use denning::codec::{Command, Decoder, Packet};
use denning_sim::building::Building;
use denning_sim::sim::{Physical, Rng, Sim};
use denning_sim::truth::TruthRecord;
use denning_sim::world::World;
use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::pty::openpty;
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
use std::io::Write;
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

#[derive(Parser, Debug)]
#[command(
    name = "denning-sim",
    about = "A Denning-style robot simulated on a pseudo-terminal"
)]
struct Args {
    /// World file (see devices/denning-sim/worlds/).
    #[arg(
        long,
        required_unless_present = "building",
        conflicts_with = "building"
    )]
    world: Option<PathBuf>,
    /// Building file: floors and elevators (see devices/denning-sim/buildings/README.md).
    #[arg(long)]
    building: Option<PathBuf>,
    /// Seed of every random choice (noise, drift, faults; in a building the start and the
    /// elevators).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulated seconds per real second.
    #[arg(long, default_value_t = 1.0)]
    time_factor: f64,
    /// Make a symlink to the pty slave here, for a stable port path.
    #[arg(long)]
    link: Option<PathBuf>,
    /// Baud rate the output is paced at.
    #[arg(long, default_value_t = 38_400)]
    baud: u32,
    /// Probability that an output byte is corrupted.
    #[arg(long, default_value_t = 0.0)]
    corrupt_rate: f64,
    /// Probability that an output byte is dropped.
    #[arg(long, default_value_t = 0.0)]
    drop_rate: f64,
    /// Fault injection, in a building: no car answers a hall call before this simulated
    /// time (s), and none moves with its doors closed; the button is pressed, none comes.
    #[arg(long, default_value_t = 0.0)]
    cars_out_until: f64,
    /// With --cars-out-until: from this simulated time (s) on.
    #[arg(long, default_value_t = 0.0)]
    cars_out_from: f64,
    /// Write the ground-truth trajectory (CSV: t,x,y,theta,v,w,stall,collisions,outside,cmd_age — seconds since the last drive command, driven — a non-zero command in force, floor, said — messages spoken, delivered — spoken at the building's goal, at_lab — in front of the lab's door on its floor).
    #[arg(long)]
    trajectory: Option<PathBuf>,
    /// Keep the robot's physical state (pose, odometry, velocities, time) in this file, and
    /// resume from it if it exists: a restarted simulator is the same robot where it was, with
    /// a new serial link (the trajectory is appended to).
    #[arg(long)]
    state: Option<PathBuf>,
    /// Lock-step: the robot stands still until the client sends STEP n (PROTOCOL.md), then
    /// advances n ms of simulated time, sends what the robot sent in them and acknowledges.
    /// Bytes are not paced. A run is then a function of world, seed and commands, at
    /// whatever speed the host allows.
    #[arg(long)]
    lockstep: bool,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: nix::libc::c_int) {
    STOP.store(true, Ordering::Release);
}

/// Simulation step (s of simulated time).
const DT: f64 = 0.01;
/// Watchdog (s of simulated time).
const WATCHDOG: f64 = 2.0;

#[derive(PartialEq)]
enum Link {
    /// Waiting for SYNC n.
    Sync(u8),
    /// Handshake done; streaming when open.
    Ready { open: bool },
}

fn main() -> ExitCode {
    let args = Args::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    use std::io::IsTerminal;
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .try_init();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("denning-sim: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> anyhow::Result<()> {
    if !(args.time_factor > 0.0 && args.time_factor.is_finite()) {
        bail!("--time-factor must be positive, got {}", args.time_factor);
    }
    for (name, p) in [
        ("--corrupt-rate", args.corrupt_rate),
        ("--drop-rate", args.drop_rate),
    ] {
        if !(0.0..=1.0).contains(&p) {
            bail!("{name} must be within 0..=1, got {p}");
        }
    }
    let mut sim = match (&args.world, &args.building) {
        (Some(w), None) => Sim::new(World::load(w)?, args.seed),
        (None, Some(b)) => Sim::in_building(Building::load(b)?, args.seed),
        _ => bail!("give exactly one of --world and --building"),
    };
    for sig in [
        nix::sys::signal::Signal::SIGINT,
        nix::sys::signal::Signal::SIGTERM,
    ] {
        // SAFETY: the handler only stores to an atomic.
        unsafe { nix::sys::signal::signal(sig, nix::sys::signal::SigHandler::Handler(on_signal)) }
            .context("installing signal handlers")?;
    }
    let pty = openpty(None, None).context("opening a pseudo-terminal")?;
    let mut t = tcgetattr(&pty.slave).context("reading terminal attributes")?;
    cfmakeraw(&mut t);
    tcsetattr(&pty.slave, SetArg::TCSANOW, &t).context("setting raw mode")?;
    let slave_path = nix::unistd::ttyname(&pty.slave).context("naming the pty slave")?;
    let master: OwnedFd = pty.master;
    let flags = OFlag::from_bits_truncate(fcntl(&master, FcntlArg::F_GETFL)?);
    fcntl(&master, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK))?;
    if let Some(link) = &args.link {
        let _ = std::fs::remove_file(link);
        std::os::unix::fs::symlink(&slave_path, link)
            .with_context(|| format!("linking {} to {}", link.display(), slave_path.display()))?;
    }
    // Keep our own slave fd open: the device may close and reopen the port at will.
    let _slave = pty.slave;
    tracing::info!(world = %sim.world.name, pty = %slave_path.display(), link = ?args.link, "robot ready");
    println!("{}", slave_path.display());
    let _ = std::io::stdout().flush();

    sim.cars_out = args.cars_out_from..args.cars_out_until;
    let resumed = args.state.as_deref().and_then(load_state);
    if let Some(p) = resumed {
        tracing::info!(time = p.time, x = p.pose[0], y = p.pose[1], "robot resumed");
        sim.resume(p);
    }
    let mut trajectory = match &args.trajectory {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::OpenOptions::new()
                .create(true)
                .write(true)
                .append(resumed.is_some())
                .truncate(resumed.is_none())
                .open(p)
                .with_context(|| format!("creating {}", p.display()))?,
        )),
        None => None,
    };
    if let Some(t) = trajectory.as_mut()
        && resumed.is_none()
    {
        writeln!(t, "{}", TruthRecord::HEADER)?;
    }
    let faults = Rng::new(args.seed.wrapping_mul(31).wrapping_add(7));
    // Resumed: time goes on from where the robot was.
    let t0 = sim.time;
    let mut robot = Robot {
        sim,
        link: Link::Sync(0),
        period: 0.1,
        next_status: t0,
        last_command: t0,
        last_drive: t0,
        watchdog: WATCHDOG,
        outbox: Vec::new(),
        trajectory,
        state: args.state.clone(),
        faults,
    };
    let mut decoder = Decoder::default();
    if args.lockstep {
        tracing::info!("lock-step: the robot moves only when told to STEP");
    }
    let started = Instant::now();
    let byte_time = 10.0 / (f64::from(args.baud) * args.time_factor);
    let mut send_budget = 0.0f64; // seconds of line time already used
    while !STOP.load(Ordering::Acquire) {
        // Commands in: in lock-step, wait for them (the robot has nothing else to do).
        if args.lockstep {
            let mut fds = [nix::poll::PollFd::new(
                master.as_fd(),
                nix::poll::PollFlags::POLLIN,
            )];
            match nix::poll::poll(&mut fds, nix::poll::PollTimeout::from(100u16)) {
                Ok(_) | Err(nix::Error::EINTR) => {}
                Err(e) => return Err(e).context("waiting for the pty"),
            }
        }
        let mut buf = [0u8; 256];
        loop {
            match nix::unistd::read(master.as_fd(), &mut buf) {
                Ok(0) | Err(nix::Error::EAGAIN) | Err(nix::Error::EIO) => break,
                Ok(n) => decoder.push(&buf[..n]),
                Err(e) => return Err(e).context("reading the pty"),
            }
        }
        while let Some(frame) = decoder.next_frame() {
            let Ok(cmd) = frame.and_then(|p| Command::decode(&p)) else {
                continue;
            };
            match cmd {
                Command::Step(ms) if args.lockstep => {
                    robot.last_command = robot.sim.time;
                    robot.step_ms(ms)?;
                }
                // A robot in real time steps on its own.
                Command::Step(_) => {}
                cmd => robot.command(cmd),
            }
        }
        if !args.lockstep {
            robot.advance(DT)?;
        }
        // Bytes out, with fault injection, paced at the baud rate (not in lock-step: there
        // the robot's time is not the host's).
        if !robot.outbox.is_empty() {
            let bytes = robot.faulty_output(args.corrupt_rate, args.drop_rate);
            write_all(&master, &bytes)?;
            send_budget += bytes.len() as f64 * byte_time;
        }
        if args.lockstep {
            continue;
        }
        // Real time: one step of simulated time, or the line time of the bytes sent.
        let target = ((robot.sim.time - t0) / args.time_factor).max(send_budget);
        let elapsed = started.elapsed().as_secs_f64();
        if target > elapsed {
            std::thread::sleep(Duration::from_secs_f64(target - elapsed));
        }
        send_budget = send_budget.max(started.elapsed().as_secs_f64());
    }
    let sim = robot.sim;
    if let Some(link) = &args.link {
        let _ = std::fs::remove_file(link);
    }
    tracing::info!(time = sim.time, collisions = sim.collisions, "robot off");
    Ok(())
}

/// The robot's state from `path`; `None` if there is none (a fresh robot) or it is unreadable
/// (said).
fn load_state(path: &std::path::Path) -> Option<Physical> {
    let text = std::fs::read_to_string(path).ok()?;
    match toml::from_str(&text) {
        Ok(p) => Some(p),
        Err(e) => {
            tracing::warn!(file = %path.display(), error = %e, "robot state ignored");
            None
        }
    }
}

/// Writes the robot's state: to a temporary file, renamed over the old one, so a simulator
/// killed while writing leaves the previous state.
fn save_state(path: &std::path::Path, p: &Physical) -> anyhow::Result<()> {
    let tmp = path.with_extension("new");
    std::fs::write(&tmp, toml::to_string(p)?)
        .with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))
}

/// The robot's side of the link: the simulated body, the protocol state, what goes out.
struct Robot {
    sim: Sim,
    link: Link,
    /// Status period (s).
    period: f64,
    next_status: f64,
    last_command: f64,
    last_drive: f64,
    /// Watchdog (s).
    watchdog: f64,
    outbox: Vec<u8>,
    trajectory: Option<std::io::BufWriter<std::fs::File>>,
    state: Option<PathBuf>,
    /// Random source of the injected faults.
    faults: Rng,
}

impl Robot {
    /// Applies one command (any but STEP).
    fn command(&mut self, cmd: Command) {
        let sim = &mut self.sim;
        self.last_command = sim.time;
        let streaming = self.link == Link::Ready { open: true };
        match cmd {
            // SYNC0 while streaming is the keep-alive (PULSE); otherwise it (re)starts
            // the handshake.
            Command::Sync0 if streaming => {}
            Command::Sync0 => {
                self.link = Link::Sync(1);
                sim.enabled = false;
                sim.cmd = [0.0; 2];
                self.outbox.extend(Packet::Sync(0).encode());
            }
            Command::Sync1 => match self.link {
                Link::Sync(1) => {
                    self.link = Link::Sync(2);
                    self.outbox.extend(Packet::Sync(1).encode());
                }
                Link::Ready { .. } => {
                    self.link = Link::Ready { open: true };
                    tracing::info!("client connected");
                }
                _ => {}
            },
            Command::Sync2 => match self.link {
                Link::Sync(2) => {
                    self.link = Link::Ready { open: false };
                    self.outbox.extend(Packet::Sync(2).encode());
                }
                // CLOSE: stop, and wait for a new handshake.
                Link::Ready { .. } => {
                    self.link = Link::Sync(0);
                    sim.enabled = false;
                    sim.cmd = [0.0; 2];
                }
                _ => {}
            },
            _ if !matches!(self.link, Link::Ready { .. }) => {}
            Command::Enable(on) => sim.enabled = on,
            Command::Vel(v) => {
                self.last_drive = sim.time;
                sim.cmd[0] = f64::from(v).clamp(-1000.0, 1000.0) / 1000.0;
            }
            Command::RVel(w) => {
                self.last_drive = sim.time;
                sim.cmd[1] = (f64::from(w).clamp(-1800.0, 1800.0) / 10.0).to_radians();
            }
            Command::Period(ms) => self.period = f64::from(ms.clamp(20, 1000)) / 1000.0,
            Command::Watchdog(ms) => self.watchdog = f64::from(ms.clamp(100, 5000)) / 1000.0,
            Command::Push => {
                let pressed = sim.push();
                self.outbox.extend(
                    Packet::Arm {
                        strokes: sim.strokes,
                        pressed,
                    }
                    .encode(),
                );
            }
            Command::Say(text) => {
                let said = sim.say(&text.to_string_lossy());
                self.outbox.extend(Packet::Said(said).encode());
            }
            Command::Step(_) => {}
        }
    }

    /// Lock-step: advances `ms` milliseconds (in steps of at most [`DT`]), then acknowledges
    /// with the robot's time.
    fn step_ms(&mut self, ms: u16) -> anyhow::Result<()> {
        let mut left = f64::from(ms) / 1000.0;
        while left > 1e-9 {
            let dt = left.min(DT);
            self.advance(dt)?;
            left -= dt;
        }
        let now_ms = (self.sim.time * 1000.0)
            .round()
            .clamp(0.0, f64::from(u32::MAX)) as u32;
        self.outbox.extend(Packet::Stepped(now_ms).encode());
        Ok(())
    }

    /// One step of `dt` seconds: the watchdog, the body, and the status and barcode packets,
    /// ground truth and kept state when a status is due.
    fn advance(&mut self, dt: f64) -> anyhow::Result<()> {
        let sim = &mut self.sim;
        if sim.time - self.last_command > self.watchdog && sim.cmd != [0.0, 0.0] {
            tracing::info!(watchdog_s = self.watchdog, "watchdog: no command, stopping");
            sim.cmd = [0.0; 2];
        }
        sim.step(dt);
        // (A little slack: lock-step sub-steps add up to the period only up to rounding.)
        if sim.time + 1e-9 < self.next_status {
            return Ok(());
        }
        self.next_status += self.period;
        if self.link == (Link::Ready { open: true }) {
            let status = sim.status();
            self.outbox.extend(Packet::Status(status).encode());
            let seen = sim.camera();
            if !seen.is_empty() {
                self.outbox.extend(Packet::Barcodes(seen).encode());
            }
        }
        if let Some(t) = self.trajectory.as_mut() {
            let [x, y, theta] = sim.pose;
            TruthRecord {
                t: sim.time,
                x,
                y,
                theta,
                v: sim.vel[0],
                w: sim.vel[1],
                stall: sim.stall,
                collisions: sim.collisions,
                outside: sim.outside(),
                cmd_age: sim.time - self.last_drive,
                driven: sim.cmd != [0.0, 0.0],
                floor: sim.floor(),
                said: u32::from(sim.said),
                delivered: sim.delivered.is_some(),
                at_lab: sim.at_lab(),
            }
            .write(t)?;
            t.flush()?;
        }
        if let Some(path) = &self.state {
            save_state(path, &sim.physical())?;
        }
        Ok(())
    }

    /// The outbox's bytes, each dropped or corrupted with the given probabilities.
    fn faulty_output(&mut self, corrupt_rate: f64, drop_rate: f64) -> Vec<u8> {
        let mut bytes: Vec<u8> = Vec::with_capacity(self.outbox.len());
        for b in self.outbox.drain(..) {
            if drop_rate > 0.0 && self.faults.uniform() < drop_rate {
                continue;
            }
            let b = if corrupt_rate > 0.0 && self.faults.uniform() < corrupt_rate {
                b ^ (1 << (self.faults.uniform() * 8.0) as u32)
            } else {
                b
            };
            bytes.push(b);
        }
        bytes
    }
}

fn write_all(fd: &OwnedFd, mut bytes: &[u8]) -> anyhow::Result<()> {
    while !bytes.is_empty() {
        match nix::unistd::write(fd, bytes) {
            Ok(n) => bytes = &bytes[n..],
            // Nobody reads the pty (no device): its buffer is full. A serial line loses the
            // bytes then; the robot must not stall.
            Err(nix::Error::EAGAIN) => return Ok(()),
            Err(e) => return Err(e).context(format!("writing the pty (fd {})", fd.as_raw_fd())),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use denning::codec::Text;

    fn robot(sim: Sim) -> Robot {
        Robot {
            sim,
            link: Link::Sync(0),
            period: 0.1,
            next_status: 0.0,
            last_command: 0.0,
            last_drive: 0.0,
            watchdog: WATCHDOG,
            outbox: Vec::new(),
            trajectory: None,
            state: None,
            faults: Rng::new(1),
        }
    }

    fn packets(r: &mut Robot) -> Vec<Packet> {
        let mut d = Decoder::default();
        d.push(&std::mem::take(&mut r.outbox));
        std::iter::from_fn(|| d.next_frame())
            .filter_map(|f| f.and_then(|p| Packet::decode(&p)).ok())
            .collect()
    }

    #[test]
    fn push_and_say_are_answered_at_once_after_the_handshake_only() {
        let world = World::parse("name = 'x'\nstart = [0.0, 0.0, 0.0]\n", "t").unwrap();
        let mut r = robot(Sim::new(world, 1));
        r.command(Command::Push);
        r.command(Command::Say(Text::new("hello")));
        assert!(packets(&mut r).is_empty(), "no link yet");
        for c in [
            Command::Sync0,
            Command::Sync1,
            Command::Sync2,
            Command::Sync1,
        ] {
            r.command(c);
        }
        packets(&mut r);
        r.command(Command::Push);
        r.command(Command::Say(Text::new("hello")));
        r.command(Command::Push);
        assert_eq!(
            packets(&mut r),
            vec![
                Packet::Arm {
                    strokes: 1,
                    pressed: 0
                },
                Packet::Said(1),
                Packet::Arm {
                    strokes: 2,
                    pressed: 0
                },
            ]
        );
    }
}
