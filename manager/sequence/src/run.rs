//! The sequencer's loop over a [`Client`]: tick the tree, wait for events, tick again; in
//! lock-step, resume the paused manager once the plan has reacted.

use crate::plan::{Plan, PlanError};
use crate::tree::{Cx, Fabric, FabricError, Node, SeqError, Status};
use skillfab_client::{Client, ClientError};
use skillfab_proto::control::{EventKind, MonitorMode};
use skillfab_proto::param::ParamValue;
use std::collections::HashSet;
use std::time::{Duration, Instant};

/// The fabric a plan drives, through a client of the local manager (or a remote one).
pub struct ClientFabric<'a> {
    client: &'a Client,
    /// The wall clock's origin, for a client that cannot read the fabric's (over a bridge):
    /// the plan's, the same for all its ticks ([`Sequencer::origin`]).
    origin: Instant,
}

impl<'a> ClientFabric<'a> {
    /// Drives the fabric of `client`; `origin` is the plan's ([`Sequencer::origin`]).
    pub fn new(client: &'a Client, origin: Instant) -> ClientFabric<'a> {
        ClientFabric { client, origin }
    }
}

fn fabric_error(e: ClientError) -> FabricError {
    match e {
        ClientError::Refused(why) => FabricError::Refused(why.to_string()),
        other => FabricError::Failed(other.to_string()),
    }
}

impl Fabric for ClientFabric<'_> {
    fn activate(&mut self, skills: &[String]) -> Result<(), FabricError> {
        let s: Vec<&str> = skills.iter().map(String::as_str).collect();
        self.client.activate(&s).map_err(fabric_error)
    }

    fn deactivate(&mut self, skills: &[String]) -> Result<(), FabricError> {
        let s: Vec<&str> = skills.iter().map(String::as_str).collect();
        self.client.deactivate(&s).map_err(fabric_error)
    }

    fn get_param(&mut self, skill: &str, param: &str) -> Result<ParamValue, FabricError> {
        self.client.get_param(skill, param).map_err(fabric_error)
    }

    fn set_param(&mut self, skill: &str, param: &str, value: &str) -> Result<(), FabricError> {
        self.client
            .set_param(skill, param, value)
            .map_err(fabric_error)
    }

    fn set_param_value(
        &mut self,
        skill: &str,
        param: &str,
        value: ParamValue,
    ) -> Result<(), FabricError> {
        self.client
            .set_param_value(skill, param, value)
            .map_err(fabric_error)
    }

    fn add_monitor(&mut self, condition: &str, hold: u32) -> Result<u64, FabricError> {
        self.client
            .add_monitor(condition, MonitorMode::Once, hold)
            .map_err(fabric_error)
    }

    fn remove_monitor(&mut self, id: u64) {
        // A monitor that fired is gone already; one of a manager that left went with it.
        let _ = self.client.remove_monitor(id);
    }

    /// The fabric's clock on this host (none while its manager restarts: time stands still
    /// for the plan's timers); over a bridge, the wall clock since the plan started.
    fn now(&mut self) -> Duration {
        if self.client.is_remote() {
            return self.origin.elapsed();
        }
        self.client.clock().map_or(Duration::ZERO, |c| c.time)
    }
}

/// A plan being run: its tree, the monitors of this client that fired, the step log.
pub struct Sequencer {
    root: Node,
    fired: HashSet<u64>,
    steps: Vec<String>,
    origin: Instant,
}

impl Sequencer {
    /// A sequencer for `plan`'s tree `tree` (its main tree if `None`).
    pub fn new(plan: &Plan, tree: Option<&str>) -> Result<Sequencer, PlanError> {
        Ok(Sequencer {
            root: Node::build(plan, tree.unwrap_or(&plan.main))?,
            fired: HashSet::new(),
            steps: Vec::new(),
            origin: Instant::now(),
        })
    }

    /// When the plan started: the origin of its wall-clock time over a bridge.
    pub fn origin(&self) -> Instant {
        self.origin
    }

    /// Takes in an event of `client`'s stream; whether the plan has something to react to
    /// (one of this client's monitors fired).
    pub fn on_event(&mut self, client: &str, event: &EventKind) -> bool {
        match event {
            EventKind::MonitorFired {
                id, client: owner, ..
            } if owner == client => {
                self.fired.insert(*id);
                true
            }
            _ => false,
        }
    }

    /// Ticks the tree once.
    pub fn tick(&mut self, fabric: &mut dyn Fabric) -> Result<Status, SeqError> {
        let mut cx = Cx {
            fabric,
            fired: &mut self.fired,
            steps: &mut self.steps,
        };
        self.root.tick(&mut cx)
    }

    /// Halts the tree: monitors removed, parameters restored.
    pub fn halt(&mut self, fabric: &mut dyn Fabric) {
        let mut cx = Cx {
            fabric,
            fired: &mut self.fired,
            steps: &mut self.steps,
        };
        self.root.halt(&mut cx);
    }

    /// The earliest fabric time a running timer (`Sleep`, `Timeout`) of the plan is due.
    pub fn deadline(&self) -> Option<Duration> {
        self.root.deadline()
    }

    /// The steps done since the last call.
    pub fn take_steps(&mut self) -> Vec<String> {
        std::mem::take(&mut self.steps)
    }
}

/// How long the loop waits for an event before ticking again (timeouts and sleeps are
/// checked at each tick).
const POLL: Duration = Duration::from_millis(20);

/// The most cycles one `step` asks for: a long timer is stepped in parts, so that Ctrl-C is
/// seen between them.
const MAX_STEP: u64 = 200;

/// Lock-step pacing. The manager pauses after a cycle in which a monitor fired; it is resumed
/// once the plan has reacted — with `run`, or, while a timer of the plan is running, with a
/// `step` exactly as far as the timer, so that a `Sleep` or `Timeout` ends in the same cycle
/// every run too. A plan run in lock-step is as reproducible as its skills. When the plan
/// ends, the manager stays paused (`ctl run` resumes it).
#[derive(Debug)]
pub struct LockStep {
    paused: bool,
}

impl LockStep {
    /// Pacing for `client`'s manager if it runs in lock-step on this host (it is taken as
    /// paused: a manager started `--paused` waits for the plan's first tick). Over a bridge
    /// the board cannot be read: a plan does not pace a remote lock-step manager.
    pub fn of(client: &Client) -> Option<LockStep> {
        client
            .clock()
            .filter(|c| c.lockstep)
            .map(|_| LockStep { paused: true })
    }

    /// Whether the manager waits for the plan (it is ticked, then resumed).
    pub fn paused(&self) -> bool {
        self.paused
    }

    /// Takes in an event: a monitor that fired paused the manager.
    pub fn on_event(&mut self, event: &EventKind) {
        if matches!(event, EventKind::MonitorFired { .. }) {
            self.paused = true;
        }
    }

    /// Resumes the manager after the plan reacted: up to its next timer (at most
    /// [`MAX_STEP`] cycles at a time), else freely.
    pub fn resume(&mut self, client: &Client, seq: &Sequencer) -> Result<(), ClientError> {
        let clock = client.clock();
        let cycles = match (seq.deadline(), clock.and_then(|c| c.period)) {
            (Some(due), Some(period)) => {
                let now = clock.map_or(Duration::ZERO, |c| c.time);
                let left = due.saturating_sub(now).as_nanos();
                let n = left.div_ceil(period.as_nanos().max(1)).max(1);
                Some(u64::try_from(n).unwrap_or(u64::MAX).min(MAX_STEP))
            }
            _ => None,
        };
        match cycles {
            // Ends at the timer, or earlier if a monitor fires: paused either way.
            Some(n) => {
                client.step(n)?;
                self.paused = true;
            }
            None => {
                client.run()?;
                self.paused = false;
            }
        }
        Ok(())
    }
}

/// Runs `seq` over `client` until the tree succeeds or fails, or `stop` says so (then the
/// tree is halted: `None`). `on_step` gets each step as it is done. In lock-step the manager
/// is paced by the plan ([`LockStep`]). On an error the tree is halted as far as the fabric
/// still answers (parameters restored, monitors removed) before the error is returned.
pub fn run(
    client: &mut Client,
    seq: &mut Sequencer,
    stop: &mut dyn FnMut() -> bool,
    on_step: &mut dyn FnMut(&Client, &str),
) -> Result<Option<Status>, SeqError> {
    let outcome = drive(client, seq, stop, on_step);
    if outcome.is_err() {
        seq.halt(&mut ClientFabric::new(client, seq.origin()));
        for s in seq.take_steps() {
            on_step(client, &s);
        }
    }
    outcome
}

fn drive(
    client: &mut Client,
    seq: &mut Sequencer,
    stop: &mut dyn FnMut() -> bool,
    on_step: &mut dyn FnMut(&Client, &str),
) -> Result<Option<Status>, SeqError> {
    let failed = |what: &'static str| {
        move |e: ClientError| SeqError::Fabric {
            what: what.into(),
            source: FabricError::Failed(e.to_string()),
        }
    };
    client
        .subscribe()
        .map_err(failed("subscribing to events"))?;
    let id = client.id().to_string();
    let mut lockstep = LockStep::of(client);
    loop {
        if stop() {
            seq.halt(&mut ClientFabric::new(client, seq.origin()));
            for s in seq.take_steps() {
                on_step(client, &s);
            }
            return Ok(None);
        }
        // Every event already here first: a plan reacts to all that fired in a cycle at once.
        while let Some(ev) = client
            .next_event(Duration::ZERO)
            .map_err(failed("reading events"))?
        {
            seq.on_event(&id, &ev.kind);
            if let Some(l) = lockstep.as_mut() {
                l.on_event(&ev.kind);
            }
        }
        // In lock-step the plan is ticked while the manager waits for it, and only then.
        if lockstep.as_ref().is_none_or(LockStep::paused) {
            let status = seq.tick(&mut ClientFabric::new(client, seq.origin()))?;
            for s in seq.take_steps() {
                on_step(client, &s);
            }
            if status != Status::Running {
                return Ok(Some(status));
            }
            if let Some(l) = lockstep.as_mut() {
                l.resume(client, seq)
                    .map_err(failed("resuming the lock-step manager"))?;
                if l.paused() {
                    continue;
                }
            }
        }
        if let Some(ev) = client.next_event(POLL).map_err(failed("reading events"))? {
            seq.on_event(&id, &ev.kind);
            if let Some(l) = lockstep.as_mut() {
                l.on_event(&ev.kind);
            }
        }
    }
}
