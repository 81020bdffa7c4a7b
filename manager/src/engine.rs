//! The cycle engine (the paper's skill manager): registry, cycle plan, readiness, liveness.
//!
//! One loop on one thread, woken by its WaitSet: by skills (registration, leaving, the run
//! that completes a cycle, a run that passed nothing on), by its own timers (period start,
//! cycle deadline, liveness tick) and by SIGINT/SIGTERM.
//!
//! A cycle k: the manager marks the expected sync skills on the board, arms the completion
//! counter with their number, publishes k and wakes only the sources (skills whose inputs are
//! not produced in the same cycle). From there skills wake each other through their topics;
//! each finished run stamps the board and takes one off the counter; the run that takes the
//! last one off wakes the manager. A run that fails, is skipped or leaves an output unwritten
//! wakes the manager too, which then takes its now-unrunnable consumers off the counter. A
//! cycle whose deadline passes is counted as an overrun and closed; the next one starts on
//! time. Cleanup between cycles is the re-arming of the counter.

use crate::control::ControlPlane;
use crate::graph::{self, Plan, PlanNode};
use crate::monitors::Monitor;
use crate::recorder::{IoSample, Recorder};
use crate::stats::{CycleStats, Report, SkillReport};
use iceoryx2::node::{Node, NodeView};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use skillfab_proto::board::{Board, MAX_SLOTS, RunStatus, SlotState, pid_alive};
use skillfab_proto::control::{EventKind, SkillFigures};
use skillfab_proto::decl::SkillDecl;
use skillfab_proto::domain::Domain;
use skillfab_proto::header::now_ns;
use skillfab_proto::param::ParamValue;
use skillfab_proto::services::RawReader;
use skillfab_proto::value::FieldPath;
use skillfab_proto::{Error as SdkError, names, services};
use std::collections::{HashMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// How often the manager checks that registered processes are alive (and its longest sleep).
/// A sync skill that dies mid-cycle is also found when the cycle's deadline passes; each
/// check reads `/proc` for every skill, so it is not done every cycle.
pub const LIVENESS_TICK: Duration = Duration::from_millis(200);
/// How often the manager removes what dead processes of the domain left behind.
const NODE_SWEEP: Duration = Duration::from_secs(1);
/// Shortest cycle period in free-running mode while no skill is expected (avoids a busy loop).
const IDLE_FREE_RUN: Duration = Duration::from_millis(1);

/// How the manager paces cycles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// A new cycle every period (the deadline defaults to the period).
    Period(Duration),
    /// The next cycle starts as soon as the previous one finished.
    FreeRun,
}

/// Manager settings.
#[derive(Debug, Clone)]
pub struct ManagerConfig {
    /// The fabric's domain.
    pub domain: Domain,
    /// Cycle pacing.
    pub pace: Pace,
    /// Longest a cycle may take before it is closed as an overrun (default: the period, or
    /// 1 s when free-running).
    pub deadline: Option<Duration>,
    /// Start with cycling stopped.
    pub paused: bool,
    /// Stop after this many cycles.
    pub max_cycles: Option<u64>,
    /// Do not start cycling until these skills have registered.
    pub wait_for: Vec<String>,
    /// How long to wait for them.
    pub wait_timeout: Duration,
    /// The fabric log (parameter changes, I/O samples); `None`: [`default_log_path`].
    pub param_log: Option<PathBuf>,
}

/// Where a manager's fabric log goes by default: `<domain>-<unix seconds>-<pid>.jsonl` in
/// [`log_dir`]. The file is created with the first record worth keeping (a manager whose
/// parameters nobody changed leaves no file).
pub fn default_log_path(domain: &Domain) -> PathBuf {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    log_dir(domain).join(format!(
        "{}-{secs}-{}.jsonl",
        domain.name(),
        std::process::id()
    ))
}

/// The directory of fabric logs: `$SKILLFAB_LOG_DIR`, else `$XDG_STATE_HOME/skillfab/log`,
/// else `~/.local/state/skillfab/log` (as `~/.ros/log` for ROS); with none of them set, the
/// domain's root directory (removed with the domain).
pub fn log_dir(domain: &Domain) -> PathBuf {
    let var = |name: &str| {
        std::env::var_os(name)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    var("SKILLFAB_LOG_DIR")
        .or_else(|| var("XDG_STATE_HOME").map(|d| d.join("skillfab/log")))
        .or_else(|| var("HOME").map(|d| d.join(".local/state/skillfab/log")))
        .unwrap_or_else(|| domain.root_path())
}

impl ManagerConfig {
    /// Defaults: 100 Hz, running.
    pub fn new(domain: Domain) -> Self {
        ManagerConfig {
            domain,
            pace: Pace::Period(Duration::from_millis(10)),
            deadline: None,
            paused: false,
            max_cycles: None,
            wait_for: Vec::new(),
            wait_timeout: Duration::from_secs(30),
            param_log: None,
        }
    }

    fn deadline(&self) -> Duration {
        self.deadline.unwrap_or(match self.pace {
            Pace::Period(p) => p,
            Pace::FreeRun => Duration::from_secs(1),
        })
    }
}

/// Why the manager stopped with an error.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ManagerError {
    /// Board, node or service set-up failed.
    #[error(transparent)]
    Sdk(#[from] SdkError),
    /// The WaitSet failed.
    #[error("manager wait: {detail}")]
    Wait {
        /// iceoryx2's error.
        detail: String,
    },
    /// Skills named in `wait_for` did not register in time.
    #[error("skills did not register within {waited:?}: {}", missing.join(", "))]
    MissingSkills {
        /// Those still missing.
        missing: Vec<String>,
        /// How long the manager waited.
        waited: Duration,
    },
}

pub(crate) struct Entry {
    pub(crate) decl: SkillDecl,
    trigger: Notifier<ipc::Service>,
    pub(crate) active: bool,
    /// Its ports are open: cycles may count on it.
    pub(crate) ready: bool,
    /// Current parameter values (the skill applies them from the next cycle).
    pub(crate) values: Vec<(String, ParamValue)>,
}

struct Running {
    k: u64,
    start_ns: u64,
    deadline: Instant,
    expected: Vec<usize>,
    /// Slots whose completion the manager has looked at.
    processed: [bool; MAX_SLOTS],
    /// Slots taken off the counter because they cannot run this cycle.
    cancelled: [bool; MAX_SLOTS],
}

/// The skill manager of one domain.
pub struct Manager {
    pub(crate) config: ManagerConfig,
    pub(crate) board: Board,
    pub(crate) node: Node<ipc::Service>,
    pub(crate) skills: Vec<Option<Entry>>,
    /// Slots in registration order (for reports).
    pub(crate) order: Vec<usize>,
    plan: Plan,
    /// The plan must be recomputed before the next cycle.
    pub(crate) dirty: bool,
    /// Cycles completed.
    pub(crate) cycle: u64,
    running: Option<Running>,
    next_start: Instant,
    pub(crate) paused: bool,
    /// Pause once this many cycles are done (`step`).
    pub(crate) stop_at: Option<u64>,
    started: bool,
    created: Instant,
    pub(crate) stats: CycleStats,
    pub(crate) deaths: u64,
    last_liveness: Instant,
    last_node_sweep: Instant,
    /// Events to publish at the end of this loop iteration.
    pub(crate) outbox: Vec<EventKind>,
    /// Installed monitors.
    pub(crate) monitors: Vec<Monitor>,
    pub(crate) next_monitor: u64,
    /// Untyped readers of topics that monitors and queries read.
    pub(crate) readers: HashMap<String, RawReader>,
    /// Names that have registered before (a new registration is then a restart).
    seen: HashSet<String>,
    /// Requests and events; taken out while the loop runs.
    control: Option<ControlPlane>,
    /// Events published so far.
    pub(crate) events_published: u64,
    /// Last arbitration seen per channel.
    pub(crate) channels: HashMap<String, ChannelView>,
    /// The fabric log's writer (`None` if its file could not be opened).
    pub(crate) recorder: Option<Recorder>,
    /// Skills whose samples are logged, with their ports.
    pub(crate) io_log: HashMap<String, Vec<IoPort>>,
}

/// A port whose samples go to the fabric log.
pub(crate) struct IoPort {
    pub(crate) dir: &'static str,
    pub(crate) port: String,
    pub(crate) topic: String,
    pub(crate) type_name: String,
    pub(crate) field: Arc<FieldPath>,
    /// On a proposal topic, the proposer's slot.
    pub(crate) slot: Option<u32>,
    /// The cycle of the last sample logged (each sample once).
    pub(crate) last: u64,
}

/// Why a skill leaves the registry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DropReason {
    /// It said goodbye on the board (a clean exit).
    Left,
    /// Its process is gone without a goodbye (crash, `kill -9`).
    Died,
}

/// The latest arbitration of a channel, as the manager last read it from the board.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ChannelView {
    pub(crate) device: String,
    pub(crate) policy: skillfab_proto::decl::Policy,
    pub(crate) cycle: u64,
    pub(crate) winner: Option<String>,
    pub(crate) weights: Vec<(String, f64)>,
}

impl Manager {
    /// Creates the domain's board and the manager's iceoryx2 node.
    pub fn new(config: ManagerConfig) -> Result<Manager, ManagerError> {
        let node = services::node(&config.domain, "skillfab-manager")?;
        // The control server exists before the board announces the manager to clients.
        let control = ControlPlane::new(&config.domain, &node)?;
        let board = Board::create(&config.domain.prefix())?;
        let now = Instant::now();
        let log_path = config
            .param_log
            .clone()
            .unwrap_or_else(|| default_log_path(&config.domain));
        let recorder = match Recorder::open(&log_path) {
            Ok(r) => {
                r.line(
                    "start",
                    None,
                    serde_json::json!({"domain": config.domain.name(), "pid": std::process::id()}),
                );
                Some(r)
            }
            Err(e) => {
                tracing::warn!(file = %log_path.display(), error = %e, "no fabric log");
                None
            }
        };
        Ok(Manager {
            paused: config.paused,
            config,
            board,
            node,
            skills: (0..MAX_SLOTS).map(|_| None).collect(),
            order: Vec::new(),
            plan: Plan::default(),
            dirty: true,
            cycle: 0,
            running: None,
            next_start: now,
            stop_at: None,
            outbox: Vec::new(),
            monitors: Vec::new(),
            next_monitor: 1,
            readers: HashMap::new(),
            seen: HashSet::new(),
            control: Some(control),
            events_published: 0,
            channels: HashMap::new(),
            recorder,
            io_log: HashMap::new(),
            started: false,
            created: now,
            stats: CycleStats::default(),
            deaths: 0,
            last_liveness: now,
            last_node_sweep: now,
        })
    }

    /// Runs until SIGINT/SIGTERM, until `stop(cycles_done)` returns true, or until
    /// `max_cycles` cycles are done; returns the report of the run.
    pub fn run(&mut self, stop: &dyn Fn(u64) -> bool) -> Result<Report, ManagerError> {
        let wait_err = |e: &dyn std::fmt::Debug| ManagerError::Wait {
            detail: format!("{e:?}"),
        };
        let wake: Listener<ipc::Service> = services::listener(&self.node, &names::manager_wake())?;
        let waitset = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<ipc::Service>()
            .map_err(|e| wait_err(&e))?;
        let _guard = waitset
            .attach_notification(&wake)
            .map_err(|e| wait_err(&e))?;
        let mut control = self.control.take().ok_or_else(|| ManagerError::Wait {
            detail: "the manager runs once".into(),
        })?;
        tracing::info!(domain = %self.config.domain, pace = ?self.config.pace, "manager up");
        let result = self.serve_loop(&waitset, &wake, &mut control, stop);
        self.control = Some(control);
        result
    }

    fn serve_loop(
        &mut self,
        waitset: &WaitSet<ipc::Service>,
        wake: &Listener<ipc::Service>,
        control: &mut ControlPlane,
        stop: &dyn Fn(u64) -> bool,
    ) -> Result<Report, ManagerError> {
        let wait_err = |e: &dyn std::fmt::Debug| ManagerError::Wait {
            detail: format!("{e:?}"),
        };
        loop {
            let timeout = self.timeout(Instant::now());
            let result = waitset
                .wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, timeout)
                .map_err(|e| wait_err(&e))?;
            // A wait cut short by a signal other than SIGINT/SIGTERM (a debugger attaching,
            // SIGSTOP/SIGCONT) goes on.
            let interrupted = match result {
                WaitSetRunResult::TerminationRequest => true,
                WaitSetRunResult::Interrupt => services::termination_requested(&self.node),
                _ => false,
            };
            if interrupted || stop(self.cycle) {
                break;
            }
            let awake = thread_cpu_ns();
            // Drained after every wait, the timed-out ones too. iceoryx2 0.10's listener keeps
            // a "notified" flag beside its socket: a notifier sends a datagram only when the
            // flag was clear, and a drain clears it. A drain that races two notifiers can
            // leave the flag set with the socket empty; from then on no notifier sends and
            // the wait never fires again, so a listener drained only when it fired stays deaf
            // for good (seen: every cycle closed by the 200 ms liveness tick). Draining on a
            // timeout too clears the flag at the next tick at the latest; it costs one
            // recvfrom (EAGAIN) per timed-out wait.
            let _ = wake.try_wait(|_| {});
            self.service_registry();
            if self.last_liveness.elapsed() >= LIVENESS_TICK {
                self.check_liveness();
                control.forget_dead_clients(self);
            }
            control.serve(self);
            self.advance()?;
            control.flush(self);
            self.stats.add_work(thread_cpu_ns().saturating_sub(awake));
            if self.running.is_none() && self.config.max_cycles.is_some_and(|m| self.cycle >= m) {
                break;
            }
        }
        Ok(self.report())
    }

    /// Lets skills that are leaving go, checks liveness once more, closes the board, and
    /// when no other process of the domain is alive, removes the domain's files (shared
    /// memory and iceoryx2 root). Returns whether it removed them.
    pub fn shutdown(mut self) -> bool {
        self.service_registry();
        self.check_liveness();
        self.board.close();
        // Wake every skill: it finds the board closed and leaves now, not at its next
        // liveness tick.
        for e in self.skills.iter().flatten() {
            let _ = e.trigger.notify();
        }
        let cleaned = self.node.try_cleanup_dead_nodes();
        // The control thread's node is ours too: close it before looking for others.
        drop(self.control.take());
        self.readers.clear();
        let others_alive = self.others_alive();
        let (domain, cycles) = (self.config.domain.clone(), self.cycle);
        drop(self);
        if !others_alive {
            domain.remove_all_files();
        }
        tracing::info!(
            cycles,
            dead_nodes_cleaned = cleaned.cleanups,
            files_removed = !others_alive,
            "manager down"
        );
        !others_alive
    }

    /// Whether an iceoryx2 node of the domain other than the manager's is alive.
    fn others_alive(&self) -> bool {
        let Ok(config) = self.config.domain.iceoryx_config() else {
            return true;
        };
        let own = *self.node.id();
        let mut alive = false;
        let listed = Node::<ipc::Service>::list(&config, |state| {
            if let NodeState::Alive(v) = &state
                && *v.id() != own
            {
                alive = true;
            }
            CallbackProgression::Continue
        });
        alive || listed.is_err()
    }

    /// Cycles completed so far.
    pub fn cycle(&self) -> u64 {
        self.cycle
    }

    fn timeout(&self, now: Instant) -> Duration {
        let until = |t: Instant| t.saturating_duration_since(now);
        let t = match &self.running {
            Some(r) => until(r.deadline),
            None if self.paused || !self.started => LIVENESS_TICK,
            None => match self.config.pace {
                Pace::Period(_) => until(self.next_start),
                Pace::FreeRun if self.plan.expected.is_empty() => IDLE_FREE_RUN,
                Pace::FreeRun => Duration::ZERO,
            },
        };
        t.min(LIVENESS_TICK)
    }

    /// Drives the cycle state machine as far as it can go now.
    fn advance(&mut self) -> Result<(), ManagerError> {
        loop {
            if let Some(k) = self.running.as_ref().map(|r| r.k) {
                self.resolve();
                if self.board.remaining(k) == 0 {
                    self.finish(false);
                } else if self
                    .running
                    .as_ref()
                    .is_some_and(|r| Instant::now() >= r.deadline)
                {
                    self.check_liveness();
                    if self.board.remaining(k) == 0 {
                        self.finish(false);
                    } else {
                        let unfinished = self.board.remaining(k);
                        tracing::warn!(cycle = k, unfinished, "cycle overrun");
                        self.outbox.push(EventKind::CycleOverrun { unfinished });
                        self.finish(true);
                    }
                } else {
                    return Ok(());
                }
            }
            if self.stop_at.is_some_and(|t| self.cycle >= t) {
                self.stop_at = None;
                self.set_paused(true);
            }
            if self.paused || self.config.max_cycles.is_some_and(|m| self.cycle >= m) {
                return Ok(());
            }
            if !self.started {
                let missing: Vec<String> = self
                    .config
                    .wait_for
                    .iter()
                    .filter(|n| {
                        !self
                            .skills
                            .iter()
                            .flatten()
                            .any(|e| e.ready && &e.decl.name == *n)
                    })
                    .cloned()
                    .collect();
                if !missing.is_empty() {
                    if self.created.elapsed() > self.config.wait_timeout {
                        return Err(ManagerError::MissingSkills {
                            missing,
                            waited: self.config.wait_timeout,
                        });
                    }
                    return Ok(());
                }
                self.started = true;
                self.next_start = Instant::now();
            }
            let now = Instant::now();
            match self.config.pace {
                Pace::Period(p) => {
                    if now < self.next_start {
                        return Ok(());
                    }
                    self.next_start += p;
                    if self.next_start < now {
                        self.next_start = now;
                    }
                }
                Pace::FreeRun => {
                    if self.plan.expected.is_empty() && !self.dirty {
                        if now < self.next_start {
                            return Ok(());
                        }
                        self.next_start = now + IDLE_FREE_RUN;
                    }
                }
            }
            self.start_cycle();
        }
    }

    fn replan(&mut self) {
        let nodes: Vec<PlanNode<'_>> = self
            .order
            .iter()
            .filter_map(|&s| {
                self.skills[s]
                    .as_ref()
                    .filter(|e| e.ready)
                    .map(|e| PlanNode {
                        slot: s,
                        decl: &e.decl,
                        active: e.active,
                    })
            })
            .collect();
        self.plan = graph::plan(&nodes);
        for &(slot, mask) in &self.plan.fresh_masks {
            self.board
                .slot(slot)
                .fresh_mask
                .store(mask, Ordering::Release);
        }
        for &s in &self.order {
            if let Some(e) = &self.skills[s] {
                let slot = self.board.slot(s);
                slot.active.store(u32::from(e.active), Ordering::Release);
                slot.priority.store(e.decl.priority, Ordering::Release);
            }
        }
        for ch in &self.plan.channels {
            if ch.index < skillfab_proto::board::MAX_CHANNELS {
                self.board.slot(ch.device).channel_proposers[ch.index]
                    .store(ch.proposers, Ordering::Release);
            }
            // Read the commands from now on (queries find the latest one).
            let topic = names::command_topic(&ch.channel);
            let schema = self.skills[ch.device]
                .as_ref()
                .and_then(|e| e.decl.inputs.get(ch.index))
                .map(|p| p.schema.clone());
            if let Some(schema) = schema
                && !self.readers.contains_key(&topic)
            {
                match RawReader::open(&self.node, &topic, &schema) {
                    Ok(r) => {
                        self.readers.insert(topic, r);
                    }
                    Err(e) => tracing::warn!(%topic, error = %e, "cannot read commands"),
                }
            }
        }
        self.dirty = false;
    }

    fn start_cycle(&mut self) {
        if self.dirty {
            self.replan();
        }
        let k = self.cycle + 1;
        for &s in &self.plan.expected {
            self.board
                .slot(s)
                .expected_cycle
                .store(k, Ordering::Release);
        }
        self.board.arm(k, self.plan.expected.len() as u32);
        let start_ns = now_ns();
        let h = self.board.header();
        h.cycle_start_ns.store(start_ns, Ordering::Release);
        h.cycle.store(k, Ordering::Release);
        self.running = Some(Running {
            k,
            start_ns,
            deadline: Instant::now() + self.config.deadline(),
            expected: self.plan.expected.clone(),
            processed: [false; MAX_SLOTS],
            cancelled: [false; MAX_SLOTS],
        });
        for &s in &self.plan.sources {
            if let Some(e) = &self.skills[s]
                && let Err(err) = e.trigger.notify()
            {
                tracing::warn!(skill = %e.decl.name, error = ?err, "could not wake skill");
            }
        }
    }

    /// Looks at runs of the current cycle that finished without passing everything on, and
    /// takes the consumers that can no longer run off the completion counter.
    fn resolve(&mut self) {
        let Some(mut run) = self.running.take() else {
            return;
        };
        let mut cancel = Vec::new();
        for &s in &run.expected {
            let slot = self.board.slot(s);
            if run.processed[s] || slot.done_cycle.load(Ordering::Acquire) != run.k {
                continue;
            }
            run.processed[s] = true;
            let status = RunStatus::from_u32(slot.status.load(Ordering::Acquire));
            let mask = slot.published_mask.load(Ordering::Acquire);
            if let Some(per_output) = self.plan.consumers.get(&s) {
                for (o, consumers) in per_output.iter().enumerate() {
                    if status != RunStatus::Ok || mask & (1 << o) == 0 {
                        cancel.extend_from_slice(consumers);
                    }
                }
            }
        }
        let n = self.cancel_all(&mut run, cancel);
        if n > 0 {
            self.board.complete(run.k, n);
        }
        self.running = Some(run);
    }

    /// Marks `start` and everything downstream of it as unable to run in this cycle; returns
    /// how many expected runs that removed.
    fn cancel_all(&self, run: &mut Running, mut todo: Vec<usize>) -> u32 {
        let mut n = 0;
        while let Some(s) = todo.pop() {
            if run.cancelled[s]
                || !run.expected.contains(&s)
                || self.board.slot(s).done_cycle.load(Ordering::Acquire) == run.k
            {
                continue;
            }
            run.cancelled[s] = true;
            n += 1;
            self.board
                .slot(s)
                .cancelled_cycle
                .store(run.k, Ordering::Release);
            // A device waiting for this skill's proposal must look again.
            for ch in self
                .plan
                .channels
                .iter()
                .filter(|c| c.proposers & (1 << s) != 0)
            {
                if let Some(e) = &self.skills[ch.device] {
                    let _ = e.trigger.notify();
                }
            }
            if let Some(per_output) = self.plan.consumers.get(&s) {
                todo.extend(per_output.iter().flatten());
            }
        }
        n
    }

    fn finish(&mut self, overrun: bool) {
        let Some(run) = self.running.take() else {
            return;
        };
        let end = run
            .expected
            .iter()
            .map(|&s| self.board.slot(s))
            .filter(|slot| slot.done_cycle.load(Ordering::Acquire) == run.k)
            .map(|slot| slot.last_end_ns.load(Ordering::Acquire))
            .max();
        let latency = if overrun {
            now_ns().saturating_sub(run.start_ns)
        } else {
            end.map_or(0, |e| e.saturating_sub(run.start_ns))
        };
        self.stats.record(latency, overrun);
        self.cycle = run.k;
        if !self.plan.channels.is_empty() {
            self.read_channels(run.k);
        }
        if !self.monitors.is_empty() {
            self.evaluate_monitors();
        }
        if !self.io_log.is_empty() {
            self.log_io();
        }
    }

    /// Copies the new samples of the I/O-logged skills to the fabric log (decoded there).
    fn log_io(&mut self) {
        let Some(rec) = self.recorder.as_ref() else {
            return;
        };
        let mut polled = HashSet::new();
        for (skill, ports) in &mut self.io_log {
            for p in ports.iter_mut() {
                let Some(reader) = self.readers.get_mut(&p.topic) else {
                    continue;
                };
                if polled.insert(p.topic.clone())
                    && let Err(e) = reader.poll()
                {
                    tracing::warn!(topic = %p.topic, error = %e, "I/O log read failed");
                }
                let Some((bytes, h)) = reader.latest_of(p.slot) else {
                    continue;
                };
                if h.cycle <= p.last {
                    continue;
                }
                p.last = h.cycle;
                rec.sample(IoSample {
                    cycle: h.cycle,
                    skill: skill.clone(),
                    dir: p.dir,
                    port: p.port.clone(),
                    topic: p.topic.clone(),
                    type_name: p.type_name.clone(),
                    stamp_ns: h.stamp_ns,
                    field: p.field.clone(),
                    bytes: bytes.to_vec(),
                });
            }
        }
    }

    /// Reads each channel's arbitration of cycle `k` from the board; a new winner is an event.
    fn read_channels(&mut self, k: u64) {
        let name_of = |s: usize| self.skills.get(s)?.as_ref().map(|e| e.decl.name.clone());
        let mut changes = Vec::new();
        for ch in &self.plan.channels {
            if ch.index >= skillfab_proto::board::MAX_CHANNELS {
                continue;
            }
            let slot = self.board.slot(ch.device);
            if slot.channel_cycle[ch.index].load(Ordering::Acquire) != k {
                continue;
            }
            let winner = slot.channel_winner[ch.index].load(Ordering::Acquire);
            let mask = slot.channel_mask[ch.index].load(Ordering::Acquire);
            let winner = (winner > 0).then(|| name_of(winner as usize - 1)).flatten();
            let contributors: Vec<usize> =
                (0..MAX_SLOTS).filter(|s| mask & (1 << s) != 0).collect();
            let weights: Vec<f64> = if ch.policy == skillfab_proto::decl::Policy::Priority {
                vec![1.0; contributors.len()]
            } else {
                let priorities: Vec<i32> = contributors
                    .iter()
                    .map(|&s| self.board.slot(s).priority.load(Ordering::Acquire))
                    .collect();
                skillfab_proto::decl::blend_weights(&priorities)
            };
            // By name: slots follow the order in which processes happened to register.
            let mut weights: Vec<(String, f64)> = contributors
                .iter()
                .zip(weights)
                .filter_map(|(&s, w)| name_of(s).map(|n| (n, w)))
                .collect();
            weights.sort_by(|a, b| a.0.cmp(&b.0));
            let view = ChannelView {
                device: name_of(ch.device).unwrap_or_default(),
                policy: ch.policy,
                cycle: k,
                winner,
                weights,
            };
            let changed = self.channels.get(&ch.channel).is_none_or(|old| {
                old.winner != view.winner
                    || old
                        .weights
                        .iter()
                        .map(|w| &w.0)
                        .ne(view.weights.iter().map(|w| &w.0))
            });
            if changed {
                changes.push(EventKind::ChannelWinner {
                    channel: ch.channel.clone(),
                    winner: view.winner.clone(),
                    weights: view.weights.clone(),
                });
            }
            self.channels.insert(ch.channel.clone(), view);
        }
        self.outbox.extend(changes);
    }

    /// Starts or stops cycling.
    pub(crate) fn set_paused(&mut self, paused: bool) {
        if self.paused != paused {
            self.paused = paused;
            self.outbox.push(EventKind::Cycling { running: !paused });
            if !paused {
                self.next_start = Instant::now();
            }
        }
    }

    /// Evaluates every monitor on the newest samples of the cycle that just finished.
    fn evaluate_monitors(&mut self) {
        let topics: HashSet<String> = self
            .monitors
            .iter()
            .flat_map(|m| m.paths.iter().map(|p| p.topic.clone()))
            .collect();
        for t in &topics {
            if let Some(r) = self.readers.get_mut(t)
                && let Err(e) = r.poll()
            {
                tracing::warn!(topic = %t, error = %e, "monitor read failed");
            }
        }
        let readers = &self.readers;
        let read = |r: &crate::monitors::Resolved| {
            let (bytes, _) = readers.get(&r.topic)?.latest_of(r.slot)?;
            r.field.read(bytes)
        };
        for m in &mut self.monitors {
            if let Some(values) = m.step(&read) {
                let stamp_ns = m
                    .paths
                    .iter()
                    .filter_map(|p| {
                        readers
                            .get(&p.topic)?
                            .latest_of(p.slot)
                            .map(|(_, h)| h.stamp_ns)
                    })
                    .max()
                    .unwrap_or(0);
                self.outbox.push(EventKind::MonitorFired {
                    id: m.id,
                    client: m.client.clone(),
                    expr: m.text.clone(),
                    values,
                    stamp_ns,
                });
            }
        }
        self.monitors.retain(|m| !m.spent());
    }

    fn service_registry(&mut self) {
        for i in 0..MAX_SLOTS {
            match self.board.slot(i).state() {
                SlotState::Pending => self.admit(i),
                SlotState::Ready => {
                    if let Some(e) = self.skills[i].as_mut().filter(|e| !e.ready) {
                        e.ready = true;
                        self.dirty = true;
                        tracing::info!(skill = %e.decl.name, "skill ready");
                        // Read its outputs from now on, so queries and monitors find the
                        // latest sample (a late subscriber would only get it at the next send).
                        let outputs = e.decl.outputs.clone();
                        for p in outputs {
                            if !self.readers.contains_key(&p.topic) {
                                match RawReader::open(&self.node, &p.topic, &p.schema) {
                                    Ok(r) => {
                                        self.readers.insert(p.topic.clone(), r);
                                    }
                                    Err(err) => {
                                        tracing::warn!(topic = %p.topic, error = %err, "cannot read topic")
                                    }
                                }
                            }
                        }
                    }
                }
                SlotState::Leaving => self.drop_slot(i, DropReason::Left),
                _ => {}
            }
        }
    }

    fn refuse(&self, i: usize, name: Option<&str>, reason: &str) {
        tracing::warn!(skill = name.unwrap_or("?"), %reason, "registration refused");
        let slot = self.board.slot(i);
        slot.write_msg(reason);
        slot.set_state(SlotState::Refused);
        if let Some(n) = name
            && let Ok(t) = services::notifier(&self.node, &names::skill_trigger(n))
        {
            let _ = t.notify();
        }
    }

    fn admit(&mut self, i: usize) {
        let slot = self.board.slot(i);
        let decl: SkillDecl = match postcard::from_bytes(&slot.read_decl()) {
            Ok(d) => d,
            Err(e) => return self.refuse(i, None, &format!("malformed declaration: {e}")),
        };
        let checked = names::check_name("skill", &decl.name, false).and_then(|()| {
            decl.inputs
                .iter()
                .chain(&decl.outputs)
                .try_for_each(|p| names::check_name("topic", &p.topic, true))
        });
        if let Err(e) = checked {
            return self.refuse(i, None, &e.to_string());
        }
        if decl.inputs.len() > 64 || decl.outputs.len() > 64 {
            return self.refuse(
                i,
                Some(&decl.name),
                "at most 64 inputs and 64 outputs per skill",
            );
        }
        // A previous instance of the same name that died is replaced, not a duplicate.
        if let Some(j) = (0..MAX_SLOTS).find(|&j| {
            j != i
                && self.skills[j]
                    .as_ref()
                    .is_some_and(|e| e.decl.name == decl.name && !pid_alive(e.decl.pid))
        }) {
            self.drop_slot(j, DropReason::Died);
        }
        let live = self.skills.iter().flatten().map(|e| &e.decl);
        if let Err(e) = graph::check_join(live, &decl) {
            return self.refuse(i, Some(&decl.name), &e.to_string());
        }
        let trigger = match services::notifier(&self.node, &names::skill_trigger(&decl.name)) {
            Ok(t) => t,
            Err(e) => return self.refuse(i, Some(&decl.name), &e.to_string()),
        };
        let slot = self.board.slot(i);
        slot.reset_counters();
        slot.generation.fetch_add(1, Ordering::Relaxed);
        slot.active
            .store(u32::from(decl.start_active), Ordering::Release);
        slot.set_state(SlotState::Accepted);
        let _ = trigger.notify();
        tracing::info!(
            skill = %decl.name, kind = %decl.kind, mode = %decl.mode, pid = decl.pid,
            active = decl.start_active, "skill registered"
        );
        let restarted = !self.seen.insert(decl.name.clone());
        if restarted && is_device(&decl) {
            self.outbox.push(EventKind::DeviceBack {
                device: decl.name.clone(),
            });
        }
        self.outbox.push(EventKind::SkillRegistered {
            skill: decl.name.clone(),
            pid: decl.pid,
            restarted,
        });
        let values = decl.param_values.clone();
        self.skills[i] = Some(Entry {
            values,
            ready: false,
            active: decl.start_active,
            decl,
            trigger,
        });
        self.order.retain(|&s| s != i);
        self.order.push(i);
        self.dirty = true;
    }

    /// Removes slot `i`: its skill left or died. Its pending run in this cycle (and whatever
    /// depended on it) is taken off the counter so the cycle does not wait for it.
    fn drop_slot(&mut self, i: usize, why: DropReason) {
        if let Some(mut run) = self.running.take() {
            let n = self.cancel_all(&mut run, vec![i]);
            if n > 0 {
                self.board.complete(run.k, n);
            }
            self.running = Some(run);
        }
        let slot = self.board.slot(i);
        if let Some(e) = self.skills[i].take() {
            if why == DropReason::Died {
                self.deaths += 1;
                tracing::warn!(skill = %e.decl.name, pid = e.decl.pid, "skill died");
                self.outbox.push(EventKind::SkillDied {
                    skill: e.decl.name.clone(),
                    pid: e.decl.pid,
                });
                if is_device(&e.decl) {
                    self.outbox.push(EventKind::DeviceLost {
                        device: e.decl.name.clone(),
                    });
                }
            } else {
                tracing::info!(skill = %e.decl.name, "skill left");
                self.outbox.push(EventKind::SkillLeft {
                    skill: e.decl.name.clone(),
                });
            }
            self.order.retain(|&s| s != i);
            self.dirty = true;
            // Stop reading its outputs: the manager must not keep a dead producer's topics
            // alive. They are read again when a new producer is ready.
            for p in &e.decl.outputs {
                self.readers.remove(&p.topic);
            }
        }
        slot.active.store(0, Ordering::Release);
        slot.pid.store(0, Ordering::Release);
        slot.set_state(SlotState::Free);
    }

    fn check_liveness(&mut self) {
        self.last_liveness = Instant::now();
        let mut died = false;
        for i in 0..MAX_SLOTS {
            let slot = self.board.slot(i);
            let state = slot.state();
            if state == SlotState::Free || state == SlotState::Refused {
                continue;
            }
            let pid = slot.pid.load(Ordering::Acquire);
            if pid != 0 && !pid_alive(pid) {
                self.drop_slot(i, DropReason::Died);
                died = true;
            }
        }
        // Frees the ports of dead processes (skills, or clients killed with Ctrl-C) so a
        // restarted instance can take their place and no shared memory is left behind.
        if died || self.last_node_sweep.elapsed() >= NODE_SWEEP {
            self.last_node_sweep = Instant::now();
            let _ = self.node.try_cleanup_dead_nodes();
        }
    }

    /// A slot's run counters, as read from the board.
    pub(crate) fn figures(&self, s: usize) -> SkillFigures {
        let slot = self.board.slot(s);
        let runs = slot.runs.load(Ordering::Acquire);
        let total = slot.compute_ns_total.load(Ordering::Acquire);
        SkillFigures {
            runs,
            skips: slot.skips.load(Ordering::Acquire),
            failures: slot.failures.load(Ordering::Acquire),
            compute_us_mean: if runs == 0 {
                0.0
            } else {
                total as f64 / runs as f64 / 1000.0
            },
            compute_us_last: slot.last_compute_ns.load(Ordering::Acquire) as f64 / 1000.0,
            last_cycle: slot.done_cycle.load(Ordering::Acquire),
            last_start_ns: slot.last_start_ns.load(Ordering::Acquire),
            last_end_ns: slot.last_end_ns.load(Ordering::Acquire),
        }
    }

    /// Figures of the run so far.
    pub fn report(&self) -> Report {
        let skills = self
            .order
            .iter()
            .filter_map(|&s| self.skills[s].as_ref().map(|e| (s, e)))
            .map(|(s, e)| SkillReport {
                name: e.decl.name.clone(),
                kind: e.decl.kind.clone(),
                mode: e.decl.mode.to_string(),
                active: e.active,
                priority: e.decl.priority,
                pid: e.decl.pid,
                figures: self.figures(s),
            })
            .collect();
        Report {
            cycles: self.stats.cycles,
            overruns: self.stats.overruns,
            latency_us: self.stats.latency_us(),
            manager_work_us: self.stats.work_us(),
            skills,
            deaths: self.deaths,
        }
    }
}

/// Whether a registered unit is a device (it serves an actuator channel).
fn is_device(d: &SkillDecl) -> bool {
    d.inputs
        .iter()
        .any(|p| matches!(p.kind, skillfab_proto::decl::PortKind::Channel(_)))
}

/// CPU time of the calling thread (ns): the manager's own work, not the time other
/// processes held the core while it was awake.
fn thread_cpu_ns() -> u64 {
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_THREAD_CPUTIME_ID).map_or(0, |t| {
        t.tv_sec() as u64 * 1_000_000_000 + t.tv_nsec() as u64
    })
}
