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

    /// The steps done since the last call.
    pub fn take_steps(&mut self) -> Vec<String> {
        std::mem::take(&mut self.steps)
    }
}

/// How long the loop waits for an event before ticking again (timeouts and sleeps are
/// checked at each tick).
const POLL: Duration = Duration::from_millis(20);

/// Runs `seq` over `client` until the tree succeeds or fails, or `stop` says so (then the
/// tree is halted: `None`). `on_step` gets each step as it is done. In lock-step the manager
/// pauses after a cycle in which a monitor fired; it is resumed once the plan has reacted,
/// so what the plan does lands in the same cycle every run (and at the start, for a manager
/// started `--paused`).
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
    let lockstep = client.clock().is_some_and(|c| c.lockstep);
    let mut first = true;
    loop {
        if stop() {
            seq.halt(&mut ClientFabric::new(client));
            for s in seq.take_steps() {
                on_step(client, &s);
            }
            return Ok(None);
        }
        // Every event already here first: a plan reacts to all that fired in a cycle at once.
        let mut wake = first;
        while let Some(ev) = client.next_event(Duration::ZERO).map_err(failed)? {
            wake |= seq.on_event(&id, &ev.kind);
        }
        let status = seq.tick(&mut ClientFabric::new(client))?;
        for s in seq.take_steps() {
            on_step(client, &s);
        }
        if status != Status::Running {
            return Ok(Some(status));
        }
        if lockstep && wake {
            client.run().map_err(failed)?;
        }
        first = false;
        if let Some(ev) = client.next_event(POLL).map_err(failed)?
            && seq.on_event(&id, &ev.kind)
        {
            // Ticked at the top of the loop, with any other event of the same cycle.
            first = true;
        }
    }
}
