//! The running plan, as its runner reports it: the tree and each node's status with the cycle
//! it has had it since (docs/sequence.md, "The plan as a live tree"). Pure bookkeeping; the
//! request handler (`requests::plan`) turns what changed into events.
//!
//! One plan per domain: a runner's shape replaces whatever plan was there (a second
//! sequencer's, or the same plan's previous runner's, which a restarted runner takes over).
//! Only the client that sent the running plan's shape reports on it; the others are told
//! their plan is not the running one ([`ControlError::PlanNotCurrent`]). A plan whose runner
//! died stays until its next runner sends the shape again (or another plan replaces it): the
//! runner may be restarted and take it over.

use skillfab_proto::control::{
    ControlError, MAX_PLAN_NAME, NodeStatus, PlanNode, PlanNodeChange, PlanTree, PlanTreeProblem,
    check_shape_part, shorten,
};

/// The running plan and a shape on its way in.
#[derive(Debug, Default)]
pub(crate) struct Plans {
    current: Option<Live>,
    /// The parts of a shape received so far (one client's at a time: a plan's shape is sent
    /// in a row, and seldom in more than one part).
    pending: Option<Pending>,
}

#[derive(Debug)]
struct Live {
    tree: PlanTree,
    /// The runner that sent the shape: the only client that reports on it.
    client: String,
}

#[derive(Debug)]
struct Pending {
    client: String,
    plan: String,
    total: u32,
    nodes: Vec<PlanNode>,
    status: Vec<NodeStatus>,
}

/// What a report changed, for the clients to hear.
#[derive(Debug, Default, PartialEq)]
pub(crate) struct PlanNews {
    /// A whole tree arrived: (its tree as installed, the plan it replaced).
    pub(crate) started: Option<(PlanTree, Option<String>)>,
    /// Nodes whose status changed, in the cycle given.
    pub(crate) changed: Vec<PlanNodeChange>,
    /// The plan ended, its root with this status.
    pub(crate) ended: Option<NodeStatus>,
}

impl Plans {
    /// The running plan.
    pub(crate) fn current(&self) -> Option<&PlanTree> {
        self.current.as_ref().map(|l| &l.tree)
    }

    /// A part of `client`'s plan shape (`total` nodes in all), arrived in `cycle`.
    pub(crate) fn shape(
        &mut self,
        client: &str,
        plan: String,
        total: u32,
        nodes: Vec<PlanNode>,
        status: Vec<NodeStatus>,
        cycle: u64,
    ) -> Result<PlanNews, ControlError> {
        let bad = |plan: &str, problem| ControlError::BadPlanTree {
            plan: shorten(plan, 120),
            problem,
        };
        if plan.len() > MAX_PLAN_NAME {
            let problem = PlanTreeProblem::NameTooLong {
                bytes: plan.len(),
                max: MAX_PLAN_NAME,
            };
            return Err(bad(&plan, problem));
        }
        let first = nodes.first().map_or(0, |n| n.id);
        let have = if first == 0 {
            0
        } else {
            match &self.pending {
                Some(p) if p.client == client && p.plan == plan && p.total == total => {
                    p.nodes.len() as u32
                }
                _ => return Err(bad(&plan, PlanTreeProblem::NotBegun { first })),
            }
        };
        check_shape_part(have, total, &nodes, &status).map_err(|p| bad(&plan, p))?;
        let pending = match self.pending.take() {
            Some(mut p) if have > 0 => {
                p.nodes.extend(nodes);
                p.status.extend(status);
                p
            }
            _ => Pending {
                client: client.to_string(),
                plan,
                total,
                nodes,
                status,
            },
        };
        if (pending.nodes.len() as u32) < pending.total {
            self.pending = Some(pending);
            return Ok(PlanNews::default());
        }
        Ok(self.install(pending, cycle))
    }

    /// A whole shape: it replaces the running plan. The same plan's tree sent again (a runner
    /// that took it over) keeps each node's `since` where its status is unchanged, and the
    /// nodes whose status differs are news.
    fn install(&mut self, p: Pending, cycle: u64) -> PlanNews {
        let previous = self.current.take();
        let same = previous
            .as_ref()
            .filter(|l| l.tree.plan == p.plan && l.tree.nodes == p.nodes);
        let mut changed = Vec::new();
        let status: Vec<(NodeStatus, u64)> = p
            .status
            .iter()
            .enumerate()
            .map(|(i, &s)| match same.map(|l| l.tree.status[i]) {
                Some((was, since)) if was == s => (s, since),
                Some(_) => {
                    changed.push(PlanNodeChange {
                        id: i as u32,
                        status: s,
                    });
                    (s, cycle)
                }
                None => (s, cycle),
            })
            .collect();
        let tree = PlanTree {
            plan: p.plan,
            nodes: p.nodes,
            status,
        };
        self.current = Some(Live {
            tree: tree.clone(),
            client: p.client,
        });
        PlanNews {
            started: Some((tree, previous.map(|l| l.tree.plan))),
            changed,
            ended: None,
        }
    }

    /// `client`'s changes of a tick of `plan`, arrived in `cycle` (`ended`: its last tick).
    pub(crate) fn tick(
        &mut self,
        client: &str,
        plan: &str,
        changes: &[PlanNodeChange],
        ended: bool,
        cycle: u64,
    ) -> Result<PlanNews, ControlError> {
        let live = match &mut self.current {
            Some(l) if l.client == client && l.tree.plan == plan => l,
            other => {
                return Err(ControlError::PlanNotCurrent {
                    plan: shorten(plan, 120),
                    current: other.as_ref().map(|l| l.tree.plan.clone()),
                });
            }
        };
        // Only what differs is news (and moves a node's `since`).
        let changed: Vec<PlanNodeChange> = changes
            .iter()
            .filter(|c| {
                live.tree
                    .status
                    .get(c.id as usize)
                    .is_none_or(|s| s.0 != c.status)
            })
            .copied()
            .collect();
        live.tree
            .apply(&changed, cycle)
            .map_err(|id| ControlError::UnknownPlanNode {
                plan: shorten(plan, 120),
                id,
                nodes: live.tree.nodes.len() as u32,
            })?;
        let ended = ended.then(|| live.tree.status.first().map_or(NodeStatus::Idle, |s| s.0));
        if ended.is_some() {
            self.current = None;
        }
        Ok(PlanNews {
            started: None,
            changed,
            ended,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use NodeStatus::*;

    fn nodes(n: u32) -> Vec<PlanNode> {
        (0..n)
            .map(|id| PlanNode {
                id,
                parent: id.checked_sub(1).map(|_| 0),
                name: format!("n{id}"),
                kind: if id == 0 { "Sequence" } else { "Activate" }.into(),
                detail: String::new(),
            })
            .collect()
    }

    fn ch(id: u32, status: NodeStatus) -> PlanNodeChange {
        PlanNodeChange { id, status }
    }

    #[test]
    fn a_shape_in_parts_counts_once_whole_and_replaces_the_running_plan() {
        let mut p = Plans::default();
        let all = nodes(4);
        let news = p
            .shape("a", "one".into(), 4, all[..2].to_vec(), vec![Idle; 2], 5)
            .unwrap();
        assert_eq!(news, PlanNews::default(), "not whole yet");
        assert!(p.current().is_none());
        // Another client's later part does not continue it.
        assert!(matches!(
            p.shape("b", "one".into(), 4, all[2..].to_vec(), vec![Idle; 2], 5),
            Err(ControlError::BadPlanTree {
                problem: PlanTreeProblem::NotBegun { first: 2 },
                ..
            })
        ));
        let news = p
            .shape("a", "one".into(), 4, all[2..].to_vec(), vec![Idle; 2], 6)
            .unwrap();
        let (tree, replaced) = news.started.unwrap();
        assert_eq!((tree.nodes.len(), replaced), (4, None));
        assert_eq!(tree.status, vec![(Idle, 6); 4]);
        let news = p
            .shape("b", "two".into(), 2, nodes(2), vec![Running, Idle], 9)
            .unwrap();
        assert_eq!(news.started.unwrap().1, Some("one".into()));
        // The first plan's runner is told, by a typed refusal.
        assert_eq!(
            p.tick("a", "one", &[ch(1, Running)], false, 10),
            Err(ControlError::PlanNotCurrent {
                plan: "one".into(),
                current: Some("two".into())
            })
        );
    }

    #[test]
    fn ticks_stamp_what_changed_refuse_unknown_nodes_and_an_end_forgets_the_plan() {
        let mut p = Plans::default();
        p.shape("a", "p".into(), 3, nodes(3), vec![Idle; 3], 1)
            .unwrap();
        let news = p
            .tick(
                "a",
                "p",
                &[ch(0, Running), ch(1, Running), ch(2, Idle)],
                false,
                4,
            )
            .unwrap();
        assert_eq!(news.changed, vec![ch(0, Running), ch(1, Running)]);
        assert_eq!(
            p.current().unwrap().status,
            vec![(Running, 4), (Running, 4), (Idle, 1)]
        );
        assert_eq!(
            p.tick("a", "p", &[ch(1, Success), ch(3, Running)], false, 5),
            Err(ControlError::UnknownPlanNode {
                plan: "p".into(),
                id: 3,
                nodes: 3
            })
        );
        assert_eq!(p.current().unwrap().status[1], (Running, 4), "none applied");
        assert!(matches!(
            p.tick("b", "p", &[], false, 5),
            Err(ControlError::PlanNotCurrent { .. })
        ));
        let news = p
            .tick("a", "p", &[ch(1, Success), ch(0, Success)], true, 6)
            .unwrap();
        assert_eq!(news.ended, Some(Success));
        assert!(p.current().is_none());
        assert_eq!(
            p.tick("a", "p", &[], false, 7),
            Err(ControlError::PlanNotCurrent {
                plan: "p".into(),
                current: None
            })
        );
    }

    #[test]
    fn a_runner_that_takes_the_plan_over_keeps_the_statuses_it_agrees_with() {
        let mut p = Plans::default();
        p.shape("a", "p".into(), 3, nodes(3), vec![Idle; 3], 1)
            .unwrap();
        p.tick(
            "a",
            "p",
            &[ch(0, Running), ch(1, Success), ch(2, Running)],
            false,
            3,
        )
        .unwrap();
        let news = p
            .shape(
                "b",
                "p".into(),
                3,
                nodes(3),
                vec![Running, Success, Idle],
                8,
            )
            .unwrap();
        assert_eq!(news.started.as_ref().unwrap().1, Some("p".into()));
        assert_eq!(news.changed, vec![ch(2, Idle)]);
        assert_eq!(
            p.current().unwrap().status,
            vec![(Running, 3), (Success, 3), (Idle, 8)]
        );
        assert!(p.tick("b", "p", &[ch(2, Running)], false, 9).is_ok());
    }

    #[test]
    fn a_name_too_long_for_an_event_is_refused() {
        let mut p = Plans::default();
        let long = "x".repeat(MAX_PLAN_NAME + 1);
        assert!(matches!(
            p.shape("a", long, 1, nodes(1), vec![Idle], 1),
            Err(ControlError::BadPlanTree {
                problem: PlanTreeProblem::NameTooLong { .. },
                ..
            })
        ));
    }
}
