//! The sequencer's control plane: `skillfab ctl` and the client library against a running
//! hello network (real processes, real iceoryx2).

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use nix::sys::signal::Signal;
use skillfab_client::{Client, ClientError};
use skillfab_proto::control::{ControlError, EventKind, MonitorMode};
use skillfab_proto::param::ParamValue;
use skillfab_tests::TestDomain;
use std::time::Duration;

/// Starts the hello network under `skillfab up` and waits until all three skills run.
fn hello(tag: &str) -> TestDomain {
    let mut t = TestDomain::new(tag);
    t.hello(&[]);
    t
}

/// Runs `skillfab ctl ARGS`; returns (success, stdout, stderr).
fn ctl(t: &TestDomain, args: &[&str]) -> (bool, String, String) {
    let out = t.run("skillfab", &[&["ctl"], args].concat());
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn json(t: &TestDomain, args: &[&str]) -> serde_json::Value {
    let out = t.ctl(&[&["--json"], args].concat());
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("ctl {args:?}: not JSON ({e}): {out}"))
}

/// A figure of `skill` in `ctl stats` (`runs`, `deadline_misses`, …).
fn figure(stats: &serde_json::Value, name: &str, field: &str) -> u64 {
    stats["skills"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == name)
        .unwrap()[field]
        .as_u64()
        .unwrap()
}

fn runs_of(stats: &serde_json::Value, name: &str) -> u64 {
    figure(stats, name, "runs")
}

/// `skill`'s deadline misses in `ctl stats`.
fn misses_of(stats: &serde_json::Value, name: &str) -> u64 {
    figure(stats, name, "deadline_misses")
}

#[test]
fn ls_set_get_query() {
    let t = hello("lsset");
    let ls = t.ctl(&["ls"]);
    for name in ["ticker", "scale", "smooth"] {
        assert!(ls.contains(name), "{ls}");
    }
    let listed = json(&t, &["ls"]);
    assert_eq!(listed.as_array().unwrap().len(), 3);
    let scale = listed
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == "scale")
        .unwrap();
    assert_eq!(scale["params"][0]["name"], "gain");
    assert_eq!(scale["params"][0]["min"], -1e6);
    assert_eq!(scale["mode"], "sync");

    t.ctl(&["set", "scale.gain=3"]);
    assert_eq!(t.ctl(&["get", "scale.gain"]).trim(), "3");
    // Applied from the next cycle: soon every new sample is 3 × its tick (= its cycle).
    t.wait_until("scaled = 3 × tick", || {
        let q = json(&t, &["query", "scale.scaled.value"]);
        let (v, cycle) = (q["value"].as_f64().unwrap(), q["cycle"].as_f64().unwrap());
        v == 3.0 * cycle
    });
    let whole = json(&t, &["query", "scale.scaled"]);
    assert!(whole["value"]["value"].is_number(), "{whole}");
}

#[test]
fn bad_requests_get_clear_errors_and_nothing_breaks() {
    let t = hello("badreq");
    let cases: &[(&[&str], &str)] = &[
        (
            &["set", "scale.gain=abc"],
            "parameter 'gain' takes a float, got 'abc'",
        ),
        (&["set", "nosuch.gain=1"], "unknown skill 'nosuch'"),
        (&["set", "scale.nope=1"], "unknown parameter 'nope'"),
        (&["set", "scale.gain=1e9"], "out of range"),
        (&["get", "scale"], "expected SKILL.PARAM"),
        (
            &["query", "scale.nope"],
            "skill 'scale' has no output 'nope'",
        ),
        (&["query", "scale.scaled.nope"], "has no field 'nope'"),
        (&["query", "ticker.tick.value[3]"], "not an array"),
        (
            &["monitor", "ticker.tick.value >", "--once"],
            "bad expression",
        ),
        (
            &["monitor", "ticker.tick > 1", "--once"],
            "more than one number",
        ),
        (&["activate", "scale", "ghost"], "unknown skill 'ghost'"),
        (&["unmonitor", "999"], "unknown monitor 999"),
        (&["priority", "ghost", "3"], "unknown skill 'ghost'"),
    ];
    for (args, expected) in cases {
        let (success, _, err) = ctl(&t, args);
        assert!(!success, "ctl {args:?} should fail");
        assert!(
            err.contains(expected),
            "ctl {args:?}: expected '{expected}' in: {err}"
        );
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
    }
    // All-or-nothing: the failed `activate scale ghost` changed nothing; the fabric runs on.
    let before = json(&t, &["stats"]);
    t.wait_until("cycles to go on", || {
        json(&t, &["stats"])["cycles"].as_u64() > before["cycles"].as_u64()
    });
    assert_eq!(t.ctl(&["get", "scale.gain"]).trim(), "2");
}

#[test]
fn a_once_monitor_prints_one_event_in_the_cycle_it_became_true() {
    let t = hello("monitor");
    // The ticker's value is the cycle number: the condition first holds in cycle 51 (or, if
    // the network is already past it, in the cycle the monitor was installed in).
    let out = t.ctl(&["monitor", "ticker.tick.value > 50", "--once"]);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 1, "{out}");
    let ev: serde_json::Value = serde_json::from_str(lines[0]).unwrap();
    assert_eq!(ev["event"], "monitor_fired");
    let value = ev["values"]["ticker.tick.value"].as_u64().unwrap();
    assert!(value > 50);
    assert_eq!(
        ev["cycle"].as_u64().unwrap(),
        value,
        "fired in the cycle whose value made it true: {ev}"
    );
    // A spent `once` monitor is gone.
    assert_eq!(json(&t, &["monitors"]), serde_json::json!([]));
}

#[test]
fn deactivate_stops_runs_activate_resumes_and_step_counts_exactly() {
    let t = hello("activation");
    t.ctl(&["deactivate", "scale"]);
    let a = json(&t, &["stats"]);
    t.wait_until("cycles without scale", || {
        json(&t, &["stats"])["cycles"].as_u64().unwrap() > a["cycles"].as_u64().unwrap() + 20
    });
    let b = json(&t, &["stats"]);
    assert_eq!(
        runs_of(&a, "scale"),
        runs_of(&b, "scale"),
        "an inactive skill does not run"
    );
    assert!(runs_of(&b, "ticker") > runs_of(&a, "ticker"));
    let state = json(&t, &["ls"]);
    assert!(
        state
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s["name"] == "scale" && s["state"] == "inactive")
    );

    t.ctl(&["activate", "scale"]);
    t.wait_until("scale to run again", || {
        runs_of(&json(&t, &["stats"]), "scale") > runs_of(&b, "scale") + 5
    });

    t.ctl(&["stop"]);
    let stopped = json(&t, &["stats"]);
    assert_eq!(stopped["running"], false);
    let c0 = stopped["cycles"].as_u64().unwrap();
    let stepped = json(&t, &["step", "5"]);
    assert_eq!(stepped["cycle"].as_u64().unwrap(), c0 + 5);
    let after = json(&t, &["stats"]);
    assert_eq!(
        after["cycles"].as_u64().unwrap(),
        c0 + 5,
        "exactly 5 cycles"
    );
    assert_eq!(after["running"], false);
    // The ticker ran in each of the 5 cycles, or missed one's deadline: on a loaded machine
    // (CI's, with the suite beside it) a cycle closes at its deadline without a late run,
    // counted as the skill's deadline miss. Never more than one run a cycle.
    let ran = runs_of(&after, "ticker") - runs_of(&stopped, "ticker");
    let late = misses_of(&after, "ticker") - misses_of(&stopped, "ticker");
    assert!(
        ran <= 5 && ran + late >= 5,
        "ticker: {ran} runs and {late} deadline misses in 5 cycles"
    );
    t.ctl(&["run"]);
    t.wait_until("cycling again", || {
        json(&t, &["stats"])["cycles"].as_u64().unwrap() > c0 + 10
    });
}

/// Whether `skill` is active, as `ctl ls` says.
fn active(t: &TestDomain, skill: &str) -> bool {
    let ls = json(t, &["ls"]);
    let s = ls
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == skill)
        .unwrap_or_else(|| panic!("{skill} not listed: {ls}"));
    s["state"] != "inactive"
}

#[test]
fn a_wanted_skill_runs_with_its_producers_and_releasing_it_releases_them() {
    let mut t = hello("want");
    t.ctl(&["deactivate", "ticker", "scale", "smooth"]);
    // smooth reads scale, which reads ticker: wanting smooth activates all three.
    t.ctl(&["want", "smooth"]);
    assert!(["ticker", "scale", "smooth"].iter().all(|s| active(&t, s)));
    let a = json(&t, &["stats"]);
    t.wait_until("smooth to run on demand", || {
        runs_of(&json(&t, &["stats"]), "smooth") > runs_of(&a, "smooth") + 5
    });
    t.ctl(&["release", "smooth"]);
    assert!(["ticker", "scale", "smooth"].iter().all(|s| !active(&t, s)));

    // A skill a client activated itself is not released with what wanted it.
    t.ctl(&["activate", "ticker"]);
    t.ctl(&["want", "smooth"]);
    t.ctl(&["release", "smooth"]);
    assert!(active(&t, "ticker"), "activated by a client, kept");
    assert!(!active(&t, "scale") && !active(&t, "smooth"));

    // Two wanted skills share a producer: it stays while one of them is wanted.
    t.ctl(&["want", "smooth", "scale"]);
    t.ctl(&["release", "smooth"]);
    assert!(active(&t, "scale"), "still wanted");
    assert!(!active(&t, "smooth"));
    // Deactivating a wanted skill is a client's choice too: it is not wanted any more.
    t.ctl(&["deactivate", "scale"]);
    assert!(!active(&t, "scale"));

    // A skill reading a topic nobody produces: refused, nothing changed.
    let lonely = t.spawn(
        "scale",
        &[
            "--name",
            "lonely",
            "--remap",
            "tick=silence",
            "--remap",
            "scaled=unheard",
        ],
    );
    let board = t.board();
    t.wait_until("lonely to register", || {
        skillfab_tests::registered(&board, "lonely").is_some()
    });
    t.ctl(&["deactivate", "lonely"]);
    let (ok, _, err) = ctl(&t, &["want", "lonely", "smooth"]);
    assert!(!ok);
    assert!(
        err.contains(
            "'lonely' reads 'silence' (its input 'tick'), which no skill or device produces"
        ),
        "{err}"
    );
    assert!(
        !active(&t, "lonely") && !active(&t, "smooth"),
        "all or none"
    );
    let c = Client::connect(&t.domain).unwrap();
    assert!(matches!(
        c.want(&["lonely"]),
        Err(ClientError::Refused(ControlError::NoProducer { .. }))
    ));
    t.signal(lonely, Signal::SIGTERM);
}

/// A monitor reads only values made after it was installed: the last output of a skill
/// deactivated before it stands on its topic and does not fire it; the first output of the
/// skill's next activation does.
#[test]
fn a_value_made_before_a_monitor_does_not_fire_it() {
    let t = hello("stale");
    let mut c = Client::connect(&t.domain).unwrap();
    c.subscribe().unwrap();
    t.wait_until("scale's output above 0", || {
        c.query("scale.scaled.value")
            .is_ok_and(|(v, _)| v.as_f64().is_some_and(|v| v > 0.0))
    });
    c.deactivate(&["scale"]).unwrap();
    let id = c
        .add_monitor("scale.scaled.value > 0", MonitorMode::Once, 0)
        .unwrap();
    let fired = |c: &mut Client, wait: Duration| {
        let until = std::time::Instant::now() + wait;
        while let Some(ev) = c
            .next_event(until.saturating_duration_since(std::time::Instant::now()))
            .unwrap()
        {
            if matches!(ev.kind, EventKind::MonitorFired { id: m, .. } if m == id) {
                return true;
            }
        }
        false
    };
    let (last, _) = c.query("scale.scaled.value").unwrap();
    assert!(
        last.as_f64().unwrap() > 0.0,
        "the stale value would fire it"
    );
    let a = json(&t, &["stats"])["cycles"].as_u64().unwrap();
    assert!(
        !fired(&mut c, Duration::from_millis(500)),
        "fired on a stale value"
    );
    assert!(
        json(&t, &["stats"])["cycles"].as_u64().unwrap() > a + 20,
        "cycles ran meanwhile"
    );
    c.activate(&["scale"]).unwrap();
    assert!(
        fired(&mut c, Duration::from_secs(20)),
        "not fired once scale ran"
    );
}

#[test]
fn the_client_library_sees_events_in_order_with_typed_errors() {
    let mut t = hello("client");
    let mut c = Client::connect(&t.domain).unwrap();
    c.subscribe().unwrap();

    c.set_param_value("scale", "gain", ParamValue::Int(4))
        .unwrap();
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(4.0)
    );
    match c.set_param_value("scale", "gain", ParamValue::Bool(true)) {
        Err(ClientError::Refused(ControlError::Param { skill, .. })) => assert_eq!(skill, "scale"),
        other => panic!("expected a parameter error, got {other:?}"),
    }
    assert!(matches!(
        c.query("nobody.x"),
        Err(ClientError::Refused(ControlError::UnknownSkill(_)))
    ));
    c.set_priority("scale", 9).unwrap();
    let id = c
        .add_monitor(
            "scale.scaled.value >= 0 and smooth.smoothed.samples > 0",
            MonitorMode::Every,
            2,
        )
        .unwrap();

    let mut seen = Vec::new();
    let mut fired = 0;
    while fired < 3 {
        let ev = c
            .next_event(Duration::from_secs(20))
            .unwrap()
            .expect("an event");
        if let EventKind::MonitorFired { id: m, values, .. } = &ev.kind {
            assert_eq!(*m, id);
            assert_eq!(values.len(), 2);
            fired += 1;
        }
        seen.push(ev);
    }
    let seqs: Vec<u64> = seen.iter().map(|e| e.seq).collect();
    assert!(
        seqs.windows(2).all(|w| w[1] == w[0] + 1),
        "consecutive: {seqs:?}"
    );
    assert!(seen.iter().any(|e| matches!(&e.kind,
        EventKind::ParamChanged { skill, param, old: ParamValue::Float(o), new: ParamValue::Float(n), by }
            if skill == "scale" && param == "gain" && *o == 2.0 && *n == 4.0 && by == c.id())));
    assert!(
        seen.iter()
            .any(|e| matches!(&e.kind, EventKind::PriorityChanged { new: 9, .. }))
    );
    assert_eq!(c.lost_events(), 0);
    c.remove_monitor(id).unwrap();

    // A skill killed: the stream says so.
    let board = t.board();
    let pid = skillfab_tests::registered(&board, "smooth")
        .unwrap()
        .decl
        .pid;
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), Signal::SIGKILL).unwrap();
    let mut died = false;
    for _ in 0..100 {
        match c.next_event(Duration::from_secs(20)).unwrap() {
            Some(ev) if matches!(&ev.kind, EventKind::SkillDied { skill, .. } if skill == "smooth") =>
            {
                died = true;
                break;
            }
            Some(_) => {}
            None => break,
        }
    }
    assert!(died, "no skill_died event");
    // `skillfab up` restarts it (on-failure): a registration that says so.
    let mut back = false;
    for _ in 0..100 {
        match c.next_event(Duration::from_secs(20)).unwrap() {
            Some(ev) if matches!(&ev.kind, EventKind::SkillRegistered { skill, restarted: true, .. } if skill == "smooth") =>
            {
                back = true;
                break;
            }
            Some(_) => {}
            None => break,
        }
    }
    assert!(back, "no restart registration");
    drop(t.board());
    let _ = &mut t;
}

#[test]
fn the_client_takes_typed_references_of_parameters_ports_and_fields() {
    use skillfab_msgs::Tick;
    use skillfab_proto::refs::{Field, Param};
    use skillfab_proto::value::Value;
    use skills::hello::{ScaleOut, ScaleParams, TickOut};
    let t = hello("typed");
    let mut c = Client::connect(&t.domain).unwrap();
    c.set("scale", ScaleParams::GAIN, 3.0).unwrap();
    assert_eq!(c.get("scale", ScaleParams::GAIN).unwrap(), 3.0);
    // A field (a u64) and a whole message, read as their Rust types.
    let tick = TickOut::TICK.field(Tick::VALUE);
    t.wait_until("scaled = 3 × tick", || {
        let (tick, k1) = c.read("ticker", &tick).unwrap();
        let (scaled, k2) = c.read("scale", ScaleOut::SCALED).unwrap();
        k1 == k2 && tick > 0 && scaled.value == 3.0 * tick as f64
    });
    // The manager checks the bounds as for text.
    assert!(matches!(
        c.set("scale", ScaleParams::GAIN, 1e9),
        Err(ClientError::Refused(ControlError::Param { .. }))
    ));
    // A reference of another type than the instance declares: refused with what it holds.
    const GAIN_AS_BOOL: Param<bool> = Param::new("gain");
    match c.get("scale", GAIN_AS_BOOL) {
        Err(ClientError::WrongType { path, got, .. }) => {
            assert_eq!((path.as_str(), got), ("scale.gain", Value::Float(3.0)))
        }
        other => panic!("expected a type mismatch, got {other:?}"),
    }
    const VALUE_AS_FLOAT: Field<f64, Tick> = Field::new("value");
    assert!(matches!(
        c.read("ticker", TickOut::TICK.field(VALUE_AS_FLOAT)),
        Err(ClientError::WrongType {
            expected: "f64",
            ..
        })
    ));
    // A typed path in a monitor's expression.
    let id = c
        .add_monitor(&format!("ticker.{tick} > 0"), MonitorMode::Once, 0)
        .unwrap();
    next_matching(&mut c, "the typed path's monitor firing", |k| match k {
        EventKind::MonitorFired { id: m, .. } if *m == id => Some(()),
        _ => None,
    });
}

/// The next event that `pick` accepts (others are skipped); fails after 20 s or 400 events.
fn next_matching<T>(
    c: &mut Client,
    what: &str,
    mut pick: impl FnMut(&EventKind) -> Option<T>,
) -> (T, u64) {
    for _ in 0..400 {
        match c.next_event(Duration::from_secs(20)).unwrap() {
            Some(ev) => {
                if let Some(x) = pick(&ev.kind) {
                    return (x, ev.time_ns);
                }
            }
            None => break,
        }
    }
    panic!("no {what} event");
}

#[test]
fn a_restarted_skill_gets_back_what_clients_set_and_monitors_keep_reading_it() {
    let t = hello("restore");
    let mut c = Client::connect(&t.domain).unwrap();
    c.subscribe().unwrap();
    c.set_param_value("scale", "gain", ParamValue::Float(3.5))
        .unwrap();
    c.set_priority("scale", 7).unwrap();
    c.deactivate(&["smooth"]).unwrap();
    let io_log = c.set_io_log("scale", true).is_ok();
    let id = c
        .add_monitor("scale.scaled.value > 0", MonitorMode::Every, 1)
        .unwrap();
    let board = t.board();
    let mut restored_at = 0;
    for name in ["scale", "smooth"] {
        let pid = skillfab_tests::registered(&board, name).unwrap().decl.pid;
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), Signal::SIGKILL).unwrap();
        next_matching(&mut c, "skill_died", |k| {
            matches!(k, EventKind::SkillDied { skill, .. } if skill == name).then_some(())
        });
        // `skillfab up` restarts it (on-failure); the registration is followed by the state.
        next_matching(&mut c, "restarted registration", |k| {
            matches!(k, EventKind::SkillRegistered { skill, restarted: true, .. } if skill == name)
                .then_some(())
        });
        let (restored, at) = next_matching(&mut c, "state_restored", |k| match k {
            EventKind::StateRestored { skill, .. } if skill == name => Some(k.clone()),
            _ => None,
        });
        let EventKind::StateRestored {
            active,
            params,
            priority,
            io_log: logged,
            dropped,
            ..
        } = restored
        else {
            unreachable!()
        };
        assert!(dropped.is_empty(), "{dropped:?}");
        if name == "scale" {
            assert!(active);
            assert_eq!(params, vec![("gain".to_string(), ParamValue::Float(3.5))]);
            assert_eq!(priority, Some(7));
            assert_eq!(logged, io_log);
            restored_at = at;
        } else {
            assert!(!active);
            assert!(params.is_empty());
            assert_eq!(priority, None);
        }
    }
    // The new scale computes with the restored gain, and the monitor reads the new process.
    let list = c.list().unwrap();
    let scale = list.iter().find(|s| s.name == "scale").unwrap();
    assert_eq!(scale.priority, 7);
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(3.5)
    );
    t.wait_until("the new smooth to be ready and inactive", || {
        c.list()
            .unwrap()
            .iter()
            .any(|s| s.name == "smooth" && s.state.as_str() == "inactive")
    });
    t.wait_until("scale to compute 3.5 x tick in one cycle", || {
        let (tick, k1) = c.query("ticker.tick.value").unwrap();
        let (scaled, k2) = c.query("scale.scaled.value").unwrap();
        let (Some(tick), Some(scaled)) = (tick.as_f64(), scaled.as_f64()) else {
            return false;
        };
        k1 == k2 && tick > 0.0 && (scaled - 3.5 * tick).abs() < 1e-9
    });
    // A firing on a sample the new process sent after its state came back.
    next_matching(
        &mut c,
        "monitor_fired on the new process's output",
        |k| match k {
            EventKind::MonitorFired {
                id: m, stamp_ns, ..
            } if *m == id && *stamp_ns > restored_at => Some(()),
            _ => None,
        },
    );
}

#[test]
fn a_killed_manager_comes_back_with_what_clients_set_and_their_monitors() {
    use skillfab_proto::board::Board;
    use std::sync::atomic::Ordering;
    let t = hello("mgrkill");
    let mut c = Client::connect(&t.domain).unwrap();
    c.subscribe().unwrap();
    c.set_param_value("scale", "gain", ParamValue::Float(2.5))
        .unwrap();
    c.set_priority("scale", 4).unwrap();
    c.deactivate(&["smooth"]).unwrap();
    let id = c
        .add_monitor("scale.scaled.value > 0", MonitorMode::Every, 1)
        .unwrap();
    let old = t.board();
    let pid = old.header().manager_pid.load(Ordering::Acquire);
    let before = skillfab_tests::cycle(&old);
    let killed_at = skillfab_proto::header::now_ns();
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), Signal::SIGKILL).unwrap();

    // `skillfab up` starts a new manager; its skills register with it again.
    let new_manager = || {
        Board::open(&t.domain.prefix()).ok().filter(|b| {
            b.manager_alive()
                && b.header().manager_pid.load(Ordering::Acquire) != pid
                && ["ticker", "scale", "smooth"]
                    .iter()
                    .all(|n| skillfab_tests::registered(b, n).is_some())
        })
    };
    t.wait_until("a new manager with the three skills", || {
        new_manager().is_some()
    });
    let board = new_manager().unwrap();
    t.wait_until("the new manager to cycle", || {
        skillfab_tests::cycle(&board) > 0
    });
    // Cycles number on from where the dead manager was.
    assert!(skillfab_tests::cycle(&board) > before);

    // The same client, not reconnected, is answered by the new manager, which has the state.
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(2.5)
    );
    t.wait_until("scale back at priority 4 and smooth back inactive", || {
        let list = c.list().unwrap();
        let state = |n: &str| list.iter().find(|s| s.name == n).cloned();
        state("scale").is_some_and(|s| s.priority == 4 && s.state.as_str() == "active")
            && state("smooth").is_some_and(|s| s.state.as_str() == "inactive")
    });
    let monitors = c.monitors().unwrap();
    assert!(
        monitors.iter().any(|m| m.id == id && m.client == c.id()),
        "{monitors:?}"
    );
    t.wait_until("scale to compute 2.5 x tick in one cycle", || {
        let (tick, k1) = c.query("ticker.tick.value").unwrap();
        let (scaled, k2) = c.query("scale.scaled.value").unwrap();
        let (Some(tick), Some(scaled)) = (tick.as_f64(), scaled.as_f64()) else {
            return false;
        };
        k1 == k2 && tick > 0.0 && (scaled - 2.5 * tick).abs() < 1e-9
    });
    // The client's monitor fires on samples sent after the kill, under its old id.
    next_matching(
        &mut c,
        "the monitor firing after the restart",
        |k| match k {
            EventKind::MonitorFired {
                id: m, stamp_ns, ..
            } if *m == id && *stamp_ns > killed_at => Some(()),
            _ => None,
        },
    );
}

#[test]
fn monitors_go_away_with_their_client() {
    let mut t = hello("owner");
    let m = t.spawn("skillfab", &["ctl", "monitor", "ticker.tick.value < 0"]);
    t.wait_until("the monitor to be installed", || {
        json(&t, &["monitors"])
            .as_array()
            .is_some_and(|a| a.len() == 1)
    });
    t.signal(m, Signal::SIGKILL);
    t.wait_exit(m);
    t.wait_until("the monitor to be removed", || {
        json(&t, &["monitors"])
            .as_array()
            .is_some_and(|a| a.is_empty())
    });
}

#[test]
fn ctl_without_a_manager_says_so() {
    let t = TestDomain::new("nomanager");
    let (success, _, err) = ctl(&t, &["ls"]);
    assert!(!success);
    assert!(err.contains("no manager is running in domain"), "{err}");
}

#[test]
fn requests_for_a_skill_that_is_away_apply_when_it_is_back() {
    let mut t = TestDomain::new("away");
    t.spawn("skillfab", &["manager", "--period-ms", "5"]);
    t.spawn("ticker", &[]);
    let scale = t.spawn("scale", &[]);
    let board = t.board();
    t.wait_until("scale to run", || {
        skillfab_tests::registered(&board, "scale").is_some_and(|s| s.runs > 2)
    });
    let mut c = Client::connect(&t.domain).unwrap();
    c.subscribe().unwrap();
    t.signal(scale, Signal::SIGKILL);
    t.wait_exit(scale);
    next_matching(&mut c, "skill_died", |k| {
        matches!(k, EventKind::SkillDied { skill, .. } if skill == "scale").then_some(())
    });
    // Nobody restarts it yet: requests are checked against its last declaration and kept.
    // Read, a parameter has the value it will have when the skill is back (a plan's
    // `WithParam` reads it to restore it later).
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(2.0),
        "the value its last process started with"
    );
    c.set_param("scale", "gain", "6").unwrap();
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(6.0)
    );
    assert!(c.get_param("scale", "nope").is_err());
    c.deactivate(&["scale"]).unwrap();
    c.set_priority("scale", 3).unwrap();
    assert!(matches!(
        c.set_param("scale", "gain", "abc"),
        Err(ClientError::Refused(ControlError::Param { .. }))
    ));
    assert!(c.set_param("scale", "nope", "1").is_err());
    assert!(matches!(
        c.activate(&["ghost"]),
        Err(ClientError::Refused(ControlError::UnknownSkill(_)))
    ));
    t.spawn("scale", &[]);
    let (restored, _) = next_matching(&mut c, "state_restored", |k| match k {
        EventKind::StateRestored { skill, .. } if skill == "scale" => Some(k.clone()),
        _ => None,
    });
    let EventKind::StateRestored {
        active,
        params,
        priority,
        ..
    } = restored
    else {
        unreachable!()
    };
    assert!(!active);
    assert_eq!(params, vec![("gain".to_string(), ParamValue::Float(6.0))]);
    assert_eq!(priority, Some(3));
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(6.0)
    );
}

/// Waits for the event that says the fabric stopped at a hold: its cycle.
fn held(c: &mut Client) -> u64 {
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while std::time::Instant::now() < deadline {
        if let Some(EventKind::Held { cycle }) = c
            .next_event(Duration::from_millis(100))
            .unwrap()
            .map(|e| e.kind)
        {
            return cycle;
        }
    }
    panic!("the fabric did not stop at a hold within 20 s");
}

#[test]
fn a_hold_stops_a_lock_step_fabric_at_its_clients_cycle_whoever_resumes_it() {
    let mut t = TestDomain::new("holds");
    t.hello_registered(&["--lockstep", "--held"]);
    let mut a = Client::connect(&t.domain).unwrap();
    a.subscribe().unwrap();
    let b = Client::connect(&t.domain).unwrap();
    // Started held: no cycle until a client holds, whoever resumes it.
    b.run().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(a.stats().unwrap().cycles, 0, "held before the first cycle");

    a.hold(Some(50)).unwrap();
    assert_eq!(held(&mut a), 50);
    // Another client's `run` (a plan runner resuming after a firing) does not pass it.
    b.run().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(a.stats().unwrap().cycles, 50, "still at the hold");

    // Holds add up: the fabric stops at the lowest, then at the next.
    b.hold(Some(120)).unwrap();
    a.hold(Some(80)).unwrap();
    assert_eq!(held(&mut a), 80);
    a.hold(None).unwrap();
    assert_eq!(held(&mut a), 120);
    assert_eq!(a.stats().unwrap().cycles, 120);
    b.hold(None).unwrap();
    t.wait_until("cycling on without holds", || {
        a.stats().unwrap().cycles > 200
    });
}

#[test]
fn the_client_librarys_example_sequencer_schedules_a_gain_on_the_hello_network() {
    let mut t = TestDomain::new("gainsched");
    t.hello(&[]);
    // `cargo test --workspace` builds the example; a run of this crate alone builds it here.
    let exe = skillfab_tests::bin("skillfab")
        .with_file_name("examples")
        .join("gain_schedule");
    if !exe.is_file() {
        let built = skillfab_tests::build_command(env!("CARGO"))
            .args([
                "build",
                "-q",
                "-p",
                "skillfab-client",
                "--example",
                "gain_schedule",
            ])
            .current_dir(skillfab_tests::repo_root())
            .status()
            .unwrap();
        assert!(built.success() && exe.is_file(), "{}", exe.display());
    }
    let out = t.command_at(&exe).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Both switches, in order, and the gain back where it was.
    let high = text
        .find("scale.gain = 6")
        .unwrap_or_else(|| panic!("{text}"));
    let back = text
        .rfind("scale.gain = 2")
        .unwrap_or_else(|| panic!("{text}"));
    assert!(high < back, "{text}");
    let c = Client::connect(&t.domain).unwrap();
    assert_eq!(
        c.get_param("scale", "gain").unwrap(),
        ParamValue::Float(2.0)
    );
    assert!(c.monitors().unwrap().is_empty(), "its monitors removed");
}
