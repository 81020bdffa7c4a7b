//! The log stream's wire: each skill's tracing lines travel as postcard-encoded [`LogLine`]s
//! (byte slices) on a per-domain publish-subscribe service ([`names::logs`]) with no paired
//! event service: readers poll, so a log line never adds a wake-up to anything. The writing
//! side (a tracing layer with a rate limit) is `skill-sdk`'s; [`LogReader`] is the reading side.

use crate::domain::Domain;
use crate::{Error, names, services};
use iceoryx2::node::Node;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// Longest message forwarded (bytes); longer ones are cut at a character boundary.
pub const MAX_MESSAGE: usize = 400;

/// The tracing filter when `RUST_LOG` is not set: `info`, but Zenoh's own crates (the
/// bridge's transport) only from warnings up — their `info` lines are session chatter.
pub const DEFAULT_FILTER: &str = "info,zenoh=warn,zenoh_transport=warn,zenoh_link_tcp=warn,\
                                  zenoh_link_tls=warn,zenoh_config=warn,zenoh_runtime=warn";
/// Largest encoded line (the publisher's slice size).
pub const MAX_LINE: usize = 640;
/// Lines each publisher keeps for late subscribers (a console opened later sees them).
const HISTORY: usize = 16;
/// Lines a reader may queue between two polls.
const READER_BUFFER: usize = 256;
/// Publishers of the log stream: every skill process, with room for dead ones awaiting cleanup.
const MAX_PUBLISHERS: usize = 2 * crate::board::MAX_SLOTS;
/// Readers at once (consoles, `ctl logs`).
const MAX_SUBSCRIBERS: usize = 8;

/// Severity, most severe first (tracing's order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Level {
    /// Something failed.
    Error,
    /// Something is wrong but went on.
    Warn,
    /// What happened.
    Info,
    /// Detail for a developer.
    Debug,
    /// Every step.
    Trace,
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

/// The log stream's service factory.
pub type LogFactory =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, [u8], ()>;

/// Opens (or creates) the domain's log stream service on `node`.
pub fn service(node: &Node<ipc::Service>) -> Result<LogFactory, Error> {
    let name = names::logs();
    let service_name = ServiceName::new(&name)
        .map_err(|e| Error::transport(&format!("service name '{name}'"), e))?;
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
        .map_err(|e| Error::transport(&format!("open '{name}'"), e))
}

/// Reads the log stream of a domain (polling: the stream wakes nobody).
pub struct LogReader {
    node: Node<ipc::Service>,
    subscriber: Subscriber<ipc::Service, [u8], ()>,
}

impl LogReader {
    /// Subscribes to `domain`'s log stream; each skill's last few lines arrive first.
    pub fn open(domain: &Domain, name: &str) -> Result<LogReader, Error> {
        let node = services::node(domain, name)?;
        let subscriber = service(&node)?
            .subscriber_builder()
            .buffer_size(READER_BUFFER)
            .history_request(HISTORY)
            .create()
            .map_err(|e| Error::transport("log subscriber", e))?;
        Ok(LogReader { node, subscriber })
    }

    /// Every line that arrived since the last call (undecodable ones are skipped).
    pub fn poll(&self) -> Result<Vec<LogLine>, Error> {
        let mut out = Vec::new();
        while let Some(s) = self
            .subscriber
            .receive()
            .map_err(|e| Error::transport("log receive", e))?
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
