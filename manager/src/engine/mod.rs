//! The cycle engine (the paper's skill manager): registry, cycle plan, readiness, liveness.
//!
//! One loop on one thread, asleep on the board's doorbell until the next timer (period
//! start, cycle deadline, liveness tick): rung by skills (registration, leaving, the run that
//! completes a cycle, a run that passed nothing on) and by the control thread (a request);
//! SIGINT/SIGTERM end the sleep too.
//!
//! A cycle k: the manager marks the expected sync skills on the board, arms the completion
//! counter with their number, publishes k and wakes only the sources (skills whose inputs are
//! not produced in the same cycle). From there skills wake each other through their topics;
//! each finished run stamps the board and takes one off the counter; the run that takes the
//! last one off wakes the manager. A run that fails, is skipped or leaves an output unwritten
//! wakes the manager too, which then takes its now-unrunnable consumers off the counter. A
//! cycle whose deadline passes is counted as an overrun and closed; the next one starts on
//! time. Cleanup between cycles is the re-arming of the counter.

//!
//! The manager's state is in parts that each own one job: the registry ([`skills`]), the
//! cycles ([`Cycles`]: plan, pacing, holds, figures), the observers ([`observers`]: readers,
//! monitors, fabric log, recording, channels, bridges), the events on their way out
//! ([`Outbox`]), the running plan's live tree ([`plans`]) and the state file ([`state`]). Requests are carried out by handlers handed the
//! parts they need ([`requests`]).

mod cycle;
mod holds;
mod observers;
mod plans;
mod record;
mod registry;
mod requests;
mod skills;
mod state;

pub use record::{RecordError, RecordSpec};

use crate::control::{ControlPlane, Outgoing, client_pid};
use crate::graph::Plan;
use crate::recorder::Recorder;
use crate::stats::{CycleStats, Report, SkillReport};
use iceoryx2::node::{Node, NodeView};
use iceoryx2::prelude::*;
use observers::Observers;
use skillfab_proto::board::{Board, MAX_SLOTS, pid_alive};
use skillfab_proto::control::{Event, EventKind, Request, SkillFigures};
use skillfab_proto::decl::SkillDecl;
use skillfab_proto::domain::Domain;
use skillfab_proto::header::now_ns;
use skillfab_proto::param::ParamValue;
use skillfab_proto::{Error as SdkError, services};
use skills::Skills;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// How often the manager checks that registered processes are alive (and its longest sleep).
/// A sync skill that dies mid-cycle is also found when the cycle's deadline passes; each
/// check reads `/proc` for every skill, so it is not done every cycle.
pub const LIVENESS_TICK: Duration = Duration::from_millis(200);
/// How often the manager removes what dead processes of the domain left behind (at once when
/// a registered unit died). A sweep lists and opens every node of the domain through iceoryx2
/// (about 3 M instructions with a handful of processes, measured with callgrind), so it is
/// rare: a client killed with Ctrl-C leaves its ports for at most this long.
const NODE_SWEEP: Duration = Duration::from_secs(5);
/// Shortest cycle period in free-running mode while no skill is expected (avoids a busy loop).
const IDLE_FREE_RUN: Duration = Duration::from_millis(1);

/// How the manager paces cycles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// A new cycle every period (the deadline defaults to the period).
    Period(Duration),
    /// The next cycle starts as soon as the previous one finished.
    FreeRun,
    /// Lock-step: cycles back to back, as free-running, but each cycle stands for one period
    /// of simulated time (the skills' clock, the simulator's step) and has no deadline short of
    /// [`LOCKSTEP_DEADLINE`]: a run is a function of its inputs, not of the CPU's speed.
    LockStep(Duration),
}

/// The deadline of a lock-step cycle: only a unit that died (or hangs) holds one this long.
pub const LOCKSTEP_DEADLINE: Duration = Duration::from_secs(10);

impl Pace {
    /// Whether cycles run in lock-step.
    pub fn is_lockstep(self) -> bool {
        matches!(self, Pace::LockStep(_))
    }

    /// The nominal period, if there is one.
    pub fn period(self) -> Option<Duration> {
        match self {
            Pace::Period(p) | Pace::LockStep(p) => Some(p),
            Pace::FreeRun => None,
        }
    }
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
    /// Run no cycle until a client holds the fabric at one (a lock-step observer's first
    /// hold; see `Request::Hold`).
    pub held: bool,
    /// Stop after this many cycles.
    pub max_cycles: Option<u64>,
    /// Do not start cycling until these skills have registered.
    pub wait_for: Vec<String>,
    /// How long to wait for them.
    pub wait_timeout: Duration,
    /// The fabric log (parameter changes, I/O samples); `None`: [`default_log_path`].
    pub param_log: Option<PathBuf>,
    /// Record every sample of these topics (and the control changes and events) from the
    /// start.
    pub record: Option<RecordSpec>,
    /// The first cycle's number (a replay numbers cycles as the recording did); a manager
    /// that takes over from a dead one numbers on from it instead.
    pub first_cycle: u64,
    /// With a period: the fabric's clock runs this many times faster than the host's, as a
    /// simulator sped up as much does — a cycle paced every period stands for
    /// `period × time_factor` of the clock skills and plans time things in (1: the host's).
    pub time_factor: f64,
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
            held: false,
            max_cycles: None,
            wait_for: Vec::new(),
            wait_timeout: Duration::from_secs(30),
            param_log: None,
            first_cycle: 1,
            time_factor: 1.0,
            record: None,
        }
    }

    /// The period of the fabric's clock (`None`: it free-runs, the clock is the host's): the
    /// pace's period, times [`ManagerConfig::time_factor`] when paced in real time.
    pub fn clock_period(&self) -> Option<Duration> {
        match self.pace {
            // (A factor that is not a positive number, which the flags refuse, counts as 1.)
            Pace::Period(p) if self.time_factor.is_finite() && self.time_factor > 0.0 => {
                let ns = (p.as_nanos() as f64 * self.time_factor).round();
                Some(Duration::from_nanos(ns.min(u64::MAX as f64) as u64))
            }
            Pace::Period(p) => Some(p),
            Pace::LockStep(p) => Some(p),
            Pace::FreeRun => None,
        }
    }

    fn deadline(&self) -> Duration {
        self.deadline.unwrap_or(match self.pace {
            Pace::Period(p) => p,
            Pace::FreeRun => Duration::from_secs(1),
            Pace::LockStep(_) => LOCKSTEP_DEADLINE,
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
    /// [`Manager::run`] was called a second time (a manager runs once).
    #[error("the manager has run already: a manager runs once")]
    RanAlready,
    /// The recording asked for cannot be written.
    #[error("recording")]
    Record(#[from] RecordError),
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
    pub(crate) active: bool,
    /// Its ports are open: cycles may count on it.
    pub(crate) ready: bool,
    /// Current parameter values (the skill applies them from the next cycle).
    pub(crate) values: Vec<(String, ParamValue)>,
}

/// How long the monitors of a client whose process died are kept (evaluated, and a `Once`
/// monitor that fires remembered as fired) before they are removed: a plan runner restarted
/// by `up` takes them over in that time (`AdoptMonitors`) and misses no condition.
pub const ORPHAN_GRACE: Duration = Duration::from_secs(10);

/// The cycle in progress.
struct Running {
    k: u64,
    start_ns: u64,
    deadline: Instant,
    /// The plan's expected units, a bit per slot (the plan is not made again while a cycle
    /// runs: its list is the cycle's order; this mask answers membership without allocating).
    expected: u64,
    /// Slots whose completion the manager has looked at.
    processed: [bool; MAX_SLOTS],
    /// Slots taken off the counter because they cannot run this cycle.
    cancelled: [bool; MAX_SLOTS],
}

/// Where the cycles stand: the plan they follow, the one in progress, what paces, pauses and
/// holds them, and their figures.
struct Cycles {
    plan: Plan,
    /// The expected units in spin mode that are not sources (their budget is on their slot,
    /// written before they were ready): rung at cycle start after the sources. Made with the
    /// plan.
    spinners: Vec<usize>,
    /// The plan must be made again before the next cycle.
    dirty: bool,
    /// Cycles completed.
    cycle: u64,
    running: Option<Running>,
    next_start: Instant,
    paused: bool,
    /// Pause once this many cycles are done (`step`).
    stop_at: Option<u64>,
    /// Clients' holds: no cycle after the lowest starts.
    holds: holds::Holds,
    /// The skills of `wait_for` have registered: cycling has begun.
    started: bool,
    created: Instant,
    stats: CycleStats,
    last_liveness: Instant,
    last_node_sweep: Instant,
    /// The previous cycle started on the period's schedule (not after a pause or a hold):
    /// a start more than a period late counts as a late start.
    on_schedule: bool,
}

/// Events on their way to clients: queued as they happen, then numbered and stamped between
/// cycles ([`Manager::stamp_events`]), then handed to the control plane.
#[derive(Default)]
struct Outbox {
    queued: Vec<EventKind>,
    stamped: Vec<Event>,
    /// Events numbered so far.
    published: u64,
}

impl Outbox {
    fn push(&mut self, event: EventKind) {
        self.queued.push(event);
    }

    fn published(&self) -> u64 {
        self.published
    }

    /// Numbers and stamps the queued events as of `cycle`; the ones just stamped.
    fn stamp(&mut self, cycle: u64) -> &[Event] {
        let from = self.stamped.len();
        for kind in std::mem::take(&mut self.queued) {
            self.published += 1;
            self.stamped.push(Event {
                seq: self.published,
                cycle,
                time_ns: now_ns(),
                kind,
            });
        }
        &self.stamped[from..]
    }
}

/// The skill manager of one domain.
pub struct Manager {
    config: ManagerConfig,
    board: Board,
    node: Node<ipc::Service>,
    /// The registered skills, by slot and in registration order.
    skills: Skills,
    cycles: Cycles,
    observers: Observers,
    events: Outbox,
    /// The running plan's tree and statuses, as its runner reports them.
    plans: plans::Plans,
    state: state::StateFile,
    /// Requests in, answers and events out.
    control: ControlPlane,
    /// [`Manager::run`] was called.
    ran: bool,
}

/// A slot's run counters, as read from the board.
pub(crate) fn figures(board: &Board, s: usize) -> SkillFigures {
    let slot = board.slot(s);
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
        deadline_misses: slot.deadline_misses.load(Ordering::Acquire),
        cycle_allocs: slot.cycle_allocs.load(Ordering::Acquire),
    }
}

impl Manager {
    /// Creates the domain's board and the manager's iceoryx2 node.
    pub fn new(config: ManagerConfig) -> Result<Manager, ManagerError> {
        let node = services::node(&config.domain, "skillfab-manager")?;
        // The control server exists before the board announces the manager to clients.
        let control = ControlPlane::new(&config.domain, &node)?;
        // A predecessor that died: its skills are told at once, and cycles number on.
        let previous_cycle = Board::retire_dead(&config.domain.prefix());
        let board = Board::create(&config.domain.prefix())?;
        let h = board.header();
        let period = config.clock_period().map_or(0, |p| p.as_nanos() as u64);
        h.period_ns.store(period, Ordering::Release);
        h.lockstep
            .store(u32::from(config.pace.is_lockstep()), Ordering::Release);
        let now = Instant::now();
        let log_path = config
            .param_log
            .clone()
            .unwrap_or_else(|| default_log_path(&config.domain));
        let fabric_log = match Recorder::open(&log_path) {
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
        let saved = state::Saved::load(&config.domain);
        let holds = if config.held {
            holds::Holds::at_start()
        } else {
            holds::Holds::default()
        };
        let cycles = Cycles {
            plan: Plan::default(),
            spinners: Vec::new(),
            dirty: true,
            cycle: previous_cycle.unwrap_or(config.first_cycle.saturating_sub(1)),
            running: None,
            next_start: now,
            paused: config.paused,
            stop_at: None,
            holds,
            started: false,
            created: now,
            stats: CycleStats::default(),
            last_liveness: now,
            last_node_sweep: now,
            on_schedule: false,
        };
        let mut manager = Manager {
            config,
            board,
            node,
            skills: Skills::new(),
            cycles,
            observers: Observers::new(fabric_log),
            events: Outbox::default(),
            plans: plans::Plans::default(),
            state: state::StateFile::default(),
            control,
            ran: false,
        };
        if let Some(saved) = saved {
            manager.restore_state(saved);
        }
        if let Some(spec) = manager.config.record.clone() {
            let at = record::RecordStart::new(
                &manager.config.domain,
                manager.cycles.cycle,
                &manager.board,
                &manager.skills,
                &manager.node,
            );
            manager
                .observers
                .start_recording(spec, &at)
                .map_err(ManagerError::Record)?;
        }
        Ok(manager)
    }

    /// Runs until SIGINT/SIGTERM, until `stop(cycles_done)` returns true, or until
    /// `max_cycles` cycles are done; returns the report of the run.
    pub fn run(&mut self, stop: &dyn Fn(u64) -> bool) -> Result<Report, ManagerError> {
        if std::mem::replace(&mut self.ran, true) {
            return Err(ManagerError::RanAlready);
        }
        tracing::info!(domain = %self.config.domain, pace = ?self.config.pace, "manager up");
        self.serve_loop(stop)
    }

    /// The manager's loop: it sleeps on its doorbell (rung by the run that ends a cycle, by
    /// registrations and by the control thread) until the next deadline or cycle start, then
    /// does what is due.
    fn serve_loop(&mut self, stop: &dyn Fn(u64) -> bool) -> Result<Report, ManagerError> {
        loop {
            // Read before doing the work: a ring from here on ends the wait at once.
            let seen = self.board.header().bell.seen();
            let awake = thread_cpu_ns();
            self.service_registry();
            if self.cycles.last_liveness.elapsed() >= LIVENESS_TICK {
                self.check_liveness();
                self.forget_dead_clients();
            }
            self.serve_requests();
            self.save_state_if_changed();
            self.advance()?;
            self.publish();
            self.cycles
                .stats
                .add_work(thread_cpu_ns().saturating_sub(awake));
            if self.cycles.running.is_none()
                && self
                    .config
                    .max_cycles
                    .is_some_and(|m| self.cycles.cycle >= m)
            {
                break;
            }
            // A signal during the wait ends it (EINTR) and is seen here next time round; one
            // that lands between this check and the wait is seen within a liveness tick.
            if services::termination_requested() || stop(self.cycles.cycle) {
                break;
            }
            let timeout = self.timeout(Instant::now());
            if !timeout.is_zero() {
                self.board.header().bell.wait(seen, timeout);
            }
        }
        Ok(self.report())
    }

    /// Carries out every request that arrived, and answers them once what they changed is
    /// in the state file (a manager killed right after the answer comes back with it).
    fn serve_requests(&mut self) {
        let mut answers = Vec::new();
        for inc in self.control.arrived() {
            let client = inc.client.as_deref().unwrap_or("?");
            let response = match inc.request {
                Err(e) => Err(e),
                Ok(Request::Step(n)) if n > 0 => {
                    self.cycles.stop_at = Some(self.in_progress() + n);
                    self.set_paused(false);
                    self.control.answer_when_stepped(inc.id, inc.client);
                    continue;
                }
                Ok(request) => self.handle(client, request),
            };
            if let Err(e) = &response {
                tracing::info!(client, error = %e, "request refused");
            }
            answers.push(Outgoing::Answer {
                id: inc.id,
                client: inc.client,
                response,
            });
        }
        if !answers.is_empty() {
            self.save_state_if_changed();
            self.control.answer(answers);
        }
    }

    /// Hands the events stamped so far, and the answers of finished `step`s, to the control
    /// plane.
    fn publish(&mut self) {
        self.stamp_events();
        let events = std::mem::take(&mut self.events.stamped);
        let stepped = self.cycles.stop_at.is_none().then_some(self.cycles.cycle);
        self.control.flush(events, stepped);
    }

    /// Releases the holds of clients whose process is gone, and drops their monitors once it
    /// has been gone for [`ORPHAN_GRACE`] — but not in lock-step: there a monitor's firing
    /// pauses the fabric until its plan has reacted, and the fabric waits for a plan runner
    /// that died (a restarted one takes its monitors over).
    fn forget_dead_clients(&mut self) {
        let dead = |c: &str| client_pid(c).is_some_and(|p| !pid_alive(p));
        // A hold goes with its client at once (the fabric would wait for nobody).
        let gone = self.cycles.holds.release_gone(dead);
        if !gone.is_empty() {
            self.state.check = true;
            tracing::info!(clients = ?gone, "holds of departed clients released");
        }
        if self.config.pace.is_lockstep() {
            return;
        }
        let removed = self.observers.drop_orphaned_monitors(dead, ORPHAN_GRACE);
        if removed > 0 {
            self.state.check = true;
            tracing::info!(removed, "monitors of departed clients removed");
        }
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
        for (s, _) in self.skills.in_order() {
            self.board.slot(s).bell.ring();
        }
        let cleaned = self.node.try_cleanup_dead_nodes();
        // The control thread's node is ours too: close it before looking for others.
        self.control.close();
        self.observers.readers.clear();
        let others_alive = self.others_alive();
        let (domain, cycles) = (self.config.domain.clone(), self.cycles.cycle);
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
        self.cycles.cycle
    }

    fn timeout(&self, now: Instant) -> Duration {
        let c = &self.cycles;
        let until = |t: Instant| t.saturating_duration_since(now);
        let t = match &c.running {
            Some(r) => until(r.deadline),
            None if c.paused || !c.started || c.holds.blocks(c.cycle) => LIVENESS_TICK,
            None => match self.config.pace {
                Pace::Period(_) => until(c.next_start),
                Pace::FreeRun | Pace::LockStep(_) if c.plan.expected.is_empty() => IDLE_FREE_RUN,
                Pace::FreeRun | Pace::LockStep(_) => Duration::ZERO,
            },
        };
        t.min(LIVENESS_TICK)
    }

    /// Figures of the run so far.
    pub fn report(&self) -> Report {
        let skills = self
            .skills
            .in_order()
            .map(|(s, e)| SkillReport {
                name: e.decl.name.clone(),
                kind: e.decl.kind.clone(),
                mode: e.decl.mode.to_string(),
                active: e.active,
                priority: e.decl.priority,
                pid: e.decl.pid,
                figures: figures(&self.board, s),
            })
            .collect();
        let stats = &self.cycles.stats;
        Report {
            cycles: stats.cycles,
            overruns: stats.overruns,
            latency_us: stats.latency_us(),
            manager_work_us: stats.work_us(),
            skills,
            deaths: self.skills.deaths,
            late_starts: stats.late_starts,
        }
    }
}

/// CPU time of the calling thread (ns): the manager's own work, not the time other
/// processes held the core while it was awake.
fn thread_cpu_ns() -> u64 {
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_THREAD_CPUTIME_ID).map_or(0, |t| {
        t.tv_sec() as u64 * 1_000_000_000 + t.tv_nsec() as u64
    })
}
