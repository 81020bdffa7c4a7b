//! The data-flow graph of registered skills: wiring checks at registration and the plan of
//! each cycle (which sync skills are expected to run, which inputs must be same-cycle, whom
//! the manager wakes at cycle start). Pure code, no I/O.

use skillfab_proto::decl::{Mode, PortDecl, PortKind, SkillDecl};
use std::collections::HashMap;

pub use skillfab_proto::registration::WiringError;
use skillfab_proto::registration::{Side, TypeDesc};

fn type_desc(p: &PortDecl) -> TypeDesc {
    TypeDesc {
        name: p.schema.type_name.clone(),
        size: p.schema.size,
        align: p.schema.align,
    }
}

fn same_type(a: &PortDecl, b: &PortDecl) -> bool {
    a.schema.type_name == b.schema.type_name
        && a.schema.size == b.schema.size
        && a.schema.align == b.schema.align
}

/// Checks that `new` can join `existing` (live, registered skills).
pub fn check_join<'a>(
    existing: impl Iterator<Item = &'a SkillDecl> + Clone,
    new: &SkillDecl,
) -> Result<(), Box<WiringError>> {
    if let Some(d) = existing.clone().find(|d| d.name == new.name) {
        return Err(Box::new(WiringError::DuplicateName {
            name: new.name.clone(),
            pid: d.pid,
        }));
    }
    let mismatch =
        |topic: &str, side, port: &PortDecl, other: &SkillDecl, other_side, op: &PortDecl| {
            WiringError::TypeMismatch {
                topic: topic.to_string(),
                skill: new.name.clone(),
                side,
                port: port.port.clone(),
                ty: type_desc(port),
                other: other.name.clone(),
                other_side,
                other_port: op.port.clone(),
                other_ty: type_desc(op),
            }
        };
    for out in &new.outputs {
        for d in existing.clone() {
            if let Some(o) = d.outputs.iter().find(|o| o.topic == out.topic) {
                // Many skills propose on one channel: fine when they agree on the type.
                if out.kind == PortKind::Proposal
                    && o.kind == PortKind::Proposal
                    && same_type(o, out)
                {
                    continue;
                }
                return Err(Box::new(if same_type(o, out) {
                    WiringError::TwoProducers {
                        topic: out.topic.clone(),
                        producer: d.name.clone(),
                        skill: new.name.clone(),
                    }
                } else {
                    mismatch(&out.topic, Side::Output, out, d, Side::Output, o)
                }));
            }
            if let Some(i) = d
                .inputs
                .iter()
                .find(|i| i.topic == out.topic && !same_type(i, out))
            {
                return Err(Box::new(mismatch(
                    &out.topic,
                    Side::Output,
                    out,
                    d,
                    Side::Input,
                    i,
                )));
            }
        }
    }
    for inp in &new.inputs {
        for d in existing.clone() {
            if matches!(inp.kind, PortKind::Channel(_))
                && d.inputs
                    .iter()
                    .any(|i| matches!(i.kind, PortKind::Channel(_)) && i.topic == inp.topic)
            {
                return Err(Box::new(WiringError::ChannelServed {
                    channel: inp.channel_name().unwrap_or(&inp.port).to_string(),
                    device: d.name.clone(),
                    skill: new.name.clone(),
                }));
            }
            if let Some(o) = d
                .outputs
                .iter()
                .find(|o| o.topic == inp.topic && !same_type(o, inp))
            {
                return Err(Box::new(mismatch(
                    &inp.topic,
                    Side::Input,
                    inp,
                    d,
                    Side::Output,
                    o,
                )));
            }
            if let Some(i) = d
                .inputs
                .iter()
                .find(|i| i.topic == inp.topic && !same_type(i, inp))
            {
                return Err(Box::new(mismatch(
                    &inp.topic,
                    Side::Input,
                    inp,
                    d,
                    Side::Input,
                    i,
                )));
            }
        }
    }
    let mut all: Vec<&SkillDecl> = existing.collect();
    all.push(new);
    if let Some(path) = find_sync_loop(&all) {
        return Err(Box::new(WiringError::Loop { skills: path }));
    }
    Ok(())
}

/// A loop among sync skills (producer → consumer edges), as `a -> b -> a`.
fn find_sync_loop(skills: &[&SkillDecl]) -> Option<Vec<String>> {
    let producer: HashMap<&str, usize> = skills
        .iter()
        .enumerate()
        .filter(|(_, d)| d.mode == Mode::Sync)
        .flat_map(|(i, d)| {
            d.outputs
                .iter()
                .filter(|o| is_data(o))
                .map(move |o| (o.topic.as_str(), i))
        })
        .collect();
    // 0 = unvisited, 1 = on the stack, 2 = done
    let mut mark = vec![0u8; skills.len()];
    let mut stack = Vec::new();
    fn visit(
        i: usize,
        skills: &[&SkillDecl],
        producer: &HashMap<&str, usize>,
        mark: &mut [u8],
        stack: &mut Vec<usize>,
    ) -> Option<Vec<String>> {
        mark[i] = 1;
        stack.push(i);
        for inp in skills[i].inputs.iter().filter(|p| is_data(p)) {
            let Some(&p) = producer.get(inp.topic.as_str()) else {
                continue;
            };
            if mark[p] == 1 {
                let from = stack.iter().position(|&s| s == p).unwrap_or(0);
                let mut names: Vec<String> = stack[from..]
                    .iter()
                    .map(|&s| skills[s].name.clone())
                    .collect();
                names.reverse();
                names.push(skills[p].name.clone());
                // Edges point producer -> consumer; the stack walked consumer -> producer.
                return Some(names);
            }
            if mark[p] == 0
                && let Some(path) = visit(p, skills, producer, mark, stack)
            {
                return Some(path);
            }
        }
        stack.pop();
        mark[i] = 2;
        None
    }
    for i in 0..skills.len() {
        if skills[i].mode == Mode::Sync
            && mark[i] == 0
            && let Some(path) = visit(i, skills, &producer, &mut mark, &mut stack)
        {
            return Some(path);
        }
    }
    None
}

/// A registered skill as the planner sees it.
#[derive(Debug, Clone)]
pub struct PlanNode<'a> {
    /// Board slot.
    pub slot: usize,
    /// Declaration.
    pub decl: &'a SkillDecl,
    /// Whether it is active.
    pub active: bool,
}

/// What the manager does each cycle until the graph changes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Plan {
    /// Sync skills expected to run each cycle (slots).
    pub expected: Vec<usize>,
    /// Same-cycle input mask per slot (for every registered slot).
    pub fresh_masks: Vec<(usize, u64)>,
    /// Skills the manager wakes at cycle start: expected sync skills with no same-cycle
    /// input, and active async skills with no inputs.
    pub sources: Vec<usize>,
    /// For each expected slot and each of its outputs, the expected slots that consume it
    /// as a same-cycle input (to cancel them when the output is not produced).
    pub consumers: HashMap<usize, Vec<Vec<usize>>>,
    /// Actuator channels and their proposers.
    pub channels: Vec<ChannelPlan>,
}

/// Plans a cycle: a sync skill is expected when it is active and every input has an active
/// producer that is either async (latest value) or itself expected.
pub fn plan(nodes: &[PlanNode<'_>]) -> Plan {
    let producer: HashMap<&str, usize> = nodes
        .iter()
        .enumerate()
        .flat_map(|(i, n)| {
            n.decl
                .outputs
                .iter()
                .filter(|o| is_data(o))
                .map(move |o| (o.topic.as_str(), i))
        })
        .collect();
    // None = not decided, Some(b) = decided; `visiting` guards loops (refused at
    // registration, but never trust that here).
    let mut expected: Vec<Option<bool>> = vec![None; nodes.len()];
    let mut visiting = vec![false; nodes.len()];
    fn decide(
        i: usize,
        nodes: &[PlanNode<'_>],
        producer: &HashMap<&str, usize>,
        expected: &mut [Option<bool>],
        visiting: &mut [bool],
    ) -> bool {
        if let Some(e) = expected[i] {
            return e;
        }
        if visiting[i] {
            return false;
        }
        visiting[i] = true;
        let n = &nodes[i];
        let mut ok = n.active && n.decl.mode == Mode::Sync;
        if ok {
            for inp in n.decl.inputs.iter().filter(|p| is_data(p)) {
                let fine = producer.get(inp.topic.as_str()).is_some_and(|&p| {
                    nodes[p].active
                        && (nodes[p].decl.mode == Mode::Async
                            || decide(p, nodes, producer, expected, visiting))
                });
                if !fine {
                    ok = false;
                    break;
                }
            }
        }
        visiting[i] = false;
        expected[i] = Some(ok);
        ok
    }
    for i in 0..nodes.len() {
        decide(i, nodes, &producer, &mut expected, &mut visiting);
    }
    let mut plan = Plan::default();
    for (i, n) in nodes.iter().enumerate() {
        let mut mask = 0u64;
        for (bit, inp) in n.decl.inputs.iter().enumerate().filter(|(_, p)| is_data(p)) {
            if let Some(&p) = producer.get(inp.topic.as_str())
                && nodes[p].decl.mode == Mode::Sync
            {
                mask |= 1 << bit;
            }
        }
        plan.fresh_masks.push((n.slot, mask));
        let is_expected = expected[i] == Some(true);
        if is_expected {
            plan.expected.push(n.slot);
            if mask == 0 {
                plan.sources.push(n.slot);
            }
            let per_output = n
                .decl
                .outputs
                .iter()
                .map(|o| {
                    nodes
                        .iter()
                        .enumerate()
                        .filter(|(j, c)| {
                            // A device is not a consumer of the proposals on its channels: a
                            // proposal not made is no reason to cancel it (it settles on its
                            // own once every proposer is done).
                            expected[*j] == Some(true)
                                && c.decl
                                    .inputs
                                    .iter()
                                    .any(|ci| is_data(ci) && ci.topic == o.topic)
                        })
                        .map(|(_, c)| c.slot)
                        .collect()
                })
                .collect();
            plan.consumers.insert(n.slot, per_output);
        } else if n.active && n.decl.mode == Mode::Async && n.decl.inputs.is_empty() {
            plan.sources.push(n.slot);
        }
        // A device: for each channel it serves, every registered skill that proposes on it.
        for (c, ch) in n
            .decl
            .inputs
            .iter()
            .enumerate()
            .filter(|(_, p)| matches!(p.kind, PortKind::Channel(_)))
        {
            let mask = nodes
                .iter()
                .filter(|p| {
                    p.decl
                        .outputs
                        .iter()
                        .any(|o| o.kind == PortKind::Proposal && o.topic == ch.topic)
                })
                .fold(0u64, |m, p| m | (1 << p.slot));
            plan.channels.push(ChannelPlan {
                device: n.slot,
                index: c,
                channel: ch.channel_name().unwrap_or(&ch.port).to_string(),
                policy: match ch.kind {
                    PortKind::Channel(p) => p,
                    _ => skillfab_proto::decl::Policy::Priority,
                },
                proposers: mask,
            });
        }
    }
    plan
}

/// Why wanted skills cannot run: one of them, or a skill one of them needs, reads a topic
/// nobody produces, or the producers loop.
#[derive(Debug, Clone, PartialEq)]
pub enum DemandError {
    /// `skill`'s data input `port` reads `topic`, which nobody produces; `wanted_by` is the
    /// wanted skill that needs it, when it is not `skill` itself.
    NoProducer {
        /// The skill.
        skill: String,
        /// Its input.
        port: String,
        /// The input's topic.
        topic: String,
        /// The wanted skill it was reached from, if another.
        wanted_by: Option<String>,
    },
    /// Producers that read each other: each reads the next, the first again at the end.
    Loop(Vec<String>),
}

/// What running `wanted` needs: the wanted skills and, transitively, the producers of their
/// data inputs (proposals and channels close no loop and need no producer), each once,
/// producers before the skills that read them. `decls` are every skill
/// and device known (registered or away); a name in `wanted` that is not among them is left
/// to the caller (it answers an unknown skill).
pub fn demand<'a>(decls: &[&'a SkillDecl], wanted: &[String]) -> Result<Vec<&'a str>, DemandError> {
    let producer: HashMap<&str, &SkillDecl> = decls
        .iter()
        .flat_map(|d| {
            d.outputs
                .iter()
                .filter(|o| is_data(o))
                .map(move |o| (o.topic.as_str(), *d))
        })
        .collect();
    let mut needed: Vec<&'a str> = Vec::new();
    for w in wanted {
        let Some(d) = decls.iter().find(|d| &d.name == w) else {
            continue;
        };
        // Depth first, with the path from the wanted skill: a skill met again on it closes a
        // loop.
        let mut path: Vec<&'a SkillDecl> = Vec::new();
        visit(d, w, &producer, &mut path, &mut needed)?;
    }
    Ok(needed)
}

fn visit<'a>(
    d: &'a SkillDecl,
    wanted: &str,
    producer: &HashMap<&str, &'a SkillDecl>,
    path: &mut Vec<&'a SkillDecl>,
    needed: &mut Vec<&'a str>,
) -> Result<(), DemandError> {
    if let Some(at) = path.iter().position(|p| p.name == d.name) {
        let mut names: Vec<String> = path[at..].iter().map(|p| p.name.clone()).collect();
        names.push(d.name.clone());
        return Err(DemandError::Loop(names));
    }
    if needed.contains(&d.name.as_str()) {
        return Ok(());
    }
    path.push(d);
    for inp in d.inputs.iter().filter(|p| is_data(p)) {
        let Some(p) = producer.get(inp.topic.as_str()) else {
            return Err(DemandError::NoProducer {
                skill: d.name.clone(),
                port: inp.port.clone(),
                topic: inp.topic.clone(),
                wanted_by: (d.name != wanted).then(|| wanted.to_string()),
            });
        };
        visit(p, wanted, producer, path, needed)?;
    }
    path.pop();
    needed.push(&d.name);
    Ok(())
}

/// A channel served by a device, and who proposes on it.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelPlan {
    /// The device's slot.
    pub device: usize,
    /// The channel's index among the device's inputs.
    pub index: usize,
    /// Channel name.
    pub channel: String,
    /// Arbitration policy.
    pub policy: skillfab_proto::decl::Policy,
    /// Slots that propose on it.
    pub proposers: u64,
}

/// Plain data ports take part in readiness; proposals and channels do not (a device samples
/// at cycle start and takes the cycle's commands at its end, so they close no loop).
fn is_data(p: &PortDecl) -> bool {
    p.kind == PortKind::Data
}

#[cfg(test)]
mod tests {
    use super::*;
    use skillfab_msgs::{Scaled, Tick};
    use skillfab_proto::param::ParamValue;

    fn skill(name: &str, mode: Mode, inputs: Vec<PortDecl>, outputs: Vec<PortDecl>) -> SkillDecl {
        SkillDecl {
            name: name.into(),
            kind: name.into(),
            mode,
            priority: 0,
            start_active: true,
            pid: 1,
            inputs,
            outputs,
            params: vec![],
            param_values: Vec::<(String, ParamValue)>::new(),
        }
    }
    fn port<T: skillfab_proto::Message>(topic: &str) -> PortDecl {
        PortDecl::of::<T>(topic)
    }

    fn hello() -> Vec<SkillDecl> {
        vec![
            skill("ticker", Mode::Sync, vec![], vec![port::<Tick>("tick")]),
            skill(
                "scale",
                Mode::Sync,
                vec![port::<Tick>("tick")],
                vec![port::<Scaled>("scaled")],
            ),
            skill(
                "smooth",
                Mode::Async,
                vec![port::<Scaled>("scaled")],
                vec![],
            ),
        ]
    }

    fn nodes(d: &[SkillDecl], active: &[bool]) -> Vec<PlanNode<'static>> {
        let leaked: &'static [SkillDecl] = Box::leak(d.to_vec().into_boxed_slice());
        leaked
            .iter()
            .enumerate()
            .map(|(i, decl)| PlanNode {
                slot: i,
                decl,
                active: active[i],
            })
            .collect()
    }

    #[test]
    fn hello_plan() {
        let p = plan(&nodes(&hello(), &[true, true, true]));
        assert_eq!(p.expected, vec![0, 1]);
        assert_eq!(p.sources, vec![0]);
        assert_eq!(p.fresh_masks, vec![(0, 0), (1, 1), (2, 1)]);
        assert_eq!(p.consumers[&0], vec![vec![1]]);
        assert_eq!(p.consumers[&1], vec![Vec::<usize>::new()]);
    }

    #[test]
    fn inactive_producer_makes_consumer_unexpected() {
        let p = plan(&nodes(&hello(), &[false, true, true]));
        assert!(p.expected.is_empty());
        assert!(p.sources.is_empty());
    }

    #[test]
    fn type_mismatch_names_both_sides() {
        let h = hello();
        let bad = skill("bad", Mode::Sync, vec![port::<Scaled>("tick")], vec![]);
        let e = check_join(h.iter(), &bad).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("'bad' input 'tick' is 'skillfab.Scaled"),
            "{text}"
        );
        assert!(
            text.contains("'ticker' output 'tick' is 'skillfab.Tick"),
            "{text}"
        );
    }

    #[test]
    fn second_producer_and_duplicate_name_are_refused() {
        let h = hello();
        let two = skill("ticker2", Mode::Sync, vec![], vec![port::<Tick>("tick")]);
        let e = check_join(h.iter(), &two).unwrap_err();
        assert!(matches!(*e, WiringError::TwoProducers { .. }), "{e}");
        let dup = skill("scale", Mode::Sync, vec![], vec![]);
        let e = check_join(h.iter(), &dup).unwrap_err();
        assert!(matches!(*e, WiringError::DuplicateName { .. }), "{e}");
    }

    #[test]
    fn sync_loops_are_refused_async_breaks_them() {
        let a = skill(
            "a",
            Mode::Sync,
            vec![port::<Tick>("y")],
            vec![port::<Tick>("x")],
        );
        let b = skill(
            "b",
            Mode::Sync,
            vec![port::<Tick>("x")],
            vec![port::<Tick>("y")],
        );
        let e = check_join([a.clone()].iter(), &b).unwrap_err();
        assert!(matches!(*e, WiringError::Loop { .. }), "{e}");
        let b_async = SkillDecl {
            mode: Mode::Async,
            ..b
        };
        assert!(check_join([a].iter(), &b_async).is_ok());
    }

    fn names(d: &[SkillDecl]) -> Vec<&SkillDecl> {
        d.iter().collect()
    }

    #[test]
    fn wanting_a_skill_needs_its_producers_first_each_once() {
        let h = hello();
        let needed = demand(&names(&h), &["smooth".into(), "scale".into()]).unwrap();
        assert_eq!(needed, ["ticker", "scale", "smooth"]);
        let needed = demand(&names(&h), &["ticker".into()]).unwrap();
        assert_eq!(needed, ["ticker"], "a source needs nothing more");
    }

    #[test]
    fn wanting_a_skill_whose_input_nobody_produces_names_the_input() {
        let h = hello();
        let without_ticker = &h[1..];
        assert_eq!(
            demand(&names(without_ticker), &["scale".into()]),
            Err(DemandError::NoProducer {
                skill: "scale".into(),
                port: "tick".into(),
                topic: "tick".into(),
                wanted_by: None,
            })
        );
        assert_eq!(
            demand(&names(without_ticker), &["smooth".into()]),
            Err(DemandError::NoProducer {
                skill: "scale".into(),
                port: "tick".into(),
                topic: "tick".into(),
                wanted_by: Some("smooth".into()),
            }),
            "the wanted skill that needs it is named"
        );
    }

    #[test]
    fn producers_that_read_each_other_are_a_loop() {
        // Registration lets an async skill close a loop; wanting one of them is refused.
        let a = skill(
            "a",
            Mode::Sync,
            vec![port::<Tick>("y")],
            vec![port::<Tick>("x")],
        );
        let b = skill(
            "b",
            Mode::Async,
            vec![port::<Tick>("x")],
            vec![port::<Tick>("y")],
        );
        let both = [a, b];
        assert_eq!(
            demand(&names(&both), &["a".into()]),
            Err(DemandError::Loop(vec!["a".into(), "b".into(), "a".into()]))
        );
    }

    #[test]
    fn proposals_and_channels_need_no_producer() {
        use skillfab_proto::decl::Policy;
        let proposer = skill(
            "proposer",
            Mode::Sync,
            vec![],
            vec![PortDecl::channel::<Tick>("drive", PortKind::Proposal)],
        );
        let device = skill(
            "device",
            Mode::Sync,
            vec![PortDecl::channel::<Tick>(
                "drive",
                PortKind::Channel(Policy::Priority),
            )],
            vec![port::<Scaled>("sonar")],
        );
        let d = [proposer, device];
        assert_eq!(demand(&names(&d), &["device".into()]).unwrap(), ["device"]);
        assert_eq!(
            demand(&names(&d), &["proposer".into()]).unwrap(),
            ["proposer"]
        );
    }
}
