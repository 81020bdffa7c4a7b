//! A client's link to a domain on another host: a Zenoh session to that domain's bridge
//! (`skillfab bridge`), which carries requests to its manager and forwards the events and
//! log lines ([`connect`]: a [`Client`] over it). Also the one place where a Zenoh
//! configuration is made from skillfab's options (the bridge uses it too).

use skillfab_client::{Address, Client, ClientError, RemoteLink};
use skillfab_proto::bridge::RemoteFailure;
use skillfab_proto::control::{self, Reply};
use skillfab_proto::log::LogLine;
use skillfab_proto::names;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::time::Duration;
use zenoh::Wait;

/// How a Zenoh session joins the others.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ZenohMode {
    /// Talks to other peers directly (a bridge's default).
    #[default]
    Peer,
    /// Talks through one peer or router it connects to (a remote `ctl`'s default).
    Client,
}

/// Where and how to open a Zenoh session.
#[derive(Debug, Clone, Default)]
pub struct ZenohOptions {
    /// Peer or client.
    pub mode: ZenohMode,
    /// Endpoints to connect to (`tcp/HOST:PORT`, `tls/HOST:PORT`); a peer retries them
    /// for ever, so a link that drops comes back.
    pub connect: Vec<String>,
    /// Endpoints to listen on (none unless asked).
    pub listen: Vec<String>,
    /// A Zenoh configuration file (TLS certificates, user/password, scouting); the options
    /// above are applied on top of it.
    pub config_file: Option<PathBuf>,
}

/// Why a Zenoh session could not be opened, or a request not sent.
fn zenoh_error(what: &str, e: zenoh::Error) -> ClientError {
    ClientError::Link {
        what: format!("zenoh: {what}"),
        cause: e,
    }
}

/// A client of the manager of `domain` on another host, through that domain's bridge
/// (`skillfab bridge`) over the Zenoh session `options` open (usually
/// `connect: ["tcp/HOST:PORT"]` in client mode). The first request tells whether the bridge
/// and its manager are there.
pub fn connect(domain: &str, options: &ZenohOptions) -> Result<Client, ClientError> {
    Client::over(domain, Remote::open(domain, options)?)
}

/// Where the manager of `domain` is reached through its bridge: what `skillfab ctl`, the
/// console and the plan runner are given with `--remote`.
pub fn address(domain: &str, options: ZenohOptions) -> Address {
    let name = domain.to_string();
    Address::Remote {
        domain: domain.to_string(),
        through: endpoints(&options),
        connect: std::sync::Arc::new(move || connect(&name, &options)),
    }
}

/// The endpoints of `o`, for messages.
fn endpoints(o: &ZenohOptions) -> String {
    if o.connect.is_empty() {
        "through the endpoints of the Zenoh configuration".to_string()
    } else {
        format!("through {}", o.connect.join(", "))
    }
}

/// How much longer a remote client waits than its bridge does for the manager: a slow
/// manager is reported as such (the bridge's `Timeout`), not as a bridge that never answered.
const BRIDGE_MARGIN: Duration = Duration::from_secs(2);

/// The Zenoh configuration for `o`: multicast scouting off and no listener unless asked
/// (a bridge is reached where it is told to be), then `o`'s mode and endpoints.
pub fn zenoh_config(o: &ZenohOptions) -> Result<zenoh::Config, ClientError> {
    let mut config = match &o.config_file {
        Some(path) => zenoh::Config::from_file(path)
            .map_err(|e| zenoh_error(&format!("Zenoh configuration {}", path.display()), e))?,
        None => {
            let mut c = zenoh::Config::default();
            set(&mut c, "scouting/multicast/enabled", "false")?;
            set(&mut c, "listen/endpoints", "[]")?;
            c
        }
    };
    let mode = match o.mode {
        ZenohMode::Peer => "\"peer\"",
        ZenohMode::Client => "\"client\"",
    };
    set(&mut config, "mode", mode)?;
    let list = |v: &[String]| serde_json_list(v);
    if !o.connect.is_empty() {
        set(&mut config, "connect/endpoints", &list(&o.connect))?;
    }
    if !o.listen.is_empty() {
        set(&mut config, "listen/endpoints", &list(&o.listen))?;
    }
    Ok(config)
}

fn serde_json_list(v: &[String]) -> String {
    serde_json::to_string(v).unwrap_or_else(|_| "[]".into())
}

fn set(c: &mut zenoh::Config, key: &str, json5: &str) -> Result<(), ClientError> {
    c.insert_json5(key, json5)
        .map_err(|e| zenoh_error(&format!("Zenoh option {key} = {json5}"), e))
}

/// Opens a session.
pub fn open(o: &ZenohOptions) -> Result<zenoh::Session, ClientError> {
    let where_ = if o.connect.is_empty() {
        "Zenoh".to_string()
    } else {
        o.connect.join(", ")
    };
    zenoh::open(zenoh_config(o)?)
        .wait()
        .map_err(|e| zenoh_error(&format!("cannot open a session to {where_}"), e))
}

/// Samples a subscriber keeps for a client that does not read them (then newer ones are
/// dropped and counted as lost by their sequence numbers, as locally).
const REMOTE_BUFFER: usize = 2048;

/// A remote domain, seen through its bridge.
struct Remote {
    session: zenoh::Session,
    /// The remote domain's name.
    domain: String,
    /// The endpoints, for messages.
    endpoint: String,
    events: Option<Feed>,
    logs: Option<Feed>,
}

/// A subscription whose samples' payloads queue up for the client's thread.
struct Feed {
    _subscriber: zenoh::pubsub::Subscriber<()>,
    rx: Receiver<Vec<u8>>,
}

impl Remote {
    /// A session to the bridge of `domain` (the bridge must answer a request to count as
    /// reached: see [`Remote::request`]).
    fn open(domain: &str, o: &ZenohOptions) -> Result<Remote, ClientError> {
        Ok(Remote {
            session: open(o)?,
            domain: domain.to_string(),
            endpoint: endpoints(o),
            events: None,
            logs: None,
        })
    }

    fn feed(&self, key: String) -> Result<Feed, ClientError> {
        let (tx, rx): (SyncSender<Vec<u8>>, _) = sync_channel(REMOTE_BUFFER);
        let subscriber = self
            .session
            .declare_subscriber(key)
            .callback(
                move |s| match tx.try_send(s.payload().to_bytes().into_owned()) {
                    Ok(()) | Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {}
                },
            )
            .wait()
            .map_err(|e| zenoh_error("remote subscription", e))?;
        Ok(Feed {
            _subscriber: subscriber,
            rx,
        })
    }
}

impl RemoteLink for Remote {
    /// Sends an encoded request to the domain's bridge and waits for its manager's answer
    /// (the bridge waits `timeout` for the manager; this side a little longer).
    fn request(&self, bytes: Vec<u8>, timeout: Duration) -> Result<Reply, ClientError> {
        let replies = self
            .session
            .get(names::remote_control(&self.domain))
            .payload(bytes)
            .timeout(timeout + BRIDGE_MARGIN)
            .wait()
            .map_err(|e| zenoh_error("remote request", e))?;
        let Ok(reply) = replies.recv() else {
            return Err(ClientError::NoBridge {
                domain: self.domain.clone(),
                through: self.endpoint.clone(),
                timeout: timeout + BRIDGE_MARGIN,
            });
        };
        match reply.result() {
            Ok(sample) => {
                let (_, response) = control::decode_response(&sample.payload().to_bytes())
                    .map_err(ClientError::Decode)?;
                Ok(response?)
            }
            Err(e) => {
                let bytes = e.payload().to_bytes();
                Err(match postcard::from_bytes::<RemoteFailure>(&bytes) {
                    Ok(RemoteFailure::NoManager(d)) => ClientError::NoManager(d),
                    Ok(RemoteFailure::Timeout(ms)) => {
                        ClientError::Timeout(Duration::from_millis(ms))
                    }
                    Ok(RemoteFailure::Full(max)) => ClientError::Full { max: max as usize },
                    Ok(failure) => ClientError::Remote {
                        domain: self.domain.clone(),
                        failure,
                    },
                    Err(_) => ClientError::RemoteUnreadable {
                        domain: self.domain.clone(),
                    },
                })
            }
        }
    }

    /// Subscribes to the remote events stream.
    fn subscribe(&mut self) -> Result<(), ClientError> {
        if self.events.is_none() {
            self.events = Some(self.feed(names::remote_events(&self.domain))?);
        }
        Ok(())
    }

    /// The next encoded event, waiting at most `timeout`.
    fn next_event(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, ClientError> {
        self.subscribe()?;
        let Some(feed) = &self.events else {
            return Ok(None);
        };
        match feed.rx.recv_timeout(timeout) {
            Ok(bytes) => Ok(Some(bytes)),
            Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => Ok(None),
        }
    }

    /// The log lines that arrived since the last call (the first call subscribes).
    fn log_lines(&mut self) -> Result<Vec<LogLine>, ClientError> {
        if self.logs.is_none() {
            self.logs = Some(self.feed(names::remote_logs(&self.domain))?);
        }
        let Some(feed) = &self.logs else {
            return Ok(Vec::new());
        };
        Ok(feed
            .rx
            .try_iter()
            .filter_map(|b| skillfab_proto::log::decode(&b).ok())
            .collect())
    }
}
