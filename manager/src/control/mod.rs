//! The manager's side of the control plane: serves requests, publishes events.
//!
//! A control thread owns the client-facing ports (request server, events publisher, client
//! wake-ups) and forwards requests to the engine over a channel; the engine carries them out
//! between cycles, so a request never races a cycle, and hands answers and events back. Every
//! refusal is a precise [`ControlError`]. A `step` request is answered when its cycles are
//! done. Events get consecutive sequence numbers in the order the engine queued them.

mod client_side;
mod list;
mod logging;
mod monitors;
mod params;
mod query;

use crate::engine::Manager;
use crate::monitors::Monitor;
use client_side::ClientSide;
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::node::Node;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use skillfab_proto::board::pid_alive;
use skillfab_proto::control::{ControlError, Event, Reply, Request, Response};
use skillfab_proto::domain::Domain;
use skillfab_proto::param::ParamError;
use skillfab_proto::{Error as SdkError, names, services};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;

pub(super) type Pending = ActiveRequest<ipc::Service, [u8], (), [u8], ()>;

/// Most cycle latencies one `Latencies` answer carries (a console's history).
const MAX_LATENCIES: usize = 1024;
/// How long the monitors of a client whose process died are kept (evaluated, and a `Once`
/// monitor that fires remembered as fired) before they are removed: a plan runner restarted
/// by `up` takes them over in that time (`AdoptMonitors`) and misses no condition.
pub const ORPHAN_GRACE: std::time::Duration = std::time::Duration::from_secs(10);

/// A request handed from the control thread to the engine.
pub(crate) struct Incoming {
    pub(super) id: u64,
    pub(super) client: Option<String>,
    pub(super) request: Result<Request, ControlError>,
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
    /// Clients that hold monitors and whose process was first seen dead then.
    orphans: Orphans,
}

/// The clients holding monitors whose process died, and since when.
#[derive(Debug, Default)]
struct Orphans(std::collections::HashMap<String, std::time::Instant>);

impl Orphans {
    /// Takes note of the clients of `dead` (those holding monitors whose process is gone)
    /// at `now`; the clients among them dead for `grace` or longer, whose monitors go.
    fn expired(
        &mut self,
        dead: std::collections::HashSet<String>,
        now: std::time::Instant,
        grace: std::time::Duration,
    ) -> std::collections::HashSet<String> {
        // A client no longer listed had its monitors taken over or removed.
        self.0.retain(|c, _| dead.contains(c));
        for c in dead {
            self.0.entry(c).or_insert(now);
        }
        self.0
            .iter()
            .filter(|(_, since)| now.duration_since(**since) >= grace)
            .map(|(c, _)| c.clone())
            .collect()
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
            orphans: Orphans::default(),
        })
    }

    /// Carries out every request that arrived.
    pub fn serve(&mut self, m: &mut Manager) {
        let mut answers = Vec::new();
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
            answers.push(Outgoing::Answer {
                id: inc.id,
                client: inc.client,
                response,
            });
        }
        if answers.is_empty() {
            return;
        }
        // What a client was told is done is in the state file before it is told: a manager
        // killed right after the answer comes back with it.
        m.save_state_if_changed();
        for a in answers {
            let _ = self.to_clients.send(a);
        }
        let _ = self.poke.notify();
    }

    /// Hands queued events and finished `step` answers to the control thread.
    pub fn flush(&mut self, m: &mut Manager) {
        let mut poke = false;
        m.stamp_events();
        if !m.stamped.is_empty() {
            let events = std::mem::take(&mut m.stamped);
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

    /// Releases the holds of clients whose process is gone, and drops their monitors once it
    /// has been gone for [`ORPHAN_GRACE`] — but not in lock-step: there a monitor's firing pauses the fabric until its plan has
    /// reacted, and the fabric waits for a plan runner that died (a restarted one takes its
    /// monitors over).
    pub fn forget_dead_clients(&mut self, m: &mut Manager) {
        // A hold goes with its client at once (the fabric would wait for nobody).
        let gone = m
            .holds
            .release_gone(|c| client_pid(c).is_some_and(|p| !pid_alive(p)));
        if !gone.is_empty() {
            m.state_check = true;
            tracing::info!(clients = ?gone, "holds of departed clients released");
        }
        if matches!(m.config.pace, crate::engine::Pace::LockStep(_)) {
            return;
        }
        let dead = m
            .monitors
            .iter()
            .filter(|mon| client_pid(&mon.client).is_some_and(|p| !pid_alive(p)))
            .map(|mon| mon.client.clone())
            .collect();
        let expired = self
            .orphans
            .expired(dead, std::time::Instant::now(), ORPHAN_GRACE);
        if expired.is_empty() {
            return;
        }
        let removed = m.monitors.remove_clients(&expired);
        if removed > 0 {
            m.state_check = true;
            tracing::info!(removed, "monitors of departed clients removed");
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

/// The refusal of a request that needs a reader of `topic` iceoryx2 would not open or poll
/// (the cause goes to the manager's log).
fn cannot_read(topic: &str, error: &skillfab_proto::Error) -> ControlError {
    tracing::warn!(%topic, error = error as &dyn std::error::Error, "cannot read topic");
    ControlError::CannotRead {
        topic: topic.into(),
    }
}

fn param_err(skill: &str, e: ParamError) -> ControlError {
    ControlError::Param {
        skill: skill.to_string(),
        error: e,
    }
}

/// Request dispatch: one handler per request, in the files of this module by concern
/// (`list`: skills and stats; `params`: activation, parameters, priorities; `query`: values;
/// `monitors`; `logging`: the fabric log).
impl Manager {
    fn slot_of(&self, name: &str) -> Result<usize, ControlError> {
        self.skills
            .slot_of(name)
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
        // Most requests change nothing; the state file is rewritten only if its bytes differ.
        self.state_check = true;
        match request {
            Request::List => Ok(Reply::Skills(self.list())),
            Request::Activate(names) => self.set_active(&names, true),
            Request::Deactivate(names) => self.set_active(&names, false),
            Request::SetParam {
                skill,
                param,
                value,
            } => self.set_param(client, &skill, &param, value),
            Request::GetParam { skill, param } => self.get_param(&skill, param),
            Request::Query(path) => self.query(&path),
            Request::AddMonitor { expr, mode, hold } => self.add_monitor(client, expr, mode, hold),
            Request::RemoveMonitor(id) => self.remove_monitor(id),
            Request::AdoptMonitors(ids) => self.adopt_monitors(client, &ids),
            Request::ProcessGaveUp {
                process,
                restarts,
                status,
            } => {
                tracing::error!(%process, restarts, %status, "skillfab up gave up restarting it");
                self.gave_up.insert(
                    process.clone(),
                    skillfab_proto::control::GaveUpInfo {
                        process: process.clone(),
                        restarts,
                        status: status.clone(),
                        cycle: self.cycle,
                    },
                );
                self.outbox
                    .push(skillfab_proto::control::EventKind::ProcessGaveUp {
                        process,
                        restarts,
                        status,
                    });
                Ok(Reply::Done)
            }
            Request::GaveUp => Ok(Reply::GaveUp(self.gave_up.values().cloned().collect())),
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
            Request::Declaration(skill) => self
                .skills
                .decl(&skill)
                .map(|d| Reply::Declaration(Box::new(d.clone())))
                .ok_or(ControlError::UnknownSkill(skill)),
            Request::Hold(at) => {
                self.holds.set(client, at);
                self.state_check = true;
                Ok(Reply::Done)
            }
            Request::Stats => Ok(Reply::Stats(self.stats_info())),
            Request::Latencies(n) => {
                let n = (n as usize).min(MAX_LATENCIES);
                Ok(Reply::Latencies {
                    cycle: self.cycle,
                    latency_us: self.stats.recent_us(n),
                    round_trip_us: self.stats.recent_round_trips_us(n),
                })
            }
            Request::SetIoLog { skill, on } => self.set_io_log(client, &skill, on),
            Request::Logging => Ok(self.logging()),
            Request::Record { file, topics } => self.record_request(file, topics),
            Request::SetPriority { skill, priority } => self.set_priority(client, skill, priority),
            Request::TopicSchema(topic) => self.topic_schema(&topic),
            Request::BridgeReport(report) => {
                self.bridges
                    .insert(report.name.clone(), (report, std::time::Instant::now()));
                Ok(Reply::Done)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;
    use std::time::{Duration, Instant};

    fn set(names: &[&str]) -> HashSet<String> {
        names.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_dead_clients_monitors_go_after_the_grace_and_not_if_taken_over() {
        let grace = Duration::from_secs(10);
        let t0 = Instant::now();
        let mut o = Orphans::default();
        assert!(o.expired(set(&["7-1", "8-1"]), t0, grace).is_empty());
        // 8-1's monitors were taken over (no longer listed); 7-1 stays dead.
        let t1 = t0 + Duration::from_secs(9);
        assert!(o.expired(set(&["7-1"]), t1, grace).is_empty());
        assert_eq!(o.expired(set(&["7-1"]), t0 + grace, grace), set(&["7-1"]));
        // 8-1 seen dead again later (say, a restarted runner that died too): a grace of
        // its own from then.
        let t2 = t0 + Duration::from_secs(12);
        assert!(o.expired(set(&["8-1"]), t2, grace).is_empty());
        assert_eq!(o.expired(set(&["8-1"]), t2 + grace, grace), set(&["8-1"]));
    }
}
