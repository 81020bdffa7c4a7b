//! The planner's plan for each shipped building, to its office, against the tree written by
//! hand for it before the planner (kept in `fixtures/hand-written.xml`, a copy of
//! `skills/plans/deliver.xml` as it was): both read as the sequencer reads them and expanded
//! — sub-trees inlined, a `Sequence` inside a `Sequence` flattened (the same run: a sequence
//! goes on into its next child in the same tick, and both start over from the first after a
//! failure), `Log` lines and node names dropped (they only write the step log), a wait
//! guarded against a dead end taken as the wait — and compared node for node. Equal
//! expansions give identical lock-step runs (up to where a guard fires).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use skillfab_planner::{From, Library, Map, map_beside, plan};
use skillfab_sequence::plan::{Kind, Plan, Spec};
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `spec` expanded into `out`, one line per node (`depth` two spaces, the node's BT tag and
/// what it does).
fn expand(plan: &Plan, spec: &Spec, depth: usize, in_sequence: bool, out: &mut Vec<String>) {
    match &spec.kind {
        Kind::SubTree(id) => expand(plan, &plan.trees[id], depth, in_sequence, out),
        Kind::Log(_) => {}
        // A wait the planner guards against a dead end (a missed turn): the same run until
        // the guard fires, where the hand-written tree waited until the run's limit.
        Kind::Parallel { children, .. } if matches!(children.get(1).map(|c| &c.kind), Some(Kind::SubTree(id)) if id == "NotAtADeadEnd") =>
        {
            expand(plan, &children[0], depth, in_sequence, out);
        }
        Kind::Sequence(children) if in_sequence => {
            for c in children {
                expand(plan, c, depth, true, out);
            }
        }
        kind => {
            out.push(format!(
                "{}{} {}",
                "  ".repeat(depth),
                kind.tag(),
                kind.detail()
            ));
            let is_sequence = matches!(kind, Kind::Sequence(_));
            for c in kind.children() {
                expand(plan, c, depth + 1, is_sequence, out);
            }
        }
    }
}

fn expanded(plan: &Plan, tree: &str) -> Vec<String> {
    let mut out = Vec::new();
    expand(plan, &plan.trees[tree], 0, false, &mut out);
    out
}

/// The planner's plan for `building` (its map beside it) to the map's office.
fn planned(building: &str) -> (Plan, String) {
    let map = Map::load(&map_beside(&repo().join(building))).unwrap();
    let route = plan(&map, None, From::Lab).unwrap();
    let library = std::fs::read_to_string(repo().join("skills/plans/deliver.xml")).unwrap();
    let xml = route
        .plan_xml(&Library::parse(&library, "deliver.xml").unwrap(), building)
        .unwrap();
    (Plan::parse(&xml, "planned").unwrap(), route.to_string())
}

#[test]
fn the_planners_plan_to_each_office_is_the_hand_written_one_node_for_node() {
    let hand = Plan::parse(
        &std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/hand-written.xml"),
        )
        .unwrap(),
        "hand-written.xml",
    )
    .unwrap();
    for (tree, building) in [
        (
            "building-a",
            "devices/denning-sim/buildings/building-a.toml",
        ),
        (
            "building-b",
            "devices/denning-sim/buildings/building-b.toml",
        ),
        (
            "building-c",
            "devices/denning-sim/buildings/heldout/building-c.toml",
        ),
        (
            "building-d",
            "devices/denning-sim/buildings/heldout/building-d.toml",
        ),
    ] {
        let (plan, route) = planned(building);
        let ours = expanded(&plan, &plan.main);
        let theirs = expanded(&hand, tree);
        // Where they part, with the nodes before it (a whole-tree dump would bury it).
        if let Some(at) = (0..ours.len().max(theirs.len())).find(|i| ours.get(*i) != theirs.get(*i))
        {
            let from = at.saturating_sub(6);
            panic!(
                "{tree}: the plans differ at node {at}\n{route}\nplanned:\n{}\nhand-written:\n{}",
                ours[from..(at + 3).min(ours.len())].join("\n"),
                theirs[from..(at + 3).min(theirs.len())].join("\n"),
            );
        }
        // Not compared empty: the whole mission is there.
        assert!(ours.len() > 100, "{tree}: {} nodes", ours.len());
    }
}
