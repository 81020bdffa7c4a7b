//! A running plan as a live tree: its shape (the nodes of the behaviour tree, sub-trees
//! inlined, numbered in preorder), each node's status with the cycle it has had it since, and
//! what a plan runner reports ([`PlanReport`]) for the manager to keep and publish
//! ([`crate::control::EventKind::PlanChanged`]).
//!
//! The runner sends the shape when its plan starts (and again when a runner takes the plan
//! over), then, after each tick that changed something, the nodes whose status changed. The
//! manager stamps each change with the cycle it arrived in and keeps the current tree, so a
//! client that comes later asks for it whole ([`crate::control::Request::Plan`]) and follows
//! the events from there.

use serde::{Deserialize, Serialize};

/// A node's status, as BehaviorTree.CPP names them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum NodeStatus {
    /// Not ticked yet, or halted since (a halted node is as if never ticked).
    #[default]
    Idle,
    /// Ticked, not done: the plan is here.
    Running,
    /// Its last tick ended it, and it worked.
    Success,
    /// Its last tick ended it, and it did not.
    Failure,
}

impl NodeStatus {
    /// Its name in text and JSON: `idle`, `running`, `success`, `failure`.
    pub fn as_str(self) -> &'static str {
        match self {
            NodeStatus::Idle => "idle",
            NodeStatus::Running => "running",
            NodeStatus::Success => "success",
            NodeStatus::Failure => "failure",
        }
    }

    /// One letter for a tree drawn in text: `·`, `R`, `S`, `F`.
    pub fn letter(self) -> char {
        match self {
            NodeStatus::Idle => '·',
            NodeStatus::Running => 'R',
            NodeStatus::Success => 'S',
            NodeStatus::Failure => 'F',
        }
    }
}

impl std::fmt::Display for NodeStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.as_str())
    }
}

/// One node of a plan's tree.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PlanNode {
    /// Its number: preorder, sub-trees inlined, from 0 (the root); a node's parent has a
    /// lower number than it.
    pub id: u32,
    /// Its parent (`None`: the root, and only the root).
    pub parent: Option<u32>,
    /// Its `name` attribute, or its element's name.
    pub name: String,
    /// Its BehaviorTree.CPP tag: `Sequence`, `Fallback`, `Parallel`, `WaitFor`, `Activate`, …
    pub kind: String,
    /// What it does, in short: the skills an action activates, the parameter it sets, the
    /// condition it waits for, a timer's length (empty when there is nothing to say).
    pub detail: String,
}

/// A node whose status changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PlanNodeChange {
    /// The node ([`PlanNode::id`]).
    pub id: u32,
    /// Its new status.
    pub status: NodeStatus,
}

/// A plan's tree with each node's status, as the manager keeps it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PlanTree {
    /// The plan's name (its file, and the tree run if not its main one).
    pub plan: String,
    /// The nodes, in id order (`nodes[i].id == i`).
    pub nodes: Vec<PlanNode>,
    /// Each node's status and the cycle it has had it since, indexed by node id.
    pub status: Vec<(NodeStatus, u64)>,
}

/// The most nodes a plan's tree may have (the plan reader's own limit, sub-trees inlined).
pub const MAX_PLAN_NODES: u32 = 100_000;

/// The longest plan name the manager keeps (bytes): it travels in every
/// [`crate::control::EventKind::PlanChanged`], which must fit an event.
pub const MAX_PLAN_NAME: usize = 256;

/// What is wrong with a plan's tree as a runner sent it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, Serialize, Deserialize)]
#[non_exhaustive]
pub enum PlanTreeProblem {
    /// A tree with no node.
    #[error("it has no node")]
    Empty,
    /// More nodes than [`MAX_PLAN_NODES`].
    #[error("{total} nodes, more than the {max} a plan may have")]
    TooManyNodes {
        /// As announced.
        total: u32,
        /// [`MAX_PLAN_NODES`].
        max: u32,
    },
    /// A name longer than [`MAX_PLAN_NAME`] bytes.
    #[error("a name of {bytes} bytes (at most {max})")]
    NameTooLong {
        /// Its length.
        bytes: usize,
        /// [`MAX_PLAN_NAME`].
        max: usize,
    },
    /// A node not numbered where it stands (ids are 0, 1, 2, … in order, across parts).
    #[error("node {got} where node {expected} was due")]
    OutOfOrder {
        /// The id due.
        expected: u32,
        /// The id sent.
        got: u32,
    },
    /// A parent that is not an earlier node, a root that has one, or another node without.
    #[error("node {id} has parent {parent:?} (the root has none, every other node an earlier one)")]
    BadParent {
        /// The node.
        id: u32,
        /// Its parent as sent.
        parent: Option<u32>,
    },
    /// Not one status per node.
    #[error("{statuses} statuses for {nodes} nodes")]
    StatusCount {
        /// Nodes in the part.
        nodes: usize,
        /// Statuses in the part.
        statuses: usize,
    },
    /// More nodes than the announced total.
    #[error("more than the {total} nodes announced")]
    PastTotal {
        /// As announced.
        total: u32,
    },
    /// A later part of a shape with no first part before it (from this client, of this plan).
    #[error("a part starting at node {first} with no shape begun")]
    NotBegun {
        /// The first node of the part.
        first: u32,
    },
}

/// What a plan runner tells the manager ([`crate::control::Request::Plan`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum PlanReport {
    /// The plan's shape and each node's status: when it starts, and when a runner takes it
    /// over. A shape larger than a request may be is sent in parts, in id order; the first
    /// part starts at node 0, and the tree counts once all `total` nodes are in.
    Shape {
        /// The plan's name.
        plan: String,
        /// Nodes in the whole tree.
        total: u32,
        /// The next nodes, in id order.
        nodes: Vec<PlanNode>,
        /// Their statuses, one per node of `nodes`.
        status: Vec<NodeStatus>,
    },
    /// The nodes whose status changed in a tick (`ended`: and the plan ended with that tick —
    /// succeeded, failed or was halted; the manager forgets it).
    Tick {
        /// The plan's name.
        plan: String,
        /// What changed, by node.
        changes: Vec<PlanNodeChange>,
        /// The plan ended.
        ended: bool,
    },
}

impl PlanTree {
    /// A node's children, in order.
    pub fn children(&self, id: u32) -> impl Iterator<Item = &PlanNode> {
        self.nodes
            .iter()
            .skip(id as usize + 1)
            .filter(move |n| n.parent == Some(id))
    }

    /// How deep each node is (the root 0), by id.
    pub fn depths(&self) -> Vec<usize> {
        let mut d = vec![0usize; self.nodes.len()];
        for n in &self.nodes {
            // Parents come before their children (checked when the tree was taken in).
            if let Some(p) = n.parent.and_then(|p| d.get(p as usize).copied()) {
                d[n.id as usize] = p + 1;
            }
        }
        d
    }

    /// The nodes that are running or hold a running node below them: where the plan is.
    pub fn running_branch(&self) -> Vec<bool> {
        let mut on = vec![false; self.nodes.len()];
        // Children after parents: walk backwards, lighting each running node's parent.
        for n in self.nodes.iter().rev() {
            let i = n.id as usize;
            if self
                .status
                .get(i)
                .is_some_and(|s| s.0 == NodeStatus::Running)
            {
                on[i] = true;
            }
            if on[i]
                && let Some(p) = n.parent
                && let Some(x) = on.get_mut(p as usize)
            {
                *x = true;
            }
        }
        on
    }

    /// Applies `changes` that arrived in `cycle`; the first node id the tree does not have
    /// refuses them all (nothing is applied).
    pub fn apply(&mut self, changes: &[PlanNodeChange], cycle: u64) -> Result<(), u32> {
        if let Some(c) = changes.iter().find(|c| c.id as usize >= self.status.len()) {
            return Err(c.id);
        }
        for c in changes {
            self.status[c.id as usize] = (c.status, cycle);
        }
        Ok(())
    }
}

/// Checks the next part of a shape: `nodes` continue a tree that has `have` nodes so far, of
/// `total` in all.
pub fn check_shape_part(
    have: u32,
    total: u32,
    nodes: &[PlanNode],
    status: &[NodeStatus],
) -> Result<(), PlanTreeProblem> {
    if total == 0 {
        return Err(PlanTreeProblem::Empty);
    }
    if total > MAX_PLAN_NODES {
        return Err(PlanTreeProblem::TooManyNodes {
            total,
            max: MAX_PLAN_NODES,
        });
    }
    if nodes.len() != status.len() {
        return Err(PlanTreeProblem::StatusCount {
            nodes: nodes.len(),
            statuses: status.len(),
        });
    }
    if u64::from(have) + nodes.len() as u64 > u64::from(total) {
        return Err(PlanTreeProblem::PastTotal { total });
    }
    for (i, n) in nodes.iter().enumerate() {
        let expected = have + i as u32;
        if n.id != expected {
            return Err(PlanTreeProblem::OutOfOrder {
                expected,
                got: n.id,
            });
        }
        let fits = match n.parent {
            None => n.id == 0,
            Some(p) => p < n.id,
        };
        if !fits {
            return Err(PlanTreeProblem::BadParent {
                id: n.id,
                parent: n.parent,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(id: u32, parent: Option<u32>) -> PlanNode {
        PlanNode {
            id,
            parent,
            name: format!("n{id}"),
            kind: "Sequence".into(),
            detail: String::new(),
        }
    }

    #[test]
    fn a_shape_is_numbered_in_preorder_with_parents_before_children() {
        let ok = [node(0, None), node(1, Some(0)), node(2, Some(1))];
        let idle = [NodeStatus::Idle; 3];
        assert_eq!(check_shape_part(0, 3, &ok, &idle), Ok(()));
        assert_eq!(check_shape_part(0, 5, &ok, &idle), Ok(()));
        assert_eq!(
            check_shape_part(3, 5, &[node(3, Some(0))], &idle[..1]),
            Ok(())
        );
        assert_eq!(
            check_shape_part(0, 2, &ok, &idle),
            Err(PlanTreeProblem::PastTotal { total: 2 })
        );
        assert_eq!(
            check_shape_part(0, 3, &ok, &idle[..2]),
            Err(PlanTreeProblem::StatusCount {
                nodes: 3,
                statuses: 2
            })
        );
        assert_eq!(
            check_shape_part(1, 3, &ok[1..], &idle[..2]),
            Ok(()),
            "a later part continues the numbering"
        );
        assert_eq!(
            check_shape_part(0, 3, &[node(0, None), node(2, Some(0))], &idle[..2]),
            Err(PlanTreeProblem::OutOfOrder {
                expected: 1,
                got: 2
            })
        );
        assert_eq!(
            check_shape_part(0, 3, &[node(0, Some(0))], &idle[..1]),
            Err(PlanTreeProblem::BadParent {
                id: 0,
                parent: Some(0)
            })
        );
        assert_eq!(
            check_shape_part(0, 3, &[node(0, None), node(1, Some(1))], &idle[..2]),
            Err(PlanTreeProblem::BadParent {
                id: 1,
                parent: Some(1)
            })
        );
        assert_eq!(
            check_shape_part(0, 3, &[node(0, None), node(1, None)], &idle[..2]),
            Err(PlanTreeProblem::BadParent {
                id: 1,
                parent: None
            })
        );
        assert_eq!(
            check_shape_part(0, 0, &[], &[]),
            Err(PlanTreeProblem::Empty)
        );
        assert!(matches!(
            check_shape_part(0, MAX_PLAN_NODES + 1, &[], &[]),
            Err(PlanTreeProblem::TooManyNodes { .. })
        ));
    }

    #[test]
    fn changes_apply_with_their_cycle_and_an_unknown_node_applies_none() {
        let mut t = PlanTree {
            plan: "p".into(),
            nodes: vec![
                node(0, None),
                node(1, Some(0)),
                node(2, Some(0)),
                node(3, Some(2)),
            ],
            status: vec![(NodeStatus::Idle, 0); 4],
        };
        let ch = |id, status| PlanNodeChange { id, status };
        t.apply(&[ch(0, NodeStatus::Running), ch(1, NodeStatus::Success)], 7)
            .unwrap();
        assert_eq!(t.status[0], (NodeStatus::Running, 7));
        assert_eq!(t.status[1], (NodeStatus::Success, 7));
        assert_eq!(
            t.apply(&[ch(2, NodeStatus::Running), ch(9, NodeStatus::Running)], 8),
            Err(9)
        );
        assert_eq!(t.status[2], (NodeStatus::Idle, 0), "nothing applied");
        t.apply(&[ch(2, NodeStatus::Running), ch(3, NodeStatus::Running)], 9)
            .unwrap();
        assert_eq!(t.running_branch(), vec![true, false, true, true]);
        assert_eq!(t.depths(), vec![0, 1, 1, 2]);
        let kids: Vec<u32> = t.children(0).map(|n| n.id).collect();
        assert_eq!(kids, vec![1, 2]);
    }
}
