//! `skillfab sequence`: plans run against a hello network (real processes, real iceoryx2) —
//! success, failure and halting, with exit status, steps, parameters and monitors checked on
//! the manager; a plan with a mistake refused with its line. The exit-lab plan drives the
//! simulated robot in `exit_lab::`.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use skillfab_client::Client;
use skillfab_proto::control::{EventKind, NodeStatus, SkillState};
use skillfab_proto::param::ParamValue;
use skillfab_tests::TestDomain;
use std::path::{Path, PathBuf};
use std::process::{Output, Stdio};

fn plan(t: &TestDomain, body: &str) -> PathBuf {
    let path = t.dir.join("plan.xml");
    std::fs::write(
        &path,
        format!("<root BTCPP_format=\"4\">\n<BehaviorTree ID=\"Main\">\n{body}\n</BehaviorTree>\n</root>\n"),
    )
    .unwrap();
    path
}

fn sequence(t: &TestDomain, plan: &Path) -> (Output, String) {
    let out = t.run("skillfab", &["sequence", plan.to_str().unwrap()]);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out, text)
}

fn state(c: &Client, skill: &str) -> SkillState {
    c.list()
        .unwrap()
        .into_iter()
        .find(|s| s.name == skill)
        .unwrap()
        .state
}

#[test]
fn a_plan_waits_times_out_falls_back_and_succeeds_and_a_refused_step_fails_it() {
    let mut t = TestDomain::new("seqrun");
    t.hello(&[]);
    let c = Client::connect(&t.domain).unwrap();
    let p = plan(
        &t,
        r#"<Sequence>
             <Deactivate skills="smooth"/>
             <WaitFor name="ticking" condition="ticker.tick.value &gt; 20"/>
             <Fallback>
               <Timeout msec="300"><WaitFor name="never" condition="ticker.tick.value &lt; 0"/></Timeout>
               <Log message="gave up waiting: the other way"/>
             </Fallback>
             <SetParam skill="scale" param="gain" value="3"/>
           </Sequence>"#,
    );
    let (out, text) = sequence(&t, &p);
    assert!(out.status.success(), "{text}");
    for step in [
        "deactivate smooth",
        "ticking: ticker.tick.value > 20",
        "Timeout: timed out after 300 ms",
        "gave up waiting: the other way",
        "scale.gain = 3",
        "the plan succeeded",
    ] {
        assert!(text.contains(step), "no '{step}' in:\n{text}");
    }
    assert_eq!(state(&c, "smooth"), SkillState::Inactive);
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(3.0)
    );
    // The timed-out monitor was removed; the one that fired is gone.
    assert!(c.monitors().unwrap().is_empty());

    // A step the manager refuses fails the plan: exit status 1, the reason word for word.
    let p = plan(
        &t,
        r#"<RetryUntilSuccessful num_attempts="2"><Activate skills="nobody"/></RetryUntilSuccessful>"#,
    );
    let (out, text) = sequence(&t, &p);
    assert!(!out.status.success(), "{text}");
    assert!(
        text.contains("activate nobody: refused: unknown skill 'nobody'")
            && text.contains("the plan failed"),
        "{text}"
    );

    // A mistake in the plan: nothing runs, the line and what is wrong are said.
    let p = plan(&t, "<Sequnce/>");
    let (out, text) = sequence(&t, &p);
    assert!(!out.status.success());
    assert!(
        text.contains("plan.xml:3: unknown node <Sequnce>"),
        "{text}"
    );
}

#[test]
fn ctrl_c_halts_a_plan_its_parameter_is_restored_and_its_monitor_removed() {
    let mut t = TestDomain::new("seqhalt");
    t.hello(&[]);
    let c = Client::connect(&t.domain).unwrap();
    let p = plan(
        &t,
        r#"<WithParam skill="scale" param="gain" value="7">
             <WaitFor name="never" condition="ticker.tick.value &lt; 0"/>
           </WithParam>"#,
    );
    let child = t
        .command("skillfab")
        .args(["sequence", p.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    t.wait_until("the plan to set the gain and install its monitor", || {
        c.get_param("scale", "gain").unwrap() == ParamValue::Float(7.0)
            && c.monitors().unwrap().len() == 1
    });
    kill(Pid::from_raw(child.id() as i32), Signal::SIGINT).unwrap();
    let out = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains("scale.gain restored to 2") && text.contains("halted"),
        "{text}"
    );
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(2.0)
    );
    assert!(c.monitors().unwrap().is_empty());
}

#[test]
fn in_lock_step_a_plans_timers_end_in_the_same_cycle_every_run() {
    let mut t = TestDomain::new("seqlock");
    t.hello_registered(&["--lockstep", "--paused"]);
    // The period is 5 ms: 500 ms are 100 cycles, 250 ms 50. The manager waits for the plan
    // (`--paused`), and is stepped exactly to each timer.
    let p = plan(
        &t,
        r#"<Sequence>
             <Log message="start"/>
             <Sleep msec="500"/>
             <Log message="woke"/>
             <Timeout msec="250"><WaitFor condition="ticker.tick.value &lt; 0"/></Timeout>
           </Sequence>"#,
    );
    let cycle_of = |text: &str, what: &str| -> u64 {
        let line = text
            .lines()
            .find(|l| l.ends_with(what))
            .unwrap_or_else(|| panic!("no '{what}' in:\n{text}"));
        line.trim_start_matches("[cycle")
            .split(',')
            .next()
            .unwrap()
            .trim()
            .parse()
            .unwrap()
    };
    for _ in 0..2 {
        let (out, text) = sequence(&t, &p);
        assert!(!out.status.success(), "the timeout fails the plan: {text}");
        let start = cycle_of(&text, "start");
        assert_eq!(cycle_of(&text, "woke"), start + 100, "{text}");
        assert_eq!(
            cycle_of(&text, "timed out after 250 ms"),
            start + 150,
            "{text}"
        );
    }

    // A monitor that fires ends a `step` early in lock-step (its client reacts first): the
    // answer names the cycle, well before the thousand asked for.
    let c = Client::connect(&t.domain).unwrap();
    let (tick, _) = c.query("ticker.tick.value").unwrap();
    let before = c.stats().unwrap().cycles;
    let at_least = tick.as_f64().unwrap() + 20.0;
    c.add_monitor(
        &format!("ticker.tick.value > {at_least}"),
        skillfab_proto::control::MonitorMode::Once,
        0,
    )
    .unwrap();
    let at = c.step(1000).unwrap();
    assert!(
        at > before + 15 && at < before + 40,
        "stepped from {before} to {at}"
    );
}

/// A runner of `plan` started on `t`'s domain, its output read line by line as it comes.
struct Runner {
    child: std::process::Child,
    lines: std::sync::mpsc::Receiver<String>,
}

impl Runner {
    fn start(t: &TestDomain, plan: &Path) -> Runner {
        use std::io::BufRead;
        let mut child = t
            .command("skillfab")
            .args(["sequence", plan.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let out = child.stdout.take().unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for l in std::io::BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(l).is_err() {
                    break;
                }
            }
        });
        Runner { child, lines }
    }

    /// Every line until one ends with `what` (then the runner is killed with SIGKILL: it dies
    /// wherever it is) or the output ends.
    fn until(&mut self, what: Option<&str>, text: &mut String) {
        while let Ok(l) = self.lines.recv_timeout(std::time::Duration::from_secs(60)) {
            text.push_str(&l);
            text.push('\n');
            if what.is_some_and(|w| l.ends_with(w)) {
                kill(Pid::from_raw(self.child.id() as i32), Signal::SIGKILL).unwrap();
                let _ = self.child.wait();
                return;
            }
        }
        let status = self.child.wait().unwrap();
        assert!(status.success(), "{status}: {text}");
    }
}

#[test]
fn a_plan_runner_killed_inside_a_with_param_a_retry_and_a_timeout_is_resumed_to_the_same_cycle() {
    let mut t = TestDomain::new("seqkill");
    t.hello_registered(&["--lockstep", "--paused"]);
    let c = Client::connect(&t.domain).unwrap();
    c.step(5).unwrap();
    let cycle_of = |text: &str, what: &str| -> u64 {
        let line = text
            .lines()
            .find(|l| l.ends_with(what))
            .unwrap_or_else(|| panic!("no '{what}' in:\n{text}"));
        line.trim_start_matches("[cycle")
            .split(',')
            .next()
            .unwrap()
            .trim()
            .parse()
            .unwrap()
    };
    // 5 ms a cycle: each attempt times out after 40 cycles; the ticker (one a cycle) passes
    // the mark in the third. Killed after the parameter is set, after each failed attempt
    // and inside the sleep, the runners together end the plan in the cycle one runner does.
    // A runner goes on pacing the manager until the kill lands, so each is killed while the
    // test holds the fabric at the cycle its line is said in (`holds`: that many cycles after
    // the start): where each runner dies is the same every run, however loaded the host.
    let run = |kills: &[&str], holds: &[u64]| -> (u64, String) {
        // The manager waits for the plan: the ticker's value now is where it starts.
        let tick = c.query("ticker.tick.value").unwrap().0.as_f64().unwrap() as u64;
        let p = plan(
            &t,
            &format!(
                r#"<Sequence>
                     <Log message="start"/>
                     <WithParam skill="scale" param="gain" value="7">
                       <Sequence>
                         <RetryUntilSuccessful num_attempts="4">
                           <Timeout name="look" msec="200"><WaitFor name="mark" condition="ticker.tick.value &gt; {}"/></Timeout>
                         </RetryUntilSuccessful>
                         <Log message="marked"/>
                         <Sleep name="rest" msec="100"/>
                       </Sequence>
                     </WithParam>
                     <Log message="done"/>
                   </Sequence>"#,
                tick + 100
            ),
        );
        let mut text = String::new();
        // The manager stays paused where the last plan ended: the plan starts there.
        let at = c.stats().unwrap().cycles;
        for (k, h) in kills.iter().zip(holds) {
            c.hold(Some(at + h)).unwrap();
            Runner::start(&t, &p).until(Some(k), &mut text);
            assert_eq!(cycle_of(&text, "start"), at, "{text}");
        }
        c.hold(None).unwrap();
        Runner::start(&t, &p).until(None, &mut text);
        let start = cycle_of(&text, "start");
        (cycle_of(&text, "done") - start, text)
    };
    let kills = [
        "scale.gain = 7 while Sequence (was 2)",
        "look: timed out after 200 ms",
        "RetryUntilSuccessful: attempt 2 failed; again",
        "marked",
    ];
    let (whole, text) = run(&[], &[]);
    assert!(whole > 100, "{text}");
    // Where each kill lands: the cycle its line is first said in, counted from the start.
    let holds: Vec<u64> = kills
        .iter()
        .map(|k| cycle_of(&text, k) - cycle_of(&text, "start"))
        .collect();
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(2.0)
    );
    let (killed, text) = run(&kills, &holds);
    assert_eq!(killed, whole, "{text}");
    for (k, h) in kills.iter().zip(&holds) {
        assert_eq!(cycle_of(&text, k) - cycle_of(&text, "start"), *h, "{text}");
    }
    assert_eq!(text.matches("resuming").count(), 4, "{text}");
    // What the plan set is restored, and no runner left a monitor behind.
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(2.0)
    );
    assert!(c.monitors().unwrap().is_empty(), "{text}");
}

/// The pids of the processes whose command line holds `needle`.
fn pids_with(needle: &str) -> Vec<i32> {
    std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<i32>().ok())
        .filter(|pid| {
            std::fs::read(format!("/proc/{pid}/cmdline"))
                .is_ok_and(|c| String::from_utf8_lossy(&c).contains(needle))
        })
        .collect()
}

#[test]
fn up_supervises_a_plan_a_killed_runner_is_restarted_and_resumes_and_a_plan_that_ended_is_not() {
    let mut t = TestDomain::new("sequp");
    std::fs::write(
        t.dir.join("up-plan.xml"),
        r#"<root BTCPP_format="4"><BehaviorTree ID="Main">
             <Sequence>
               <WithParam skill="scale" param="gain" value="7">
                 <WaitFor name="later" condition="ticker.tick.value &gt; 600"/>
               </WithParam>
               <Log message="done"/>
             </Sequence>
           </BehaviorTree></root>"#,
    )
    .unwrap();
    let launch = t.launch_file(&format!(
        "{}[plan]\nfile = \"up-plan.xml\"\n",
        skillfab_tests::HELLO
    ));
    let up = t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let c = loop {
        if let Ok(c) = Client::connect(&t.domain) {
            break c;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let gain = |c: &Client| c.get_param("scale", "gain").ok();
    t.wait_until("the plan to set scale.gain", || {
        gain(&c) == Some(ParamValue::Float(7.0))
    });
    let runners = pids_with("up-plan.xml");
    assert_eq!(runners.len(), 1, "{runners:?}");
    kill(Pid::from_raw(runners[0]), Signal::SIGKILL).unwrap();
    // Restarted by `up`, the plan goes on waiting (the parameter stays set), then ends and
    // restores the value from before the plan — one started afresh would read 7 as it.
    t.wait_until("the resumed plan to end", || {
        gain(&c) == Some(ParamValue::Float(2.0))
    });
    let log = || std::fs::read_to_string(t.dir.join(format!("{up}-skillfab.log"))).unwrap();
    t.wait_until("up to see the plan finish", || {
        log().contains("process finished process=plan")
    });
    let log = log();
    assert!(
        log.contains("process exited; restarting process=plan"),
        "{log}"
    );
    assert!(c.monitors().unwrap().is_empty());
    assert!(pids_with("up-plan.xml").is_empty());
}

#[test]
fn when_up_gives_up_on_a_crashing_process_an_event_says_so_a_plan_reacts_and_a_later_runner_knows()
{
    let mut t = TestDomain::new("seqgaveup");
    // A process that fails at once, every time: restarted twice (1 s, then 2 s later), then
    // given up.
    let launch = t.launch_file(&format!(
        "{}[[process]]\nname = \"crasher\"\nbin = \"false\"\nregisters = false\n\
         max_restarts = 2\nbackoff_ms = 1000\n",
        skillfab_tests::HELLO
    ));
    t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let board = t.board();
    t.wait_until("the hello network to register", || {
        ["ticker", "scale", "smooth"]
            .iter()
            .all(|n| skillfab_tests::registered(&board, n).is_some())
    });
    let mut c = Client::connect(&t.domain).unwrap();
    c.subscribe().unwrap();
    // The plan watches for it beside its work, and takes another way when it comes.
    let p = plan(
        &t,
        r#"<Fallback>
             <Parallel success_count="1" failure_count="1">
               <WaitFor name="work" condition="ticker.tick.value &lt; 0"/>
               <Inverter><WaitGaveUp name="crasher gone" process="crasher"/></Inverter>
             </Parallel>
             <SetParam skill="scale" param="gain" value="9"/>
           </Fallback>"#,
    );
    let (out, text) = sequence(&t, &p);
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains("crasher gone: skillfab up gave up restarting crasher"),
        "{text}"
    );
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(9.0)
    );
    // Every client heard it.
    let mut heard = None;
    while let Some(e) = c.next_event(std::time::Duration::from_secs(1)).unwrap() {
        if let skillfab_proto::control::EventKind::ProcessGaveUp {
            process, restarts, ..
        } = e.kind
        {
            heard = Some((process, restarts));
            break;
        }
    }
    assert_eq!(heard, Some(("crasher".to_string(), 2)));
    assert!(c.monitors().unwrap().is_empty(), "{text}");

    // The manager lists it for a client that was not there to hear it: a runner started
    // after the event goes past the same leaf at once.
    let listed: Vec<(String, u32)> = c
        .gave_up()
        .unwrap()
        .into_iter()
        .map(|g| (g.process, g.restarts))
        .collect();
    assert_eq!(listed, [("crasher".to_string(), 2)]);
    let later = plan(
        &t,
        r#"<Sequence>
             <WaitGaveUp name="crasher gone before" process="crasher"/>
             <SetParam skill="scale" param="gain" value="4"/>
           </Sequence>"#,
    );
    let (out, text) = sequence(&t, &later);
    assert!(out.status.success(), "{text}");
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(4.0)
    );
}

/// `skillfab sequence FILE --check ARGS`: exit status and what it printed.
fn check(t: &TestDomain, file: &Path, args: &[&str]) -> (bool, String) {
    let out = t.run(
        "skillfab",
        &[&["sequence", file.to_str().unwrap(), "--check"], args].concat(),
    );
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

#[test]
fn a_plans_names_are_checked_against_a_launch_files_skills_and_a_running_domain() {
    let mut t = TestDomain::new("seqcheck");
    let root = skillfab_tests::repo_root();
    let launch = |name: &str| root.join("skills/launch").join(name);
    // The shipped plans fit the skills they drive.
    for (plan, l) in [
        ("exit-lab.xml", "exit-lab.toml"),
        ("deliver.xml", "deliver.toml"),
    ] {
        let file = root.join("skills/plans").join(plan);
        let (ok, text) = check(&t, &file, &["--launch", launch(l).to_str().unwrap()]);
        assert!(
            ok && text.contains("every skill, parameter, output and field"),
            "{text}"
        );
    }
    // Each kind of mistake, with its line, all of them at once.
    let bad = plan(
        &t,
        r#"<Sequence>
             <Activate skills="explore, avoid, barcode_trak"/>
             <SetParam skill="avoid" param="safe_distanse" value="0.3"/>
             <SetParam skill="avoid" param="safe_distance" value="-4"/>
             <WaitFor condition="barcode_track.targt.seen == 1"/>
             <WaitFor condition="barcode_track.target.sen == 1"/>
             <WaitFor condition="denning.sonar.range &lt; 0.3"/>
             <WaitFor condition="min(denning.sonar.range[0..3]) &lt; 0.25"/>
             <WaitGaveUp process="denningg"/>
           </Sequence>"#,
    );
    let (ok, text) = check(
        &t,
        &bad,
        &["--launch", launch("exit-lab.toml").to_str().unwrap()],
    );
    assert!(!ok, "{text}");
    for (line, what) in [
        (4, "no skill 'barcode_trak'"),
        (5, "unknown parameter 'safe_distanse'"),
        (6, "'safe_distance' = -4 is out of range"),
        (7, "has no output 'targt' (outputs: target)"),
        (8, "has no field 'sen'"),
        (9, "names more than one number"),
        (11, "no process 'denningg' in the launch file"),
    ] {
        let at = format!("plan.xml:{line}:");
        assert!(
            text.lines().any(|l| l.contains(&at) && l.contains(what)),
            "line {line}: {what}\n{text}"
        );
    }
    assert!(
        !text.contains("plan.xml:10:"),
        "min() over a range is fine: {text}"
    );
    assert!(text.contains("7 name(s) of the plan do not fit"), "{text}");

    // Without --launch: the running domain's skills, as they registered.
    let (ok, text) = check(&t, &bad, &[]);
    assert!(
        ok && text.contains("not checked"),
        "no manager, no check: {text}"
    );
    t.hello(&[]);
    let good = plan(
        &t,
        r#"<Sequence>
             <WithParam skill="scale" param="gain" value="3">
               <WaitFor condition="smooth.smoothed.value &gt; 10"/>
             </WithParam>
           </Sequence>"#,
    );
    let (ok, text) = check(&t, &good, &[]);
    assert!(ok && text.contains("registered in domain"), "{text}");
    let renamed = plan(&t, r#"<WaitFor condition="smooth.smoothd.value &gt; 10"/>"#);
    let (ok, text) = check(&t, &renamed, &[]);
    assert!(!ok && text.contains("has no output 'smoothd'"), "{text}");
}

/// The plan of `the_running_plan_is_a_live_tree_…`, by node number: (name, status it ends
/// with, whether it runs for a while before it ends).
const LIVE_NODES: [(&str, NodeStatus, bool); 7] = [
    ("live", NodeStatus::Success, true),
    ("Activate", NodeStatus::Success, false),
    ("ticking", NodeStatus::Success, true),
    ("Fallback", NodeStatus::Success, true),
    ("Timeout", NodeStatus::Failure, true),
    // Halted by its timeout: as if never ticked.
    ("never", NodeStatus::Idle, true),
    ("Log", NodeStatus::Success, false),
];

#[test]
fn the_running_plan_is_a_live_tree_in_the_manager_the_events_and_the_recording() {
    let mut t = TestDomain::new("seqlive");
    let rec = t.dir.join("live.mcap");
    t.hello(&["--record", rec.to_str().unwrap()]);
    let mut c = Client::connect(&t.domain).unwrap();
    c.subscribe().unwrap();
    assert_eq!(c.plan().unwrap(), None, "no plan runs yet");
    let p = plan(
        &t,
        r#"<Sequence name="live">
             <Activate skills="smooth"/>
             <WaitFor name="ticking" condition="ticker.tick.value &gt; 20"/>
             <Fallback>
               <Timeout msec="1500"><WaitFor name="never" condition="ticker.tick.value &lt; 0"/></Timeout>
               <Log message="the other way"/>
             </Fallback>
           </Sequence>"#,
    );
    let child = t
        .command("skillfab")
        .args(["sequence", p.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // While it waits under its timeout, the manager has the tree, the running branch being
    // the root, the fallback, the timeout and the monitor's wait.
    let mut seen = None;
    t.wait_until(
        "the live tree to show the plan waiting under its timeout",
        || {
            seen = c.plan().unwrap();
            seen.as_ref()
                .is_some_and(|tree| tree.status[5].0 == NodeStatus::Running)
        },
    );
    let running = seen.unwrap();
    let names: Vec<&str> = running.nodes.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(names, LIVE_NODES.map(|n| n.0));
    assert_eq!(running.nodes[4].kind, "Timeout");
    assert_eq!(running.nodes[4].detail, "1500 ms");
    assert_eq!(running.nodes[5].parent, Some(4));
    assert_eq!(
        running.running_branch(),
        [true, false, false, true, true, true, false]
    );
    let out = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert_eq!(c.plan().unwrap(), None, "the plan ended: none runs");

    // The events: the tree arrived, then each node's changes, then the end.
    let mut changes: Vec<(u64, u32, NodeStatus)> = Vec::new();
    let mut started = false;
    loop {
        let ev = c
            .next_event(std::time::Duration::from_secs(10))
            .unwrap()
            .expect("the plan's events");
        match ev.kind {
            EventKind::PlanStarted {
                nodes, replaced, ..
            } => {
                assert_eq!((nodes, replaced), (7, None));
                started = true;
            }
            EventKind::PlanChanged {
                cycle, changes: c, ..
            } => {
                assert!(started, "the tree comes before its changes");
                changes.extend(c.iter().map(|c| (cycle, c.id, c.status)));
            }
            EventKind::PlanEnded { status, .. } => {
                assert_eq!(status, NodeStatus::Success);
                break;
            }
            _ => {}
        }
    }
    assert_eq!(c.lost_events(), 0);
    let cycles: Vec<u64> = changes.iter().map(|c| c.0).collect();
    assert!(cycles.is_sorted(), "cycles never go back: {changes:?}");
    for (id, (name, last, runs)) in LIVE_NODES.iter().enumerate() {
        let mine: Vec<NodeStatus> = changes
            .iter()
            .filter(|c| c.1 == id as u32)
            .map(|c| c.2)
            .collect();
        assert!(
            mine.windows(2).all(|w| w[0] != w[1]),
            "{name}: each change is a change: {mine:?}"
        );
        assert_eq!(mine.last(), Some(last), "{name}: {mine:?}");
        if *runs {
            assert_eq!(mine[0], NodeStatus::Running, "{name} runs first: {mine:?}");
        }
    }
    // What the manager answered while the plan ran is what the events had said by then.
    let (_, since) = running.status[5];
    assert!(
        changes.contains(&(since, 5, NodeStatus::Running)),
        "{changes:?}"
    );

    // The recording holds the tree and every change: rebuilt from it, the statuses follow
    // the same steps.
    let mut recorded: Vec<(u64, u32, NodeStatus)> = Vec::new();
    t.wait_until("the recording to hold the plan's end", || {
        let records = crate::replay::records(&rec);
        let Some(tree) = records.iter().find(|r| r["kind"] == "plan") else {
            return false;
        };
        assert_eq!(tree["nodes"].as_array().unwrap().len(), 7);
        assert_eq!(tree["nodes"][5]["name"], "never");
        assert_eq!(tree["nodes"][5]["parent"], 4);
        let status = |s: &str| match s {
            "idle" => NodeStatus::Idle,
            "running" => NodeStatus::Running,
            "success" => NodeStatus::Success,
            "failure" => NodeStatus::Failure,
            other => panic!("status {other}"),
        };
        recorded = records
            .iter()
            .filter(|r| r["kind"] == "event" && r["event"] == "plan_changed")
            .flat_map(|r| {
                let at = r["at"].as_u64().unwrap();
                r["changes"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(move |c| {
                        (
                            at,
                            c["id"].as_u64().unwrap() as u32,
                            status(c["status"].as_str().unwrap()),
                        )
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        records
            .iter()
            .any(|r| r["kind"] == "event" && r["event"] == "plan_ended" && r["status"] == "success")
    });
    assert_eq!(recorded, changes);
}
