//! Forwards each skill's tracing events onto the domain's log stream
//! ([`skillfab_proto::log`]), so a console or `skillfab ctl logs` can show them next to the
//! running fabric.
//!
//! - In a skill process, [`init_tracing`](crate::init_tracing) installs a [`ForwardLayer`]
//!   beside the usual stderr output; [`forward`] starts the forwarder once the skill's name and
//!   domain are known. The layer only formats the line and `try_send`s it to a bounded queue —
//!   it never blocks the skill — after a token bucket ([`RATE_PER_S`] lines/s, bursts of
//!   [`BURST`]); lines over the rate are counted and the next line that passes carries the
//!   count (`dropped`).
//! - A forwarder thread with its own node publishes the lines.

use iceoryx2::port::update_connections::UpdateConnections;
use skillfab_proto::domain::Domain;
use skillfab_proto::header::now_ns;
use skillfab_proto::log::{Level, LogLine, MAX_LINE, MAX_MESSAGE, encode, service};
use skillfab_proto::services;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, OnceLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Lines per second a process may forward on average.
pub const RATE_PER_S: f64 = 50.0;
/// Lines a process may forward at once after a quiet spell.
pub const BURST: f64 = 50.0;
/// How long the forwarder sleeps while nothing is logged (it then offers its history to new
/// readers): rarely, so an idle skill's forwarder costs next to no wake-ups.
const QUIET: Duration = Duration::from_millis(500);

fn level(l: &tracing::Level) -> Level {
    match *l {
        tracing::Level::ERROR => Level::Error,
        tracing::Level::WARN => Level::Warn,
        tracing::Level::INFO => Level::Info,
        tracing::Level::DEBUG => Level::Debug,
        _ => Level::Trace,
    }
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
/// [`init_tracing`](crate::init_tracing); inert until [`forward`] runs).
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
            level: level(meta.level()),
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
            .map_err(|e| skillfab_proto::Error::transport("log publisher", e))?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use skillfab_proto::log::decode;

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
