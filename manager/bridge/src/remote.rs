//! The domain's control plane, events and log lines, served to clients on other hosts
//! (`skillfab ctl --remote`, `console --remote`, `Client::connect_remote`).
//!
//! A request arrives as a Zenoh query holding the same encoded request a local client sends;
//! the bridge carries it out through a local [`Client`] of its own per remote client (so a
//! monitor belongs to the remote client that installed it, and one client's `step` does not
//! hold up another's requests) and replies with the manager's encoded answer — or, when there
//! is no answer to give, a [`RemoteFailure`].

use crate::{BridgeError, zenoh_error};
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
use std::time::Duration;
use zenoh::Wait;
use zenoh::query::Query;

/// A remote client's worker ends after this long without a request (its local client, and
/// the monitors that belonged to it, go with it).
const CLIENT_IDLE: Duration = Duration::from_secs(300);

/// How often log lines are picked up (the log stream has no event service: readers poll).
const LOG_POLL: Duration = Duration::from_millis(50);

/// How often the forwarding threads look for the end of the process.
const TICK: Duration = Duration::from_millis(200);

/// Serves remote requests until the process is asked to end; `requests` counts them.
pub(crate) fn serve_control(
    session: &zenoh::Session,
    domain: &Domain,
    requests: Arc<AtomicU64>,
) -> Result<(), BridgeError> {
    let (tx, rx) = channel::<Query>();
    let _queryable = session
        .declare_queryable(names::remote_control(domain.name()))
        .callback(move |q| {
            let _ = tx.send(q);
        })
        .wait()
        .map_err(|e| zenoh_error("control queryable", e))?;
    let mut workers: HashMap<String, Sender<(Query, control::RequestEnvelope)>> = HashMap::new();
    while !crate::stopping() {
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
        let mut job = (query, envelope);
        // A worker that ended (idle) is replaced; the job goes to the new one.
        for _ in 0..2 {
            let worker = workers
                .entry(job.1.client.clone())
                .or_insert_with(|| spawn_worker(domain.clone()));
            match worker.send(job) {
                Ok(()) => break,
                Err(back) => {
                    job = back.0;
                    workers.remove(&job.1.client);
                }
            }
        }
    }
    Ok(())
}

fn reply(query: &Query, response: &Response) {
    let bytes = control::encode_response(response);
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
    while let Ok((query, envelope)) = jobs.recv_timeout(CLIENT_IDLE) {
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
        other => RemoteFailure::Other(other.to_string()),
    }
}

/// Forwards every event of the domain to `skillfab/<domain>/events` until the process is
/// asked to end (reconnecting to a manager that left and came back).
pub(crate) fn forward_events(session: &zenoh::Session, domain: &Domain) -> Result<(), BridgeError> {
    let publisher = session
        .declare_publisher(names::remote_events(domain.name()))
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .map_err(|e| zenoh_error("events publisher", e))?;
    let mut client: Option<Client> = None;
    while !crate::stopping() {
        let Some(c) = client.as_mut() else {
            client = Client::connect(domain)
                .ok()
                .and_then(|mut c| c.subscribe().ok().map(|()| c));
            if client.is_none() {
                std::thread::sleep(TICK);
            }
            continue;
        };
        match c.next_event(TICK) {
            Ok(Some(ev)) => {
                if let Ok(bytes) = control::encode_event(&ev)
                    && let Err(e) = publisher.put(bytes).wait()
                {
                    tracing::warn!(error = %e, "event not forwarded");
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
) -> Result<(), BridgeError> {
    let publisher = session
        .declare_publisher(names::remote_logs(domain.name()))
        .wait()
        .map_err(|e| zenoh_error("logs publisher", e))?;
    let reader = LogReader::open(domain, &format!("{bridge}-logs"))?;
    while !crate::stopping() {
        std::thread::sleep(LOG_POLL);
        for line in reader.poll()? {
            if let Ok(bytes) = skillfab_proto::log::encode(&line)
                && let Err(e) = publisher.put(bytes).wait()
            {
                tracing::warn!(error = %e, "log line not forwarded");
            }
        }
    }
    Ok(())
}
