//! Where a client finds its manager: on this host, or on another through a link that another
//! crate opens. The client itself speaks only shared memory; the link to another host (Zenoh,
//! in `skillfab-bridge`) plugs in through [`RemoteLink`], so a program that never leaves its
//! host (a skill, the C library, the demo) links no network stack.

use crate::{Client, ClientError};
use skillfab_proto::control::Reply;
use skillfab_proto::domain::Domain;
use skillfab_proto::log::LogLine;
use std::fmt;
use std::sync::Arc;
use std::time::Duration;

/// A client's link to a domain on another host: the control requests carried to that
/// domain's manager, and its events and log lines carried back (`skillfab-bridge` implements
/// it over Zenoh).
pub trait RemoteLink: Send {
    /// Sends an encoded request and waits for the manager's answer (`timeout` is what the
    /// far end waits for its manager; the link may wait a little longer).
    fn request(&self, bytes: Vec<u8>, timeout: Duration) -> Result<Reply, ClientError>;
    /// Subscribes to the domain's events: every event published from now on can be read.
    fn subscribe(&mut self) -> Result<(), ClientError>;
    /// The next encoded event, waiting at most `timeout`; `None` if none came.
    fn next_event(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, ClientError>;
    /// The log lines that arrived since the last call (the first call subscribes).
    fn log_lines(&mut self) -> Result<Vec<LogLine>, ClientError>;
}

/// Opens a client of a domain on another host (each call a new connection).
pub type Connect = Arc<dyn Fn() -> Result<Client, ClientError> + Send + Sync>;

/// Where a domain's manager is reached: what `ctl`, the console and the plan runner are
/// given, so they connect (and reconnect) the same way to a local or a remote domain.
#[derive(Clone)]
pub enum Address {
    /// The manager of this domain on this host, through shared memory.
    Local(Domain),
    /// The manager of a domain on another host.
    Remote {
        /// The remote domain's name.
        domain: String,
        /// How it is reached (for messages: "tcp/10.0.0.2:7447").
        through: String,
        /// Opens a connection.
        connect: Connect,
    },
}

impl std::fmt::Display for Address {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Address::Local(d) => write!(f, "domain '{d}'"),
            Address::Remote {
                domain, through, ..
            } => write!(f, "domain '{domain}' through {through}"),
        }
    }
}

impl Address {
    /// A connection to the manager.
    pub fn connect(&self) -> Result<Client, ClientError> {
        match self {
            Address::Local(d) => Client::connect(d),
            Address::Remote { connect, .. } => connect(),
        }
    }

    /// Whether the manager is on another host.
    pub fn is_remote(&self) -> bool {
        matches!(self, Address::Remote { .. })
    }

    /// The domain's name.
    pub fn domain(&self) -> &str {
        match self {
            Address::Local(d) => d.name(),
            Address::Remote { domain, .. } => domain,
        }
    }
}

impl fmt::Debug for Address {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Address::Local(d) => write!(f, "Local({})", d.name()),
            Address::Remote {
                domain, through, ..
            } => write!(f, "Remote({domain} through {through})"),
        }
    }
}
