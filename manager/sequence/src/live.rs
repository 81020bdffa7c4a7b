//! The plan as a live tree: each node's status as the ticks leave it, reported to the
//! manager — its shape once (again by a runner that takes the plan over), then after each tick
//! the nodes whose status changed, in one request, none when nothing changed. The manager
//! stamps them with their cycle, keeps the tree and publishes `PlanChanged` events
//! (docs/sequence.md).
//!
//! A report that fails does not fail the plan: the live tree is for people watching it. A
//! manager that has no such plan (it was restarted) is sent the shape again, with the
//! statuses as they are; a plan another runner replaced, or a tree the manager refuses, is no
//! longer reported (said in the log).

use crate::tree::{Fabric, FabricError};
use skillfab_proto::control::{
    ControlError, MAX_PLAN_NAME, MAX_REQUEST_BYTES, NodeStatus, PlanNode, PlanNodeChange,
    PlanReport,
};

/// Bytes of nodes one part of a shape carries at most, estimated: well under a request's
/// [`MAX_REQUEST_BYTES`] (the estimate counts a node's texts and 24 bytes for the rest).
const PART_BYTES: usize = MAX_REQUEST_BYTES / 2;

/// A plan's live tree and what the manager has of it.
#[derive(Debug)]
pub struct LiveTree {
    plan: String,
    shape: Vec<PlanNode>,
    /// Each node's status as the ticks leave it (by node number).
    pub(crate) status: Vec<NodeStatus>,
    /// The statuses as last reported: the manager's.
    reported: Vec<NodeStatus>,
    reporting: Reporting,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Reporting {
    /// The shape is still to be sent.
    Unannounced,
    /// The manager has the tree: changes are sent.
    On,
    /// Not reported any more (the plan ended, was replaced, or its tree was refused).
    Off,
}

impl LiveTree {
    /// The live tree of the plan named `plan` (shortened to [`MAX_PLAN_NAME`] bytes, its end
    /// kept) with this shape, every node `Idle`.
    pub fn new(plan: &str, shape: Vec<PlanNode>) -> LiveTree {
        let n = shape.len();
        LiveTree {
            plan: short_name(plan),
            shape,
            status: vec![NodeStatus::Idle; n],
            reported: vec![NodeStatus::Idle; n],
            reporting: Reporting::Unannounced,
        }
    }

    /// The plan's name as reported.
    pub fn plan(&self) -> &str {
        &self.plan
    }

    /// Its nodes.
    pub fn shape(&self) -> &[PlanNode] {
        &self.shape
    }

    /// Each node's status now.
    pub fn status(&self) -> &[NodeStatus] {
        &self.status
    }

    /// Renames the plan (before its shape is sent).
    pub(crate) fn rename(&mut self, plan: &str) {
        self.plan = short_name(plan);
    }

    /// Sends the shape if it is not sent yet. A runner that took the plan over (`resumed`)
    /// goes on from the statuses the manager has of the same tree, so that what its
    /// predecessor reported stands.
    pub(crate) fn announce(&mut self, fabric: &mut dyn Fabric, resumed: bool) {
        if self.reporting != Reporting::Unannounced {
            return;
        }
        if resumed
            && let Ok(Some(t)) = fabric.current_plan()
            && t.plan == self.plan
            && t.nodes == self.shape
        {
            self.status = t.status.iter().map(|s| s.0).collect();
        }
        for part in shape_parts(&self.plan, &self.shape, &self.status) {
            if let Err(e) = fabric.report_plan(part) {
                self.refused(e, "its tree");
                return;
            }
        }
        self.reported.clone_from(&self.status);
        self.reporting = Reporting::On;
    }

    /// Sends the changes since the last report, if any (`ended`: the plan ended with this
    /// tick: said even when nothing changed, and nothing is reported after it).
    pub(crate) fn report(&mut self, fabric: &mut dyn Fabric, ended: bool) {
        if self.reporting == Reporting::Unannounced {
            // The shape carries the statuses as they are.
            self.announce(fabric, false);
        }
        if self.reporting != Reporting::On {
            return;
        }
        let changes = changes(&self.reported, &self.status);
        if changes.is_empty() && !ended {
            return;
        }
        let tick = PlanReport::Tick {
            plan: self.plan.clone(),
            changes,
            ended,
        };
        match fabric.report_plan(tick) {
            Ok(()) => {
                self.reported.clone_from(&self.status);
                if ended {
                    self.reporting = Reporting::Off;
                }
            }
            // The manager does not have the plan (it restarted): the tree again, as it is.
            Err(FabricError::Refused(e))
                if matches!(*e, ControlError::PlanNotCurrent { current: None, .. }) =>
            {
                self.reporting = Reporting::Unannounced;
                self.announce(fabric, false);
                if ended && self.reporting == Reporting::On {
                    self.report(fabric, true);
                }
            }
            Err(e) => self.refused(e, "a tick's changes"),
        }
    }

    /// A report that did not go through: refused, the live tree is not reported any more; a
    /// fabric that cannot be asked, the changes wait for the next report.
    fn refused(&mut self, e: FabricError, what: &str) {
        match e {
            FabricError::Refused(why) => {
                tracing::warn!(plan = %self.plan, error = %why, "the manager refused {what}: the plan's live tree is not reported any more");
                self.reporting = Reporting::Off;
            }
            FabricError::Failed(why) => {
                tracing::debug!(plan = %self.plan, error = %why, "{what} not reported");
            }
        }
    }
}

/// The nodes whose status differs between `reported` and `now`, by node number.
pub fn changes(reported: &[NodeStatus], now: &[NodeStatus]) -> Vec<PlanNodeChange> {
    reported
        .iter()
        .zip(now)
        .enumerate()
        .filter(|(_, (a, b))| a != b)
        .map(|(id, (_, b))| PlanNodeChange {
            id: id as u32,
            status: *b,
        })
        .collect()
}

/// A plan's shape as the reports that carry it: parts in node order, each well within a
/// request's size.
pub fn shape_parts(plan: &str, shape: &[PlanNode], status: &[NodeStatus]) -> Vec<PlanReport> {
    let total = shape.len() as u32;
    let mut parts = Vec::new();
    let mut start = 0;
    while start < shape.len() {
        let mut end = start;
        let mut bytes = 0;
        while end < shape.len() {
            let n = &shape[end];
            let size = n.name.len() + n.kind.len() + n.detail.len() + 24;
            if end > start && bytes + size > PART_BYTES {
                break;
            }
            bytes += size;
            end += 1;
        }
        parts.push(PlanReport::Shape {
            plan: plan.to_string(),
            total,
            nodes: shape[start..end].to_vec(),
            status: status[start..end].to_vec(),
        });
        start = end;
    }
    parts
}

/// `plan` in at most [`MAX_PLAN_NAME`] bytes: its end (a file's name) kept.
fn short_name(plan: &str) -> String {
    if plan.len() <= MAX_PLAN_NAME {
        return plan.to_string();
    }
    let mut cut = plan.len() - (MAX_PLAN_NAME - '…'.len_utf8());
    while !plan.is_char_boundary(cut) {
        cut += 1;
    }
    format!("…{}", &plan[cut..])
}
