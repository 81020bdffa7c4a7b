//! The domain's control plane, events and log lines, served to clients on other hosts
//! (`skillfab ctl --remote`, `console --remote`, `skillfab_bridge::connect`).
//!
//! A request arrives as a Zenoh query holding the same encoded request a local client sends;
//! the bridge carries it out through a local [`Client`] of its own per remote client (so a
//! monitor belongs to the remote client that installed it, and one client's `step` does not
//! hold up another's requests) and replies with the manager's encoded answer — or, when there
//! is no answer to give, a [`RemoteFailure`].

use crate::{BridgeError, Stop, warn_once, zenoh_error};
use skillfab_client::{Client, ClientError};
use skillfab_proto::bridge::RemoteFailure;
use skillfab_proto::control::{self, Response};
use skillfab_proto::domain::Domain;
use skillfab_proto::log::LogReader;
use skillfab_proto::names;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh::query::Query;

/// A remote client's worker is let go after this long without a request (its local client,
/// and the monitors that belonged to it, go with it).
const CLIENT_IDLE: Duration = Duration::from_secs(300);

/// Remote clients served at once. Each holds one of the manager's control places
/// ([`skillfab_proto::services::CONTROL_MAX_CLIENTS`]); beyond this many, the one heard
/// from least recently is let go, so remote clients can never crowd out local ones.
const MAX_REMOTE_CLIENTS: usize = 32;

/// How often log lines are picked up (the log stream has no event service: readers poll).
const LOG_POLL: Duration = Duration::from_millis(50);

/// How often the forwarding threads look for the end of the process.
const TICK: Duration = Duration::from_millis(200);

/// Serves remote requests until the process is asked to end; `requests` counts them.
pub(crate) fn serve_control(
    session: &zenoh::Session,
    domain: &Domain,
    requests: Arc<AtomicU64>,
    stop: &Stop,
) -> Result<(), BridgeError> {
    let (tx, rx) = channel::<Query>();
    let _queryable = session
        .declare_queryable(names::remote_control(domain.name()))
        .callback(move |q| {
            let _ = tx.send(q);
        })
        .wait()
        .map_err(|e| zenoh_error("control queryable", e))?;
    let mut workers: HashMap<String, Worker> = HashMap::new();
    while !stop.is_set() {
        // Idle workers are let go here, by the only thread that sends to them: a request is
        // never handed to a worker that is ending (one that is let go finishes its queue).
        workers.retain(|_, w| w.last.elapsed() < CLIENT_IDLE);
        let query = match rx.recv_timeout(TICK) {
            Ok(q) => q,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        requests.fetch_add(1, Ordering::Relaxed);
        let bytes = query
            .payload()
            .map(|p| p.to_bytes().into_owned())
            .unwrap_or_default();
        let envelope = match control::decode_request(&bytes) {
            Ok(e) => e,
            // A malformed request or another protocol version: the manager's own answer.
            Err(e) => {
                reply(&query, &Response::Err(e));
                continue;
            }
        };
        let id = envelope.client.clone();
        if !workers.contains_key(&id)
            && workers.len() >= MAX_REMOTE_CLIENTS
            && let Some(oldest) = workers
                .iter()
                .min_by_key(|(_, w)| w.last)
                .map(|(k, _)| k.clone())
        {
            tracing::info!(
                client = %oldest,
                "{MAX_REMOTE_CLIENTS} remote clients: the least recently heard from is let go"
            );
            workers.remove(&oldest);
        }
        let worker = workers.entry(id.clone()).or_insert_with(|| Worker {
            jobs: spawn_worker(domain.clone()),
            last: Instant::now(),
        });
        worker.last = Instant::now();
        if let Err(back) = worker.jobs.send((query, envelope)) {
            // Its thread is gone (it panicked): said, and a fresh one serves the next request.
            workers.remove(&id);
            fail(&(back.0).0, &RemoteFailure::WorkerFailed);
        }
    }
    Ok(())
}

/// One remote client's worker: its job queue, and when it was last given one.
struct Worker {
    jobs: Sender<(Query, control::RequestEnvelope)>,
    last: Instant,
}

fn reply(query: &Query, response: &Response) {
    // A Zenoh reply belongs to its query: no request number needed.
    let bytes = control::encode_response(0, response);
    if let Err(e) = query.reply(query.key_expr().clone(), bytes).wait() {
        tracing::warn!(error = %e, "remote answer not sent");
    }
}

fn fail(query: &Query, failure: &RemoteFailure) {
    let bytes = postcard::to_allocvec(failure).unwrap_or_default();
    if let Err(e) = query.reply_err(bytes).wait() {
        tracing::warn!(error = %e, "remote failure not sent");
    }
}

/// A worker carrying out one remote client's requests in order.
fn spawn_worker(domain: Domain) -> Sender<(Query, control::RequestEnvelope)> {
    let (tx, rx) = channel();
    std::thread::spawn(move || work(&domain, &rx));
    tx
}

fn work(domain: &Domain, jobs: &Receiver<(Query, control::RequestEnvelope)>) {
    let mut client: Option<Client> = None;
    // Until the dispatcher lets the worker go (and its queue is done).
    while let Ok((query, envelope)) = jobs.recv() {
        if client.is_none() {
            match Client::connect(domain) {
                Ok(c) => client = Some(c),
                Err(e) => {
                    fail(&query, &failure(&e));
                    continue;
                }
            }
        }
        let Some(c) = client.as_ref() else { continue };
        match c.request(&envelope.request) {
            Ok(r) => reply(&query, &Response::Ok(r)),
            Err(ClientError::Refused(e)) => reply(&query, &Response::Err(e)),
            Err(e) => {
                // The manager went away (or another failure): connect afresh next time.
                client = None;
                fail(&query, &failure(&e));
            }
        }
    }
}

fn failure(e: &ClientError) -> RemoteFailure {
    match e {
        ClientError::NoManager(d) => RemoteFailure::NoManager(d.clone()),
        ClientError::Timeout(t) => RemoteFailure::Timeout(t.as_millis() as u64),
        ClientError::Full { max } => RemoteFailure::Full(*max as u32),
        other => {
            tracing::warn!(
                error = other as &dyn std::error::Error,
                "a remote request failed here"
            );
            RemoteFailure::BridgeClient
        }
    }
}

/// Forwards every event of the domain to `skillfab/<domain>/events` until the process is
/// asked to end (reconnecting to a manager that left and came back).
pub(crate) fn forward_events(
    session: &zenoh::Session,
    domain: &Domain,
    stop: &Stop,
) -> Result<(), BridgeError> {
    let publisher = session
        .declare_publisher(names::remote_events(domain.name()))
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .map_err(|e| zenoh_error("events publisher", e))?;
    let mut client: Option<Client> = None;
    let mut failing = false;
    while !stop.is_set() {
        let Some(c) = client.as_mut() else {
            client = Client::connect(domain)
                .ok()
                .and_then(|c| c.subscribe().ok().map(|()| c));
            if client.is_none() {
                std::thread::sleep(TICK);
            }
            continue;
        };
        match c.next_event(TICK) {
            Ok(Some(ev)) => {
                if let Ok(bytes) = control::encode_event(&ev) {
                    match publisher.put(bytes).wait() {
                        Ok(()) => failing = false,
                        Err(e) => warn_once(&mut failing, "event not forwarded", &e),
                    }
                }
            }
            Ok(None) => {}
            Err(_) => client = None,
        }
    }
    Ok(())
}

/// Forwards the domain's log lines to `skillfab/<domain>/logs` until the process is asked to
/// end.
pub(crate) fn forward_logs(
    session: &zenoh::Session,
    domain: &Domain,
    bridge: &str,
    stop: &Stop,
) -> Result<(), BridgeError> {
    let publisher = session
        .declare_publisher(names::remote_logs(domain.name()))
        .wait()
        .map_err(|e| zenoh_error("logs publisher", e))?;
    let mut reader: Option<LogReader> = None;
    let mut failing = false;
    while !stop.is_set() {
        std::thread::sleep(LOG_POLL);
        let lines = match reader.as_ref() {
            Some(r) => r.poll(),
            None => LogReader::open(domain, &format!("{bridge}-logs")).and_then(|r| {
                let lines = r.poll();
                reader = Some(r);
                lines
            }),
        };
        let lines = match lines {
            Ok(lines) => lines,
            Err(e) => {
                // Opened afresh at the next poll; said once per run of failures.
                reader = None;
                warn_once(&mut failing, "log lines not read", &e);
                continue;
            }
        };
        for line in lines {
            if let Ok(bytes) = skillfab_proto::log::encode(&line) {
                match publisher.put(bytes).wait() {
                    Ok(()) => failing = false,
                    Err(e) => warn_once(&mut failing, "log line not forwarded", &e),
                }
            }
        }
    }
    Ok(())
}
