//! `skillfab bridge`: one domain's end of a link to other hosts, over Zenoh.
//!
//! Layout:
//! - this file: the options ([`BridgeArgs`]), the errors, [`run`] (one thread per job);
//! - [`export`](crate::export): local topics put on Zenoh as they are published;
//! - [`import`](crate::import): remote topics republished here by the bridge's own async skill;
//! - [`remote`](crate::remote): the control plane, events and logs served to remote clients;
//! - [`figures`](crate::figures): samples, losses and latency per topic, reported to the
//!   manager (`ctl stats`);
//! - [`link`]: the client's side — a [`Client`] of a domain on another host, through that
//!   domain's bridge ([`connect`], [`address`]), and the Zenoh options both sides share.
//!
//! The only crate of the workspace that links Zenoh: `skillfab` has it with its `bridge`
//! feature, and programs that never leave their host (skills, the C library) never do.
//!
//! Sync skills stay on their manager's host: the cycle is a shared-memory protocol. A remote
//! producer reaches local skills as an async producer does (latest sample, with its age); an
//! actuator channel cannot be imported.

#![warn(missing_docs)]

mod export;
mod figures;
mod import;
pub mod link;
mod remote;

pub use link::{ZenohMode, ZenohOptions, address, connect};

use figures::TopicFigures;
use skillfab_client::{Client, ClientError};
use skillfab_proto::bridge::BridgeStats;
use skillfab_proto::control::Request;
use skillfab_proto::domain::Domain;
use skillfab_proto::{names, services};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// `skillfab bridge` options.
#[derive(clap::Args, Debug, Clone)]
pub struct BridgeArgs {
    /// The bridge's name in its domain (its importing skill's instance name).
    #[arg(long, default_value = "bridge")]
    pub name: String,
    /// Zenoh endpoint to connect to, e.g. `tcp/10.0.0.2:7447` (repeatable; retried for ever).
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Zenoh endpoint to listen on, e.g. `tcp/0.0.0.0:7447` (repeatable; none unless asked).
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// A Zenoh configuration file (TLS, user/password, scouting, …); the options above are
    /// applied on top of it.
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
    /// Join as a Zenoh client (through a router) rather than as a peer.
    #[arg(long)]
    pub client_mode: bool,
    /// Local topics to send out (comma-separated or repeated).
    #[arg(long, value_delimiter = ',', value_name = "TOPIC")]
    pub export: Vec<String>,
    /// Remote topics to republish here (comma-separated or repeated).
    #[arg(long, value_delimiter = ',', value_name = "TOPIC")]
    pub import: Vec<String>,
    /// The remote domain the imports come from (default: a domain of the same name).
    #[arg(long, value_name = "DOMAIN")]
    pub from: Option<String>,
    /// Do not serve this domain's control plane, events and logs to remote clients.
    #[arg(long)]
    pub no_control: bool,
}

/// Why the bridge stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BridgeError {
    /// Zenoh refused something.
    #[error("zenoh: {what}: {cause}")]
    Zenoh {
        /// What was being done.
        what: String,
        /// Zenoh's error.
        cause: zenoh::Error,
    },
    /// The local fabric (iceoryx2) failed.
    #[error(transparent)]
    Fabric(#[from] skillfab_proto::Error),
    /// The local manager could not be asked.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// The bridge's importing skill could not be declared (a remote schema it cannot take).
    #[error("the importing skill: {0}")]
    Declare(#[from] skill_sdk::foreign::DeclError),
    /// The bridge's importing skill failed to run.
    #[error("the importing skill: {0}")]
    Skill(#[from] skill_sdk::foreign::RunError),
    /// The remote side.
    #[error("{0}")]
    Remote(String),
    /// A bad option.
    #[error("{0}")]
    Usage(String),
}

pub(crate) fn zenoh_error(what: &str, e: zenoh::Error) -> BridgeError {
    BridgeError::Zenoh {
        what: what.to_string(),
        cause: e,
    }
}

/// Logs the first failure of a run of them (`failing` is cleared by the next success).
pub(crate) fn warn_once(failing: &mut bool, what: &str, e: &dyn std::fmt::Display) {
    if !*failing {
        tracing::warn!(error = %e, "{what} (said once until it works again)");
        *failing = true;
    }
}

/// Set when the bridge is to end, seen by its threads. Only the main thread reads iceoryx2's
/// termination flag (a read clears it); it sets this one for the others.
#[derive(Clone, Default)]
pub(crate) struct Stop(Arc<AtomicBool>);

impl Stop {
    /// Whether the bridge is ending.
    pub(crate) fn is_set(&self) -> bool {
        self.0.load(Ordering::Acquire)
    }

    fn set(&self) {
        self.0.store(true, Ordering::Release);
    }
}

/// The bridge's threads: on every way out of [`run`] (an error included) they are told to
/// stop and joined.
struct Threads {
    stop: Stop,
    handles: Vec<std::thread::JoinHandle<()>>,
}

impl Threads {
    /// Runs `job` on a thread of its own; its error is logged and kept for the reports.
    fn spawn(
        &mut self,
        what: &'static str,
        errors: &Errors,
        job: impl FnOnce(Stop) -> Result<(), BridgeError> + Send + 'static,
    ) {
        let (stop, errors) = (self.stop.clone(), errors.clone());
        self.handles.push(std::thread::spawn(move || {
            if let Err(e) = job(stop) {
                tracing::error!(error = %e, "{what} stopped");
                errors.push(format!("{what} stopped: {e}"));
            }
        }));
    }
}

impl Drop for Threads {
    fn drop(&mut self) {
        self.stop.set();
        for t in self.handles.drain(..) {
            let _ = t.join();
        }
    }
}

/// Why topics are not carried, shared by the threads that find out and the reporter.
#[derive(Clone, Default)]
pub(crate) struct Errors(Arc<std::sync::Mutex<Vec<String>>>);

impl Errors {
    pub(crate) fn push(&self, why: String) {
        if let Ok(mut e) = self.0.lock() {
            e.push(why);
        }
    }

    fn all(&self) -> Vec<String> {
        self.0.lock().map(|e| e.clone()).unwrap_or_default()
    }
}

/// How often the bridge reports its figures to the manager.
const REPORT_EVERY: Duration = Duration::from_secs(1);

/// How long a bridge waits for an answer about a remote topic's schema before asking again.
const SCHEMA_WAIT: Duration = Duration::from_secs(2);

/// Runs the bridge of `domain` until SIGINT/SIGTERM.
pub fn run(domain: &Domain, args: &BridgeArgs) -> Result<(), BridgeError> {
    let domain = domain.clone();
    names::check_name("bridge", &args.name, false)?;
    for t in args.export.iter().chain(&args.import) {
        names::check_name("topic", t, true)?;
    }
    let from = args
        .from
        .clone()
        .unwrap_or_else(|| domain.name().to_string());
    names::check_name("domain", &from, false)?;
    if let Some(why) = args
        .import
        .iter()
        .find_map(|t| import::never_importable(t, &from))
    {
        return Err(BridgeError::Usage(why));
    }
    let options = ZenohOptions {
        mode: if args.client_mode {
            ZenohMode::Client
        } else {
            ZenohMode::Peer
        },
        connect: args.connect.clone(),
        listen: args.listen.clone(),
        config_file: args.zenoh_config.clone(),
    };
    let session = link::open(&options)?;
    tracing::info!(domain = %domain, zid = %session.zid(), "bridge up");
    // Termination is seen through iceoryx2's handler, installed by a node's wait.
    let node = services::node(&domain, &format!("{}-main", args.name))?;
    let local = wait_for_manager(&domain, &node)?;
    let Some(local) = local else { return Ok(()) };

    let requests = Arc::new(AtomicU64::new(0));
    let errors = Errors::default();
    let mut threads = Threads {
        stop: Stop::default(),
        handles: Vec::new(),
    };
    // The control plane first: a topic still waited for holds up nothing else.
    if !args.no_control {
        let (s, d, r) = (session.clone(), domain.clone(), requests.clone());
        threads.spawn("remote control", &errors, move |stop| {
            remote::serve_control(&s, &d, r, &stop)
        });
        let (s, d) = (session.clone(), domain.clone());
        threads.spawn("event forwarding", &errors, move |stop| {
            remote::forward_events(&s, &d, &stop)
        });
        let (s, d, n) = (session.clone(), domain.clone(), args.name.clone());
        threads.spawn("log forwarding", &errors, move |stop| {
            remote::forward_logs(&s, &d, &n, &stop)
        });
    }
    let mut exports = Vec::new();
    for topic in &args.export {
        // The type is known once a local skill declares the topic (the export's thread asks).
        let figures = TopicFigures::new(topic, "", "");
        exports.push(figures.clone());
        let (session, domain, name, topic) = (
            session.clone(),
            domain.clone(),
            args.name.clone(),
            topic.clone(),
        );
        threads.spawn("export", &errors, move |stop| {
            export::serve(&session, &domain, &name, &topic, &figures, &stop)
        });
    }

    let mut imports = Vec::new();
    for topic in &args.import {
        let schema = loop {
            match import::remote_schema(&session, &from, topic, SCHEMA_WAIT) {
                Ok(Some(s)) => break Some(s),
                Ok(None) => {}
                // An exporter answered nonsense: this topic is refused, the others go on.
                Err(e) => {
                    tracing::error!("{e}");
                    errors.push(e.to_string());
                    break None;
                }
            }
            tracing::info!(topic, from = %from, "waiting for the remote bridge that exports the topic");
            if node.wait(Duration::from_millis(100)).is_err() {
                return Ok(());
            }
        };
        let Some(schema) = schema else { continue };
        let import = import::Import {
            topic: topic.clone(),
            from: from.clone(),
            schema,
        };
        match import::refusal(&import, &local.list()?, &args.name) {
            Some(why) => {
                tracing::error!("{why}");
                errors.push(why);
            }
            None => imports.push(import),
        }
    }
    let import_figures: Vec<TopicFigures> = imports
        .iter()
        .map(|i| TopicFigures::new(&i.topic, &i.from, &i.schema.type_name))
        .collect();

    let report = Reporter {
        name: args.name.clone(),
        domain: domain.clone(),
        session: session.clone(),
        exports,
        imports: import_figures.clone(),
        requests,
        errors: errors.clone(),
    };
    drop(local);
    threads.spawn("reports", &errors, move |stop| {
        report.run(&stop);
        Ok(())
    });

    if imports.is_empty() {
        while node.wait(Duration::from_millis(200)).is_ok() {}
    } else {
        let skill_args = vec![
            "skillfab-bridge".to_string(),
            "--name".into(),
            args.name.clone(),
            "--domain".into(),
            domain.name().to_string(),
        ];
        import::serve(&session, &imports, &import_figures, skill_args)?;
    }
    tracing::info!("bridge leaving");
    drop(threads);
    session
        .close()
        .wait()
        .map_err(|e| zenoh_error("close", e))?;
    Ok(())
}

/// A client of the local manager, once there is one (`None`: asked to end while waiting).
fn wait_for_manager(
    domain: &Domain,
    node: &iceoryx2::node::Node<iceoryx2::prelude::ipc::Service>,
) -> Result<Option<Client>, BridgeError> {
    let mut told = false;
    loop {
        match Client::connect(domain) {
            Ok(c) => return Ok(Some(c)),
            Err(ClientError::NoManager(_)) => {}
            Err(e) => return Err(e.into()),
        }
        if !told {
            tracing::info!("waiting for the manager of domain '{domain}'");
            told = true;
        }
        if node.wait(Duration::from_millis(200)).is_err() {
            return Ok(None);
        }
    }
}

/// Sends the bridge's figures to its manager about once a second.
struct Reporter {
    name: String,
    domain: Domain,
    session: zenoh::Session,
    exports: Vec<TopicFigures>,
    imports: Vec<TopicFigures>,
    requests: Arc<AtomicU64>,
    errors: Errors,
}

impl Reporter {
    fn run(self, stop: &Stop) {
        // A client is not `Send`: this thread has its own.
        let mut client = Client::connect(&self.domain).ok();
        let mut next = Instant::now();
        // Whether the link was up at the last look, and ever.
        let (mut was_up, mut ever_up, mut reconnects) = (false, false, 0u64);
        while !stop.is_set() {
            let now = Instant::now();
            if now < next {
                std::thread::sleep((next - now).min(Duration::from_millis(200)));
                continue;
            }
            next = now + REPORT_EVERY;
            let info = self.session.info();
            let links = info.peers_zid().wait().count() + info.routers_zid().wait().count();
            match (links > 0, was_up) {
                (false, true) => tracing::warn!("Zenoh link lost; reconnecting"),
                (true, false) if ever_up => {
                    reconnects += 1;
                    tracing::info!("Zenoh link back");
                }
                _ => {}
            }
            was_up = links > 0;
            ever_up |= was_up;
            let stats = BridgeStats {
                name: self.name.clone(),
                links: links as u32,
                reconnects,
                exports: self.exports.iter().map(TopicFigures::report).collect(),
                imports: self.imports.iter().map(TopicFigures::report).collect(),
                requests: self.requests.load(Ordering::Relaxed),
                errors: self.errors.all(),
            };
            if client.is_none() {
                client = Client::connect(&self.domain).ok();
            }
            // A manager that left is connected to afresh at the next report.
            if let Some(c) = client.as_ref()
                && c.request(&Request::BridgeReport(stats)).is_err()
            {
                client = None;
            }
        }
    }
}
