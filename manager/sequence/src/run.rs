//! The sequencer's loop over a [`Client`]: tick the tree, wait for events, tick again; in
//! lock-step, resume the paused manager once the plan has reacted.

use crate::keep::{Kept, PlanState, PlanStore};
use crate::live::LiveTree;
use crate::plan::{Plan, PlanError};
use crate::tree::{Cx, Fabric, FabricError, Node, Override, Saved, SeqError, Status};
use skillfab_client::{Client, ClientError};
use skillfab_proto::control::{EventKind, MonitorFate, MonitorMode, PlanReport, PlanTree};
use skillfab_proto::param::ParamValue;
use std::collections::HashSet;
use std::time::{Duration, Instant, SystemTime};

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
        ClientError::Refused(why) => why.into(),
        other => FabricError::Failed(std::sync::Arc::new(other)),
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

    fn want(&mut self, skills: &[String]) -> Result<(), FabricError> {
        let s: Vec<&str> = skills.iter().map(String::as_str).collect();
        self.client.want(&s).map_err(fabric_error)
    }

    fn release(&mut self, skills: &[String]) -> Result<(), FabricError> {
        let s: Vec<&str> = skills.iter().map(String::as_str).collect();
        self.client.release(&s).map_err(fabric_error)
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

    fn adopt_monitors(&mut self, ids: &[u64]) -> Result<Vec<MonitorFate>, FabricError> {
        self.client.adopt_monitors(ids).map_err(fabric_error)
    }

    fn monitors(&mut self) -> Result<Vec<(u64, String)>, FabricError> {
        let list = self.client.monitors().map_err(fabric_error)?;
        Ok(list.into_iter().map(|m| (m.id, m.client)).collect())
    }

    fn gave_up(&mut self) -> Result<Vec<String>, FabricError> {
        let list = self.client.gave_up().map_err(fabric_error)?;
        Ok(list.into_iter().map(|g| g.process).collect())
    }

    /// The fabric's clock on this host (none while its manager restarts: time stands still
    /// for the plan's timers); over a bridge, the wall clock since the plan started.
    fn now(&mut self) -> Duration {
        if self.client.is_remote() {
            return self.origin.elapsed();
        }
        self.client.clock().map_or(Duration::ZERO, |c| c.time)
    }

    fn report_plan(&mut self, report: PlanReport) -> Result<(), FabricError> {
        self.client.report_plan(report).map_err(fabric_error)
    }

    fn current_plan(&mut self) -> Result<Option<PlanTree>, FabricError> {
        self.client.plan().map_err(fabric_error)
    }
}

/// A plan being run: its tree, the monitors of this client that fired, the step log, the
/// parameters it set; and where its state is kept for a runner that takes over.
pub struct Sequencer {
    root: Node,
    fired: HashSet<u64>,
    steps: Vec<String>,
    origin: Instant,
    overrides: Vec<Override>,
    keep: Option<Keeping>,
    /// Processes `skillfab up` gave up restarting: those its events name, and those the
    /// manager listed before the first tick (their events went by before this runner).
    gave_up: HashSet<String>,
    /// Whether the manager was asked for them.
    asked_gave_up: bool,
    /// Each node's status, reported to the manager as it changes.
    live: LiveTree,
}

/// A plan whose state is kept ([`Sequencer::kept`]).
struct Keeping {
    store: PlanStore,
    state: PlanState,
    /// A second tree, into which a kept state is read (used only if it fits).
    spare: Option<Node>,
    /// Start over whatever was kept (`--fresh`).
    fresh: bool,
    /// How the runner started, once it has ([`Sequencer::open`]).
    opened: Option<Opening>,
    /// A failed save was said once.
    warned: bool,
}

/// How a runner whose plan's state is kept started.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Opening {
    /// Nothing was kept: the plan starts from its first node.
    Fresh,
    /// The same plan was running: it goes on where its last runner left it.
    Resumed {
        /// Where it was (the running leaves, timers, parameters set).
        at: Vec<String>,
    },
    /// Another plan's state, or one that cannot be resumed, was kept: what it had set was
    /// restored and its monitors removed, and this plan starts from its first node.
    StartedOver {
        /// Why.
        why: String,
    },
}

impl Sequencer {
    /// A sequencer for `plan`'s tree `tree` (its main tree if `None`); its live tree is
    /// named after the tree.
    pub fn new(plan: &Plan, tree: Option<&str>) -> Result<Sequencer, PlanError> {
        let tree = tree.unwrap_or(&plan.main);
        let (root, shape) = Node::build_shaped(plan, tree)?;
        Ok(Sequencer {
            root,
            live: LiveTree::new(tree, shape),
            fired: HashSet::new(),
            steps: Vec::new(),
            origin: Instant::now(),
            overrides: Vec::new(),
            keep: None,
            gave_up: HashSet::new(),
            asked_gave_up: false,
        })
    }

    /// The same, with the plan's state kept in `store` after every tick, so that a runner
    /// started after this one dies (same plan, same domain) resumes it at the node it was in
    /// ([`Sequencer::open`]). `file` names the plan in the kept state and messages; with
    /// `fresh`, a kept plan is not resumed: what it had set is restored, and this one starts
    /// from its first node.
    pub fn kept(
        plan: &Plan,
        tree: Option<&str>,
        file: &str,
        store: PlanStore,
        fresh: bool,
    ) -> Result<Sequencer, PlanError> {
        let tree = tree.unwrap_or(&plan.main);
        let mut seq = Sequencer::new(plan, Some(tree))?;
        // The live tree's name: the file, and the tree if not the one the file runs.
        if tree == plan.main {
            seq.live.rename(file);
        } else {
            seq.live.rename(&format!("{file} ({tree})"));
        }
        seq.keep = Some(Keeping {
            store,
            state: PlanState::new(file, tree, plan.fingerprint, ""),
            spare: Some(Node::build(plan, tree)?),
            fresh,
            opened: None,
            warned: false,
        });
        Ok(seq)
    }

    /// The plan's live tree: its shape and each node's status.
    pub fn live(&self) -> &LiveTree {
        &self.live
    }

    /// How this runner started (after [`Sequencer::open`]; `None` for a plan not kept).
    pub fn opening(&self) -> Option<&Opening> {
        self.keep.as_ref().and_then(|k| k.opened.as_ref())
    }

    /// Takes over what the plan's last runner kept, once, before the first tick: the same
    /// plan resumes (its monitors taken over — those that fired while no runner ran count as
    /// fired, those gone are installed again — parameters set by `WithParam`s that are no
    /// longer running restored); anything else is undone first (parameters restored,
    /// monitors removed). `me` is this runner's client id. A plan not kept starts fresh.
    pub fn open(&mut self, fabric: &mut dyn Fabric, me: &str) -> Result<Opening, SeqError> {
        let Some(k) = self.keep.as_mut() else {
            return Ok(Opening::Fresh);
        };
        if let Some(o) = &k.opened {
            return Ok(o.clone());
        }
        k.state.runners = vec![me.to_string()];
        let old = match k.store.load() {
            Kept::Nothing => None,
            Kept::Unreadable(why) => {
                let why = format!(
                    "the kept plan state is unreadable ({why}); what it set cannot be restored"
                );
                return self.opened(Opening::StartedOver { why });
            }
            Kept::State(s) => Some(*s),
        };
        let Some(old) = old else {
            return self.opened(Opening::Fresh);
        };
        let (file, tree) = (&k.state.file, &k.state.tree);
        let mut why = if k.fresh {
            Some("--fresh".to_string())
        } else if old.file != *file || old.tree != *tree {
            Some(format!(
                "another plan was running ({}, tree {})",
                old.file, old.tree
            ))
        } else if old.fingerprint != k.state.fingerprint {
            Some(format!("{file} changed since its last runner"))
        } else {
            None
        };
        if why.is_none()
            && let Some(mut spare) = k.spare.take()
        {
            let mut saved = old.nodes.iter();
            let fits = spare
                .load(&mut saved, &old.overrides)
                .and_then(|()| match saved.next() {
                    Some(_) => Err("it has more nodes than the tree".to_string()),
                    None => Ok(()),
                });
            match fits {
                Ok(()) => {
                    self.root = spare;
                    return self.resume(fabric, old, me);
                }
                Err(e) => why = Some(format!("its kept state does not fit the plan: {e}")),
            }
        }
        let why = why.unwrap_or_default();
        self.undo(fabric, &old, &why)?;
        self.opened(Opening::StartedOver { why })
    }

    /// Undoes what the runners of `old` left set (their overrides, latest first) and
    /// installed (their monitors).
    fn undo(
        &mut self,
        fabric: &mut dyn Fabric,
        old: &PlanState,
        why: &str,
    ) -> Result<(), SeqError> {
        self.steps.push(format!(
            "the plan {} (tree {}) of runner(s) {} is not resumed ({why}): undoing what it set",
            old.file,
            old.tree,
            old.runners.join(", ")
        ));
        self.restore_all(fabric, &old.overrides)?;
        let mut theirs: HashSet<u64> = old
            .nodes
            .iter()
            .filter_map(|n| match n {
                Saved::WaitFor(m) => *m,
                _ => None,
            })
            .collect();
        if let Ok(all) = fabric.monitors() {
            theirs.extend(
                all.iter()
                    .filter(|(_, c)| old.runners.contains(c))
                    .map(|(id, _)| *id),
            );
        }
        for id in theirs {
            fabric.remove_monitor(id);
        }
        Ok(())
    }

    /// Restores `overrides`, latest first, each step said (a refusal too); stops at a
    /// fabric that cannot be asked.
    fn restore_all(
        &mut self,
        fabric: &mut dyn Fabric,
        overrides: &[Override],
    ) -> Result<(), SeqError> {
        for o in overrides.iter().rev() {
            let what = format!("{}.{} restored to {}", o.skill, o.param, o.before);
            match fabric.set_param_value(&o.skill, &o.param, o.before) {
                Ok(()) => self.steps.push(what),
                Err(FabricError::Refused(r)) => self.steps.push(format!("{what}: refused: {r}")),
                Err(cause) => return Err(SeqError::Fabric { what, cause }),
            }
        }
        Ok(())
    }

    /// Goes on with the plan `old` kept (loaded into the tree already).
    fn resume(
        &mut self,
        fabric: &mut dyn Fabric,
        old: PlanState,
        me: &str,
    ) -> Result<Opening, SeqError> {
        self.overrides = old.overrides.clone();
        self.fired = old.fired.iter().copied().collect();
        // Parameters set by a `WithParam` that had ended when its runner died, before it
        // could say so: restored now.
        let mut setting = Vec::new();
        self.root.setting(&mut setting);
        let stale: Vec<Override> = self
            .overrides
            .iter()
            .filter(|o| !setting.contains(&o.node))
            .cloned()
            .collect();
        self.restore_all(fabric, &stale)?;
        self.overrides
            .retain(|x| !stale.iter().any(|o| o.node == x.node));
        // The running `WaitFor`s' monitors: taken over, counted as fired, or installed again.
        let mut ids = Vec::new();
        self.root.monitors(&mut ids);
        let fates = if ids.is_empty() {
            Vec::new()
        } else {
            fabric
                .adopt_monitors(&ids)
                .map_err(|cause| SeqError::Fabric {
                    what: "taking over the plan's monitors".into(),
                    cause,
                })?
        };
        let (mut live, mut fired, mut gone) = (0, 0, HashSet::new());
        for (id, fate) in ids.iter().zip(fates) {
            match fate {
                MonitorFate::Live => live += 1,
                MonitorFate::Fired(_) => {
                    fired += 1;
                    self.fired.insert(*id);
                }
                MonitorFate::Gone => {
                    gone.insert(*id);
                }
            }
        }
        // Where it is, said before the monitors that are gone are forgotten (a `WaitFor`
        // whose monitor is installed again is still where the plan is).
        let mut at = Vec::new();
        self.root.running(&mut at);
        self.root.forget_monitors(&gone);
        // Monitors a runner installed in a tick it did not live to keep: nobody waits on them.
        if let Ok(all) = fabric.monitors() {
            for (id, client) in all {
                if old.runners.contains(&client) && !ids.contains(&id) {
                    fabric.remove_monitor(id);
                }
            }
        }
        let Some(k) = self.keep.as_mut() else {
            return Ok(Opening::Fresh);
        };
        k.state.runners = old.runners;
        k.state.runners.push(me.to_string());
        k.state.started = old.started;
        let since = SystemTime::now()
            .duration_since(old.started)
            .unwrap_or_default();
        self.origin = Instant::now().checked_sub(since).unwrap_or(self.origin);
        k.state.ticked = old.ticked;
        self.steps.push(format!(
            "resuming {} (runner {} of it) at: {}; monitors: {live} taken over, {fired} fired meanwhile, {} installed again",
            k.state.file,
            k.state.runners.len(),
            if at.is_empty() { "its start".to_string() } else { at.join("; ") },
            gone.len()
        ));
        self.opened(Opening::Resumed { at })
    }

    fn opened(&mut self, o: Opening) -> Result<Opening, SeqError> {
        if let Some(k) = self.keep.as_mut() {
            k.opened = Some(o.clone());
        }
        self.commit();
        Ok(o)
    }

    /// Keeps the plan's state as it is now, the time of its last tick as `ticked` says (a
    /// time: ticked then; `None`: halted, not ticked since).
    fn commit_ticked(&mut self, ticked: Option<Duration>) {
        if let Some(k) = self.keep.as_mut() {
            k.state.ticked = ticked;
        }
        self.commit();
    }

    /// Keeps the plan's state as it is now (its last tick's time as it was: a runner's
    /// opening is not a tick).
    fn commit(&mut self) {
        let Some(k) = self.keep.as_mut() else {
            return;
        };
        k.state.nodes.clear();
        self.root.save(&mut k.state.nodes);
        k.state.fired = self.fired.iter().copied().collect();
        k.state.fired.sort_unstable();
        k.state.overrides.clone_from(&self.overrides);
        save(k);
    }

    /// Forgets the kept state: the plan ended (succeeded, failed or was halted).
    fn ended(&mut self) {
        if let Some(k) = &self.keep {
            k.store.remove();
        }
    }

    /// Whether a runner took the plan over from another (the fabric may be running: in
    /// lock-step the plan waits for it to pause).
    fn resumed(&self) -> bool {
        matches!(self.opening(), Some(Opening::Resumed { .. }))
    }

    /// Whether the plan's last tick was at fabric time `now`: taken over in the cycle the
    /// paused manager is in, its last runner ticked it there and died before resuming the
    /// manager.
    fn ticked_at(&self, now: Duration) -> bool {
        self.keep
            .as_ref()
            .is_some_and(|k| k.state.ticked == Some(now))
    }

    /// When the plan started: the origin of its wall-clock time over a bridge.
    pub fn origin(&self) -> Instant {
        self.origin
    }

    /// Takes in an event of `client`'s stream; whether the plan has something to react to
    /// (one of this client's monitors fired, or `up` gave up on a process).
    pub fn on_event(&mut self, client: &str, event: &EventKind) -> bool {
        match event {
            EventKind::ProcessGaveUp { process, .. } => self.gave_up.insert(process.clone()),
            EventKind::MonitorFired {
                id, client: owner, ..
            } if owner == client => {
                self.fired.insert(*id);
                true
            }
            _ => false,
        }
    }

    /// Ticks the tree once (a kept plan's state is kept after it, and forgotten when the
    /// tree ends).
    pub fn tick(&mut self, fabric: &mut dyn Fabric) -> Result<Status, SeqError> {
        if !self.asked_gave_up {
            let listed = fabric.gave_up().map_err(|cause| SeqError::Fabric {
                what: "asking which processes `up` gave up on".into(),
                cause,
            })?;
            self.gave_up.extend(listed);
            self.asked_gave_up = true;
        }
        let resumed = self.resumed();
        self.live.announce(fabric, resumed);
        let keep = &mut self.keep;
        let mut keep = |o: &[Override]| {
            if let Some(k) = keep.as_mut() {
                k.state.overrides = o.to_vec();
                save(k);
            }
        };
        let mut cx = Cx {
            fabric,
            fired: &mut self.fired,
            steps: &mut self.steps,
            overrides: &mut self.overrides,
            gave_up: &self.gave_up,
            keep: &mut keep,
            status: &mut self.live.status,
        };
        // A tick cut short by the fabric is not kept (as if its runner died in it): the
        // runner halts the tree, and the halted state is kept.
        let status = self.root.tick(&mut cx)?;
        let now = fabric.now();
        match status {
            Status::Running => self.commit_ticked(Some(now)),
            // The plan ended: nothing to take over.
            Status::Success | Status::Failure => self.ended(),
        }
        self.live.report(fabric, status != Status::Running);
        Ok(status)
    }

    /// Halts the tree: monitors removed, parameters restored; its state is kept (a runner
    /// started again takes it over).
    pub fn halt(&mut self, fabric: &mut dyn Fabric) {
        self.halt_tree(fabric);
        self.live.report(fabric, false);
    }

    /// Halts the tree and ends the plan (Ctrl-C): nothing is kept for another runner, and
    /// the manager is told the plan ended.
    pub fn halt_and_end(&mut self, fabric: &mut dyn Fabric) {
        self.halt_tree(fabric);
        self.ended();
        self.live.report(fabric, true);
    }

    fn halt_tree(&mut self, fabric: &mut dyn Fabric) {
        let mut keep = |_: &[Override]| {};
        let mut cx = Cx {
            fabric,
            fired: &mut self.fired,
            steps: &mut self.steps,
            overrides: &mut self.overrides,
            gave_up: &self.gave_up,
            keep: &mut keep,
            status: &mut self.live.status,
        };
        self.root.halt(&mut cx);
        // A halted tree was not ticked: its next runner ticks it at once.
        self.commit_ticked(None);
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

/// Writes `k`'s state (a failure is said once: the plan goes on, but a runner that takes
/// over would not find where it was).
fn save(k: &mut Keeping) {
    match k.store.save(&k.state) {
        Ok(()) => k.warned = false,
        Err(e) if !k.warned => {
            k.warned = true;
            tracing::warn!(file = %k.store.path().display(), error = %e, "the plan's state cannot be kept");
        }
        Err(_) => {}
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
    /// A runner that took over while the manager ran waits for it to pause (at a monitor's
    /// firing or the end of its predecessor's `step`) before it ticks.
    until_paused: bool,
}

impl LockStep {
    /// Pacing for `client`'s manager if it runs in lock-step on this host (it is taken as
    /// paused: a manager started `--paused` waits for the plan's first tick). Over a bridge
    /// the board cannot be read: a plan does not pace a remote lock-step manager.
    pub fn of(client: &Client) -> Option<LockStep> {
        client.clock().filter(|c| c.lockstep).map(|_| LockStep {
            paused: true,
            until_paused: false,
        })
    }

    /// Whether the manager waits for the plan (it is ticked, then resumed).
    pub fn paused(&self) -> bool {
        self.paused
    }

    /// Takes in an event: a monitor that fired paused the manager.
    pub fn on_event(&mut self, event: &EventKind) {
        let paused = match event {
            EventKind::MonitorFired { .. } => true,
            EventKind::Cycling { running: false } => self.until_paused,
            _ => false,
        };
        if paused {
            (self.paused, self.until_paused) = (true, false);
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
            cause: FabricError::Failed(std::sync::Arc::new(e)),
        }
    };
    client
        .subscribe()
        .map_err(failed("subscribing to events"))?;
    let id = client.id().to_string();
    seq.open(&mut ClientFabric::new(client, seq.origin()), &id)?;
    for s in seq.take_steps() {
        on_step(client, &s);
    }
    let mut lockstep = LockStep::of(client);
    if seq.resumed()
        && let Some(l) = lockstep.as_mut()
    {
        if client
            .stats()
            .map_err(failed("reading the manager's state"))?
            .running
        {
            // Taken over while the manager runs (its last runner died after `run` or inside a
            // `step`): the manager pauses at the next firing or the step's end.
            (l.paused, l.until_paused) = (false, true);
        } else if client.clock().is_some_and(|c| seq.ticked_at(c.time)) {
            // Its last runner ticked the plan in this cycle and died before resuming the
            // manager: resumed as that runner would have. Ticked again in the same cycle, a
            // retry's next attempt (due at the next tick) would start a cycle early.
            l.resume(client, seq)
                .map_err(failed("resuming the lock-step manager"))?;
        }
    }
    loop {
        if stop() {
            seq.halt_and_end(&mut ClientFabric::new(client, seq.origin()));
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
