//! Running a plan: a behaviour tree ticked by the sequencer's loop. Nodes keep their own
//! state between ticks; a node that is halted (its parent no longer needs it) undoes what it
//! holds — a `WaitFor` removes its monitor, a `WithParam` restores its parameter.

use crate::plan::{Kind, Plan, PlanError, Spec};
use skillfab_proto::param::ParamValue;
use std::collections::HashSet;
use std::time::Duration;

/// What a node returns when ticked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// Not done yet: tick it again.
    Running,
    /// Done, and it worked.
    Success,
    /// Done, and it did not.
    Failure,
}

/// Why a fabric request did not do what was asked.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FabricError {
    /// The manager refused it (an unknown skill, a value out of range, …): the action fails,
    /// and the plan can fall back.
    #[error("{0}")]
    Refused(String),
    /// The fabric could not be asked (no manager, a broken link): the plan stops.
    #[error("{0}")]
    Failed(String),
}

/// What a plan needs of the fabric: the client library's requests, and the fabric's time.
pub trait Fabric {
    /// Activates skills (all or none).
    fn activate(&mut self, skills: &[String]) -> Result<(), FabricError>;
    /// Deactivates skills (all or none).
    fn deactivate(&mut self, skills: &[String]) -> Result<(), FabricError>;
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
    /// The fabric's time (cycle × period with a period; lock-step included).
    fn now(&mut self) -> Duration;
}

/// Why a plan stopped without an outcome.
#[derive(Debug, thiserror::Error)]
pub enum SeqError {
    /// The plan is not sound.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// The fabric could not be asked.
    #[error("{what}: {source}")]
    Fabric {
        /// The node's step.
        what: String,
        /// Why.
        #[source]
        source: FabricError,
    },
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
            Err(source) => Err(SeqError::Fabric {
                what: what.to_string(),
                source,
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
}

impl Node {
    /// The runtime tree of `plan`'s tree `id` (sub-trees inlined).
    pub fn build(plan: &Plan, id: &str) -> Result<Node, PlanError> {
        let spec = plan.trees.get(id).ok_or_else(|| PlanError {
            file: String::new(),
            line: 0,
            reason: format!(
                "no tree '{id}' (the plan has {})",
                plan.trees.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        })?;
        Ok(Node::from_spec(plan, spec))
    }

    fn from_spec(plan: &Plan, spec: &Spec) -> Node {
        let many = |c: &[Spec]| {
            c.iter()
                .map(|s| Node::from_spec(plan, s))
                .collect::<Vec<_>>()
        };
        let one = |c: &Spec| Box::new(Node::from_spec(plan, c));
        let state = match &spec.kind {
            Kind::Sequence(c) => State::Chain {
                children: many(c),
                at: 0,
                go_on: Status::Success,
            },
            Kind::Fallback(c) => State::Chain {
                children: many(c),
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
                children: many(children),
            },
            Kind::Retry { attempts, child } => State::Retry {
                child: one(child),
                attempts: *attempts,
                failed: 0,
                again: false,
            },
            Kind::Timeout { after, child } => State::Timeout {
                child: one(child),
                after: *after,
                since: None,
            },
            Kind::Inverter(c) => State::Inverter(one(c)),
            Kind::KeepRunningUntilFailure(c) => State::KeepRunning(one(c)),
            Kind::ForceSuccess(c) => State::Force(one(c), Status::Success),
            Kind::ForceFailure(c) => State::Force(one(c), Status::Failure),
            Kind::WithParam {
                skill,
                param,
                value,
                child,
            } => State::WithParam {
                skill: skill.clone(),
                param: param.clone(),
                value: value.clone(),
                child: one(child),
                old: None,
            },
            Kind::Activate(_)
            | Kind::Deactivate(_)
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
            // Checked when the plan was read: the tree exists and does not contain itself.
            Kind::SubTree(id) => match plan.trees.get(id) {
                Some(t) => return Node::from_spec(plan, t),
                None => State::Act(Kind::AlwaysFailure),
            },
        };
        Node {
            name: spec.name.clone(),
            state,
        }
    }

    /// Ticks the node once.
    pub fn tick(&mut self, cx: &mut Cx<'_>) -> Result<Status, SeqError> {
        let name = &self.name;
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
                    let r = cx.fabric.get_param(skill, param);
                    let Some(before) = cx.outcome(&what, r)? else {
                        return Ok(Status::Failure);
                    };
                    let r = cx.fabric.set_param(skill, param, value);
                    if cx.outcome(&what, r)?.is_none() {
                        return Ok(Status::Failure);
                    }
                    cx.step(format!("{what} (was {before})"));
                    *old = Some(before);
                }
                let status = child.tick(cx)?;
                if status != Status::Running
                    && let Some(before) = old.take()
                {
                    restore(cx, skill, param, before)?;
                }
                Ok(status)
            }
            State::Act(kind) => act(kind, cx),
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
        let children: Vec<&Node> = match &self.state {
            State::Chain { children, .. } | State::Parallel { children, .. } => {
                children.iter().collect()
            }
            State::Retry { child, .. }
            | State::Timeout { child, .. }
            | State::Inverter(child)
            | State::KeepRunning(child)
            | State::Force(child, _)
            | State::WithParam { child, .. } => vec![child],
            _ => Vec::new(),
        };
        children
            .into_iter()
            .filter_map(Node::deadline)
            .chain(own)
            .min()
    }

    /// Stops a running node: what it holds is undone, its state is as if never ticked.
    pub fn halt(&mut self, cx: &mut Cx<'_>) {
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
                    && let Err(e) = restore(cx, skill, param, before)
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
            State::Act(_) => {}
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

fn restore(cx: &mut Cx<'_>, skill: &str, param: &str, before: ParamValue) -> Result<(), SeqError> {
    let what = format!("{skill}.{param} restored to {before}");
    let r = cx.fabric.set_param_value(skill, param, before);
    if cx.outcome(&what, r)?.is_some() {
        cx.step(what);
    }
    Ok(())
}
