//! The engine on a fabric that records what it is asked (no processes): node semantics,
//! halting, parameters restored, refusals as failures; and the reader's errors.

use crate::plan::Plan;
use crate::run::Sequencer;
use crate::tree::{Fabric, FabricError, Status};
use skillfab_proto::control::{
    ControlError, MonitorFate, NodeStatus, PlanNodeChange, PlanReport, PlanTree,
};
use skillfab_proto::param::{ParamError, ParamKind, ParamValue};
use std::collections::BTreeMap;
use std::time::Duration;

/// A fabric in memory: skills, parameters (f64), monitors, a clock moved by hand.
#[derive(Default)]
struct Mock {
    active: BTreeMap<String, bool>,
    params: BTreeMap<String, f64>,
    monitors: BTreeMap<u64, String>,
    /// Who installed each monitor.
    owners: BTreeMap<u64, String>,
    /// Monitors that fired (and went).
    fired: Vec<u64>,
    /// The client asking (a restarted runner is another).
    client: String,
    /// Requests answered so far, and the one that finds the fabric gone (a runner dying).
    requests: usize,
    die_at: Option<usize>,
    next: u64,
    now: Duration,
    log: Vec<String>,
    /// Processes `up` gave up on, as the manager lists them.
    gave_up: Vec<String>,
    /// The plan reports sent, in order (not counted as requests: they change nothing the
    /// plan reads).
    reports: Vec<PlanReport>,
    /// The live tree as a manager keeps it.
    tree: Option<PlanTree>,
}

impl Mock {
    fn new(skills: &[&str]) -> Mock {
        let mut m = Mock::default();
        for s in skills {
            m.active.insert((*s).to_string(), false);
        }
        m.params.insert("avoid.safe_distance".into(), 0.6);
        m.client = "me".into();
        m
    }

    /// Counts a request; `Failed` at the one a runner dies in.
    fn request(&mut self) -> Result<(), FabricError> {
        self.requests += 1;
        if self.die_at == Some(self.requests) {
            return Err(FabricError::Failed(std::sync::Arc::from(Box::<
                dyn std::error::Error + Send + Sync,
            >::from(
                "the runner died here",
            ))));
        }
        Ok(())
    }

    fn known(&self, skills: &[String]) -> Result<(), FabricError> {
        match skills.iter().find(|s| !self.active.contains_key(*s)) {
            Some(s) => Err(ControlError::UnknownSkill(s.clone()).into()),
            None => Ok(()),
        }
    }

    /// The id of the monitor on `condition`.
    fn monitor(&self, condition: &str) -> u64 {
        self.monitors
            .iter()
            .find(|(_, c)| *c == condition)
            .map(|(id, _)| *id)
            .unwrap_or_else(|| panic!("no monitor on {condition}: {:?}", self.monitors))
    }

    fn on(&self) -> Vec<&str> {
        self.active
            .iter()
            .filter(|(_, a)| **a)
            .map(|(s, _)| s.as_str())
            .collect()
    }
}

fn unknown_param(skill: &str, param: &str) -> FabricError {
    ControlError::Param {
        skill: skill.into(),
        error: ParamError::Unknown {
            param: param.into(),
        },
    }
    .into()
}

impl Fabric for Mock {
    fn activate(&mut self, skills: &[String]) -> Result<(), FabricError> {
        self.request()?;
        self.known(skills)?;
        for s in skills {
            self.active.insert(s.clone(), true);
        }
        Ok(())
    }

    fn deactivate(&mut self, skills: &[String]) -> Result<(), FabricError> {
        self.request()?;
        self.known(skills)?;
        for s in skills {
            self.active.insert(s.clone(), false);
        }
        Ok(())
    }

    fn want(&mut self, skills: &[String]) -> Result<(), FabricError> {
        self.activate(skills)
    }

    fn release(&mut self, skills: &[String]) -> Result<(), FabricError> {
        self.deactivate(skills)
    }

    fn get_param(&mut self, skill: &str, param: &str) -> Result<ParamValue, FabricError> {
        self.request()?;
        self.params
            .get(&format!("{skill}.{param}"))
            .map(|v| ParamValue::Float(*v))
            .ok_or_else(|| unknown_param(skill, param))
    }

    fn set_param(&mut self, skill: &str, param: &str, value: &str) -> Result<(), FabricError> {
        self.request()?;
        let key = format!("{skill}.{param}");
        if !self.params.contains_key(&key) {
            return Err(unknown_param(skill, param));
        }
        let v = value.parse().map_err(|_| ControlError::Param {
            skill: skill.into(),
            error: ParamError::Unparsable {
                param: param.into(),
                expected: ParamKind::Float,
                text: value.into(),
            },
        })?;
        self.params.insert(key.clone(), v);
        self.log.push(format!("{key}={value}"));
        Ok(())
    }

    fn set_param_value(
        &mut self,
        skill: &str,
        param: &str,
        value: ParamValue,
    ) -> Result<(), FabricError> {
        self.set_param(skill, param, &value.to_string())
    }

    fn add_monitor(&mut self, condition: &str, _hold: u32) -> Result<u64, FabricError> {
        self.request()?;
        if condition.contains("nobody") {
            return Err(ControlError::UnknownSkill("nobody".into()).into());
        }
        self.next += 1;
        self.monitors.insert(self.next, condition.to_string());
        self.owners.insert(self.next, self.client.clone());
        Ok(self.next)
    }

    fn remove_monitor(&mut self, id: u64) {
        self.monitors.remove(&id);
    }

    fn adopt_monitors(&mut self, ids: &[u64]) -> Result<Vec<MonitorFate>, FabricError> {
        self.request()?;
        Ok(ids
            .iter()
            .map(|id| {
                if self.monitors.contains_key(id) {
                    self.owners.insert(*id, self.client.clone());
                    MonitorFate::Live
                } else if self.fired.contains(id) {
                    MonitorFate::Fired(0)
                } else {
                    MonitorFate::Gone
                }
            })
            .collect())
    }

    fn monitors(&mut self) -> Result<Vec<(u64, String)>, FabricError> {
        self.request()?;
        Ok(self
            .monitors
            .keys()
            .map(|id| (*id, self.owners[id].clone()))
            .collect())
    }

    fn gave_up(&mut self) -> Result<Vec<String>, FabricError> {
        self.request()?;
        Ok(self.gave_up.clone())
    }

    fn now(&mut self) -> Duration {
        self.now
    }

    fn report_plan(&mut self, report: PlanReport) -> Result<(), FabricError> {
        self.reports.push(report.clone());
        match report {
            PlanReport::Shape {
                plan,
                nodes,
                status,
                ..
            } => {
                let status = status.into_iter().map(|s| (s, 0)).collect::<Vec<_>>();
                match &mut self.tree {
                    Some(t) if nodes.first().is_some_and(|n| n.id > 0) => {
                        t.nodes.extend(nodes);
                        t.status.extend(status);
                    }
                    _ => {
                        self.tree = Some(PlanTree {
                            plan,
                            nodes,
                            status,
                        })
                    }
                }
            }
            PlanReport::Tick {
                plan,
                changes,
                ended,
            } => {
                let Some(t) = self.tree.as_mut().filter(|t| t.plan == plan) else {
                    return Err(ControlError::PlanNotCurrent {
                        plan,
                        current: self.tree.as_ref().map(|t| t.plan.clone()),
                    }
                    .into());
                };
                t.apply(&changes, self.now.as_millis() as u64)
                    .map_err(|id| ControlError::UnknownPlanNode {
                        plan: plan.clone(),
                        id,
                        nodes: t.nodes.len() as u32,
                    })?;
                if ended {
                    self.tree = None;
                }
            }
        }
        Ok(())
    }

    fn current_plan(&mut self) -> Result<Option<PlanTree>, FabricError> {
        Ok(self.tree.clone())
    }
}

fn plan(body: &str) -> Plan {
    let text =
        format!(r#"<root BTCPP_format="4"><BehaviorTree ID="Main">{body}</BehaviorTree></root>"#);
    Plan::parse(&text, "test.xml").unwrap_or_else(|e| panic!("{e}"))
}

/// A monitor firing, as the manager's event says it (a `Once` monitor is then gone).
fn fire(seq: &mut Sequencer, f: &mut Mock, id: u64) {
    f.monitors.remove(&id);
    f.fired.push(id);
    let ev = skillfab_proto::control::EventKind::MonitorFired {
        id,
        client: f.owners.get(&id).cloned().unwrap_or_else(|| "me".into()),
        expr: String::new(),
        values: Vec::new(),
        stamp_ns: 0,
    };
    assert!(seq.on_event(&f.client, &ev));
}

#[test]
fn wait_gave_up_knows_a_give_up_from_before_the_runner_and_hears_one_after() {
    let p = plan(
        r#"<Sequence>
             <WaitGaveUp process="denning"/>
             <WaitGaveUp process="wander"/>
             <Activate skills="avoid"/>
           </Sequence>"#,
    );
    let mut f = Mock::new(&["wander", "avoid"]);
    // `up` gave up on the device before this runner started: its event went by unheard.
    f.gave_up = vec!["denning".into()];
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    let ev = skillfab_proto::control::EventKind::ProcessGaveUp {
        process: "wander".into(),
        restarts: 5,
        status: "signal 9".into(),
    };
    assert!(seq.on_event("me", &ev));
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
    assert_eq!(f.on(), ["avoid"]);
}

#[test]
fn want_and_release_are_actions_on_the_skills_they_name() {
    let p = plan(
        r#"<Sequence>
             <Want skills="wander, avoid"/>
             <Release skills="wander"/>
           </Sequence>"#,
    );
    let mut f = Mock::new(&["wander", "avoid"]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
    assert_eq!(f.on(), ["avoid"]);
    let text = r#"<root BTCPP_format="4"><BehaviorTree ID="Main"><Want skill="wander"/></BehaviorTree></root>"#;
    let err = Plan::parse(text, "test.xml").unwrap_err();
    assert!(err.reason.contains("skills"), "{err}");
}

#[test]
fn a_sequence_activates_waits_for_its_monitor_and_goes_on() {
    let p = plan(
        r#"<Sequence>
             <Activate skills="wander, avoid"/>
             <WaitFor condition="barcode_track.target.seen == 1"/>
             <Deactivate skills="wander"/>
           </Sequence>"#,
    );
    let mut f = Mock::new(&["wander", "avoid"]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(f.on(), ["avoid", "wander"]);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    let id = f.monitor("barcode_track.target.seen == 1");
    // Another client's monitor is not this plan's.
    let other = skillfab_proto::control::EventKind::MonitorFired {
        id,
        client: "someone-else".into(),
        expr: String::new(),
        values: Vec::new(),
        stamp_ns: 0,
    };
    assert!(!seq.on_event("me", &other));
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    fire(&mut seq, &mut f, id);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
    assert_eq!(f.on(), ["avoid"]);
    assert_eq!(
        seq.take_steps(),
        [
            "activate wander, avoid",
            "WaitFor: barcode_track.target.seen == 1",
            "deactivate wander"
        ]
    );
}

#[test]
fn the_first_branch_of_a_parallel_to_finish_halts_the_other_and_a_param_is_restored() {
    // The exit-lab pattern: search along the wall while watching for the door; the door
    // found first halts the search (its monitor removed, its parameter restored).
    let p = plan(
        r#"<Parallel success_count="1" failure_count="1">
             <WaitFor name="door" condition="door_locate.door.found == 1"/>
             <WithParam skill="avoid" param="safe_distance" value="0.3">
               <WaitFor name="far" condition="barcode_track.target.range > 4.0"/>
             </WithParam>
           </Parallel>"#,
    );
    let mut f = Mock::new(&[]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(f.params["avoid.safe_distance"], 0.3);
    assert_eq!(f.monitors.len(), 2);
    let door = f.monitor("door_locate.door.found == 1");
    fire(&mut seq, &mut f, door);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
    assert!(f.monitors.is_empty(), "{:?}", f.monitors);
    assert_eq!(f.params["avoid.safe_distance"], 0.6);
    let steps = seq.take_steps();
    assert!(
        steps.contains(&"avoid.safe_distance restored to 0.6".to_string()),
        "{steps:?}"
    );
}

#[test]
fn a_timeout_halts_its_child_in_fabric_time_and_a_fallback_takes_the_next_way() {
    let p = plan(
        r#"<Fallback>
             <Timeout msec="2000"><WaitFor condition="x.y.z == 1"/></Timeout>
             <Activate skills="home"/>
           </Fallback>"#,
    );
    let mut f = Mock::new(&["home"]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    f.now = Duration::from_millis(1999);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    f.now = Duration::from_millis(2000);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
    assert!(f.monitors.is_empty());
    assert_eq!(f.on(), ["home"]);
}

#[test]
fn a_refused_request_fails_its_node_and_a_retry_tries_again_up_to_its_attempts() {
    let p = plan(
        r#"<RetryUntilSuccessful num_attempts="3"><Activate skills="nobody"/></RetryUntilSuccessful>"#,
    );
    let mut f = Mock::new(&[]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Failure);
    let steps = seq.take_steps();
    assert!(
        steps[0].contains("activate nobody: refused: unknown skill 'nobody'"),
        "{steps:?}"
    );
    // A monitor on something that is not there fails its WaitFor the same way.
    let p = plan(r#"<Inverter><WaitFor condition="nobody.x.y == 1"/></Inverter>"#);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
}

#[test]
fn subtrees_sleep_and_force() {
    let text = r#"<root BTCPP_format="4" main_tree_to_execute="Main">
      <BehaviorTree ID="Main">
        <Sequence>
          <SubTree ID="Pause"/>
          <ForceSuccess><AlwaysFailure/></ForceSuccess>
          <Action ID="Log" message="done"/>
        </Sequence>
      </BehaviorTree>
      <BehaviorTree ID="Pause"><Sleep msec="500"/></BehaviorTree>
    </root>"#;
    let p = Plan::parse(text, "t.xml").unwrap();
    let mut f = Mock::new(&[]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    f.now = Duration::from_millis(500);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
    assert_eq!(seq.take_steps(), ["done"]);
    // The other tree alone.
    let mut pause = Sequencer::new(&p, Some("Pause")).unwrap();
    assert_eq!(pause.tick(&mut f).unwrap(), Status::Running);
    assert!(Sequencer::new(&p, Some("Nope")).is_err());
}

#[test]
fn a_plan_with_mistakes_is_refused_with_the_line_and_what_is_wrong() {
    let cases = [
        (
            "<root BTCPP_format=\"4\"><BehaviorTree ID=\"A\">\n<Sequnce/></BehaviorTree></root>",
            2,
            "unknown node <Sequnce>",
        ),
        (
            "<root BTCPP_format=\"4\"><BehaviorTree ID=\"A\">\n<Timeout><AlwaysSuccess/></Timeout></BehaviorTree></root>",
            2,
            "needs msec",
        ),
        (
            "<root BTCPP_format=\"4\"><BehaviorTree ID=\"A\">\n<Inverter/></BehaviorTree></root>",
            2,
            "exactly one child",
        ),
        (
            "<root BTCPP_format=\"4\"><BehaviorTree ID=\"A\">\n<WaitFor hold=\"x\" condition=\"a.b.c\"/></BehaviorTree></root>",
            2,
            "hold=\"x\"",
        ),
        (
            "<root BTCPP_format=\"4\"><BehaviorTree ID=\"A\"><SubTree ID=\"A\"/></BehaviorTree></root>",
            1,
            "contains itself",
        ),
        (
            "<root BTCPP_format=\"4\"><BehaviorTree ID=\"A\"><SubTree ID=\"B\"/></BehaviorTree></root>",
            1,
            "no tree has that ID",
        ),
        ("<root BTCPP_format=\"3\"/>", 1, "only format 4"),
        (
            "<root BTCPP_format=\"4\"><BehaviorTree ID=\"A\">\n<Sequence a=\"1></BehaviorTree></root>",
            2,
            "not well-formed XML",
        ),
        (
            "<root BTCPP_format=\"4\"><BehaviorTree ID=\"A\"><AlwaysSuccess/></BehaviorTree><BehaviorTree ID=\"B\"><AlwaysSuccess/></BehaviorTree></root>",
            1,
            "no main_tree_to_execute",
        ),
        (
            "<root BTCPP_format=\"4\"><BehaviorTree ID=\"A\">\n<Parallel success_count=\"3\"><AlwaysSuccess/></Parallel></BehaviorTree></root>",
            2,
            "1 to 1",
        ),
    ];
    for (text, line, reason) in cases {
        let e = Plan::parse(text, "bad.xml").unwrap_err();
        assert_eq!(e.line, line, "{e}");
        assert!(e.reason.contains(reason), "{e} (wanted: {reason})");
        assert!(
            e.to_string().starts_with(&format!("bad.xml:{line}: ")),
            "{e}"
        );
    }
}

#[test]
fn the_shipped_exit_lab_plan_searches_both_ways_then_goes_through_with_a_lowered_distance() {
    let text = include_str!("../../../skills/plans/exit-lab.xml");
    let p = Plan::parse(text, "exit-lab.xml").unwrap();
    let skills = [
        "explore",
        "avoid",
        "barcode_track",
        "home",
        "door_locate",
        "wall_follow",
        "go_through",
    ];
    let mut f = Mock::new(&skills);
    f.params.insert("wall_follow.side".into(), 1.0);
    f.params.insert("avoid.beside".into(), 10.0);
    let mut seq = Sequencer::new(&p, None).unwrap();
    let step = |f: &mut Mock, seq: &mut Sequencer, fired: Option<&str>| {
        if let Some(c) = fired {
            let id = f.monitor(c);
            fire(seq, f, id);
        }
        assert_eq!(seq.tick(f).unwrap(), Status::Running);
    };
    step(&mut f, &mut seq, None);
    assert_eq!(f.on(), ["avoid", "barcode_track", "explore"]);
    // explore and home drive through gaps: echoes beside the way pass.
    assert_eq!(f.params["avoid.beside"], 0.15);
    step(&mut f, &mut seq, Some("barcode_track.target.seen == 1"));
    assert_eq!(f.on(), ["avoid", "barcode_track", "door_locate", "home"]);
    assert_eq!(f.params["avoid.beside"], 0.15);
    step(&mut f, &mut seq, Some("barcode_track.target.range < 1.7"));
    assert_eq!(
        f.on(),
        ["avoid", "barcode_track", "door_locate", "wall_follow"]
    );
    assert_eq!(f.params["wall_follow.side"], -1.0);
    // Along the wall every echo counts.
    assert_eq!(f.params["avoid.beside"], 10.0);
    step(&mut f, &mut seq, Some("barcode_track.target.range > 4.0"));
    assert_eq!(f.on(), ["avoid", "barcode_track", "door_locate", "home"]);
    step(&mut f, &mut seq, Some("barcode_track.target.range < 1.7"));
    assert_eq!(f.params["wall_follow.side"], 1.0);
    step(&mut f, &mut seq, Some("door_locate.door.found == 1"));
    assert_eq!(
        f.on(),
        ["avoid", "barcode_track", "door_locate", "go_through"]
    );
    assert_eq!(f.params["avoid.safe_distance"], 0.2);
    assert_eq!(f.params["avoid.beside"], 10.0);
    // Only the door's monitor was left, and it fired: none stays behind.
    assert!(f.monitors.is_empty(), "{:?}", f.monitors);
    // Halted (the robot is outside): the distance comes back.
    seq.halt(&mut f);
    assert_eq!(f.params["avoid.safe_distance"], 0.6);
}

#[test]
fn the_earliest_running_timer_is_the_plans_deadline() {
    let p = plan(
        r#"<Parallel success_count="1">
             <Timeout msec="5000"><WaitFor condition="a.b.c == 1"/></Timeout>
             <Sequence><Sleep msec="2000"/><Sleep msec="9000"/></Sequence>
           </Parallel>"#,
    );
    let mut f = Mock::new(&[]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.deadline(), None, "no timer runs before the first tick");
    f.now = Duration::from_millis(1000);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(seq.deadline(), Some(Duration::from_millis(3000)));
    // The first sleep over, the next one and the timeout remain.
    f.now = Duration::from_millis(3000);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(seq.deadline(), Some(Duration::from_millis(6000)));
    f.now = Duration::from_millis(6000);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Failure);
    assert_eq!(seq.deadline(), None, "halted timers are not due");
}

#[test]
fn a_parallel_decides_as_soon_as_it_can_and_the_later_children_do_not_act() {
    // The door and "near the barcode" fire in the same cycle: the door (first) decides, and
    // the search branch is halted before it reacts.
    let p = plan(
        r#"<Parallel success_count="1" failure_count="1">
             <WaitFor name="door" condition="door == 1"/>
             <Sequence>
               <WaitFor name="near" condition="near == 1"/>
               <Activate skills="wall_follow"/>
             </Sequence>
           </Parallel>"#,
    );
    let mut f = Mock::new(&["wall_follow"]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    let (door, near) = (f.monitor("door == 1"), f.monitor("near == 1"));
    fire(&mut seq, &mut f, door);
    fire(&mut seq, &mut f, near);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
    assert!(f.on().is_empty(), "the search reacted: {:?}", f.on());

    // All must succeed and all may fail: one success and one failure can no longer succeed.
    let p = plan(
        r#"<Parallel success_count="-1" failure_count="-1">
             <AlwaysSuccess/><AlwaysFailure/>
           </Parallel>"#,
    );
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Failure);
}

#[test]
fn a_retry_is_due_at_once_and_a_timeout_past_its_time_does_not_tick_its_child() {
    let p = plan(
        r#"<RetryUntilSuccessful num_attempts="-1"><Activate skills="nobody"/></RetryUntilSuccessful>"#,
    );
    let mut f = Mock::new(&["home"]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(
        seq.deadline(),
        Some(Duration::ZERO),
        "a retry waits for nothing"
    );

    let p = plan(
        r#"<Timeout msec="1000"><Sequence><Sleep msec="1000"/><Activate skills="home"/></Sequence></Timeout>"#,
    );
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    f.now = Duration::from_millis(1000);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Failure);
    assert!(f.on().is_empty(), "started after its time: {:?}", f.on());
}

#[test]
fn misspelt_attributes_zero_timeouts_blackboard_keys_and_deep_nesting_are_refused() {
    let refused = |body: &str| {
        let text =
            format!("<root BTCPP_format=\"4\"><BehaviorTree ID=\"A\">{body}</BehaviorTree></root>");
        Plan::parse(&text, "p.xml").unwrap_err().reason
    };
    let e = refused(r#"<Parallel success_threshold="1"><AlwaysSuccess/></Parallel>"#);
    assert!(
        e.contains("no attribute success_threshold (it takes success_count, failure_count)"),
        "{e}"
    );
    let e = refused(r#"<Timeout msec="0"><AlwaysSuccess/></Timeout>"#);
    assert!(e.contains("at least 1"), "{e}");
    let e = refused(r#"<Sleep msec="{delay}"/>"#);
    assert!(e.contains("there is no blackboard"), "{e}");
    let e = refused(
        r#"<RetryUntilSuccessful num_attempts="4294967296"><AlwaysSuccess/></RetryUntilSuccessful>"#,
    );
    assert!(e.contains("at most 4294967295"), "{e}");
    let deep = format!(
        "{}<AlwaysSuccess/>{}",
        "<Inverter>".repeat(80),
        "</Inverter>".repeat(80)
    );
    let e = refused(&deep);
    assert!(e.contains("nested deeper than 64"), "{e}");
    // Sub-trees used twice at every level: refused by size, checked once per tree.
    let mut text = String::from("<root BTCPP_format=\"4\" main_tree_to_execute=\"T0\">");
    for i in 0..30 {
        text += &format!(
            "<BehaviorTree ID=\"T{i}\"><Sequence><SubTree ID=\"T{n}\"/><SubTree ID=\"T{n}\"/></Sequence></BehaviorTree>",
            n = i + 1
        );
    }
    text += "<BehaviorTree ID=\"T30\"><AlwaysSuccess/></BehaviorTree></root>";
    let e = Plan::parse(&text, "p.xml").unwrap_err();
    assert!(e.reason.contains("more than 100000 nodes"), "{e}");
}

/// A plan with the three nodes whose state matters most when a runner dies: a parameter set
/// for a while, a `Timeout` and a `RetryUntilSuccessful` (the door is seen on the third
/// attempt), then a `Sleep`.
const RESUMABLE: &str = r#"<Sequence>
     <Activate skills="wander"/>
     <WithParam skill="avoid" param="safe_distance" value="0.2">
       <Sequence>
         <ForceSuccess><Timeout msec="500"><WaitFor name="never" condition="never.x.y == 1"/></Timeout></ForceSuccess>
         <RetryUntilSuccessful num_attempts="5">
           <Timeout name="look" msec="300"><WaitFor name="door" condition="door.found == 1"/></Timeout>
         </RetryUntilSuccessful>
         <Sleep msec="200"/>
       </Sequence>
     </WithParam>
     <Deactivate skills="wander"/>
   </Sequence>"#;

/// Where a runner of [`RESUMABLE`] got: the tick it ended in and how, and the fabric then.
#[derive(Debug)]
struct End {
    tick: u32,
    status: Status,
    /// Requests the last runner made (not compared).
    requests: usize,
    params: BTreeMap<String, f64>,
    on: Vec<String>,
    monitors: usize,
}

/// Runs [`RESUMABLE`] one tick per 100 ms of fabric time (the door's monitor fires once it
/// is 1.5 s), its state kept in `store`. With `die_at`, the runner dies in that request to
/// the fabric (nothing more it does is kept), and another takes over.
fn run_resumable(store: &std::path::Path, die_at: Option<usize>) -> (End, Vec<String>) {
    let _ = std::fs::remove_file(store);
    let p = plan(RESUMABLE);
    let mut f = Mock::new(&["wander"]);
    f.die_at = die_at;
    let mut steps = Vec::new();
    let mut n = 1;
    f.client = format!("runner-{n}");
    let kept = |p: &Plan| {
        Sequencer::kept(
            p,
            None,
            "test.xml",
            crate::keep::PlanStore::at(store.to_path_buf()),
            false,
        )
        .unwrap()
    };
    let mut seq = kept(&p);
    let me = f.client.clone();
    seq.open(&mut f, &me).unwrap();
    for tick in 1..200 {
        f.now = Duration::from_millis(100 * u64::from(tick));
        if f.now >= Duration::from_millis(1500)
            && let Some((&id, _)) = f.monitors.iter().find(|(_, c)| *c == "door.found == 1")
        {
            fire(&mut seq, &mut f, id);
        }
        let status = match seq.tick(&mut f) {
            Ok(s) => s,
            Err(_) => {
                // This runner is dead; the next one takes over (the fabric answers again).
                f.die_at = None;
                n += 1;
                f.client = format!("runner-{n}");
                steps.extend(seq.take_steps());
                seq = kept(&p);
                let me = f.client.clone();
                seq.open(&mut f, &me).unwrap();
                seq.tick(&mut f).unwrap()
            }
        };
        steps.extend(seq.take_steps());
        if status != Status::Running {
            let end = End {
                tick,
                status,
                requests: f.requests,
                params: f.params.clone(),
                on: f.on().iter().map(|s| s.to_string()).collect(),
                monitors: f.monitors.len(),
            };
            return (end, steps);
        }
    }
    panic!("the plan did not end: {steps:#?}");
}

#[test]
fn a_runner_that_dies_anywhere_is_taken_over_and_the_plan_ends_as_an_uninterrupted_one() {
    let dir = std::env::temp_dir().join(format!("sf-plan-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let store = dir.join("plan");
    let (whole, steps) = run_resumable(&store, None);
    assert_eq!(whole.status, Status::Success, "{steps:#?}");
    assert_eq!(whole.params["avoid.safe_distance"], 0.6);
    assert_eq!(whole.monitors, 0);
    assert!(!store.exists(), "a plan that ended leaves nothing kept");
    // Dying in each request the plan makes, in turn: asking which processes `up` gave up
    // on, inside the `WithParam` (between reading the parameter and setting it, too), the
    // `Timeout`, each attempt of the retry.
    assert_eq!(whole.requests, 10, "{whole:?}");
    let same = |e: &End| (e.tick, e.status, e.params.clone(), e.on.clone(), e.monitors);
    for die_at in 1..=whole.requests {
        let (end, steps) = run_resumable(&store, Some(die_at));
        assert_eq!(
            same(&end),
            same(&whole),
            "died at request {die_at}: {steps:#?}"
        );
        assert!(
            steps
                .iter()
                .any(|s| s.starts_with("resuming test.xml (runner 2 of it)")),
            "died at request {die_at}: {steps:#?}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn another_plan_a_changed_file_or_fresh_first_undoes_what_the_last_runner_set() {
    let dir = std::env::temp_dir().join(format!("sf-plan-other-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let store = || crate::keep::PlanStore::at(dir.join("plan"));
    let p = plan(RESUMABLE);
    // Each way a kept plan is not resumed: the runner that left it had set the parameter
    // and was waiting; the next one restores it and removes its monitors, then starts over.
    let changed = plan(&RESUMABLE.replace("msec=\"200\"", "msec=\"300\""));
    let cases: [(&Plan, &str, bool, &str); 3] = [
        (
            &p,
            "other.xml",
            false,
            "another plan was running (test.xml, tree Main)",
        ),
        (
            &changed,
            "test.xml",
            false,
            "test.xml changed since its last runner",
        ),
        (&p, "test.xml", true, "--fresh"),
    ];
    for (next, file, fresh, why) in cases {
        let mut f = Mock::new(&["wander"]);
        f.client = "runner-1".into();
        let mut seq = Sequencer::kept(&p, None, "test.xml", store(), false).unwrap();
        seq.open(&mut f, "runner-1").unwrap();
        for _ in 0..3 {
            seq.tick(&mut f).unwrap();
        }
        assert_eq!(f.params["avoid.safe_distance"], 0.2);
        assert_eq!(f.monitors.len(), 1);
        drop(seq);
        f.client = "runner-2".into();
        let mut seq = Sequencer::kept(next, None, file, store(), fresh).unwrap();
        let opening = seq.open(&mut f, "runner-2").unwrap();
        assert_eq!(
            opening,
            crate::run::Opening::StartedOver { why: why.into() }
        );
        assert_eq!(f.params["avoid.safe_distance"], 0.6, "{why}");
        assert!(f.monitors.is_empty(), "{why}: {:?}", f.monitors);
        let steps = seq.take_steps();
        assert!(steps[0].contains(why), "{steps:?}");
        assert_eq!(steps[1], "avoid.safe_distance restored to 0.6");
        // It starts from its first node.
        seq.tick(&mut f).unwrap();
        assert_eq!(seq.take_steps()[0], "activate wander");
    }
    // A kept state that cannot be read: said, and the plan starts over.
    std::fs::write(dir.join("plan"), b"{not json").unwrap();
    let mut f = Mock::new(&["wander"]);
    let mut seq = Sequencer::kept(&p, None, "test.xml", store(), false).unwrap();
    let crate::run::Opening::StartedOver { why } = seq.open(&mut f, "runner-3").unwrap() else {
        panic!("resumed from garbage");
    };
    assert!(why.contains("unreadable"), "{why}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The statuses a manager holds of the plan's live tree, by node number.
fn held(f: &Mock) -> Vec<NodeStatus> {
    f.tree
        .as_ref()
        .expect("the manager has the plan")
        .status
        .iter()
        .map(|s| s.0)
        .collect()
}

/// The changes of each `Tick` report sent after the first `skip` reports.
fn ticks(f: &Mock, skip: usize) -> Vec<(Vec<PlanNodeChange>, bool)> {
    f.reports[skip..]
        .iter()
        .map(|r| match r {
            PlanReport::Tick { changes, ended, .. } => (changes.clone(), *ended),
            other => panic!("a tick's report expected: {other:?}"),
        })
        .collect()
}

fn ch(id: u32, status: NodeStatus) -> PlanNodeChange {
    PlanNodeChange { id, status }
}

#[test]
fn the_live_tree_is_sent_once_then_only_what_each_tick_changed() {
    use NodeStatus::*;
    let p = plan(
        r#"<Sequence name="mission">
             <Activate skills="wander, avoid"/>
             <WaitFor name="seen" condition="barcode_track.target.seen == 1"/>
             <Log message="seen"/>
           </Sequence>"#,
    );
    let mut f = Mock::new(&["wander", "avoid"]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    let shape = seq.live().shape().to_vec();
    let described: Vec<(u32, Option<u32>, &str, &str, &str)> = shape
        .iter()
        .map(|n| {
            (
                n.id,
                n.parent,
                n.name.as_str(),
                n.kind.as_str(),
                n.detail.as_str(),
            )
        })
        .collect();
    assert_eq!(
        described,
        [
            (0, None, "mission", "Sequence", ""),
            (1, Some(0), "Activate", "Activate", "wander, avoid"),
            (
                2,
                Some(0),
                "seen",
                "WaitFor",
                "barcode_track.target.seen == 1"
            ),
            (3, Some(0), "Log", "Log", "seen"),
        ]
    );
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    // The shape first, every node idle; then the first tick's changes.
    let PlanReport::Shape {
        plan: name,
        total,
        nodes,
        status,
    } = &f.reports[0]
    else {
        panic!("{:?}", f.reports)
    };
    assert_eq!((name.as_str(), *total), ("Main", 4));
    assert_eq!((nodes, status), (&shape, &vec![Idle; 4]));
    assert_eq!(
        ticks(&f, 1),
        [(vec![ch(0, Running), ch(1, Success), ch(2, Running)], false)]
    );
    // A tick that changed nothing sends nothing.
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(f.reports.len(), 2);
    assert_eq!(held(&f), [Running, Success, Running, Idle]);
    let id = f.monitor("barcode_track.target.seen == 1");
    fire(&mut seq, &mut f, id);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
    assert_eq!(
        ticks(&f, 2),
        [(vec![ch(0, Success), ch(2, Success), ch(3, Success)], true)]
    );
    assert!(f.tree.is_none(), "the plan ended: the manager forgets it");
    // Nothing is reported after the end.
    seq.halt(&mut f);
    assert_eq!(f.reports.len(), 3);
}

#[test]
fn a_halted_branch_goes_idle_and_a_restarted_manager_gets_the_tree_again() {
    use NodeStatus::*;
    let p = plan(
        r#"<Parallel success_count="1">
             <WaitFor condition="door_locate.door.found == 1"/>
             <Sequence>
               <Activate skills="wander"/>
               <Sleep msec="5000"/>
             </Sequence>
           </Parallel>"#,
    );
    let mut f = Mock::new(&["wander"]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(held(&f), [Running, Running, Running, Success, Running]);
    // The manager restarted: it has no plan; the next change brings the whole tree again,
    // with the statuses as they are.
    f.tree = None;
    let sent = f.reports.len();
    f.now = Duration::from_secs(1);
    let id = f.monitor("door_locate.door.found == 1");
    fire(&mut seq, &mut f, id);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
    assert!(matches!(f.reports[sent], PlanReport::Tick { .. }));
    assert!(
        matches!(&f.reports[sent + 1], PlanReport::Shape { status, .. } if *status == [Success, Success, Idle, Idle, Idle]),
        "{:?}",
        &f.reports[sent..]
    );
    // The halted sequence and all below it are idle, as if never ticked; the end follows.
    assert_eq!(ticks(&f, sent + 2), [(vec![], true)]);
    assert!(f.tree.is_none());
}

#[test]
fn halting_a_plan_on_ctrl_c_leaves_every_node_idle_and_ends_it() {
    use NodeStatus::*;
    let p = plan(
        r#"<Sequence>
             <Activate skills="wander"/>
             <Sleep msec="5000"/>
           </Sequence>"#,
    );
    let mut f = Mock::new(&["wander"]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    assert_eq!(held(&f), [Running, Success, Running]);
    let sent = f.reports.len();
    seq.halt_and_end(&mut f);
    assert_eq!(
        ticks(&f, sent),
        [(vec![ch(0, Idle), ch(1, Idle), ch(2, Idle)], true)]
    );
    assert_eq!(seq.live().status(), [Idle; 3]);
}

#[test]
fn a_refused_report_stops_the_reports_not_the_plan() {
    let p = plan(r#"<Sequence><Activate skills="wander"/><Sleep msec="5000"/></Sequence>"#);
    let mut f = Mock::new(&["wander"]);
    let mut seq = Sequencer::new(&p, None).unwrap();
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    // Another runner's plan replaced this one.
    f.tree.as_mut().unwrap().plan = "other.xml".into();
    let sent = f.reports.len();
    f.now = Duration::from_secs(6);
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Success);
    assert_eq!(f.reports.len(), sent + 1, "refused once, then no more");
    assert_eq!(f.on(), ["wander"]);
}

#[test]
fn a_large_tree_goes_in_parts_each_within_a_request_and_numbered_in_order() {
    // 3000 nodes with long details: more than one request can carry.
    let leaves: String = (0..2999)
        .map(|i| format!(r#"<Log name="step {i}" message="{}"/>"#, "x".repeat(150)))
        .collect();
    let p = plan(&format!("<Sequence>{leaves}</Sequence>"));
    let seq = Sequencer::new(&p, None).unwrap();
    let live = seq.live();
    let parts = crate::live::shape_parts(live.plan(), live.shape(), live.status());
    assert!(parts.len() > 1, "{} part(s)", parts.len());
    let mut next = 0;
    for part in &parts {
        let bytes = skillfab_proto::control::encode_request(
            "123456-7",
            u64::MAX,
            &skillfab_proto::control::Request::Plan(part.clone()),
        )
        .unwrap();
        assert!(bytes.len() <= skillfab_proto::control::MAX_REQUEST_BYTES);
        let PlanReport::Shape { nodes, total, .. } = part else {
            panic!("{part:?}")
        };
        assert_eq!(*total, 3000);
        for n in nodes {
            assert_eq!(n.id, next);
            next += 1;
        }
    }
    assert_eq!(next, 3000);
    assert_eq!(
        crate::live::changes(
            &[NodeStatus::Idle, NodeStatus::Running, NodeStatus::Success],
            &[
                NodeStatus::Running,
                NodeStatus::Running,
                NodeStatus::Failure
            ],
        ),
        [ch(0, NodeStatus::Running), ch(2, NodeStatus::Failure)]
    );
}

#[test]
fn sub_trees_are_inlined_in_the_shape_under_the_node_that_names_them() {
    let text = r#"<root BTCPP_format="4" main_tree_to_execute="Main">
        <BehaviorTree ID="Main"><Sequence><SubTree ID="Search"/><Log message="done"/></Sequence></BehaviorTree>
        <BehaviorTree ID="Search"><Fallback name="search"><Sleep msec="10"/><AlwaysFailure/></Fallback></BehaviorTree>
      </root>"#;
    let p = Plan::parse(text, "sub.xml").unwrap();
    let seq = Sequencer::new(&p, None).unwrap();
    let shape: Vec<(u32, Option<u32>, &str)> = seq
        .live()
        .shape()
        .iter()
        .map(|n| (n.id, n.parent, n.kind.as_str()))
        .collect();
    assert_eq!(
        shape,
        [
            (0, None, "Sequence"),
            (1, Some(0), "Fallback"),
            (2, Some(1), "Sleep"),
            (3, Some(1), "AlwaysFailure"),
            (4, Some(0), "Log"),
        ]
    );
}

#[test]
fn a_runner_that_takes_a_plan_over_goes_on_from_the_live_tree_its_predecessor_reported() {
    use NodeStatus::*;
    let dir = std::env::temp_dir().join(format!("sf-plan-live-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let store = || crate::keep::PlanStore::at(dir.join("plan"));
    let p = plan(RESUMABLE);
    let mut f = Mock::new(&["wander"]);
    f.client = "runner-1".into();
    let mut seq = Sequencer::kept(&p, None, "test.xml", store(), false).unwrap();
    seq.open(&mut f, "runner-1").unwrap();
    seq.tick(&mut f).unwrap();
    let before = held(&f);
    assert_eq!(before[0], Running);
    assert_eq!(before[1], Success, "the Activate");
    assert_eq!(f.tree.as_ref().unwrap().plan, "test.xml");
    drop(seq);
    // The next runner sends the same tree with the statuses the manager has: nothing it
    // did not do itself changes; its first tick changes nothing either (the same nodes run).
    f.client = "runner-2".into();
    let mut seq = Sequencer::kept(&p, None, "test.xml", store(), false).unwrap();
    let sent = f.reports.len();
    assert!(matches!(
        seq.open(&mut f, "runner-2").unwrap(),
        crate::run::Opening::Resumed { .. }
    ));
    assert_eq!(seq.tick(&mut f).unwrap(), Status::Running);
    let PlanReport::Shape { status, .. } = &f.reports[sent] else {
        panic!("{:?}", &f.reports[sent..])
    };
    assert_eq!(*status, before);
    assert_eq!(f.reports.len(), sent + 1, "{:?}", &f.reports[sent..]);
    assert_eq!(held(&f), before);
    let _ = std::fs::remove_dir_all(&dir);
}
