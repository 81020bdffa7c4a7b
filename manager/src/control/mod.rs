//! The manager's control plane: the transport of requests, answers and events.
//!
//! A control thread owns the client-facing ports (request server, events publisher, client
//! wake-ups) and forwards requests to the engine over a channel; the engine carries them out
//! between cycles (`engine::requests`), so a request never races a cycle, and hands answers and
//! events back through [`ControlPlane`]. A `step` request is answered when its cycles are done.
//! Events get consecutive sequence numbers in the order the engine queued them. Nothing here
//! knows the manager's state.

mod client_side;

use client_side::ClientSide;
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::node::Node;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use skillfab_proto::control::{ControlError, Event, Reply, Request, Response};
use skillfab_proto::domain::Domain;
use skillfab_proto::{Error as SdkError, names, services};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;

pub(super) type Pending = ActiveRequest<ipc::Service, [u8], (), [u8], ()>;

/// A request handed from the control thread to the engine.
pub(crate) struct Incoming {
    pub(crate) id: u64,
    pub(crate) client: Option<String>,
    pub(crate) request: Result<Request, ControlError>,
}

/// What the engine hands back to the control thread.
pub(crate) enum Outgoing {
    Answer {
        id: u64,
        client: Option<String>,
        response: Response,
    },
    Events(Vec<Event>),
}

/// The engine's end of the control plane. Requests are received, and answers and events
/// sent, on a thread of their own: talking to clients can block (a client that leaves while
/// its connection is being set up makes iceoryx2 wait), and that must never hold up a cycle.
pub struct ControlPlane {
    from_clients: Receiver<Incoming>,
    to_clients: Sender<Outgoing>,
    /// Wakes the control thread (an event on `skillfab/control`).
    poke: Notifier<ipc::Service>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    /// `step` requests waiting for their cycles.
    steps: Vec<(u64, Option<String>)>,
}

impl ControlPlane {
    /// Opens the control and events services on a new thread; returns once they exist.
    pub fn new(domain: &Domain, node: &Node<ipc::Service>) -> Result<ControlPlane, SdkError> {
        let (to_engine, from_clients) = channel();
        let (to_clients, from_engine) = channel();
        let (ready_tx, ready_rx) = channel();
        let stop = Arc::new(AtomicBool::new(false));
        let (d, st) = (domain.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("control".into())
            .spawn(move || {
                let _span = tracing::info_span!("control", domain = %d).entered();
                match ClientSide::open(&d) {
                    Ok(mut side) => {
                        let _ = ready_tx.send(Ok(()));
                        side.serve(&to_engine, &from_engine, &st);
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                    }
                }
            })
            .map_err(|e| SdkError::transport("control thread", e))?;
        ready_rx
            .recv()
            .map_err(|e| SdkError::transport("control thread start", e))??;
        Ok(ControlPlane {
            from_clients,
            to_clients,
            poke: services::notifier(node, &names::control())?,
            stop,
            thread: Some(thread),
            steps: Vec::new(),
        })
    }

    /// The requests that arrived since the last call, oldest first.
    pub(crate) fn arrived(&self) -> Vec<Incoming> {
        self.from_clients.try_iter().collect()
    }

    /// Answers requests (the engine has made what it answers durable first).
    pub(crate) fn answer(&self, answers: Vec<Outgoing>) {
        for a in answers {
            let _ = self.to_clients.send(a);
        }
        let _ = self.poke.notify();
    }

    /// Keeps a `step` request's answer until [`ControlPlane::flush`] is told its cycles are
    /// done.
    pub(crate) fn answer_when_stepped(&mut self, id: u64, client: Option<String>) {
        self.steps.push((id, client));
    }

    /// Hands `events` to the control thread, and, when `stepped` says at which cycle the
    /// last `step` ended, the answers of the `step` requests waiting for it.
    pub(crate) fn flush(&mut self, events: Vec<Event>, stepped: Option<u64>) {
        let mut poke = false;
        if !events.is_empty() {
            let _ = self.to_clients.send(Outgoing::Events(events));
            poke = true;
        }
        if let Some(cycle) = stepped
            && !self.steps.is_empty()
        {
            for (id, client) in std::mem::take(&mut self.steps) {
                let _ = self.to_clients.send(Outgoing::Answer {
                    id,
                    client,
                    response: Ok(Reply::Stepped(cycle)),
                });
            }
            poke = true;
        }
        if poke {
            let _ = self.poke.notify();
        }
    }

    /// Stops the control thread (its node closes with it).
    pub(crate) fn close(&mut self) {
        self.stop.store(true, Ordering::Release);
        let _ = self.poke.notify();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for ControlPlane {
    fn drop(&mut self) {
        self.close();
    }
}

/// A client id is `<pid>-<n>`; the pid tells whether it still lives.
pub(crate) fn client_pid(client: &str) -> Option<u32> {
    client.split('-').next()?.parse().ok()
}
