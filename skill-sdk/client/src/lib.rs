//! The control-plane client: what a sequencer (and `skillfab ctl`) uses to drive the
//! reactive layer — activate and deactivate skills, set and get parameters, query values,
//! install monitors, run/stop/step the manager, and receive events. [`json`] renders its
//! answers for scripts (`skillfab ctl --json`, the C ABI).
//!
//! ```no_run
//! use skillfab_client::Client;
//! use skillfab_proto::control::MonitorMode;
//! use skillfab_proto::domain::Domain;
//! use std::time::Duration;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut c = Client::connect(&Domain::new("default")?)?;
//! c.set_param("scale", "gain", "3")?;
//! let id = c.add_monitor("ticker.tick.value > 50", MonitorMode::Once, 0)?;
//! while let Some(ev) = c.next_event(Duration::from_secs(5))? {
//!     println!("{ev:?}");
//! }
//! # Ok(()) }
//! ```
//!
//! ## Typed references
//!
//! Parameters and values can be named by the references the skill-sdk derives generate
//! ([`skillfab_proto::refs`]) instead of text: the compiler then checks the names and the
//! value types, and a renamed parameter or port stops the sequencer compiling. The skill
//! stays an instance name (launch files name instances). A sequencer gets the references of
//! Rust skills from their crate (`skills::hello::ScaleParams::GAIN`); for a skill in another
//! language it declares them itself:
//!
//! ```no_run
//! # use skillfab_client::Client;
//! # use skillfab_proto::domain::Domain;
//! use skillfab_proto::refs::{Field, OutputRef, Param};
//!
//! /// The message type (a sequencer takes it from its crate: `skillfab_msgs::Tick`).
//! struct Tick;
//!
//! const GAIN: Param<f64> = Param::new("gain");
//! const TICK: OutputRef<Tick> = OutputRef::new("tick");
//! const VALUE: Field<u64, Tick> = Field::new("value");
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! # let c = Client::connect(&Domain::new("default")?)?;
//! c.set("scale", GAIN, 3.0)?;
//! let gain: f64 = c.get("scale", GAIN)?;
//! let (tick, cycle) = c.read("ticker", TICK.field(VALUE))?; // a u64
//! println!("cycle {cycle}: tick {tick}, gain {gain}");
//! # Ok(()) }
//! ```

#![warn(missing_docs)]

pub use skillfab_proto::json;

mod address;

pub use address::{Address, RemoteLink};

use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use skillfab_proto::board::Board;
use skillfab_proto::control::{
    self, ControlError, Event, GaveUpInfo, MonitorFate, MonitorInfo, MonitorMode, ParamArg,
    PlanReport, PlanTree, Reply, Request, SkillInfo, Stats,
};
use skillfab_proto::domain::Domain;
use skillfab_proto::log::{LogLine, LogReader};
use skillfab_proto::param::{ParamType, ParamValue};
use skillfab_proto::refs::{Param, ValuePath};
use skillfab_proto::value::{FromValue, Value};
use skillfab_proto::{names, services};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Why a control call failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ClientError {
    /// The manager refused the request; the reason is precise.
    #[error(transparent)]
    Refused(#[from] ControlError),
    /// iceoryx2 set-up or transfer failed.
    #[error(transparent)]
    Fabric(#[from] skillfab_proto::Error),
    /// No manager runs in the domain.
    #[error("no manager is running in domain '{0}'")]
    NoManager(String),
    /// No answer in time.
    #[error("no answer from the manager within {0:?}")]
    Timeout(Duration),
    /// An answer or event that does not decode.
    #[error("undecodable answer: {0}")]
    Decode(postcard::Error),
    /// A request that does not encode.
    #[error("the request does not encode: {0}")]
    Encode(postcard::Error),
    /// Every place on the control plane stayed taken for as long as the client waits.
    #[error("the manager serves at most {max} clients at once and none left")]
    Full {
        /// Clients served at once.
        max: usize,
    },
    /// An answer of the wrong kind for the request.
    #[error("unexpected answer: {0:?}")]
    Unexpected(Box<Reply>),
    /// Another thread sharing this client panicked while it held the client's port.
    #[error("the client was poisoned by a thread that panicked while using it")]
    Poisoned,
    /// The link to another host (a Zenoh session to a bridge) could not be opened or
    /// configured, or refused a request.
    #[error("{what}: {cause}")]
    Link {
        /// What was being done.
        what: String,
        /// The link's own error.
        cause: Box<dyn std::error::Error + Send + Sync>,
    },
    /// No bridge of the remote domain answered (not running, not reachable, or another
    /// domain name on that host).
    #[error("no bridge of domain '{domain}' answered {through} within {timeout:?}")]
    NoBridge {
        /// The remote domain asked for.
        domain: String,
        /// The endpoints tried ("through tcp/…"), or the configuration file's.
        through: String,
        /// How long the client waited.
        timeout: Duration,
    },
    /// The remote domain's bridge could not carry the request out.
    #[error("the bridge of domain '{domain}': {failure}")]
    Remote {
        /// The remote domain.
        domain: String,
        /// The bridge's reason.
        failure: skillfab_proto::bridge::RemoteFailure,
    },
    /// A typed read ([`Client::get`], [`Client::read`]) found a value of another type than
    /// its reference's: the instance declares it otherwise (another version of the skill, or
    /// an instance of another skill than the one the reference was made for).
    #[error("{path} is {got}, which is not a {expected}")]
    WrongType {
        /// `skill.param`, or `skill.port[.field][index]`.
        path: String,
        /// The reference's type.
        expected: &'static str,
        /// The value the manager answered.
        got: Value,
    },
    /// The remote domain's bridge answered with a failure this client cannot read (another
    /// skillfab version).
    #[error("the bridge of domain '{domain}' failed, with an answer this client cannot read")]
    RemoteUnreadable {
        /// The remote domain.
        domain: String,
    },
}

fn sdk(what: &str, e: impl std::error::Error + Send + Sync + 'static) -> ClientError {
    ClientError::Fabric(skillfab_proto::Error::transport(what, e))
}

/// Recent cycles' timing, oldest first (µs).
#[derive(Debug, Clone, PartialEq)]
pub struct CycleTimes {
    /// The last cycle completed.
    pub cycle: u64,
    /// Cycle start → last expected run done (the manager's cycle latency).
    pub latency_us: Vec<f32>,
    /// Cycle start → the manager handling the completion (one more wake-up).
    pub round_trip_us: Vec<f32>,
}

/// The control plane's client port.
type ControlPort = iceoryx2::port::client::Client<ipc::Service, [u8], (), [u8], ()>;

/// How long a client waits for an answer before it asks again (doubling, at most
/// [`RETRY_MAX`]). An answer usually comes within a cycle; a repeat costs a new port and is
/// answered once by the manager whatever happened to the first.
const RETRY_AFTER: Duration = Duration::from_secs(1);
const RETRY_MAX: Duration = Duration::from_secs(4);

/// A request sent, its answer awaited.
type Pending = iceoryx2::pending_response::PendingResponse<ipc::Service, [u8], (), [u8], ()>;

/// The events subscriber and the listener woken after each publication.
type EventsPort = (Subscriber<ipc::Service, [u8], ()>, Listener<ipc::Service>);

/// A port on the control plane; while its places are all taken ([`services::CONTROL_MAX_CLIENTS`]
/// clients at once), waits for one until `deadline`.
fn control_port(node: &Node<ipc::Service>, deadline: Instant) -> Result<ControlPort, ClientError> {
    use iceoryx2::service::port_factory::client::ClientCreateError;
    loop {
        match services::control_service(node)?
            .client_builder()
            .initial_max_slice_len(control::MAX_REQUEST_BYTES)
            .allocation_strategy(AllocationStrategy::Static)
            .create()
        {
            Ok(p) => return Ok(p),
            Err(ClientCreateError::ExceedsMaxSupportedClients) if Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(ClientCreateError::ExceedsMaxSupportedClients) => {
                return Err(ClientError::Full {
                    max: services::CONTROL_MAX_CLIENTS,
                });
            }
            Err(e) => return Err(sdk("control client", e)),
        }
    }
}

/// A connection to a domain's manager: on this host through shared memory, or on another
/// through that domain's bridge ([`Client::over`], which `skillfab-bridge` opens). Both behave
/// the same.
pub struct Client {
    id: String,
    /// The domain's name.
    domain: String,
    link: Link,
    /// The number of the last request sent.
    seq: AtomicU64,
    last_seq: u64,
    lost: u64,
    timeout: Duration,
}

/// How requests reach the manager.
enum Link {
    Local(Box<Local>),
    Remote(Box<Mutex<dyn RemoteLink>>),
}

/// The shared-memory link of a client on the manager's host.
struct Local {
    domain: Domain,
    /// Renewed when an answer is overdue (see [`Local::request`]); `None` between dropping
    /// the old one and getting a new one.
    port: Mutex<Option<ControlPort>>,
    /// Held for the whole of a request: the port has room for one at a time.
    turn: Mutex<()>,
    wake: Notifier<ipc::Service>,
    answers: Listener<ipc::Service>,
    node: Node<ipc::Service>,
    /// Subscribed on first use (a monitor installed, an event read): a client that never
    /// reads events costs the manager nothing.
    events: Mutex<Option<EventsPort>>,
    /// Opened on first use ([`Client::log_lines`]).
    logs: Option<LogReader>,
}

fn next_id() -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

impl Client {
    /// Connects to the manager of `domain` (which must be running). Events published from
    /// now on reach [`Client::next_event`].
    pub fn connect(domain: &Domain) -> Result<Client, ClientError> {
        let id = next_id();
        match Board::open(&domain.prefix()) {
            Ok(b) if b.manager_alive() => {}
            // Another user's domain: say so rather than "no manager".
            Err(skillfab_proto::Error::Board { name, source })
                if source.kind() == std::io::ErrorKind::PermissionDenied =>
            {
                return Err(ClientError::Fabric(skillfab_proto::Error::DomainAccess {
                    domain: domain.name().to_string(),
                    path: format!("/dev/shm/{}", name.trim_start_matches('/')),
                    reason: "permission denied: the domain belongs to another user".into(),
                }));
            }
            _ => return Err(ClientError::NoManager(domain.name().to_string())),
        }
        let node = services::node(domain, &format!("client-{id}"))?;
        let answers = services::listener(&node, &names::client(&id))?;
        let port = control_port(&node, Instant::now() + Duration::from_secs(10))?;
        let wake = services::notifier(&node, &names::control())?;
        Ok(Client {
            id,
            domain: domain.name().to_string(),
            link: Link::Local(Box::new(Local {
                domain: domain.clone(),
                port: Mutex::new(Some(port)),
                turn: Mutex::new(()),
                node,
                wake,
                answers,
                events: Mutex::new(None),
                logs: None,
            })),
            seq: AtomicU64::new(0),
            last_seq: 0,
            lost: 0,
            timeout: Duration::from_secs(10),
        })
    }

    /// A client of the manager of `domain` on another host, whose requests, events and log
    /// lines travel over `link` (`skillfab_bridge::connect` opens one over Zenoh). Requests,
    /// answers, errors and events are those of a local client; a monitor belongs to this
    /// client as locally. The first request tells whether the other end is there.
    pub fn over(domain: &str, link: impl RemoteLink + 'static) -> Result<Client, ClientError> {
        names::check_name("domain", domain, false)?;
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_string())
            .unwrap_or_default();
        Ok(Client {
            id: format!("{host}-{}", next_id()),
            domain: domain.to_string(),
            link: Link::Remote(Box::new(Mutex::new(link))),
            seq: AtomicU64::new(0),
            last_seq: 0,
            lost: 0,
            timeout: Duration::from_secs(10),
        })
    }

    /// Whether this client reaches its domain through a bridge.
    pub fn is_remote(&self) -> bool {
        matches!(self.link, Link::Remote(_))
    }

    /// The domain's name.
    pub fn domain(&self) -> &str {
        &self.domain
    }

    /// The fabric's clock as the manager set it for the current cycle (what skills read:
    /// cycle × period with a period, lock-step included). `None` over a bridge (the board is
    /// another host's shared memory) or with no manager running.
    pub fn clock(&self) -> Option<skillfab_proto::board::Clock> {
        match &self.link {
            Link::Local(l) => Board::open(&l.domain.prefix())
                .ok()
                .filter(Board::manager_alive)
                .map(|b| b.header().clock()),
            Link::Remote(_) => None,
        }
    }

    /// This client's id (monitors belong to it).
    pub fn id(&self) -> &str {
        &self.id
    }

    /// How long a request waits for its answer (default 10 s; `step` waits as long as the
    /// manager lives).
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// Sends a request and waits for the answer.
    ///
    /// The request carries a number. With no answer after [`RETRY_AFTER`] (doubling), it is
    /// sent again, under the same number, on a new port: iceoryx2 0.10 can miss a connection
    /// when many clients connect at once, and a request or an answer on it is lost; a new
    /// port makes the server connect again. The manager carries a number out once: a repeat
    /// gets the answer already given, or waits for the first. A manager that dies before it
    /// answers and is replaced (`skillfab up` restarts it) is asked again too: the new one
    /// has the state the old one saved, but not its answers, so a request the old one carried
    /// out is carried out once more — to the same effect, except `monitor`, which then installs
    /// a second monitor.
    pub fn request(&self, request: &Request) -> Result<Reply, ClientError> {
        let seq = self.seq.fetch_add(1, Ordering::Relaxed) + 1;
        let bytes = control::encode_request(&self.id, seq, request).map_err(ClientError::Encode)?;
        if bytes.len() > control::MAX_REQUEST_BYTES {
            // What the manager would answer; the port's samples could not even hold it.
            return Err(ClientError::Refused(ControlError::RequestTooLarge {
                bytes: bytes.len(),
                max: control::MAX_REQUEST_BYTES,
            }));
        }
        let patient = matches!(request, Request::Step(_));
        match &self.link {
            Link::Local(l) => l.request(seq, &bytes, patient, self.timeout),
            Link::Remote(r) => {
                // `step` waits as long as the manager lives: an hour stands for that here.
                let timeout = if patient {
                    Duration::from_secs(3600)
                } else {
                    self.timeout
                };
                // The session is shared; requests of threads sharing the client take turns.
                r.lock()
                    .map_err(|_| ClientError::Poisoned)?
                    .request(bytes, timeout)
            }
        }
    }
}

impl Local {
    /// See [`Client::request`].
    fn request(
        &self,
        seq: u64,
        bytes: &[u8],
        patient: bool,
        timeout: Duration,
    ) -> Result<Reply, ClientError> {
        // One request at a time on the port (threads sharing a client take turns).
        let _turn = self.turn.lock().map_err(|_| ClientError::Poisoned)?;
        let mut serving = self.manager_pid();
        let mut pending = Some(self.send(bytes, timeout)?);
        let start = Instant::now();
        let (mut retry, mut retry_at) = (RETRY_AFTER, start + RETRY_AFTER);
        // Poll often at first: the answer usually comes within a cycle, and the manager
        // finishes connecting its answer channel when this side polls.
        let mut nap = Duration::from_micros(500);
        loop {
            if let Some(p) = &pending
                && let Some(answer) = p.receive().map_err(|e| sdk("receive answer", e))?
            {
                let (answers, response) =
                    control::decode_response(answer.payload()).map_err(ClientError::Decode)?;
                // The answer to an earlier request of this client, delivered late, is not ours;
                // 0 answers whatever was sent (a request the manager could not read: another
                // protocol version, undecodable bytes, too large).
                if answers == seq || answers == 0 {
                    return Ok(response?);
                }
                tracing::debug!(seq, answers, "a stale answer ignored");
                continue;
            }
            if !patient && start.elapsed() > timeout {
                return Err(ClientError::Timeout(timeout));
            }
            let _ = self.answers.timed_wait(|_| {}, nap);
            nap = (nap * 2).min(Duration::from_millis(100));
            let now = Instant::now();
            if now >= retry_at {
                // The pending answer holds the old port's place: it goes first.
                drop(pending.take());
                self.renew_port(timeout)?;
                pending = Some(self.send(bytes, timeout)?);
                retry = (retry * 2).min(RETRY_MAX);
                retry_at = now + retry;
                continue;
            }
            if nap < Duration::from_millis(100) {
                continue;
            }
            // No answer for a while: is it still the manager that was asked?
            match self.manager_pid() {
                Some(pid) if Some(pid) != serving => {
                    serving = Some(pid);
                    drop(pending.take());
                    self.renew_port(timeout)?;
                    pending = Some(self.send(bytes, timeout)?);
                }
                None if start.elapsed() > Duration::from_secs(1) => {
                    return Err(ClientError::NoManager(self.domain.name().to_string()));
                }
                _ => {}
            }
        }
    }

    /// Sends an encoded request and wakes the control plane.
    fn send(&self, bytes: &[u8], timeout: Duration) -> Result<Pending, ClientError> {
        let mut port = self.port.lock().map_err(|_| ClientError::Poisoned)?;
        let port = match &mut *port {
            Some(p) => p,
            none => none.insert(control_port(&self.node, Instant::now() + timeout)?),
        };
        let pending = port
            .loan_slice_uninit(bytes.len())
            .map_err(|e| sdk("loan request", e))?
            .write_from_slice(bytes)
            .send()
            .map_err(|e| sdk("send request", e))?;
        self.wake
            .notify()
            .map_err(|e| sdk("wake the control plane", e))?;
        Ok(pending)
    }

    /// Replaces the control port by a new one (the manager's server connects to it anew).
    fn renew_port(&self, timeout: Duration) -> Result<(), ClientError> {
        let mut port = self.port.lock().map_err(|_| ClientError::Poisoned)?;
        // The old one goes first: a client holds one of the control plane's places.
        drop(port.take());
        *port = Some(control_port(&self.node, Instant::now() + timeout)?);
        Ok(())
    }

    /// The process id of the domain's running manager.
    fn manager_pid(&self) -> Option<u32> {
        Board::open(&self.domain.prefix())
            .ok()
            .filter(Board::manager_alive)
            .map(|b| b.header().manager_pid.load(Ordering::Acquire))
    }

    fn events(&self) -> Result<std::sync::MutexGuard<'_, Option<EventsPort>>, ClientError> {
        self.events.lock().map_err(|_| ClientError::Poisoned)
    }

    /// Subscribes to the events stream.
    fn subscribe(&self) -> Result<(), ClientError> {
        let mut events = self.events()?;
        if events.is_none() {
            let listener = services::listener(&self.node, &names::events())?;
            let sub = services::events_service(&self.node)?
                .subscriber_builder()
                .buffer_size(services::EVENT_BUFFER)
                .create()
                .map_err(|e| sdk("events subscriber", e))?;
            *events = Some((sub, listener));
        }
        Ok(())
    }

    /// The next encoded event, waiting at most `timeout`.
    fn next_event(&self, timeout: Duration) -> Result<Option<Vec<u8>>, ClientError> {
        self.subscribe()?;
        let events = self.events()?;
        let Some((events, listener)) = events.as_ref() else {
            return Ok(None);
        };
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(sample) = events.receive().map_err(|e| sdk("receive event", e))? {
                return Ok(Some(sample.payload().to_vec()));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            let _ = listener.timed_wait(|_| {}, (deadline - now).min(Duration::from_millis(200)));
        }
    }
}

impl Client {
    fn done(&self, request: Request) -> Result<(), ClientError> {
        match self.request(&request)? {
            Reply::Done => Ok(()),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Every registered skill.
    pub fn list(&self) -> Result<Vec<SkillInfo>, ClientError> {
        match self.request(&Request::List)? {
            Reply::Skills(s) => Ok(s),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Activates skills, all or none.
    pub fn activate(&self, skills: &[&str]) -> Result<(), ClientError> {
        self.done(Request::Activate(
            skills.iter().map(|s| s.to_string()).collect(),
        ))
    }

    /// Deactivates skills, all or none.
    pub fn deactivate(&self, skills: &[&str]) -> Result<(), ClientError> {
        self.done(Request::Deactivate(
            skills.iter().map(|s| s.to_string()).collect(),
        ))
    }

    /// Wants skills, all or none: each is activated with every skill it reads from
    /// (transitively); refused when one of them reads a topic nobody produces.
    pub fn want(&self, skills: &[&str]) -> Result<(), ClientError> {
        self.done(Request::Want(
            skills.iter().map(|s| s.to_string()).collect(),
        ))
    }

    /// Releases wanted skills, all or none, and the skills activated for them that nothing
    /// wanted reads from any more.
    pub fn release(&self, skills: &[&str]) -> Result<(), ClientError> {
        self.done(Request::Release(
            skills.iter().map(|s| s.to_string()).collect(),
        ))
    }

    /// Sets a parameter from text (parsed by its declared type); applied from the next cycle.
    pub fn set_param(&self, skill: &str, param: &str, value: &str) -> Result<(), ClientError> {
        self.done(Request::SetParam {
            skill: skill.into(),
            param: param.into(),
            value: ParamArg::Text(value.into()),
        })
    }

    /// Sets a parameter to a typed value; applied from the next cycle.
    pub fn set_param_value(
        &self,
        skill: &str,
        param: &str,
        value: ParamValue,
    ) -> Result<(), ClientError> {
        self.done(Request::SetParam {
            skill: skill.into(),
            param: param.into(),
            value: ParamArg::Value(value),
        })
    }

    /// A parameter's current value.
    pub fn get_param(&self, skill: &str, param: &str) -> Result<ParamValue, ClientError> {
        match self.request(&Request::GetParam {
            skill: skill.into(),
            param: param.into(),
        })? {
            Reply::Param(v) => Ok(v),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Sets parameter `param` of skill instance `skill` to `value`, typed by the reference
    /// (`c.set("go", GoParams::SPEED, 0.3)`); applied from the next cycle. The manager checks
    /// the bounds.
    pub fn set<T: ParamType, Of>(
        &self,
        skill: &str,
        param: Param<T, Of>,
        value: T,
    ) -> Result<(), ClientError> {
        self.set_param_value(skill, param.name(), value.to_value())
    }

    /// The current value of parameter `param` of skill instance `skill`, as the reference's
    /// type ([`ClientError::WrongType`] if the instance declares another).
    pub fn get<T: ParamType, Of>(
        &self,
        skill: &str,
        param: Param<T, Of>,
    ) -> Result<T, ClientError> {
        let value = self.get_param(skill, param.name())?;
        T::from_value(&value).ok_or_else(|| ClientError::WrongType {
            path: format!("{skill}.{param}"),
            expected: std::any::type_name::<T>(),
            got: value.into(),
        })
    }

    /// The latest value at `skill.output[.field][index]` and the cycle it was produced in.
    pub fn query(&self, path: &str) -> Result<(Value, u64), ClientError> {
        match self.request(&Request::Query(path.into()))? {
            Reply::Value { value, cycle } => Ok((value, cycle)),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// The latest value at `path` of an output of skill instance `skill`, as the path's type,
    /// and the cycle it was produced in: `c.read("odometry",
    /// OdometryOut::ODOM.field(Odometry::X))` is an `f64`, `c.read("ticker", TickOut::TICK)`
    /// a whole `Tick`. The [`query`](Client::query) of `skill.path`, converted
    /// ([`ClientError::WrongType`] if the instance declares it otherwise).
    pub fn read<T: FromValue>(
        &self,
        skill: &str,
        path: impl Into<ValuePath<T>>,
    ) -> Result<(T, u64), ClientError> {
        let path = format!("{skill}.{}", path.into());
        let (value, cycle) = self.query(&path)?;
        match T::from_value(&value) {
            Some(v) => Ok((v, cycle)),
            None => Err(ClientError::WrongType {
                path,
                expected: std::any::type_name::<T>(),
                got: value,
            }),
        }
    }

    /// Installs a monitor; its firings arrive as events ([`Client::next_event`]). Returns its
    /// id. The client is subscribed to events first, so not even a firing in the very next
    /// cycle is missed (over a bridge, the subscription reaches the far side before the
    /// request does: one link, in order).
    pub fn add_monitor(
        &self,
        expr: &str,
        mode: MonitorMode,
        hold: u32,
    ) -> Result<u64, ClientError> {
        self.subscribe()?;
        match self.request(&Request::AddMonitor {
            expr: expr.into(),
            mode,
            hold,
        })? {
            Reply::MonitorAdded(id) => Ok(id),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Takes over monitors another client installed (a restarted plan runner its
    /// predecessor's): those still installed are this client's from now on, and their
    /// firings reach it. What became of each, in order. Subscribes to events first, so a
    /// firing right after the hand-over is not missed.
    pub fn adopt_monitors(&self, ids: &[u64]) -> Result<Vec<MonitorFate>, ClientError> {
        self.subscribe()?;
        match self.request(&Request::AdoptMonitors(ids.to_vec()))? {
            Reply::Adopted(f) if f.len() == ids.len() => Ok(f),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// The processes `skillfab up` gave up restarting and that have not come back since
    /// (what its `ProcessGaveUp` events said, for a client that was not there to see them).
    pub fn gave_up(&self) -> Result<Vec<GaveUpInfo>, ClientError> {
        match self.request(&Request::GaveUp)? {
            Reply::GaveUp(list) => Ok(list),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// The plan running now — its tree, and each node's status with the cycle it has had it
    /// since — or `None` when no plan runs. Its changes come as `EventKind::PlanChanged`
    /// events ([`Client::subscribe`]); a `PlanStarted` event says a new tree replaced it.
    pub fn plan(&self) -> Result<Option<PlanTree>, ClientError> {
        match self.request(&Request::CurrentPlan)? {
            Reply::Plan(tree) => Ok(tree),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// A plan runner's report to the manager: its plan's tree when it starts, the status
    /// changes of a tick (`skillfab sequence` sends them; docs/sequence.md). A report about
    /// a plan the manager does not run for this client is refused with
    /// `ControlError::PlanNotCurrent`, one naming a node the tree does not have with
    /// `ControlError::UnknownPlanNode`, a malformed tree with `ControlError::BadPlanTree`.
    pub fn report_plan(&self, report: PlanReport) -> Result<(), ClientError> {
        self.done(Request::Plan(report))
    }

    /// Removes a monitor.
    pub fn remove_monitor(&self, id: u64) -> Result<(), ClientError> {
        self.done(Request::RemoveMonitor(id))
    }

    /// The message schema of `topic`, as the skills that declare it declare it.
    pub fn topic_schema(
        &self,
        topic: &str,
    ) -> Result<skillfab_proto::schema::MessageSchema, ClientError> {
        match self.request(&Request::TopicSchema(topic.into()))? {
            Reply::Schema(s) => Ok(s),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Every monitor.
    pub fn monitors(&self) -> Result<Vec<MonitorInfo>, ClientError> {
        match self.request(&Request::ListMonitors)? {
            Reply::Monitors(m) => Ok(m),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Starts cycling.
    pub fn run(&self) -> Result<(), ClientError> {
        self.done(Request::Run)
    }

    /// Stops cycling after the current cycle.
    pub fn stop(&self) -> Result<(), ClientError> {
        self.done(Request::Stop)
    }

    /// Runs `n` cycles then stops; returns the cycle count when they are done.
    pub fn step(&self, n: u64) -> Result<u64, ClientError> {
        match self.request(&Request::Step(n))? {
            Reply::Stepped(c) => Ok(c),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Holds the fabric at cycle `at`: no cycle after it starts until this client moves the
    /// hold or releases it (`None`). The manager publishes `EventKind::Held` when it stops
    /// there. A lock-step observer acts at cycles of its own choosing with it: the same run
    /// every time.
    pub fn hold(&self, at: Option<u64>) -> Result<(), ClientError> {
        self.done(Request::Hold(at))
    }

    /// A skill's declaration as it registered (its last one while it is away).
    pub fn declaration(&self, skill: &str) -> Result<skillfab_proto::decl::SkillDecl, ClientError> {
        match self.request(&Request::Declaration(skill.into()))? {
            Reply::Declaration(d) => Ok(*d),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Cycle and skill statistics.
    pub fn stats(&self) -> Result<Stats, ClientError> {
        match self.request(&Request::Stats)? {
            Reply::Stats(s) => Ok(s),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Changes a skill's arbitration priority from the next cycle.
    pub fn set_priority(&self, skill: &str, priority: i32) -> Result<(), ClientError> {
        self.done(Request::SetPriority {
            skill: skill.into(),
            priority,
        })
    }

    /// The latencies of up to `n` most recent cycles (µs, oldest first) and the last cycle.
    pub fn latencies(&self, n: u32) -> Result<(u64, Vec<f32>), ClientError> {
        self.cycle_times(n).map(|t| (t.cycle, t.latency_us))
    }

    /// The latencies and round trips of up to `n` most recent cycles (µs, oldest first).
    pub fn cycle_times(&self, n: u32) -> Result<CycleTimes, ClientError> {
        match self.request(&Request::Latencies(n))? {
            Reply::Latencies {
                cycle,
                latency_us,
                round_trip_us,
            } => Ok(CycleTimes {
                cycle,
                latency_us,
                round_trip_us,
            }),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Turns the logging of a skill's input and output samples on or off.
    pub fn set_io_log(&self, skill: &str, on: bool) -> Result<(), ClientError> {
        self.done(Request::SetIoLog {
            skill: skill.into(),
            on,
        })
    }

    /// Starts recording every sample of `topics` (empty: all), the control changes and the
    /// events into the MCAP file `file` (replacing a recording in progress).
    pub fn record_start(&self, file: &str, topics: &[&str]) -> Result<(), ClientError> {
        self.done(Request::Record {
            file: Some(file.into()),
            topics: topics.iter().map(|t| t.to_string()).collect(),
        })
    }

    /// Stops the recording in progress (the file is finished and closed).
    pub fn record_stop(&self) -> Result<(), ClientError> {
        self.done(Request::Record {
            file: None,
            topics: Vec::new(),
        })
    }

    /// The manager's fabric log file and the skills whose samples it logs.
    pub fn logging(&self) -> Result<(Option<String>, Vec<String>), ClientError> {
        match self.request(&Request::Logging)? {
            Reply::Logging { file, io_skills } => Ok((file, io_skills)),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Subscribes to the events stream (done by the first [`Client::next_event`] too): every
    /// event published from now on can be read.
    pub fn subscribe(&self) -> Result<(), ClientError> {
        match &self.link {
            Link::Local(l) => l.subscribe(),
            Link::Remote(r) => r.lock().map_err(|_| ClientError::Poisoned)?.subscribe(),
        }
    }

    /// The next event, waiting at most `timeout`; `None` if none came.
    pub fn next_event(&mut self, timeout: Duration) -> Result<Option<Event>, ClientError> {
        let bytes = match &mut self.link {
            Link::Local(l) => l.next_event(timeout)?,
            Link::Remote(r) => r
                .get_mut()
                .map_err(|_| ClientError::Poisoned)?
                .next_event(timeout)?,
        };
        let Some(bytes) = bytes else {
            return Ok(None);
        };
        let ev = control::decode_event(&bytes).map_err(ClientError::Decode)?;
        if self.last_seq != 0 && ev.seq > self.last_seq + 1 {
            self.lost += ev.seq - self.last_seq - 1;
        }
        self.last_seq = ev.seq;
        Ok(Some(ev))
    }

    /// The skills' log lines that arrived since the last call (the first call subscribes to
    /// the domain's log stream and may bring the most recent lines from before).
    pub fn log_lines(&mut self) -> Result<Vec<LogLine>, ClientError> {
        match &mut self.link {
            Link::Local(l) => {
                if l.logs.is_none() {
                    l.logs = Some(LogReader::open(&l.domain, &format!("logs-{}", self.id))?);
                }
                match &l.logs {
                    Some(r) => Ok(r.poll()?),
                    None => Ok(Vec::new()),
                }
            }
            Link::Remote(r) => r.get_mut().map_err(|_| ClientError::Poisoned)?.log_lines(),
        }
    }

    /// Events lost because this client did not read them fast enough (sequence gaps).
    pub fn lost_events(&self) -> u64 {
        self.lost
    }
}
