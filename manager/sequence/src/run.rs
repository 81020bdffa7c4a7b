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
    /// The wall clock's origin, for a client that cannot read the fabric's (over a bridge).
    start: Instant,
}

impl<'a> ClientFabric<'a> {
    /// Drives the fabric of `client`.
    pub fn new(client: &'a Client) -> ClientFabric<'a> {
        ClientFabric {
            client,
            start: Instant::now(),
        }
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

    fn now(&mut self) -> Duration {
        match self.client.clock() {
            Some(c) => c.time,
            None => self.start.elapsed(),
        }
    }
}

/// A plan being run: its tree, the monitors of this client that fired, the step log.
pub struct Sequencer {
    root: Node,
    fired: HashSet<u64>,
    steps: Vec<String>,
}

impl Sequencer {
    /// A sequencer for `plan`'s tree `tree` (its main tree if `None`).
    pub fn new(plan: &Plan, tree: Option<&str>) -> Result<Sequencer, PlanError> {
        Ok(Sequencer {
            root: Node::build(plan, tree.unwrap_or(&plan.main))?,
            fired: HashSet::new(),
            steps: Vec::new(),
        })
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

/// Lock-step pacing. The manager pauses after a cycle in which a monitor fired; it is resumed
/// once the plan has reacted — with `run`, or, while a timer of the plan is running, with a
/// `step` exactly as far as the timer, so that a `Sleep` or `Timeout` ends in the same cycle
/// every run too. A plan run in lock-step is as reproducible as its skills.
#[derive(Debug)]
pub struct LockStep {
    paused: bool,
}

impl LockStep {
    /// Pacing for `client`'s manager if it runs in lock-step (it is taken as paused: a
    /// manager started `--paused` waits for the plan's first tick).
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

    /// Resumes the manager after the plan reacted: up to its next timer, else freely.
    pub fn resume(&mut self, client: &Client, seq: &Sequencer) -> Result<(), ClientError> {
        let clock = client.clock();
        let cycles = match (seq.deadline(), clock.and_then(|c| c.period)) {
            (Some(due), Some(period)) => {
                let now = clock.map_or(Duration::ZERO, |c| c.time);
                let left = due.saturating_sub(now).as_nanos();
                Some(left.div_ceil(period.as_nanos().max(1)).max(1) as u64)
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
/// is paced by the plan ([`LockStep`]).
pub fn run(
    client: &mut Client,
    seq: &mut Sequencer,
    stop: &dyn Fn() -> bool,
    on_step: &mut dyn FnMut(&Client, &str),
) -> Result<Option<Status>, SeqError> {
    let failed = |e: ClientError| SeqError::Fabric {
        what: "events".into(),
        source: FabricError::Failed(e.to_string()),
    };
    client.subscribe().map_err(failed)?;
    let id = client.id().to_string();
    let mut lockstep = LockStep::of(client);
    loop {
        if stop() {
            seq.halt(&mut ClientFabric::new(client));
            for s in seq.take_steps() {
                on_step(client, &s);
            }
            return Ok(None);
        }
        // Every event already here first: a plan reacts to all that fired in a cycle at once.
        while let Some(ev) = client.next_event(Duration::ZERO).map_err(failed)? {
            seq.on_event(&id, &ev.kind);
            if let Some(l) = lockstep.as_mut() {
                l.on_event(&ev.kind);
            }
        }
        // In lock-step the plan is ticked while the manager waits for it, and only then.
        if lockstep.as_ref().is_none_or(LockStep::paused) {
            let status = seq.tick(&mut ClientFabric::new(client))?;
            for s in seq.take_steps() {
                on_step(client, &s);
            }
            if status != Status::Running {
                return Ok(Some(status));
            }
            if let Some(l) = lockstep.as_mut() {
                l.resume(client, seq).map_err(failed)?;
                if l.paused() {
                    continue;
                }
            }
        }
        if let Some(ev) = client.next_event(POLL).map_err(failed)? {
            seq.on_event(&id, &ev.kind);
            if let Some(l) = lockstep.as_mut() {
                l.on_event(&ev.kind);
            }
        }
    }
}
