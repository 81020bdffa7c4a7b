//! Running a plan: a behaviour tree ticked by the sequencer's loop. Nodes keep their own
//! state between ticks; a node that is halted (its parent no longer needs it) undoes what it
//! holds — a `WaitFor` removes its monitor, a `WithParam` restores its parameter.

use crate::plan::{Kind, Plan, PlanError, Spec};
use serde::{Deserialize, Serialize};
use skillfab_proto::control::{
    ControlError, MonitorFate, NodeStatus, PlanNode, PlanReport, PlanTree,
};
use skillfab_proto::param::ParamValue;
use std::collections::HashSet;
use std::time::Duration;

/// What a node returns when ticked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Status {
    /// Not done yet: tick it again.
    Running,
    /// Done, and it worked.
    Success,
    /// Done, and it did not.
    Failure,
}

impl From<Status> for NodeStatus {
    fn from(s: Status) -> NodeStatus {
        match s {
            Status::Running => NodeStatus::Running,
            Status::Success => NodeStatus::Success,
            Status::Failure => NodeStatus::Failure,
        }
    }
}

/// Why a fabric request did not do what was asked.
#[derive(Debug, Clone, thiserror::Error)]
pub enum FabricError {
    /// The manager refused it (an unknown skill, a value out of range, …): the action fails,
    /// and the plan can fall back.
    #[error(transparent)]
    Refused(Box<ControlError>),
    /// The fabric could not be asked (no manager, a broken link): the plan stops.
    #[error(transparent)]
    Failed(std::sync::Arc<dyn std::error::Error + Send + Sync>),
}

impl From<ControlError> for FabricError {
    fn from(e: ControlError) -> FabricError {
        FabricError::Refused(Box::new(e))
    }
}

/// What a plan needs of the fabric: the client library's requests, and the fabric's time.
pub trait Fabric {
    /// Activates skills (all or none).
    fn activate(&mut self, skills: &[String]) -> Result<(), FabricError>;
    /// Deactivates skills (all or none).
    fn deactivate(&mut self, skills: &[String]) -> Result<(), FabricError>;
    /// Wants skills (all or none): each is activated with the skills it reads from.
    fn want(&mut self, skills: &[String]) -> Result<(), FabricError>;
    /// Releases wanted skills (all or none), and what was activated only for them.
    fn release(&mut self, skills: &[String]) -> Result<(), FabricError>;
    /// A parameter's value.
    fn get_param(&mut self, skill: &str, param: &str) -> Result<ParamValue, FabricError>;
    /// Sets a parameter from text (as `ctl set` takes it).
    fn set_param(&mut self, skill: &str, param: &str, value: &str) -> Result<(), FabricError>;
    /// Sets a parameter to a value read before.
    fn set_param_value(
        &mut self,
        skill: &str,
        param: &str,
        value: ParamValue,
    ) -> Result<(), FabricError>;
    /// Installs a monitor that fires once, after the condition held `hold` cycles; its id.
    fn add_monitor(&mut self, condition: &str, hold: u32) -> Result<u64, FabricError>;
    /// Removes a monitor (one that fired already is gone: not an error).
    fn remove_monitor(&mut self, id: u64);
    /// Takes over monitors another client installed (a runner that died before this one):
    /// what became of each, in order.
    fn adopt_monitors(&mut self, ids: &[u64]) -> Result<Vec<MonitorFate>, FabricError>;
    /// Every installed monitor: (id, the client it belongs to).
    fn monitors(&mut self) -> Result<Vec<(u64, String)>, FabricError>;
    /// The processes `skillfab up` gave up restarting and that have not come back since.
    fn gave_up(&mut self) -> Result<Vec<String>, FabricError>;
    /// The fabric's time (cycle × period with a period; lock-step included).
    fn now(&mut self) -> Duration;
    /// Tells the manager how the plan stands: its tree, or the status changes of a tick
    /// (the live tree; docs/sequence.md).
    fn report_plan(&mut self, report: PlanReport) -> Result<(), FabricError>;
    /// The plan the manager has running, with its statuses (a runner that takes a plan over
    /// goes on from them).
    fn current_plan(&mut self) -> Result<Option<PlanTree>, FabricError>;
}

/// Why a plan stopped without an outcome.
#[derive(Debug, thiserror::Error)]
pub enum SeqError {
    /// The plan is not sound.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// The fabric could not be asked.
    #[error("{what}: {cause}")]
    Fabric {
        /// The node's step.
        what: String,
        /// Why (in the message).
        cause: FabricError,
    },
}

/// A parameter a `WithParam` set and must restore, with the value it had before. It is put
/// in the plan's kept state *before* the parameter is set, so that a runner that dies at any
/// instant leaves behind what to restore (a restarted runner, or one that starts another
/// plan, restores it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Override {
    /// The `WithParam` node's number (preorder, sub-trees inlined).
    pub node: usize,
    /// Skill instance.
    pub skill: String,
    /// Parameter.
    pub param: String,
    /// Its value before the plan set it.
    pub before: ParamValue,
}

/// A node's state between ticks, as kept for a runner that resumes the plan (one per node,
/// in preorder; the plan's fingerprint guarantees the same tree).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Saved {
    /// `Sequence`, `Fallback`: the child it is at.
    Chain(usize),
    /// `Parallel`: the children decided.
    Parallel(Vec<Option<Status>>),
    /// `RetryUntilSuccessful`: attempts failed, and whether the next is due now.
    Retry(u32, bool),
    /// `Timeout`, `Sleep`: since when (fabric time), if running.
    Timer(Option<Duration>),
    /// `WithParam`: whether its parameter is set (the value to restore is an [`Override`]).
    WithParam(bool),
    /// `WaitFor`: its monitor, if running.
    WaitFor(Option<u64>),
    /// Anything that keeps nothing.
    Nothing,
}

/// What a tick can see and do: the fabric, the monitors that fired since the last tick, and
/// the step log.
pub struct Cx<'a> {
    /// The fabric.
    pub fabric: &'a mut dyn Fabric,
    /// Monitors that fired and have not been taken by their node yet.
    pub fired: &'a mut HashSet<u64>,
    /// What was done, in order (the runner prints and drains it).
    pub steps: &'a mut Vec<String>,
    /// The parameters set by `WithParam`s that are running, to restore.
    pub overrides: &'a mut Vec<Override>,
    /// The processes `skillfab up` gave up restarting (events seen by this runner).
    pub gave_up: &'a HashSet<String>,
    /// Keeps `overrides` where a restarted runner finds them (before a parameter is set).
    pub keep: &'a mut dyn FnMut(&[Override]),
    /// Each node's status, by node number: what its last tick returned, `Idle` if never
    /// ticked or halted since (the live tree's statuses; a number past its end is not kept).
    pub status: &'a mut [NodeStatus],
}

impl Cx<'_> {
    fn step(&mut self, what: String) {
        tracing::debug!("{what}");
        self.steps.push(what);
    }

    /// The outcome of a request: a refusal fails the node (said in the steps), anything
    /// else stops the plan.
    fn outcome<T>(&mut self, what: &str, r: Result<T, FabricError>) -> Result<Option<T>, SeqError> {
        match r {
            Ok(v) => Ok(Some(v)),
            Err(FabricError::Refused(why)) => {
                self.step(format!("{what}: refused: {why}"));
                Ok(None)
            }
            Err(cause) => Err(SeqError::Fabric {
                what: what.to_string(),
                cause,
            }),
        }
    }

    /// The status of an action whose request gave `r`: success (the step said), or failure
    /// when refused.
    fn done(&mut self, what: String, r: Result<(), FabricError>) -> Result<Status, SeqError> {
        Ok(match self.outcome(&what, r)? {
            Some(()) => {
                self.step(what);
                Status::Success
            }
            None => Status::Failure,
        })
    }
}

/// A node and its state between ticks.
pub struct Node {
    name: String,
    /// Its number in the tree (preorder, sub-trees inlined).
    id: usize,
    state: State,
}

enum State {
    /// A sequence (`go_on` success) or a fallback (`go_on` failure): children in order while
    /// each returns `go_on`.
    Chain {
        children: Vec<Node>,
        at: usize,
        go_on: Status,
    },
    Parallel {
        children: Vec<Node>,
        done: Vec<Option<Status>>,
        success: usize,
        failure: usize,
    },
    Retry {
        child: Box<Node>,
        attempts: Option<u32>,
        failed: u32,
        /// The child failed and is tried again at the next tick (due now).
        again: bool,
    },
    Timeout {
        child: Box<Node>,
        after: Duration,
        since: Option<Duration>,
    },
    Inverter(Box<Node>),
    KeepRunning(Box<Node>),
    Force(Box<Node>, Status),
    WithParam {
        skill: String,
        param: String,
        value: String,
        child: Box<Node>,
        old: Option<ParamValue>,
    },
    /// An action that keeps no state between ticks (`Activate`, `Deactivate`, `SetParam`,
    /// `Log`, `AlwaysSuccess`, `AlwaysFailure`), as written.
    Act(Kind),
    WaitFor {
        condition: String,
        hold: u32,
        monitor: Option<u64>,
    },
    Sleep {
        after: Duration,
        since: Option<Duration>,
    },
    WaitGaveUp(String),
}

impl Node {
    /// The runtime tree of `plan`'s tree `id` (sub-trees inlined).
    pub fn build(plan: &Plan, id: &str) -> Result<Node, PlanError> {
        Node::build_shaped(plan, id).map(|(node, _)| node)
    }

    /// The runtime tree of `plan`'s tree `id`, and its shape as the live tree shows it: one
    /// [`PlanNode`] per node, numbered as the nodes are (preorder, sub-trees inlined).
    pub fn build_shaped(plan: &Plan, id: &str) -> Result<(Node, Vec<PlanNode>), PlanError> {
        let spec = plan.trees.get(id).ok_or_else(|| PlanError {
            file: String::new(),
            line: 0,
            reason: format!(
                "no tree '{id}' (the plan has {})",
                plan.trees.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        })?;
        let mut shape = Vec::new();
        let node = Node::from_spec(plan, spec, &mut 0, None, &mut shape);
        Ok((node, shape))
    }

    fn from_spec(
        plan: &Plan,
        spec: &Spec,
        next: &mut usize,
        parent: Option<u32>,
        shape: &mut Vec<PlanNode>,
    ) -> Node {
        // A sub-tree is its tree's root, in its place (it takes no number of its own).
        if let Kind::SubTree(tree) = &spec.kind
            && let Some(t) = plan.trees.get(tree)
        {
            return Node::from_spec(plan, t, next, parent, shape);
        }
        let id = *next;
        *next += 1;
        shape.push(PlanNode {
            id: id as u32,
            parent,
            name: spec.name.clone(),
            kind: spec.kind.tag().to_string(),
            detail: spec.kind.detail(),
        });
        let me = Some(id as u32);
        let state = match &spec.kind {
            Kind::Sequence(c) => State::Chain {
                children: Node::many(plan, c, next, me, shape),
                at: 0,
                go_on: Status::Success,
            },
            Kind::Fallback(c) => State::Chain {
                children: Node::many(plan, c, next, me, shape),
                at: 0,
                go_on: Status::Failure,
            },
            Kind::Parallel {
                success,
                failure,
                children,
            } => State::Parallel {
                done: vec![None; children.len()],
                success: success.unwrap_or(children.len()),
                failure: *failure,
                children: Node::many(plan, children, next, me, shape),
            },
            Kind::Retry { attempts, child } => State::Retry {
                child: Box::new(Node::from_spec(plan, child, next, me, shape)),
                attempts: *attempts,
                failed: 0,
                again: false,
            },
            Kind::Timeout { after, child } => State::Timeout {
                child: Box::new(Node::from_spec(plan, child, next, me, shape)),
                after: *after,
                since: None,
            },
            Kind::Inverter(c) => {
                State::Inverter(Box::new(Node::from_spec(plan, c, next, me, shape)))
            }
            Kind::KeepRunningUntilFailure(c) => {
                State::KeepRunning(Box::new(Node::from_spec(plan, c, next, me, shape)))
            }
            Kind::ForceSuccess(c) => State::Force(
                Box::new(Node::from_spec(plan, c, next, me, shape)),
                Status::Success,
            ),
            Kind::ForceFailure(c) => State::Force(
                Box::new(Node::from_spec(plan, c, next, me, shape)),
                Status::Failure,
            ),
            Kind::WithParam {
                skill,
                param,
                value,
                child,
            } => State::WithParam {
                skill: skill.clone(),
                param: param.clone(),
                value: value.clone(),
                child: Box::new(Node::from_spec(plan, child, next, me, shape)),
                old: None,
            },
            Kind::Activate(_)
            | Kind::Deactivate(_)
            | Kind::Want(_)
            | Kind::Release(_)
            | Kind::SetParam { .. }
            | Kind::Log(_)
            | Kind::AlwaysSuccess
            | Kind::AlwaysFailure => State::Act(spec.kind.clone()),
            Kind::WaitFor { condition, hold } => State::WaitFor {
                condition: condition.clone(),
                hold: *hold,
                monitor: None,
            },
            Kind::Sleep(d) => State::Sleep {
                after: *d,
                since: None,
            },
            Kind::WaitGaveUp(p) => State::WaitGaveUp(p.clone()),
            // Checked when the plan was read: the tree exists (handled above) and does not
            // contain itself.
            Kind::SubTree(_) => State::Act(Kind::AlwaysFailure),
        };
        Node {
            name: spec.name.clone(),
            id,
            state,
        }
    }

    fn many(
        plan: &Plan,
        specs: &[Spec],
        next: &mut usize,
        parent: Option<u32>,
        shape: &mut Vec<PlanNode>,
    ) -> Vec<Node> {
        specs
            .iter()
            .map(|s| Node::from_spec(plan, s, next, parent, shape))
            .collect()
    }

    /// Ticks the node once; its status in the live tree is what it returns.
    pub fn tick(&mut self, cx: &mut Cx<'_>) -> Result<Status, SeqError> {
        let status = self.tick_own(cx)?;
        if let Some(s) = cx.status.get_mut(self.id) {
            *s = status.into();
        }
        Ok(status)
    }

    fn tick_own(&mut self, cx: &mut Cx<'_>) -> Result<Status, SeqError> {
        let (name, id) = (&self.name, self.id);
        match &mut self.state {
            State::Chain {
                children,
                at,
                go_on,
            } => {
                let go_on = *go_on;
                while *at < children.len() {
                    match children[*at].tick(cx)? {
                        Status::Running => return Ok(Status::Running),
                        s if s == go_on => *at += 1,
                        s => {
                            *at = 0;
                            return Ok(s);
                        }
                    }
                }
                *at = 0;
                Ok(go_on)
            }
            State::Parallel {
                children,
                done,
                success,
                failure,
            } => {
                // As BehaviorTree.CPP: decided as soon as enough children succeeded, or
                // too many failed for the successes still needed; the others are halted
                // before they are ticked again.
                let n = children.len();
                let mut outcome = None;
                for i in 0..n {
                    if done[i].is_none() {
                        match children[i].tick(cx)? {
                            Status::Running => {}
                            s => done[i] = Some(s),
                        }
                    }
                    let count = |s: Status| done.iter().filter(|d| **d == Some(s)).count();
                    let (won, lost) = (count(Status::Success), count(Status::Failure));
                    if won >= *success {
                        outcome = Some(Status::Success);
                    } else if lost >= *failure || n - lost < *success {
                        outcome = Some(Status::Failure);
                    }
                    if outcome.is_some() {
                        break;
                    }
                }
                let Some(outcome) = outcome else {
                    return Ok(Status::Running);
                };
                for (c, d) in children.iter_mut().zip(done.iter_mut()) {
                    if d.is_none() {
                        c.halt(cx);
                    }
                    *d = None;
                }
                Ok(outcome)
            }
            State::Retry {
                child,
                attempts,
                failed,
                again,
            } => match child.tick(cx)? {
                Status::Failure => {
                    *failed += 1;
                    if attempts.is_some_and(|n| *failed >= n) {
                        (*failed, *again) = (0, false);
                        return Ok(Status::Failure);
                    }
                    cx.step(format!("{name}: attempt {} failed; again", *failed));
                    // Tried again at the next tick, which is due at once (a child that fails
                    // at once does not spin within one tick).
                    *again = true;
                    Ok(Status::Running)
                }
                Status::Success => {
                    (*failed, *again) = (0, false);
                    Ok(Status::Success)
                }
                Status::Running => {
                    *again = false;
                    Ok(Status::Running)
                }
            },
            State::Timeout {
                child,
                after,
                since,
            } => {
                let now = cx.fabric.now();
                let started = *since.get_or_insert(now);
                // Past its time the child is not ticked again (it would start more).
                if now.saturating_sub(started) >= *after {
                    child.halt(cx);
                    *since = None;
                    cx.step(format!("{name}: timed out after {} ms", after.as_millis()));
                    return Ok(Status::Failure);
                }
                match child.tick(cx)? {
                    Status::Running => Ok(Status::Running),
                    s => {
                        *since = None;
                        Ok(s)
                    }
                }
            }
            State::Inverter(child) => Ok(match child.tick(cx)? {
                Status::Success => Status::Failure,
                Status::Failure => Status::Success,
                Status::Running => Status::Running,
            }),
            State::KeepRunning(child) => Ok(match child.tick(cx)? {
                Status::Failure => Status::Failure,
                _ => Status::Running,
            }),
            State::Force(child, to) => Ok(match child.tick(cx)? {
                Status::Running => Status::Running,
                _ => *to,
            }),
            State::WithParam {
                skill,
                param,
                value,
                child,
                old,
            } => {
                if old.is_none() {
                    let what = format!("{skill}.{param} = {value} while {}", child.name);
                    let kept = cx.overrides.iter().find(|o| o.node == id);
                    let before = match kept {
                        // A runner that died had read it (and maybe set it): that value is
                        // the one to restore, not what the parameter holds now.
                        Some(o) => o.before,
                        None => {
                            let r = cx.fabric.get_param(skill, param);
                            let Some(before) = cx.outcome(&what, r)? else {
                                return Ok(Status::Failure);
                            };
                            cx.overrides.push(Override {
                                node: id,
                                skill: skill.clone(),
                                param: param.clone(),
                                before,
                            });
                            (cx.keep)(cx.overrides);
                            before
                        }
                    };
                    let r = cx.fabric.set_param(skill, param, value);
                    if cx.outcome(&what, r)?.is_none() {
                        cx.overrides.retain(|o| o.node != id);
                        return Ok(Status::Failure);
                    }
                    cx.step(format!("{what} (was {before})"));
                    *old = Some(before);
                }
                let status = child.tick(cx)?;
                if status != Status::Running
                    && let Some(before) = old.take()
                {
                    restore(cx, id, skill, param, before)?;
                }
                Ok(status)
            }
            State::Act(kind) => act(kind, cx),
            State::WaitGaveUp(process) => Ok(if cx.gave_up.contains(process) {
                cx.step(format!("{name}: skillfab up gave up restarting {process}"));
                Status::Success
            } else {
                Status::Running
            }),
            State::WaitFor {
                condition,
                hold,
                monitor,
            } => {
                let Some(id) = *monitor else {
                    let what = format!("{name}: wait for {condition}");
                    let r = cx.fabric.add_monitor(condition, *hold);
                    return Ok(match cx.outcome(&what, r)? {
                        Some(id) => {
                            *monitor = Some(id);
                            Status::Running
                        }
                        None => Status::Failure,
                    });
                };
                if cx.fired.remove(&id) {
                    *monitor = None;
                    cx.step(format!("{name}: {condition}"));
                    return Ok(Status::Success);
                }
                Ok(Status::Running)
            }
            State::Sleep { after, since } => {
                let now = cx.fabric.now();
                let started = *since.get_or_insert(now);
                if now.saturating_sub(started) >= *after {
                    *since = None;
                    return Ok(Status::Success);
                }
                Ok(Status::Running)
            }
        }
    }

    /// The earliest fabric time at which a running `Sleep` or `Timeout` below this node is
    /// due (lock-step: the manager is stepped exactly that far, so a timer ends in the same
    /// cycle every run).
    pub fn deadline(&self) -> Option<Duration> {
        let own = match &self.state {
            State::Sleep {
                after,
                since: Some(s),
            }
            | State::Timeout {
                after,
                since: Some(s),
                ..
            } => Some(*s + *after),
            // A retry waits for nothing: due now.
            State::Retry { again: true, .. } => Some(Duration::ZERO),
            _ => None,
        };
        self.children()
            .into_iter()
            .filter_map(Node::deadline)
            .chain(own)
            .min()
    }

    /// Stops a running node: what it holds is undone, its state is as if never ticked — and
    /// so is its status and every status below it (`Idle`, as BehaviorTree.CPP resets them).
    pub fn halt(&mut self, cx: &mut Cx<'_>) {
        self.halt_own(cx);
        self.idle(cx.status);
    }

    /// Its status and every one below it `Idle`.
    fn idle(&self, status: &mut [NodeStatus]) {
        if let Some(s) = status.get_mut(self.id) {
            *s = NodeStatus::Idle;
        }
        for c in self.children() {
            c.idle(status);
        }
    }

    fn halt_own(&mut self, cx: &mut Cx<'_>) {
        let id = self.id;
        match &mut self.state {
            State::Chain { children, at, .. } => {
                if let Some(c) = children.get_mut(*at) {
                    c.halt(cx);
                }
                *at = 0;
            }
            State::Parallel { children, done, .. } => {
                for (c, d) in children.iter_mut().zip(done.iter_mut()) {
                    if d.is_none() {
                        c.halt(cx);
                    }
                    *d = None;
                }
            }
            State::Retry {
                child,
                failed,
                again,
                ..
            } => {
                child.halt(cx);
                (*failed, *again) = (0, false);
            }
            State::Timeout { child, since, .. } => {
                child.halt(cx);
                *since = None;
            }
            State::Inverter(child) | State::KeepRunning(child) | State::Force(child, _) => {
                child.halt(cx)
            }
            State::WithParam {
                skill,
                param,
                child,
                old,
                ..
            } => {
                child.halt(cx);
                if let Some(before) = old.take()
                    && let Err(e) = restore(cx, id, skill, param, before)
                {
                    tracing::warn!(error = %e, "parameter not restored");
                }
            }
            State::WaitFor { monitor, .. } => {
                if let Some(id) = monitor.take() {
                    cx.fabric.remove_monitor(id);
                    cx.fired.remove(&id);
                }
            }
            State::Sleep { since, .. } => *since = None,
            State::Act(_) | State::WaitGaveUp(_) => {}
        }
    }
}

/// Carries out an action that keeps no state.
fn act(kind: &Kind, cx: &mut Cx<'_>) -> Result<Status, SeqError> {
    match kind {
        Kind::Activate(skills) => {
            let r = cx.fabric.activate(skills);
            cx.done(format!("activate {}", skills.join(", ")), r)
        }
        Kind::Deactivate(skills) => {
            let r = cx.fabric.deactivate(skills);
            cx.done(format!("deactivate {}", skills.join(", ")), r)
        }
        Kind::Want(skills) => {
            let r = cx.fabric.want(skills);
            cx.done(format!("want {}", skills.join(", ")), r)
        }
        Kind::Release(skills) => {
            let r = cx.fabric.release(skills);
            cx.done(format!("release {}", skills.join(", ")), r)
        }
        Kind::SetParam {
            skill,
            param,
            value,
        } => {
            let r = cx.fabric.set_param(skill, param, value);
            cx.done(format!("{skill}.{param} = {value}"), r)
        }
        Kind::Log(message) => {
            cx.step(message.clone());
            Ok(Status::Success)
        }
        Kind::AlwaysSuccess => Ok(Status::Success),
        // AlwaysFailure; nothing else is built as an `Act`.
        _ => Ok(Status::Failure),
    }
}

/// Restores what `WithParam` node `node` set; its override is forgotten once the manager
/// has answered (restored, or refused: a skill that is gone has nothing to restore).
fn restore(
    cx: &mut Cx<'_>,
    node: usize,
    skill: &str,
    param: &str,
    before: ParamValue,
) -> Result<(), SeqError> {
    let what = format!("{skill}.{param} restored to {before}");
    let r = cx.fabric.set_param_value(skill, param, before);
    let answered = cx.outcome(&what, r)?;
    cx.overrides.retain(|o| o.node != node);
    if answered.is_some() {
        cx.step(what);
    }
    Ok(())
}

impl Node {
    fn children(&self) -> Vec<&Node> {
        match &self.state {
            State::Chain { children, .. } | State::Parallel { children, .. } => {
                children.iter().collect()
            }
            State::Retry { child, .. }
            | State::Timeout { child, .. }
            | State::Inverter(child)
            | State::KeepRunning(child)
            | State::Force(child, _)
            | State::WithParam { child, .. } => vec![child],
            State::Act(_) | State::WaitFor { .. } | State::Sleep { .. } | State::WaitGaveUp(_) => {
                Vec::new()
            }
        }
    }

    fn children_mut(&mut self) -> Vec<&mut Node> {
        match &mut self.state {
            State::Chain { children, .. } | State::Parallel { children, .. } => {
                children.iter_mut().collect()
            }
            State::Retry { child, .. }
            | State::Timeout { child, .. }
            | State::Inverter(child)
            | State::KeepRunning(child)
            | State::Force(child, _)
            | State::WithParam { child, .. } => vec![child],
            State::Act(_) | State::WaitFor { .. } | State::Sleep { .. } | State::WaitGaveUp(_) => {
                Vec::new()
            }
        }
    }

    /// The state of this node and those below it, in preorder.
    pub fn save(&self, out: &mut Vec<Saved>) {
        out.push(match &self.state {
            State::Chain { at, .. } => Saved::Chain(*at),
            State::Parallel { done, .. } => Saved::Parallel(done.clone()),
            State::Retry { failed, again, .. } => Saved::Retry(*failed, *again),
            State::Timeout { since, .. } | State::Sleep { since, .. } => Saved::Timer(*since),
            State::WithParam { old, .. } => Saved::WithParam(old.is_some()),
            State::WaitFor { monitor, .. } => Saved::WaitFor(*monitor),
            State::Inverter(_)
            | State::KeepRunning(_)
            | State::Force(..)
            | State::Act(_)
            | State::WaitGaveUp(_) => Saved::Nothing,
        });
        for c in self.children() {
            c.save(out);
        }
    }

    /// Takes the state [`Node::save`] gave back (the values to restore from `overrides`).
    /// An error if it does not fit this tree: nothing is half-applied by the caller, which
    /// builds a new tree.
    pub fn load(
        &mut self,
        saved: &mut std::slice::Iter<'_, Saved>,
        overrides: &[Override],
    ) -> Result<(), String> {
        let id = self.id;
        let s = saved
            .next()
            .ok_or_else(|| format!("it ends before node {id} ({})", self.name))?;
        match (&mut self.state, s) {
            (State::Chain { at, children, .. }, Saved::Chain(a)) if *a < children.len() => *at = *a,
            (State::Parallel { done, .. }, Saved::Parallel(d)) if d.len() == done.len() => {
                done.clone_from(d)
            }
            (State::Retry { failed, again, .. }, Saved::Retry(f, a)) => {
                (*failed, *again) = (*f, *a)
            }
            (State::Timeout { since, .. } | State::Sleep { since, .. }, Saved::Timer(t)) => {
                *since = *t
            }
            (State::WithParam { old, .. }, Saved::WithParam(set)) => {
                *old = match (set, overrides.iter().find(|o| o.node == id)) {
                    (false, _) => None,
                    (true, Some(o)) => Some(o.before),
                    (true, None) => {
                        return Err(format!(
                            "node {id} ({}) set a parameter without keeping its value",
                            self.name
                        ));
                    }
                };
            }
            (State::WaitFor { monitor, .. }, Saved::WaitFor(m)) => *monitor = *m,
            (
                State::Inverter(_)
                | State::KeepRunning(_)
                | State::Force(..)
                | State::Act(_)
                | State::WaitGaveUp(_),
                Saved::Nothing,
            ) => {}
            (_, other) => {
                return Err(format!("node {id} ({}) does not keep {other:?}", self.name));
            }
        }
        for c in self.children_mut() {
            c.load(saved, overrides)?;
        }
        Ok(())
    }

    /// The running `WithParam` nodes (whose overrides are still needed).
    pub fn setting(&self, out: &mut Vec<usize>) {
        if let State::WithParam { old: Some(_), .. } = &self.state {
            out.push(self.id);
        }
        for c in self.children() {
            c.setting(out);
        }
    }

    /// The monitors of the running `WaitFor`s.
    pub fn monitors(&self, out: &mut Vec<u64>) {
        if let State::WaitFor {
            monitor: Some(m), ..
        } = &self.state
        {
            out.push(*m);
        }
        for c in self.children() {
            c.monitors(out);
        }
    }

    /// Forgets monitors that are gone (a resumed `WaitFor` installs its monitor again at its
    /// next tick: the condition is checked afresh).
    pub fn forget_monitors(&mut self, gone: &HashSet<u64>) {
        if let State::WaitFor { monitor, .. } = &mut self.state
            && monitor.is_some_and(|m| gone.contains(&m))
        {
            *monitor = None;
        }
        for c in self.children_mut() {
            c.forget_monitors(gone);
        }
    }

    /// The leaves and timers that are running, by name: where the plan is.
    pub fn running(&self, out: &mut Vec<String>) {
        let here = match &self.state {
            State::WaitFor {
                monitor: Some(_),
                condition,
                ..
            } => Some(format!("{} (waiting for {condition})", self.name)),
            State::Sleep { since: Some(_), .. } | State::Timeout { since: Some(_), .. } => {
                Some(self.name.clone())
            }
            State::WithParam {
                old: Some(_),
                skill,
                param,
                value,
                ..
            } => Some(format!("{skill}.{param} = {value}")),
            State::Retry { failed, .. } if *failed > 0 => {
                Some(format!("{} ({failed} attempt(s) failed)", self.name))
            }
            _ => None,
        };
        out.extend(here);
        for c in self.children() {
            c.running(out);
        }
    }
}
