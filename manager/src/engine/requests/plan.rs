//! `plan`: a plan runner's reports (the tree of its plan, the status changes of each tick),
//! kept by [`Plans`] and told to clients as events; and the running plan, for a client that
//! asks.

use super::Effects;
use crate::engine::plans::Plans;
use skillfab_proto::control::{ControlError, EventKind, PlanNodeChange, PlanReport};

/// The most status changes one `PlanChanged` event carries. An event is at most 2048 bytes
/// (`EVENT_MAX_BYTES`); a change is at most 4 (a node id under 2^21 as a varint, its status)
/// and the rest of the event at most about 300 (its number, cycle and time, the plan's name
/// of at most `MAX_PLAN_NAME` bytes): 400 leave room. A tick that changed more comes as
/// several events.
const CHANGES_PER_EVENT: usize = 400;

/// Takes in `client`'s report, arrived in `cycle`: what changed comes back as events (and a
/// whole tree as a record for the recording).
pub(crate) fn report(
    plans: &mut Plans,
    client: &str,
    report: PlanReport,
    cycle: u64,
) -> Result<Effects, ControlError> {
    let (plan, news) = match report {
        PlanReport::Shape {
            plan,
            total,
            nodes,
            status,
        } => {
            let news = plans.shape(client, plan.clone(), total, nodes, status, cycle)?;
            (plan, news)
        }
        PlanReport::Tick {
            plan,
            changes,
            ended,
        } => {
            let news = plans.tick(client, &plan, &changes, ended, cycle)?;
            (plan, news)
        }
    };
    let mut effects = Effects::default();
    if let Some((tree, replaced)) = news.started {
        effects.events.push(EventKind::PlanStarted {
            plan: plan.clone(),
            client: client.to_string(),
            nodes: tree.nodes.len() as u32,
            replaced,
        });
        effects.plan_trees.push(tree);
    }
    effects.events.extend(changed(&plan, cycle, &news.changed));
    if let Some(status) = news.ended {
        effects.events.push(EventKind::PlanEnded { plan, status });
    }
    Ok(effects)
}

/// `changes` as `PlanChanged` events, each small enough to be one event.
fn changed(plan: &str, cycle: u64, changes: &[PlanNodeChange]) -> Vec<EventKind> {
    changes
        .chunks(CHANGES_PER_EVENT)
        .map(|c| EventKind::PlanChanged {
            plan: plan.to_string(),
            cycle,
            changes: c.to_vec(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use skillfab_proto::control::{
        Event, MAX_PLAN_NAME, MAX_PLAN_NODES, NodeStatus, PlanNode, encode_event_within,
    };

    #[test]
    fn the_largest_change_event_fits_an_event() {
        let changes: Vec<PlanNodeChange> = (0..CHANGES_PER_EVENT as u32)
            .map(|i| PlanNodeChange {
                id: MAX_PLAN_NODES - 1 - i,
                status: NodeStatus::Failure,
            })
            .collect();
        let kind = changed(&"p".repeat(MAX_PLAN_NAME), u64::MAX, &changes).remove(0);
        let e = Event {
            seq: u64::MAX,
            cycle: u64::MAX,
            time_ns: u64::MAX,
            kind,
        };
        assert!(encode_event_within(&e, skillfab_proto::services::EVENT_MAX_BYTES).is_some());
        assert_eq!(
            changed("p", 1, &vec![changes[0]; 2 * CHANGES_PER_EVENT + 1]).len(),
            3
        );
    }

    #[test]
    fn a_whole_tree_is_news_and_a_record_an_unknown_node_is_refused() {
        let mut plans = Plans::default();
        let node = |id, parent| PlanNode {
            id,
            parent,
            name: format!("n{id}"),
            kind: "Sequence".into(),
            detail: String::new(),
        };
        let shape = PlanReport::Shape {
            plan: "p".into(),
            total: 2,
            nodes: vec![node(0, None), node(1, Some(0))],
            status: vec![NodeStatus::Running, NodeStatus::Idle],
        };
        let e = report(&mut plans, "1-0", shape, 3).unwrap();
        assert_eq!(e.plan_trees.len(), 1);
        assert!(matches!(
            &e.events[0],
            EventKind::PlanStarted {
                nodes: 2,
                replaced: None,
                ..
            }
        ));
        let bad = PlanReport::Tick {
            plan: "p".into(),
            changes: vec![PlanNodeChange {
                id: 2,
                status: NodeStatus::Running,
            }],
            ended: false,
        };
        assert!(matches!(
            report(&mut plans, "1-0", bad, 4),
            Err(ControlError::UnknownPlanNode {
                id: 2,
                nodes: 2,
                ..
            })
        ));
        let end = PlanReport::Tick {
            plan: "p".into(),
            changes: vec![PlanNodeChange {
                id: 0,
                status: NodeStatus::Success,
            }],
            ended: true,
        };
        let e = report(&mut plans, "1-0", end, 5).unwrap();
        assert_eq!(
            e.events,
            vec![
                EventKind::PlanChanged {
                    plan: "p".into(),
                    cycle: 5,
                    changes: vec![PlanNodeChange {
                        id: 0,
                        status: NodeStatus::Success
                    }]
                },
                EventKind::PlanEnded {
                    plan: "p".into(),
                    status: NodeStatus::Success
                }
            ]
        );
    }
}
