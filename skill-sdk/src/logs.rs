//! The log stream: each skill's tracing events, forwarded over a per-domain iceoryx2
//! publish-subscribe service ([`names::logs`]) so a console or `skillfab ctl logs` can show
//! them next to the running fabric.
//!
//! - In a skill process, [`init_tracing`](crate::runtime::init_tracing) installs a
//!   [`ForwardLayer`] beside the usual stderr output; [`forward`] starts the forwarder once the
//!   skill's name and domain are known. The layer only formats the line and `try_send`s it to
//!   a bounded queue — it never blocks the skill — after a token bucket
//!   ([`RATE_PER_S`] lines/s, bursts of [`BURST`]); lines over the rate are counted and the
//!   next line that passes carries the count (`dropped`).
//! - A forwarder thread with its own node publishes the lines (postcard-encoded [`LogLine`]s
//!   as byte slices). The service has no paired event service: readers poll, so a log line
//!   never adds a wake-up to anything.
//! - [`LogReader`] is the reading side.

use crate::domain::Domain;
use crate::header::now_ns;
use crate::{SdkError, names, services};
use iceoryx2::node::Node;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, OnceLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Lines per second a process may forward on average.
pub const RATE_PER_S: f64 = 50.0;
/// Lines a process may forward at once after a quiet spell.
pub const BURST: f64 = 50.0;
/// Longest message forwarded (bytes); longer ones are cut at a character boundary.
pub const MAX_MESSAGE: usize = 400;
/// Largest encoded line (the publisher's slice size).
const MAX_LINE: usize = 640;
/// Lines each publisher keeps for late subscribers (a console opened later sees them).
const HISTORY: usize = 16;
/// Lines a reader may queue between two polls.
const READER_BUFFER: usize = 256;
/// Publishers of the log stream: every skill process, with room for dead ones awaiting cleanup.
const MAX_PUBLISHERS: usize = 2 * crate::board::MAX_SLOTS;
/// How long the forwarder sleeps while nothing is logged (it then offers its history to new
/// readers): rarely, so an idle skill's forwarder costs next to no wake-ups.
const QUIET: Duration = Duration::from_millis(500);
/// Readers at once (consoles, `ctl logs`).
const MAX_SUBSCRIBERS: usize = 8;

/// Severity, most severe first (tracing's order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[allow(missing_docs)]
pub enum Level {
    Error,
    Warn,
    Info,
    Debug,
    Trace,
}

impl From<&tracing::Level> for Level {
    fn from(l: &tracing::Level) -> Self {
        match *l {
            tracing::Level::ERROR => Level::Error,
            tracing::Level::WARN => Level::Warn,
            tracing::Level::INFO => Level::Info,
            tracing::Level::DEBUG => Level::Debug,
            _ => Level::Trace,
        }
    }
}

impl std::fmt::Display for Level {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(match self {
            Level::Error => "ERROR",
            Level::Warn => "WARN",
            Level::Info => "INFO",
            Level::Debug => "DEBUG",
            Level::Trace => "TRACE",
        })
    }
}

/// One forwarded log line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LogLine {
    /// The skill (instance name) that logged it.
    pub skill: String,
    /// Its process id.
    pub pid: u32,
    /// Severity.
    pub level: Level,
    /// The tracing target (module path).
    pub target: String,
    /// The message, then `key=value` for each other field.
    pub message: String,
    /// Monotonic clock (ns) when it was logged.
    pub time_ns: u64,
    /// Lines this process dropped (rate limit, full queue) since the previous forwarded one.
    pub dropped: u32,
}

impl std::fmt::Display for LogLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:<5} {}: {}", self.level, self.skill, self.message)?;
        if self.dropped > 0 {
            write!(f, " ({} lines dropped before)", self.dropped)?;
        }
        Ok(())
    }
}

/// Encodes a line.
pub fn encode(line: &LogLine) -> Result<Vec<u8>, postcard::Error> {
    postcard::to_allocvec(line)
}

/// Decodes a line.
pub fn decode(bytes: &[u8]) -> Result<LogLine, postcard::Error> {
    postcard::from_bytes(bytes)
}

/// A token bucket: `rate` per second on average, at most `burst` at once.
#[derive(Debug)]
pub struct TokenBucket {
    rate: f64,
    burst: f64,
    tokens: f64,
    last: Instant,
}

impl TokenBucket {
    /// A full bucket.
    pub fn new(rate: f64, burst: f64) -> TokenBucket {
        TokenBucket {
            rate,
            burst,
            tokens: burst,
            last: Instant::now(),
        }
    }

    /// Takes a token at `now` if there is one.
    pub fn take(&mut self, now: Instant) -> bool {
        let dt = now.saturating_duration_since(self.last).as_secs_f64();
        self.last = now;
        self.tokens = (self.tokens + dt * self.rate).min(self.burst);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// Where forwarded lines go once [`forward`] has run.
struct Sink {
    skill: String,
    /// `None` asks the forwarder to stop.
    tx: SyncSender<Option<LogLine>>,
    bucket: Mutex<(TokenBucket, u32)>,
}

static SINK: OnceLock<Sink> = OnceLock::new();

/// The tracing layer that forwards events to the log stream (installed by
/// [`init_tracing`](crate::runtime::init_tracing); inert until [`forward`] runs).
#[derive(Debug, Default)]
pub struct ForwardLayer;

#[derive(Default)]
struct Fields {
    message: String,
    rest: String,
}

impl tracing::field::Visit for Fields {
    fn record_str(&mut self, field: &tracing::field::Field, value: &str) {
        if field.name() == "message" {
            self.message.push_str(value);
        } else {
            self.rest.push_str(&format!(" {}={value}", field.name()));
        }
    }

    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.message.push_str(&format!("{value:?}"));
        } else {
            self.rest.push_str(&format!(" {}={value:?}", field.name()));
        }
    }
}

fn cut(mut s: String, max: usize) -> String {
    if s.len() > max {
        let mut end = max;
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        s.truncate(end);
        s.push('…');
    }
    s
}

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for ForwardLayer {
    fn on_event(
        &self,
        event: &tracing::Event<'_>,
        _ctx: tracing_subscriber::layer::Context<'_, S>,
    ) {
        let Some(sink) = SINK.get() else {
            return;
        };
        let meta = event.metadata();
        // iceoryx2's own messages and the forwarder's would only echo the transport.
        if meta.target().starts_with("iceoryx2") {
            return;
        }
        let dropped = {
            let Ok(mut b) = sink.bucket.lock() else {
                return;
            };
            if !b.0.take(Instant::now()) {
                b.1 = b.1.saturating_add(1);
                return;
            }
            std::mem::take(&mut b.1)
        };
        let mut f = Fields::default();
        event.record(&mut f);
        let line = LogLine {
            skill: sink.skill.clone(),
            pid: std::process::id(),
            level: meta.level().into(),
            target: cut(meta.target().to_string(), 120),
            message: cut(f.message + &f.rest, MAX_MESSAGE),
            time_ns: now_ns(),
            dropped,
        };
        if let Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) =
            sink.tx.try_send(Some(line))
            && let Ok(mut b) = sink.bucket.lock()
        {
            b.1 = b.1.saturating_add(1 + dropped);
        }
    }
}

/// Stops the forwarder when dropped (publishing what is queued first).
#[derive(Debug)]
pub struct ForwardGuard {
    stop: Arc<AtomicBool>,
    tx: SyncSender<Option<LogLine>>,
    thread: Option<JoinHandle<()>>,
}

impl Drop for ForwardGuard {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        // Wakes the forwarder at once (if the queue is full it sees the flag within QUIET).
        let _ = self.tx.try_send(None);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Starts forwarding this process's tracing events as skill `skill`'s lines in `domain`.
/// Only the first call in a process takes effect; `None` if forwarding was already set up
/// or its thread could not start.
pub fn forward(domain: &Domain, skill: &str) -> Option<ForwardGuard> {
    let (tx, rx) = sync_channel(256);
    SINK.set(Sink {
        skill: skill.to_string(),
        tx: tx.clone(),
        bucket: Mutex::new((TokenBucket::new(RATE_PER_S, BURST), 0)),
    })
    .ok()?;
    let stop = Arc::new(AtomicBool::new(false));
    let (d, st, name) = (domain.clone(), stop.clone(), format!("{skill}-log"));
    let thread = std::thread::Builder::new()
        .name("log-forward".into())
        .spawn(move || forward_loop(&d, &name, &rx, &st))
        .ok()?;
    Some(ForwardGuard {
        stop,
        tx,
        thread: Some(thread),
    })
}

fn forward_loop(
    domain: &Domain,
    node_name: &str,
    rx: &Receiver<Option<LogLine>>,
    stop: &AtomicBool,
) {
    let publisher = services::node(domain, node_name).and_then(|node| {
        let p = service(&node)?
            .publisher_builder()
            .initial_max_slice_len(MAX_LINE)
            .create()
            .map_err(|e| transport("log publisher", e))?;
        Ok((node, p))
    });
    let (_node, publisher) = match publisher {
        Ok(p) => p,
        // Without a stream the lines still reach stderr; say so once, there only.
        Err(e) => {
            eprintln!("log forwarding off: {e}");
            return;
        }
    };
    loop {
        match rx.recv_timeout(QUIET) {
            Ok(None) => return,
            Ok(Some(line)) => {
                let Ok(bytes) = encode(&line) else { continue };
                if bytes.len() > MAX_LINE {
                    continue;
                }
                if let Ok(s) = publisher.loan_slice_uninit(bytes.len()) {
                    let _ = s.write_from_slice(&bytes).send();
                }
            }
            Err(RecvTimeoutError::Timeout) => {
                if stop.load(Ordering::Acquire) {
                    return;
                }
                // A publisher hands its history to new readers when it looks for them: do
                // that while quiet too, so a console opened later sees a quiet skill's lines.
                let _ = publisher.update_connections();
            }
            Err(RecvTimeoutError::Disconnected) => return,
        }
    }
}

fn transport(what: &str, e: impl std::fmt::Debug) -> SdkError {
    SdkError::Transport {
        what: what.to_string(),
        detail: format!("{e:?}"),
    }
}

type LogFactory =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, [u8], ()>;

fn service(node: &Node<ipc::Service>) -> Result<LogFactory, SdkError> {
    let name = names::logs();
    let service_name =
        ServiceName::new(&name).map_err(|e| transport(&format!("service name '{name}'"), e))?;
    node.service_builder(&service_name)
        .publish_subscribe::<[u8]>()
        .max_publishers(MAX_PUBLISHERS)
        .max_subscribers(MAX_SUBSCRIBERS)
        .max_nodes(MAX_PUBLISHERS + MAX_SUBSCRIBERS + 8)
        .history_size(HISTORY)
        .subscriber_max_buffer_size(READER_BUFFER)
        .subscriber_max_borrowed_samples(2)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| transport(&format!("open '{name}'"), e))
}

/// Reads the log stream of a domain (polling: the stream wakes nobody).
pub struct LogReader {
    node: Node<ipc::Service>,
    subscriber: Subscriber<ipc::Service, [u8], ()>,
}

impl LogReader {
    /// Subscribes to `domain`'s log stream; each skill's last few lines arrive first.
    pub fn open(domain: &Domain, name: &str) -> Result<LogReader, SdkError> {
        let node = services::node(domain, name)?;
        let subscriber = service(&node)?
            .subscriber_builder()
            .buffer_size(READER_BUFFER)
            .history_request(HISTORY)
            .create()
            .map_err(|e| transport("log subscriber", e))?;
        Ok(LogReader { node, subscriber })
    }

    /// Every line that arrived since the last call (undecodable ones are skipped).
    pub fn poll(&self) -> Result<Vec<LogLine>, SdkError> {
        let mut out = Vec::new();
        while let Some(s) = self
            .subscriber
            .receive()
            .map_err(|e| transport("log receive", e))?
        {
            if let Ok(line) = decode(s.payload()) {
                out.push(line);
            }
        }
        Ok(out)
    }

    /// Waits `timeout`; `false` once SIGINT/SIGTERM asked this process to stop.
    pub fn wait(&self, timeout: Duration) -> bool {
        self.node.wait(timeout).is_ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bucket_allows_bursts_then_the_rate() {
        let mut b = TokenBucket::new(50.0, 50.0);
        let t0 = Instant::now();
        let burst = (0..100).filter(|_| b.take(t0)).count();
        assert_eq!(burst, 50);
        // One second later: 50 more, not more.
        let t1 = t0 + Duration::from_secs(1);
        assert_eq!((0..100).filter(|_| b.take(t1)).count(), 50);
        // A long pause refills only up to the burst.
        let t2 = t1 + Duration::from_secs(60);
        assert_eq!((0..100).filter(|_| b.take(t2)).count(), 50);
    }

    #[test]
    fn lines_round_trip_and_fit_the_slice() {
        let line = LogLine {
            skill: "x".repeat(64),
            pid: u32::MAX,
            level: Level::Warn,
            target: "skills::nav::door_locate".into(),
            message: cut("é".repeat(1000), MAX_MESSAGE),
            time_ns: u64::MAX,
            dropped: u32::MAX,
        };
        let bytes = encode(&line).unwrap();
        assert!(bytes.len() <= MAX_LINE, "{}", bytes.len());
        assert_eq!(decode(&bytes).unwrap(), line);
        assert!(line.to_string().starts_with("WARN "));
    }
}
