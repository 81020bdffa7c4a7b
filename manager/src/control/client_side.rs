//! The control thread: the clients' side of the manager (request server, events publisher,
//! client wake-ups), so talking to clients never holds up a cycle.

use super::*;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::BackpressureStrategy;
use skillfab_proto::board::{Board, pid_alive};
use skillfab_proto::control;
use std::collections::{HashMap, VecDeque};

/// The control thread's ports: the clients' side of the manager.
pub(super) struct ClientSide {
    _node: Node<ipc::Service>,
    server: Server<ipc::Service, [u8], (), [u8], ()>,
    events: Publisher<ipc::Service, [u8], ()>,
    events_notifier: Notifier<ipc::Service>,
    listener: Listener<ipc::Service>,
    /// The board, for the engine's doorbell (opened at the first request: the engine
    /// creates the board after this thread's services exist).
    board: Option<Board>,
    prefix: String,
    /// One notifier per client that asked something: wakes it when its answer is in.
    clients: HashMap<String, Notifier<ipc::Service>>,
    /// Requests handed to the engine, by id: the request to answer, and who sent it under
    /// which number.
    pending: HashMap<u64, (Pending, Option<(String, u64)>)>,
    /// The same, by (client, number): a repeat of a request still being carried out takes
    /// the first one's place (the client waits on the repeat).
    in_flight: HashMap<(String, u64), u64>,
    /// The last answers given to each client, by request number, to give again when the
    /// client asks again (the answer did not reach it) instead of carrying the request out
    /// twice.
    answered: HashMap<String, VecDeque<(u64, Vec<u8>)>>,
    next_id: u64,
}

/// Answers kept per client for repeats: a client waits for each answer before it asks again,
/// so the last few are all a repeat can be about.
const ANSWERS_KEPT: usize = 4;

impl ClientSide {
    pub(super) fn open(domain: &Domain) -> Result<ClientSide, SdkError> {
        let node = services::node(domain, "skillfab-control")?;
        let server = services::control_service(&node)?
            .server_builder()
            .initial_max_slice_len(control::MAX_ANSWER_BYTES)
            .allocation_strategy(AllocationStrategy::Static)
            // A client whose answer queue is full (it stopped reading) loses that answer; the
            // default, retrying until it reads, would stall every other client behind it.
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .max_loaned_responses_per_request(1)
            .create()
            .map_err(|e| SdkError::transport("control server", e))?;
        let events = services::events_service(&node)?
            .publisher_builder()
            .initial_max_slice_len(services::EVENT_MAX_BYTES)
            .allocation_strategy(AllocationStrategy::Static)
            .create()
            .map_err(|e| SdkError::transport("events publisher", e))?;
        Ok(ClientSide {
            events_notifier: services::notifier(&node, &names::events())?,
            listener: services::listener(&node, &names::control())?,
            board: None,
            prefix: domain.prefix(),
            server,
            events,
            _node: node,
            clients: HashMap::new(),
            pending: HashMap::new(),
            in_flight: HashMap::new(),
            answered: HashMap::new(),
            next_id: 0,
        })
    }

    pub(super) fn serve(
        &mut self,
        to_engine: &Sender<Incoming>,
        from_engine: &Receiver<Outgoing>,
        stop: &AtomicBool,
    ) {
        let mut last_sweep = std::time::Instant::now();
        while !stop.load(Ordering::Acquire) {
            // Signals are the engine's business; this thread only waits for pokes.
            let _ = self
                .listener
                .timed_wait(|_| {}, std::time::Duration::from_millis(500));
            let mut forwarded = false;
            loop {
                let request = match self.server.receive() {
                    Ok(Some(r)) => r,
                    Ok(None) => break,
                    Err(e) => {
                        tracing::warn!(error = ?e, "control receive failed");
                        break;
                    }
                };
                self.next_id += 1;
                let bytes = request.payload();
                let decoded = if bytes.len() > control::MAX_REQUEST_BYTES {
                    Err(control::ControlError::RequestTooLarge {
                        bytes: bytes.len(),
                        max: control::MAX_REQUEST_BYTES,
                    })
                } else {
                    control::decode_request(bytes)
                };
                let (from, request_body) = match decoded {
                    Ok(env) => (Some((env.client, env.seq)), Ok(env.request)),
                    Err(e) => (None, Err(e)),
                };
                if let Some((client, seq)) = &from {
                    if let Some(bytes) = self
                        .answered
                        .get(client)
                        .and_then(|a| a.iter().find(|(n, _)| n == seq).map(|(_, b)| b.clone()))
                    {
                        self.send_answer(&request, Some(client), &bytes);
                        continue;
                    }
                    if let Some(id) = self.in_flight.get(&(client.clone(), *seq))
                        && let Some(first) = self.pending.get_mut(id)
                    {
                        first.0 = request;
                        continue;
                    }
                    self.in_flight.insert((client.clone(), *seq), self.next_id);
                }
                let client = from.as_ref().map(|(c, _)| c.clone());
                self.pending.insert(self.next_id, (request, from));
                let _ = to_engine.send(Incoming {
                    id: self.next_id,
                    client,
                    request: request_body,
                });
                forwarded = true;
            }
            if forwarded {
                self.wake_engine();
            }
            while let Ok(out) = from_engine.try_recv() {
                match out {
                    Outgoing::Answer {
                        id,
                        client,
                        response,
                    } => {
                        if let Some((req, from)) = self.pending.remove(&id) {
                            let seq = from.as_ref().map_or(0, |(_, seq)| *seq);
                            let bytes = control::encode_response(seq, &response);
                            self.send_answer(&req, client.as_deref(), &bytes);
                            if let Some((client, seq)) = from {
                                self.in_flight.remove(&(client.clone(), seq));
                                let kept = self.answered.entry(client).or_default();
                                if kept.len() == ANSWERS_KEPT {
                                    kept.pop_front();
                                }
                                kept.push_back((seq, bytes));
                            }
                        }
                    }
                    Outgoing::Events(events) => self.publish(&events),
                }
            }
            if last_sweep.elapsed() > std::time::Duration::from_secs(1) {
                last_sweep = std::time::Instant::now();
                self.clients
                    .retain(|c, _| client_pid(c).is_none_or(pid_alive));
                self.answered
                    .retain(|c, _| client_pid(c).is_none_or(pid_alive));
            }
        }
    }

    /// Rings the engine's doorbell.
    fn wake_engine(&mut self) {
        if self.board.is_none() {
            self.board = Board::open(&self.prefix).ok();
        }
        match &self.board {
            Some(b) => b.ring_manager(),
            None => tracing::warn!("no board yet: the engine sees the request at its next tick"),
        }
    }

    fn send_answer(&mut self, request: &Pending, client: Option<&str>, bytes: &[u8]) {
        // The client's wake-up service exists while it waits: open it (never create it).
        if let Some(c) = client
            && !self.clients.contains_key(c)
        {
            match services::notifier_existing(&self._node, &names::client(c)) {
                Ok(n) => {
                    self.clients.insert(c.to_string(), n);
                }
                Err(e) => tracing::debug!(client = c, error = %e, "client has no wake-up service"),
            }
        }
        let sent = request
            .loan_slice_uninit(bytes.len())
            .map(|r| r.write_from_slice(bytes))
            .map_err(|e| format!("{e:?}"))
            .and_then(|r| r.send().map_err(|e| format!("{e:?}")));
        if let Err(e) = sent {
            tracing::warn!(error = %e, "control answer failed");
        }
        if let Some(n) = client.and_then(|c| self.clients.get(c)) {
            let _ = n.notify();
        }
    }

    fn publish(&mut self, events: &[Event]) {
        for event in events {
            let sent = control::encode_event_within(event, services::EVENT_MAX_BYTES)
                .ok_or_else(|| format!("larger than {} bytes", services::EVENT_MAX_BYTES))
                .and_then(|b| {
                    self.events
                        .loan_slice_uninit(b.len())
                        .map(|s| s.write_from_slice(&b))
                        .map_err(|e| format!("{e:?}"))
                })
                .and_then(|s| s.send().map_err(|e| format!("{e:?}")));
            if let Err(e) = sent {
                tracing::warn!(seq = event.seq, error = %e, "event not published");
            }
        }
        let _ = self.events_notifier.notify();
    }
}
