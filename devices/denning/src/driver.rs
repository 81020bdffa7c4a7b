//! The driver thread: owns the transport, keeps the latest sample, sends the latest command.
//!
//! It never blocks the fabric: the device process reads the latest sample through a mutex held
//! for microseconds, and a changed command is written to the port at once by the device
//! process itself (a second handle on the port, under the same mutex), so the thread sleeps
//! until bytes come or its 50 ms read timeout. The thread does the handshake, decodes the
//! status stream (resynchronising after garbage), unwraps odometry, re-sends the drive command
//! every 100 ms (which also feeds the robot's 2 s watchdog), stops the drive on its own when
//! the fabric's commands stop (500 ms), and reconnects when the link goes quiet for 1 s or the
//! port vanishes.

use crate::codec::{Command, DecodeStats, Decoder, Packet, Sighting, Status, wrap_delta};
use crate::transport::{Transport, Writer};
use std::io;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub use crate::codec::SONARS;
/// A fabric command older than this is replaced by stop.
pub const COMMAND_TIMEOUT: Duration = Duration::from_millis(500);
/// A link without a valid packet for this long is reconnected.
pub const LINK_TIMEOUT: Duration = Duration::from_secs(1);
/// The robot's watchdog this driver sets at every connect (ms).
pub const ROBOT_WATCHDOG_MS: u16 = 400;
/// How often an unchanged drive command is sent again (the keep-alive); a changed one is
/// sent at once.
pub const RESEND: Duration = Duration::from_millis(100);

/// What the robot reported last.
#[derive(Debug, Clone, Default)]
pub struct Sample {
    /// Whether the handshake is done and packets flow.
    pub connected: bool,
    /// When the last valid packet arrived.
    pub received: Option<Instant>,
    /// Odometry (m, m, rad), unwrapped in one frame for the life of the robot's own dead
    /// reckoning ([`Odometer`]): across reconnects and, with a store, across device processes.
    pub pose: (f64, f64, f64),
    /// Velocities (m/s, rad/s).
    pub vel: (f64, f64),
    /// Each sonar's newest reading (`None`: not read since the driver started).
    pub sonar: [Option<SonarReading>; SONARS],
    /// Stall and bumper flags.
    pub flags: u16,
    /// Battery (V).
    pub battery: f64,
    /// Latest barcode sightings and when.
    pub barcodes: (Vec<Sighting>, Option<Instant>),
    /// Decoder counters (this connection and all before).
    pub stats: DecodeStats,
    /// Successful handshakes.
    pub connects: u64,
    /// The button pusher's last report: strokes so far, the button the last one pressed
    /// (0: none), and when it came.
    pub arm: Option<(u16, u16, Instant)>,
    /// Messages the robot has spoken.
    pub said: u16,
}

/// One sonar's reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SonarReading {
    /// What came back.
    pub echo: Echo,
    /// When it was read, on the driver's clock ([`Driver::now`]).
    pub read_at: Instant,
}

/// What a sonar heard.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Echo {
    /// An echo from this far (m, from the ring).
    Range(f64),
    /// No echo: nothing within the sonar's reach (the protocol's range 0).
    Silent,
}

impl Echo {
    /// Whether the sonar sees free space at least `d` far (m): an echo from `d` or beyond,
    /// or none.
    pub fn clear_to(self, d: f64) -> bool {
        match self {
            Echo::Range(r) => r >= d,
            Echo::Silent => true,
        }
    }
}

struct Shared {
    sample: Sample,
    command: Option<((f64, f64), Instant)>,
    /// The connected port's writing half and what went out on it last.
    link: Option<Link>,
    /// Set once the fabric runs in lock-step ([`Driver::step`]).
    steps: Option<Steps>,
}

/// Lock-step book-keeping. The robot only moves when told to step, so time is the robot's:
/// a packet is stamped with the robot time of the acknowledgement that ends its step, as an
/// `Instant` that many milliseconds after `base` — every age the device computes is then a
/// function of the robot's run, not of how fast the host is.
struct Steps {
    /// The instant standing for robot time zero.
    base: Instant,
    /// Robot time (ms) of the last acknowledged step.
    acked_ms: u64,
    /// When the step in flight was sent.
    pending: Option<Instant>,
    /// Packets of the step in flight, applied when its acknowledgement comes.
    held: Vec<Packet>,
}

impl Steps {
    fn now(&self) -> Instant {
        self.base + Duration::from_millis(self.acked_ms)
    }
}

/// Why a lock-step step failed.
#[derive(Debug, thiserror::Error)]
pub enum StepError {
    /// No connection to the robot within the wait.
    #[error("the robot is not connected")]
    NotConnected,
    /// The step was sent and not acknowledged within the wait.
    #[error("the robot did not acknowledge a step within {0:?} (is the simulator in --lockstep?)")]
    NoAck(Duration),
    /// Writing to the port failed.
    #[error("writing the step: {0}")]
    Io(#[from] io::Error),
}

impl Shared {
    /// The driver's clock: the host's, or the robot's in lock-step.
    fn now(&self) -> Instant {
        self.steps.as_ref().map_or_else(Instant::now, Steps::now)
    }
}

struct Link {
    writer: Box<dyn Writer>,
    /// The last velocities sent (wire units) and when.
    last_wire: Option<(i16, i16)>,
    last_sent: Instant,
}

impl Shared {
    /// Sends the drive command if it changed or the keep-alive is due: the fabric's command,
    /// or stop once it is older than [`COMMAND_TIMEOUT`].
    fn send_command(&mut self, now: Instant) -> io::Result<()> {
        // In lock-step the command goes out with each step.
        if self.steps.is_some() {
            return Ok(());
        }
        let Some(link) = self.link.as_mut() else {
            return Ok(());
        };
        let (v, w) = match self.command {
            Some((vw, at)) if now.duration_since(at) < COMMAND_TIMEOUT => vw,
            _ => (0.0, 0.0),
        };
        let wire = wire(v, w);
        if Some(wire) != link.last_wire || now.duration_since(link.last_sent) >= RESEND {
            link.last_sent = now;
            link.last_wire = Some(wire);
            link.writer.write_all(&Command::Vel(wire.0).encode())?;
            link.writer.write_all(&Command::RVel(wire.1).encode())?;
        }
        Ok(())
    }
}

/// The running driver.
pub struct Driver {
    shared: Arc<Mutex<Shared>>,
    /// Notified when the link comes up and when a step is acknowledged.
    stepped: Arc<Condvar>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

/// The robot's x and y (15-bit millimetres that wrap at 32768) unwrapped into one frame. The
/// frame starts at (0, 0) where the first driver on this robot first heard from it and then
/// follows the robot's own dead reckoning: a reconnect, or a new device process that finds
/// the previous one's store (a hot swap, a restart), unwraps from the last raw value seen, so
/// positions skills hold in the odometry frame (a barcode, a door) stay valid. (A robot that
/// reboots restarts its dead reckoning; that is a new frame this cannot tell from a move of
/// less than 16 m.)
#[derive(Debug)]
pub struct Odometer {
    /// Last raw (x, y) and the unwrapped millimetres at that packet.
    last: Option<((u16, u16), (i64, i64))>,
    /// File the last values are kept in (written as they change, atomically).
    store: Option<std::path::PathBuf>,
}

impl Odometer {
    /// An odometer that continues the frame kept in `store`, if that holds one.
    pub fn new(store: Option<std::path::PathBuf>) -> Odometer {
        let last = store.as_ref().and_then(|p| {
            let text = std::fs::read_to_string(p).ok()?;
            let v: Vec<i64> = text
                .split_whitespace()
                .map(str::parse)
                .collect::<Result<_, _>>()
                .ok()?;
            let raw = |i: usize| u16::try_from(v[i]).ok().filter(|r| *r < 0x8000);
            (v.len() == 4).then_some(((raw(0)?, raw(1)?), (v[2], v[3])))
        });
        if let Some(((x, y), (ux, uy))) = last {
            tracing::info!(
                raw_x = x,
                raw_y = y,
                x_mm = ux,
                y_mm = uy,
                "odometry frame continued"
            );
        }
        Odometer { last, store }
    }

    /// Unwraps a packet's raw (x, y); returns millimetres in the frame.
    pub fn update(&mut self, x: u16, y: u16) -> (i64, i64) {
        let now = match self.last {
            None => (0, 0),
            Some(((px, py), (ux, uy))) => (
                ux + i64::from(wrap_delta(px, x)),
                uy + i64::from(wrap_delta(py, y)),
            ),
        };
        if self.last.map(|l| l.0) != Some((x, y)) {
            self.last = Some(((x, y), now));
            self.save();
        }
        now
    }

    fn save(&self) {
        let (Some(p), Some(((x, y), (ux, uy)))) = (&self.store, self.last) else {
            return;
        };
        let tmp = p.with_extension("tmp");
        let written = std::fs::write(&tmp, format!("{x} {y} {ux} {uy}\n"))
            .and_then(|()| std::fs::rename(&tmp, p));
        if let Err(e) = written {
            tracing::debug!(error = %e, "odometry frame not stored");
        }
    }
}

/// Velocities (m/s, rad/s) in the protocol's units (mm/s, 0.1 °/s), clamped to its limits.
fn wire(v: f64, w: f64) -> (i16, i16) {
    (
        (v * 1000.0).round().clamp(-1000.0, 1000.0) as i16,
        (w.to_degrees() * 10.0).round().clamp(-1800.0, 1800.0) as i16,
    )
}

fn lock(m: &Mutex<Shared>) -> MutexGuard<'_, Shared> {
    // A poisoned lock only means the driver thread panicked mid-update: the data is still
    // the best there is.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Opens a transport (called again on every reconnect).
pub type Opener = Box<dyn Fn() -> io::Result<Box<dyn Transport>> + Send>;

impl Driver {
    /// Starts the driver thread; odometry starts a new frame.
    pub fn start(open: Opener) -> Driver {
        Driver::start_with(open, Odometer::new(None))
    }

    /// Starts the driver thread with `odometer` (which may continue an earlier frame).
    pub fn start_with(open: Opener, mut odometer: Odometer) -> Driver {
        let shared = Arc::new(Mutex::new(Shared {
            sample: Sample::default(),
            command: None,
            link: None,
            steps: None,
        }));
        let stepped = Arc::new(Condvar::new());
        let stop = Arc::new(AtomicBool::new(false));
        let (s, st, cv) = (shared.clone(), stop.clone(), stepped.clone());
        let thread = std::thread::Builder::new()
            .name("denning-driver".into())
            .spawn(move || run(&open, &s, &cv, &st, &mut odometer))
            .ok();
        Driver {
            shared,
            stepped,
            stop,
            thread,
        }
    }

    /// The latest sample.
    pub fn latest(&self) -> Sample {
        lock(&self.shared).sample.clone()
    }

    /// The driver's clock, the one sample times are on: the host's, or in lock-step the
    /// robot's (the time of the last acknowledged step).
    pub fn now(&self) -> Instant {
        lock(&self.shared).now()
    }

    /// Lock-step: sends the drive command (m/s, rad/s) and a STEP of `ms` milliseconds, and
    /// waits until the robot acknowledges it — and every packet of the step has been taken
    /// into the sample — or `wait` passes. The first call switches the driver to lock-step for
    /// good (no keep-alive commands; the robot's time stamps packets). Returns the robot's
    /// time (ms) after the step.
    pub fn step(
        &self,
        translate: f64,
        rotate: f64,
        ms: u16,
        wait: Duration,
    ) -> Result<u64, StepError> {
        let deadline = Instant::now() + wait;
        self.enter_lockstep();
        let (mut s, connected) = self.wait_while(deadline, |s| s.link.is_none());
        if !connected {
            return Err(StepError::NotConnected);
        }
        let now = Instant::now();
        s.command = Some(((translate, rotate), now));
        let (v, w) = wire(translate, rotate);
        if let Some(link) = s.link.as_mut() {
            let mut bytes = Command::Vel(v).encode();
            bytes.extend(Command::RVel(w).encode());
            bytes.extend(Command::Step(ms).encode());
            link.writer.write_all(&bytes)?;
            link.last_wire = Some((v, w));
            link.last_sent = now;
        }
        if let Some(st) = s.steps.as_mut() {
            st.pending = Some(now);
        }
        drop(s);
        let pending = |s: &Shared| s.steps.as_ref().is_some_and(|st| st.pending.is_some());
        let (mut s, acked) = self.wait_while(deadline, pending);
        if !acked {
            if let Some(st) = s.steps.as_mut() {
                st.pending = None;
            }
            return Err(StepError::NoAck(wait));
        }
        Ok(s.steps.as_ref().map_or(0, |st| st.acked_ms))
    }

    /// Waits for the driver thread's news (a connection, an acknowledgement) while `waiting`
    /// holds, until `deadline`; returns the lock and whether the wait ended before it.
    fn wait_while(
        &self,
        deadline: Instant,
        waiting: impl Fn(&Shared) -> bool,
    ) -> (MutexGuard<'_, Shared>, bool) {
        let mut s = lock(&self.shared);
        while waiting(&s) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return (s, false);
            }
            s = self
                .stepped
                .wait_timeout(s, left)
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
        (s, true)
    }

    /// Switches to lock-step for good (idempotent; [`Driver::step`] does it too): from now on
    /// the robot's time stamps packets. Whatever was stamped on the host's clock before (the
    /// connection itself) is put at robot time zero, so no age depends on how long the host
    /// took to get here.
    pub fn enter_lockstep(&self) {
        let mut s = lock(&self.shared);
        if s.steps.is_none() {
            let base = Instant::now();
            s.steps = Some(Steps {
                base,
                acked_ms: 0,
                pending: None,
                held: Vec::new(),
            });
            s.sample.received = s.sample.received.map(|_| base);
        }
    }

    /// Waits until the robot is connected, at most `wait`; whether it is. (In lock-step the
    /// first cycle's sample must not depend on whether the handshake beat it.)
    pub fn wait_connected(&self, wait: Duration) -> bool {
        self.wait_while(Instant::now() + wait, |s| s.link.is_none())
            .1
    }

    /// Sends a one-off command (a pusher stroke, a message to say) now; whether it went out
    /// (not while the robot is not connected). In lock-step it reaches the robot before the
    /// cycle's step, so the robot acts on it in that step.
    pub fn send(&self, cmd: Command) -> bool {
        let mut s = lock(&self.shared);
        let Some(link) = s.link.as_mut() else {
            return false;
        };
        match link.writer.write_all(&cmd.encode()) {
            Ok(()) => true,
            Err(e) => {
                tracing::debug!(error = %e, "command not written");
                false
            }
        }
    }

    /// Sets the drive command (m/s, rad/s).
    pub fn command(&self, translate: f64, rotate: f64) {
        let now = Instant::now();
        let mut s = lock(&self.shared);
        s.command = Some(((translate, rotate), now));
        // A changed command goes out now; a broken link is the driver thread's to notice.
        if let Err(e) = s.send_command(now) {
            tracing::debug!(error = %e, "command not written");
        }
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn run(
    open: &Opener,
    shared: &Mutex<Shared>,
    stepped: &Condvar,
    stop: &AtomicBool,
    odometer: &mut Odometer,
) {
    let mut total = DecodeStats::default();
    while !stop.load(Ordering::Acquire) {
        match open() {
            Ok(mut t) => {
                match session(t.as_mut(), shared, stepped, stop, &mut total, odometer) {
                    Ok(()) => {}
                    Err(e) => tracing::warn!(error = %e, "robot link lost; reconnecting"),
                }
                // Leave the robot stopped if the link is still there.
                let _ = t.write_all(&Command::Vel(0).encode());
                let _ = t.write_all(&Command::RVel(0).encode());
            }
            Err(e) => tracing::debug!(error = %e, "cannot open the port yet"),
        }
        lock(shared).sample.connected = false;
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn read_packets(t: &mut dyn Transport, d: &mut Decoder, out: &mut Vec<Packet>) -> io::Result<()> {
    let mut buf = [0u8; 512];
    let n = t.read(&mut buf)?;
    d.push(&buf[..n]);
    while let Some(f) = d.next_frame() {
        if let Ok(p) = f.and_then(|p| Packet::decode(&p)) {
            out.push(p);
        }
    }
    Ok(())
}

fn handshake(t: &mut dyn Transport, d: &mut Decoder) -> io::Result<bool> {
    // CLOSE first: a robot still streaming to a previous connection returns to the handshake.
    t.write_all(&Command::Sync2.encode())?;
    for (cmd, echo) in [
        (Command::Sync0, 0u8),
        (Command::Sync1, 1),
        (Command::Sync2, 2),
    ] {
        t.write_all(&cmd.encode())?;
        let deadline = Instant::now() + Duration::from_millis(300);
        let mut ok = false;
        while !ok && Instant::now() < deadline {
            let mut pk = Vec::new();
            read_packets(t, d, &mut pk)?;
            ok = pk.contains(&Packet::Sync(echo));
        }
        if !ok {
            return Ok(false);
        }
    }
    t.write_all(&Command::Sync1.encode())?; // OPEN
    t.write_all(&Command::Enable(true).encode())?;
    // The robot stops on its own 400 ms after this driver goes quiet (a killed device
    // process, a cut cable): four keep-alives' worth, not the robot's default 2 s.
    t.write_all(&Command::Watchdog(ROBOT_WATCHDOG_MS).encode())?;
    Ok(true)
}

fn session(
    t: &mut dyn Transport,
    shared: &Mutex<Shared>,
    stepped: &Condvar,
    stop: &AtomicBool,
    total: &mut DecodeStats,
    odometer: &mut Odometer,
) -> io::Result<()> {
    let mut d = Decoder::default();
    if !handshake(t, &mut d)? {
        return Err(io::Error::new(
            io::ErrorKind::TimedOut,
            "no handshake answer",
        ));
    }
    tracing::info!("robot connected");
    {
        let mut s = lock(shared);
        s.sample.connected = true;
        s.sample.connects += 1;
        s.sample.received = Some(s.now());
    }
    let writer = t.writer()?;
    {
        let mut s = lock(shared);
        s.link = Some(Link {
            writer,
            last_wire: None,
            last_sent: Instant::now() - RESEND,
        });
        // A step sent on the previous link is lost with it.
        if let Some(st) = s.steps.as_mut() {
            st.pending = None;
            st.held.clear();
        }
    }
    stepped.notify_all();
    let result = serve_link(t, d, shared, stepped, stop, total, odometer);
    lock(shared).link = None;
    result
}

/// The session's loop: read and apply packets, send the keep-alive, watch the timeouts.
fn serve_link(
    t: &mut dyn Transport,
    mut d: Decoder,
    shared: &Mutex<Shared>,
    stepped: &Condvar,
    stop: &AtomicBool,
    total: &mut DecodeStats,
    odometer: &mut Odometer,
) -> io::Result<()> {
    let mut last_packet = Instant::now();
    let base = *total;
    while !stop.load(Ordering::Acquire) {
        let mut packets = Vec::new();
        read_packets(t, &mut d, &mut packets)?;
        let now = Instant::now();
        if !packets.is_empty() {
            last_packet = now;
        }
        let waiting = {
            let mut s = lock(shared);
            let mut acked = false;
            for p in packets {
                if let Some(st) = s.steps.as_mut() {
                    // Lock-step: a step's packets wait for its acknowledgement, and take
                    // the robot time it carries.
                    let Packet::Stepped(ms) = p else {
                        st.held.push(p);
                        continue;
                    };
                    st.acked_ms = u64::from(ms);
                    st.pending = None;
                    acked = true;
                    let at = st.now();
                    for p in std::mem::take(&mut st.held) {
                        apply(&mut s.sample, p, odometer, at);
                    }
                } else {
                    apply(&mut s.sample, p, odometer, now);
                }
            }
            if acked {
                stepped.notify_all();
            }
            s.sample.stats = DecodeStats {
                frames: base.frames + d.stats.frames,
                garbage: base.garbage + d.stats.garbage,
                bad_checksum: base.bad_checksum + d.stats.bad_checksum,
                bad_count: base.bad_count + d.stats.bad_count,
            };
            *total = s.sample.stats;
            // In lock-step the robot is silent between steps: only a step that goes
            // unanswered makes the link look dead.
            s.steps.as_ref().map(|st| st.pending)
        };
        let silent_since = match waiting {
            None => last_packet,
            Some(None) => now,
            Some(Some(sent)) => sent.max(last_packet),
        };
        if now.duration_since(silent_since) > LINK_TIMEOUT {
            return Err(io::Error::new(io::ErrorKind::TimedOut, "no packet for 1 s"));
        }
        // The keep-alive, and stop once the fabric's commands are stale.
        lock(shared).send_command(now)?;
    }
    Ok(())
}

fn apply(s: &mut Sample, p: Packet, odometer: &mut Odometer, at: Instant) {
    match p {
        Packet::Status(st) => apply_status(s, &st, odometer, at),
        Packet::Barcodes(b) => s.barcodes = (b, Some(at)),
        Packet::Arm { strokes, pressed } => s.arm = Some((strokes, pressed, at)),
        Packet::Said(n) => s.said = n,
        Packet::Sync(_) | Packet::Stepped(_) => {}
    }
}

fn apply_status(s: &mut Sample, st: &Status, odometer: &mut Odometer, now: Instant) {
    let acc = odometer.update(st.x, st.y);
    let th = f64::from(st.th) / 4096.0 * std::f64::consts::TAU;
    s.pose = (acc.0 as f64 / 1000.0, acc.1 as f64 / 1000.0, th);
    s.vel = (
        f64::from(st.vel) / 1000.0,
        (f64::from(st.rvel) / 10.0).to_radians(),
    );
    s.flags = st.flags;
    s.battery = f64::from(st.battery) / 10.0;
    s.received = Some(now);
    for &(n, mm) in &st.sonars {
        if let Some(reading) = s.sonar.get_mut(usize::from(n)) {
            let echo = match mm {
                0 => Echo::Silent,
                mm => Echo::Range(f64::from(mm) / 1000.0),
            };
            *reading = Some(SonarReading { echo, read_at: now });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::memory_pair;

    #[test]
    fn odometry_continues_its_frame_from_the_store_across_the_wrap() {
        let store = std::env::temp_dir().join(format!("denning-odom-{}", std::process::id()));
        let _ = std::fs::remove_file(&store);
        let mut a = Odometer::new(Some(store.clone()));
        assert_eq!(a.update(16384, 100), (0, 0), "a new frame starts at zero");
        assert_eq!(a.update(32000, 100), (15616, 0));
        assert_eq!(a.update(500, 90), (16884, -10), "across the 15-bit wrap");
        drop(a);
        // Another process on the same robot: the frame goes on from the last raw value.
        let mut b = Odometer::new(Some(store.clone()));
        assert_eq!(b.update(700, 90), (17084, -10));
        // A torn or foreign store starts a new frame instead of a wrong one.
        std::fs::write(&store, "12 x").unwrap();
        assert_eq!(Odometer::new(Some(store.clone())).update(5, 5), (0, 0));
        let _ = std::fs::remove_file(&store);
    }

    /// A scripted robot on the other end of an in-memory pair.
    #[test]
    fn handshake_status_and_commands_over_a_fake_link() {
        let (client, mut robot) = memory_pair();
        let slot = Mutex::new(Some(client));
        let driver = Driver::start(Box::new(move || {
            slot.lock()
                .ok()
                .and_then(|mut s| s.take())
                .map(|c| Box::new(c) as Box<dyn Transport>)
                .ok_or_else(|| io::Error::other("used"))
        }));
        let mut d = Decoder::default();
        let mut seen = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(10);
        let mut x: u16 = 32760;
        while Instant::now() < deadline {
            let mut buf = [0u8; 256];
            let n = robot.read(&mut buf).unwrap();
            d.push(&buf[..n]);
            while let Some(Ok(p)) = d.next_frame() {
                let c = Command::decode(&p).unwrap();
                if let Command::Sync0 | Command::Sync1 | Command::Sync2 = c
                    && (1..4).contains(&seen.len())
                {
                    let n = match c {
                        Command::Sync0 => 0,
                        Command::Sync1 => 1,
                        _ => 2,
                    };
                    robot.write_all(&Packet::Sync(n).encode()).unwrap();
                }
                seen.push(c);
            }
            if seen.contains(&Command::Enable(true)) {
                // Stream status packets across the 15-bit rollover.
                x = (x + 3) & 0x7fff;
                let st = Status {
                    x,
                    th: 1024,
                    sonars: vec![(3, 1500)],
                    ..Status::default()
                };
                robot.write_all(&Packet::Status(st).encode()).unwrap();
                driver.command(0.25, 0.0);
            }
            if seen.contains(&Command::Vel(250)) && driver.latest().pose.0 > 0.02 {
                break;
            }
        }
        let s = driver.latest();
        assert!(s.connected);
        assert!(seen.starts_with(&[
            Command::Sync2,
            Command::Sync0,
            Command::Sync1,
            Command::Sync2,
            Command::Sync1,
            Command::Enable(true)
        ]));
        assert!(
            seen.contains(&Command::Vel(250)),
            "the fabric's command reached the robot"
        );
        assert!(
            s.pose.0 > 0.02,
            "odometry unwrapped across the rollover: {:?}",
            s.pose
        );
        assert!((s.pose.2 - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        assert_eq!(s.sonar[3].unwrap().echo, Echo::Range(1.5));
    }
}
