//! The manager's side of the control plane: serves requests, publishes events.
//!
//! A control thread owns the client-facing ports (request server, events publisher, client
//! wake-ups) and forwards requests to the engine over a channel; the engine carries them out
//! between cycles, so a request never races a cycle, and hands answers and events back. Every
//! refusal is a precise [`ControlError`]. A `step` request is answered when its cycles are
//! done. Events get consecutive sequence numbers in the order the engine queued them.

use crate::engine::Manager;
use crate::monitors::expr;
use crate::monitors::{Monitor, Resolved};
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;
use skillfab_proto::board::pid_alive;
use skillfab_proto::control::{
    self, ChannelStat, ControlError, Event, EventKind, ParamArg, ParamErrorText, PortInfo, Reply,
    Request, Response, SkillInfo, SkillStat, SkillState, Stats,
};
use skillfab_proto::domain::Domain;
use skillfab_proto::header::now_ns;
use skillfab_proto::param::{ParamError, ParamValue, check_bounds};
use skillfab_proto::services::RawReader;
use skillfab_proto::value::{self, FieldPath, OutputPath, Value};
use skillfab_proto::{Error as SdkError, names, services};
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;

type Pending = ActiveRequest<ipc::Service, [u8], (), [u8], ()>;

/// Most cycle latencies one `Latencies` answer carries (a console's history).
const MAX_LATENCIES: usize = 1024;

/// A request handed from the control thread to the engine.
pub(crate) struct Incoming {
    id: u64,
    client: Option<String>,
    request: Result<Request, ControlError>,
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
    seq: u64,
    /// `step` requests waiting for their cycles.
    steps: Vec<(u64, Option<String>)>,
}

fn transport(what: &str, e: impl std::fmt::Debug) -> SdkError {
    SdkError::Transport {
        what: what.to_string(),
        detail: format!("{e:?}"),
    }
}

/// A client id is `<pid>-<n>`; the pid tells whether it still lives.
fn client_pid(client: &str) -> Option<u32> {
    client.split('-').next()?.parse().ok()
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
            .map_err(|e| transport("control thread", e))?;
        ready_rx
            .recv()
            .map_err(|e| transport("control thread start", e))??;
        Ok(ControlPlane {
            from_clients,
            to_clients,
            poke: services::notifier(node, &names::control())?,
            stop,
            thread: Some(thread),
            seq: 0,
            steps: Vec::new(),
        })
    }

    /// Carries out every request that arrived.
    pub fn serve(&mut self, m: &mut Manager) {
        let mut answered = false;
        while let Ok(inc) = self.from_clients.try_recv() {
            let response = match inc.request {
                Err(e) => Err(e),
                Ok(Request::Step(n)) if n > 0 => {
                    m.stop_at = Some(m.in_progress() + n);
                    m.set_paused(false);
                    self.steps.push((inc.id, inc.client));
                    continue;
                }
                Ok(request) => m.handle(inc.client.as_deref().unwrap_or("?"), request),
            };
            if let Err(e) = &response {
                tracing::info!(client = inc.client.as_deref().unwrap_or("?"), error = %e, "request refused");
            }
            let _ = self.to_clients.send(Outgoing::Answer {
                id: inc.id,
                client: inc.client,
                response,
            });
            answered = true;
        }
        if answered {
            let _ = self.poke.notify();
        }
    }

    /// Hands queued events and finished `step` answers to the control thread.
    pub fn flush(&mut self, m: &mut Manager) {
        let mut poke = false;
        if !m.outbox.is_empty() {
            let events = std::mem::take(&mut m.outbox)
                .into_iter()
                .map(|kind| {
                    self.seq += 1;
                    Event {
                        seq: self.seq,
                        cycle: m.cycle,
                        time_ns: now_ns(),
                        kind,
                    }
                })
                .collect();
            m.events_published = self.seq;
            let _ = self.to_clients.send(Outgoing::Events(events));
            poke = true;
        }
        if m.stop_at.is_none() && !self.steps.is_empty() {
            for (id, client) in std::mem::take(&mut self.steps) {
                let _ = self.to_clients.send(Outgoing::Answer {
                    id,
                    client,
                    response: Ok(Reply::Stepped(m.cycle)),
                });
            }
            poke = true;
        }
        if poke {
            let _ = self.poke.notify();
        }
    }

    /// Drops the monitors of clients whose process is gone.
    pub fn forget_dead_clients(&mut self, m: &mut Manager) {
        let before = m.monitors.len();
        m.monitors
            .retain(|mon| client_pid(&mon.client).is_none_or(pid_alive));
        if m.monitors.len() != before {
            tracing::info!(
                removed = before - m.monitors.len(),
                "monitors of departed clients removed"
            );
        }
    }
}

impl Drop for ControlPlane {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        let _ = self.poke.notify();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The control thread's ports: the clients' side of the manager.
struct ClientSide {
    _node: Node<ipc::Service>,
    server: Server<ipc::Service, [u8], (), [u8], ()>,
    events: Publisher<ipc::Service, [u8], ()>,
    events_notifier: Notifier<ipc::Service>,
    listener: Listener<ipc::Service>,
    wake_engine: Notifier<ipc::Service>,
    /// One notifier per client that asked something: wakes it when its answer is in.
    clients: HashMap<String, Notifier<ipc::Service>>,
    pending: HashMap<u64, Pending>,
    next_id: u64,
}

impl ClientSide {
    fn open(domain: &Domain) -> Result<ClientSide, SdkError> {
        let node = services::node(domain, "skillfab-control")?;
        let server = services::control_service(&node)?
            .server_builder()
            .initial_max_slice_len(4096)
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| transport("control server", e))?;
        let events = services::events_service(&node)?
            .publisher_builder()
            .initial_max_slice_len(services::EVENT_MAX_BYTES)
            .allocation_strategy(AllocationStrategy::Static)
            .create()
            .map_err(|e| transport("events publisher", e))?;
        Ok(ClientSide {
            events_notifier: services::notifier(&node, &names::events())?,
            listener: services::listener(&node, &names::control())?,
            wake_engine: services::notifier(&node, &names::manager_wake())?,
            server,
            events,
            _node: node,
            clients: HashMap::new(),
            pending: HashMap::new(),
            next_id: 0,
        })
    }

    fn serve(
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
                let (client, request_body) = match control::decode_request(request.payload()) {
                    Ok(env) => (Some(env.client), Ok(env.request)),
                    Err(e) => (None, Err(e)),
                };
                self.pending.insert(self.next_id, request);
                let _ = to_engine.send(Incoming {
                    id: self.next_id,
                    client,
                    request: request_body,
                });
                forwarded = true;
            }
            if forwarded {
                let _ = self.wake_engine.notify();
            }
            while let Ok(out) = from_engine.try_recv() {
                match out {
                    Outgoing::Answer {
                        id,
                        client,
                        response,
                    } => {
                        if let Some(req) = self.pending.remove(&id) {
                            self.answer(&req, client.as_deref(), &response);
                        }
                    }
                    Outgoing::Events(events) => self.publish(&events),
                }
            }
            if last_sweep.elapsed() > std::time::Duration::from_secs(1) {
                last_sweep = std::time::Instant::now();
                self.clients
                    .retain(|c, _| client_pid(c).is_none_or(pid_alive));
            }
        }
    }

    fn answer(&mut self, request: &Pending, client: Option<&str>, response: &Response) {
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
        let bytes = control::encode_response(response);
        let sent = request
            .loan_slice_uninit(bytes.len())
            .map(|r| r.write_from_slice(&bytes))
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

fn param_err(skill: &str, e: ParamError) -> ControlError {
    ControlError::Param {
        skill: skill.to_string(),
        error: ParamErrorText::from(e),
    }
}

impl Manager {
    fn slot_of(&self, name: &str) -> Result<usize, ControlError> {
        self.order
            .iter()
            .copied()
            .find(|&s| self.skills[s].as_ref().is_some_and(|e| e.decl.name == name))
            .ok_or_else(|| ControlError::UnknownSkill(name.to_string()))
    }

    /// The cycle in progress, or the last one done.
    pub(crate) fn in_progress(&self) -> u64 {
        self.board
            .header()
            .cycle
            .load(Ordering::Acquire)
            .max(self.cycle)
    }

    /// Carries out one request.
    pub(crate) fn handle(&mut self, client: &str, request: Request) -> Response {
        match request {
            Request::List => Ok(Reply::Skills(self.list())),
            Request::Activate(names) => self.set_active(&names, true),
            Request::Deactivate(names) => self.set_active(&names, false),
            Request::SetParam {
                skill,
                param,
                value,
            } => self.set_param(client, &skill, &param, value),
            Request::GetParam { skill, param } => {
                let s = self.slot_of(&skill)?;
                let e = self.skills[s]
                    .as_ref()
                    .ok_or_else(|| ControlError::UnknownSkill(skill.clone()))?;
                e.values
                    .iter()
                    .find(|(n, _)| *n == param)
                    .map(|(_, v)| Reply::Param(*v))
                    .ok_or_else(|| param_err(&skill, ParamError::Unknown { param }))
            }
            Request::Query(path) => self.query(&path),
            Request::AddMonitor { expr, mode, hold } => {
                let parsed = expr::parse(&expr).map_err(|error| ControlError::BadExpression {
                    expr: expr.clone(),
                    error,
                })?;
                let mut paths = Vec::new();
                for p in expr::paths(&parsed) {
                    let aggregate = !parsed_is_scalar_use(&parsed, p);
                    let (topic, field, slot) =
                        self.resolve_path(&p.skill, &p.output, &p.field, &p.text)?;
                    check_numeric(&field, aggregate).map_err(|reason| ControlError::BadPath {
                        path: p.text.clone(),
                        reason,
                    })?;
                    self.open_reader(&p.skill, &p.output)?;
                    paths.push(Resolved {
                        path: p.clone(),
                        topic,
                        field,
                        slot,
                    });
                }
                let id = self.next_monitor;
                self.next_monitor += 1;
                self.monitors.push(Monitor::new(
                    id,
                    expr,
                    parsed,
                    mode,
                    hold,
                    client.to_string(),
                    paths,
                ));
                Ok(Reply::MonitorAdded(id))
            }
            Request::RemoveMonitor(id) => {
                let before = self.monitors.len();
                self.monitors.retain(|m| m.id != id);
                if self.monitors.len() == before {
                    return Err(ControlError::UnknownMonitor(id));
                }
                Ok(Reply::Done)
            }
            Request::ListMonitors => Ok(Reply::Monitors(
                self.monitors.iter().map(Monitor::info).collect(),
            )),
            Request::Run => {
                self.stop_at = None;
                self.set_paused(false);
                Ok(Reply::Done)
            }
            Request::Stop => {
                self.stop_at = None;
                self.set_paused(true);
                Ok(Reply::Done)
            }
            Request::Step(_) => Ok(Reply::Stepped(self.cycle)),
            Request::Stats => Ok(Reply::Stats(self.stats_info())),
            Request::Latencies(n) => Ok(Reply::Latencies {
                cycle: self.cycle,
                latency_us: self.stats.recent_us((n as usize).min(MAX_LATENCIES)),
            }),
            Request::SetIoLog { skill, on } => self.set_io_log(client, &skill, on),
            Request::Logging => Ok(Reply::Logging {
                file: self
                    .recorder
                    .as_ref()
                    .map(|r| r.path().display().to_string()),
                io_skills: {
                    let mut v: Vec<String> = self.io_log.keys().cloned().collect();
                    v.sort();
                    v
                },
            }),
            Request::SetPriority { skill, priority } => {
                let s = self.slot_of(&skill)?;
                if let Some(e) = self.skills[s].as_mut() {
                    let old = e.decl.priority;
                    e.decl.priority = priority;
                    if old != priority {
                        // Written to the board at the next cycle start: arbitration changes
                        // from the next cycle.
                        self.dirty = true;
                        if let Some(r) = &self.recorder {
                            r.line(
                                "priority",
                                Some(self.in_progress()),
                                serde_json::json!({"skill": skill, "old": old, "new": priority, "by": client}),
                            );
                        }
                        self.outbox.push(EventKind::PriorityChanged {
                            skill,
                            old,
                            new: priority,
                            by: client.to_string(),
                        });
                    }
                }
                Ok(Reply::Done)
            }
        }
    }

    /// Starts or stops logging a skill's input and output samples to the fabric log.
    fn set_io_log(&mut self, client: &str, skill: &str, on: bool) -> Response {
        let s = self.slot_of(skill)?;
        let e = self.skills[s]
            .as_ref()
            .ok_or_else(|| ControlError::UnknownSkill(skill.to_string()))?;
        if !on {
            if self.io_log.remove(skill).is_some()
                && let Some(r) = &self.recorder
            {
                r.line(
                    "iolog",
                    Some(self.cycle),
                    serde_json::json!({"skill": skill, "on": false, "by": client}),
                );
            }
            return Ok(Reply::Done);
        }
        if self.recorder.is_none() {
            return Err(ControlError::Refused(
                "the manager has no fabric log file (see its start-up warning)".into(),
            ));
        }
        let mut ports = Vec::new();
        let sides = [("in", &e.decl.inputs), ("out", &e.decl.outputs)];
        for (dir, decls) in sides {
            for p in decls {
                let field = value::resolve(&p.schema, "").map_err(|err| ControlError::BadPath {
                    path: format!("{skill}.{}", p.port),
                    reason: err.reason,
                })?;
                let slot = (dir == "out" && p.kind == skillfab_proto::decl::PortKind::Proposal)
                    .then_some(s as u32);
                ports.push((
                    dir,
                    p.port.clone(),
                    p.topic.clone(),
                    p.schema.clone(),
                    field,
                    slot,
                ));
            }
        }
        let mut logged = Vec::new();
        for (dir, port, topic, schema, field, slot) in ports {
            if !self.readers.contains_key(&topic) {
                let reader = RawReader::open(&self.node, &topic, &schema)
                    .map_err(|e| ControlError::Refused(e.to_string()))?;
                self.readers.insert(topic.clone(), reader);
            }
            logged.push(crate::engine::IoPort {
                dir,
                port,
                topic,
                type_name: schema.type_name.clone(),
                field: std::sync::Arc::new(field),
                slot,
                last: self.cycle,
            });
        }
        if let Some(r) = &self.recorder {
            r.line(
                "iolog",
                Some(self.cycle),
                serde_json::json!({"skill": skill, "on": true, "by": client}),
            );
        }
        self.io_log.insert(skill.to_string(), logged);
        Ok(Reply::Done)
    }

    fn list(&self) -> Vec<SkillInfo> {
        let ports = |p: &[skillfab_proto::decl::PortDecl]| {
            p.iter()
                .map(|p| PortInfo {
                    port: p.port.clone(),
                    topic: p.topic.clone(),
                    type_name: p.schema.type_name.clone(),
                })
                .collect()
        };
        self.order
            .iter()
            .filter_map(|&s| self.skills[s].as_ref().map(|e| (s, e)))
            .map(|(s, e)| SkillInfo {
                name: e.decl.name.clone(),
                kind: e.decl.kind.clone(),
                mode: e.decl.mode,
                state: if !e.ready {
                    SkillState::Starting
                } else if e.active {
                    SkillState::Active
                } else {
                    SkillState::Inactive
                },
                priority: e.decl.priority,
                pid: e.decl.pid,
                params: e.decl.params.clone(),
                values: e.values.clone(),
                inputs: ports(&e.decl.inputs),
                outputs: ports(&e.decl.outputs),
                figures: self.figures(s),
            })
            .collect()
    }

    fn stats_info(&self) -> Stats {
        let l = self.stats.latency_us();
        Stats {
            cycles: self.cycle,
            running: !self.paused,
            overruns: self.stats.overruns,
            latency_us: l,
            skills: self
                .list()
                .into_iter()
                .map(|s| SkillStat {
                    name: s.name,
                    figures: s.figures,
                })
                .collect(),
            deaths: self.deaths,
            events: self.events_published,
            channels: {
                let mut v: Vec<ChannelStat> = self
                    .channels
                    .iter()
                    .map(|(c, v)| {
                        let who = match (&v.winner, v.weights.is_empty()) {
                            (Some(w), _) => w.clone(),
                            (None, true) => "safe".to_string(),
                            (None, false) => "blend".to_string(),
                        };
                        ChannelStat {
                            channel: c.clone(),
                            winner: who,
                            cycle: v.cycle,
                        }
                    })
                    .collect();
                v.sort_by(|a, b| a.channel.cmp(&b.channel));
                v
            },
        }
    }

    fn set_active(&mut self, names: &[String], active: bool) -> Response {
        let slots = names
            .iter()
            .map(|n| self.slot_of(n))
            .collect::<Result<Vec<_>, _>>()?;
        for s in slots {
            let Some(e) = self.skills[s].as_mut() else {
                continue;
            };
            if e.active == active {
                continue;
            }
            // Takes effect at the next cycle start (the plan writes it to the board), so a
            // skill deactivated mid-cycle still finishes the run the cycle counts on.
            e.active = active;
            let skill = e.decl.name.clone();
            self.dirty = true;
            tracing::info!(%skill, active, "activation changed");
            self.outbox.push(if active {
                EventKind::SkillActivated { skill }
            } else {
                EventKind::SkillDeactivated { skill }
            });
        }
        Ok(Reply::Done)
    }

    fn set_param(&mut self, client: &str, skill: &str, param: &str, arg: ParamArg) -> Response {
        let s = self.slot_of(skill)?;
        let e = self.skills[s]
            .as_mut()
            .ok_or_else(|| ControlError::UnknownSkill(skill.to_string()))?;
        let spec = e
            .decl
            .params
            .iter()
            .find(|p| p.name == param)
            .ok_or_else(|| {
                param_err(
                    skill,
                    ParamError::Unknown {
                        param: param.into(),
                    },
                )
            })?;
        let value = match arg {
            ParamArg::Text(t) => ParamValue::parse(spec.kind, &t).ok_or_else(|| {
                param_err(
                    skill,
                    ParamError::Unparsable {
                        param: param.into(),
                        expected: spec.kind,
                        text: t.clone(),
                    },
                )
            })?,
            ParamArg::Value(v) => v.coerce(spec.kind).ok_or_else(|| {
                param_err(
                    skill,
                    ParamError::WrongType {
                        param: param.into(),
                        expected: spec.kind,
                        got: v,
                    },
                )
            })?,
        };
        check_bounds(spec, value).map_err(|err| param_err(skill, err))?;
        let old = e
            .values
            .iter()
            .find(|(n, _)| n == param)
            .map_or(spec.default, |(_, v)| *v);
        match e.values.iter_mut().find(|(n, _)| n == param) {
            Some(slot) => slot.1 = value,
            None => e.values.push((param.to_string(), value)),
        }
        let bytes = postcard::to_allocvec(&e.values)
            .map_err(|err| ControlError::Refused(err.to_string()))?;
        self.board
            .slot(s)
            .write_params(&bytes)
            .map_err(|err| ControlError::Refused(err.to_string()))?;
        tracing::info!(skill, param, %old, new = %value, by = client, cycle = self.cycle, "parameter changed");
        if let Some(r) = &self.recorder {
            r.param(self.in_progress(), skill, param, old, value, client);
        }
        self.outbox.push(EventKind::ParamChanged {
            skill: skill.to_string(),
            param: param.to_string(),
            old,
            new: value,
            by: client.to_string(),
        });
        Ok(Reply::Done)
    }

    /// Topic and field of `skill.output[.field]`.
    fn resolve_path(
        &self,
        skill: &str,
        output: &str,
        field: &str,
        text: &str,
    ) -> Result<(String, FieldPath, Option<u32>), ControlError> {
        let bad = |reason: String| ControlError::BadPath {
            path: text.to_string(),
            reason,
        };
        let s = self.slot_of(skill)?;
        let e = self.skills[s]
            .as_ref()
            .ok_or_else(|| ControlError::UnknownSkill(skill.to_string()))?;
        let port = e
            .decl
            .outputs
            .iter()
            .find(|p| p.port == output)
            .ok_or_else(|| {
                let names: Vec<&str> = e.decl.outputs.iter().map(|p| p.port.as_str()).collect();
                bad(format!(
                    "skill '{skill}' has no output '{output}' (outputs: {})",
                    names.join(", ")
                ))
            })?;
        let f = value::resolve(&port.schema, field).map_err(|err| bad(err.reason))?;
        // Every proposer publishes on its channel's topic: read this skill's own proposals.
        let slot = (port.kind == skillfab_proto::decl::PortKind::Proposal).then_some(s as u32);
        Ok((port.topic.clone(), f, slot))
    }

    fn open_reader(&mut self, skill: &str, output: &str) -> Result<(), ControlError> {
        let s = self.slot_of(skill)?;
        let Some(port) = self.skills[s]
            .as_ref()
            .and_then(|e| e.decl.outputs.iter().find(|p| p.port == output))
        else {
            return Err(ControlError::UnknownSkill(skill.to_string()));
        };
        if !self.readers.contains_key(&port.topic) {
            let reader = RawReader::open(&self.node, &port.topic, &port.schema)
                .map_err(|e| ControlError::Refused(e.to_string()))?;
            self.readers.insert(port.topic.clone(), reader);
        }
        Ok(())
    }

    /// `channel.<name>[.command[.field]]`: the channel's last arbitration and command.
    fn query_channel(&mut self, text: &str, rest: &str) -> Response {
        let (name, sub) = match rest.split_once('.') {
            Some((n, s)) => (n, Some(s)),
            None => (rest, None),
        };
        let view = self
            .channels
            .get(name)
            .cloned()
            .ok_or_else(|| ControlError::BadPath {
                path: text.into(),
                reason: format!("no channel '{name}' has been arbitrated (channels: {})", {
                    let mut c: Vec<&str> = self.channels.keys().map(String::as_str).collect();
                    c.sort();
                    c.join(", ")
                }),
            })?;
        let schema = self
            .order
            .iter()
            .filter_map(|&s| self.skills[s].as_ref())
            .flat_map(|e| e.decl.inputs.iter())
            .find(|p| {
                p.channel_name() == Some(name)
                    && matches!(p.kind, skillfab_proto::decl::PortKind::Channel(_))
            })
            .map(|p| p.schema.clone())
            .ok_or_else(|| ControlError::NoValue(text.into()))?;
        let topic = skillfab_proto::names::command_topic(name);
        if !self.readers.contains_key(&topic) {
            let r = RawReader::open(&self.node, &topic, &schema)
                .map_err(|e| ControlError::Refused(e.to_string()))?;
            self.readers.insert(topic.clone(), r);
        }
        let field = match sub {
            None => "",
            Some(s) => s
                .strip_prefix("command")
                .ok_or_else(|| ControlError::BadPath {
                    path: text.into(),
                    reason: "a channel has '.command[.field]' and nothing else".into(),
                })?,
        };
        let f = value::resolve(&schema, field).map_err(|e| ControlError::BadPath {
            path: text.into(),
            reason: e.reason,
        })?;
        let reader = self
            .readers
            .get_mut(&topic)
            .ok_or_else(|| ControlError::NoValue(text.into()))?;
        reader
            .poll()
            .map_err(|e| ControlError::Refused(e.to_string()))?;
        let command = reader
            .latest()
            .and_then(|(b, h)| Some((f.read(b)?, h.cycle)));
        if sub.is_some() {
            let (value, cycle) = command.ok_or_else(|| ControlError::NoValue(text.into()))?;
            return Ok(Reply::Value { value, cycle });
        }
        let value = Value::Struct(vec![
            ("channel".into(), Value::Text(name.into())),
            ("device".into(), Value::Text(view.device.clone())),
            ("policy".into(), Value::Text(view.policy.to_string())),
            (
                "winner".into(),
                view.winner.clone().map_or(Value::Null, Value::Text),
            ),
            (
                "weights".into(),
                Value::Struct(
                    view.weights
                        .iter()
                        .map(|(n, w)| (n.clone(), Value::Float(*w)))
                        .collect(),
                ),
            ),
            // The latest command may be from a later cycle than the arbitration record.
            (
                "command_cycle".into(),
                command.as_ref().map_or(Value::Null, |c| Value::UInt(c.1)),
            ),
            ("command".into(), command.map_or(Value::Null, |c| c.0)),
        ]);
        Ok(Reply::Value {
            value,
            cycle: view.cycle,
        })
    }

    fn query(&mut self, path: &str) -> Response {
        let text = path.trim();
        if let Some(rest) = text.strip_prefix("channel.") {
            return self.query_channel(text, rest);
        }
        let path = OutputPath::parse(text).map_err(|e| ControlError::BadPath {
            path: text.into(),
            reason: e.reason,
        })?;
        let (topic, f, slot) = self.resolve_path(&path.skill, &path.output, &path.field, text)?;
        self.open_reader(&path.skill, &path.output)?;
        let reader = self
            .readers
            .get_mut(&topic)
            .ok_or_else(|| ControlError::NoValue(text.into()))?;
        reader
            .poll()
            .map_err(|e| ControlError::Refused(e.to_string()))?;
        let (bytes, header) = reader
            .latest_of(slot)
            .ok_or_else(|| ControlError::NoValue(text.into()))?;
        let value = f
            .read(bytes)
            .ok_or_else(|| ControlError::NoValue(text.into()))?;
        Ok(Reply::Value {
            value,
            cycle: header.cycle,
        })
    }
}

/// Whether path `p` is used as a plain number (not inside min()/max()).
fn parsed_is_scalar_use(e: &expr::Expr, p: &expr::PathRef) -> bool {
    use expr::Expr::*;
    match e {
        Path(q) => q == p,
        Min(_) | Max(_) | Num(_) | Bool(_) => false,
        Neg(x) | Not(x) => parsed_is_scalar_use(x, p),
        Arith(_, l, r) | Cmp(_, l, r) | And(l, r) | Or(l, r) => {
            parsed_is_scalar_use(l, p) || parsed_is_scalar_use(r, p)
        }
    }
}

/// A plain path must name one number; inside min()/max() an array or range of numbers.
fn check_numeric(f: &FieldPath, aggregate: bool) -> Result<(), String> {
    use skillfab_proto::schema::FieldKind;
    let prim = |k: &FieldKind| matches!(k, FieldKind::Prim(_));
    match (aggregate, &f.kind, f.count) {
        (false, k, None) if prim(k) => Ok(()),
        (false, _, _) => Err("names more than one number: use min() or max(), or index it".into()),
        (true, k, Some(_)) if prim(k) => Ok(()),
        (true, FieldKind::Array { elem, .. }, None) if prim(elem) => Ok(()),
        (true, _, _) => Err("min()/max() need an array or a range of numbers".into()),
    }
}
