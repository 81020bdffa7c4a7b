//! Rendering and key tests on ratatui's `TestBackend`: the console's main states drawn into
//! a buffer and read back as text.

use super::app::{App, Command, Dir, Link, Pane, PlanView, PortView, Snapshot, Update};
use super::view::{bar_strip, compact, render};
use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{KeyCode, KeyEvent};
use skillfab_proto::control::{
    ChannelStat, NodeStatus, Percentiles, PlanNode, PlanTree, PortInfo, SkillFigures, SkillInfo,
    SkillState, Stats,
};
use skillfab_proto::decl::Mode;
use skillfab_proto::log::{Level, LogLine};
use skillfab_proto::param::{ParamKind, ParamSpec, ParamValue};
use skillfab_proto::value::Value;

fn skill(name: &str, mode: Mode, state: SkillState, runs: u64, last: u64) -> SkillInfo {
    SkillInfo {
        name: name.into(),
        kind: name.into(),
        mode,
        state,
        priority: 0,
        pid: 4000 + runs as u32 % 1000,
        params: Vec::new(),
        values: Vec::new(),
        inputs: Vec::new(),
        outputs: Vec::new(),
        figures: SkillFigures {
            runs,
            last_cycle: last,
            compute_us_last: 3.2,
            compute_us_mean: 2.87,
            ..SkillFigures::default()
        },
    }
}

fn port(p: &str, ty: &str) -> PortInfo {
    PortInfo {
        port: p.into(),
        topic: p.into(),
        type_name: ty.into(),
    }
}

/// The hello network (ticker → scale → smooth) plus a sonar-like device, as a snapshot.
fn hello() -> Snapshot {
    let mut ticker = skill("ticker", Mode::Sync, SkillState::Active, 1234, 1234);
    ticker.outputs = vec![port("tick", "skillfab.Tick")];
    let mut scale = skill("scale", Mode::Sync, SkillState::Active, 1234, 1234);
    scale.inputs = vec![port("tick", "skillfab.Tick")];
    scale.outputs = vec![port("scaled", "skillfab.Scaled")];
    scale.params = vec![ParamSpec {
        name: "gain".into(),
        kind: ParamKind::Float,
        default: ParamValue::Float(2.0),
        min: Some(ParamValue::Float(-1e6)),
        max: Some(ParamValue::Float(1e6)),
        doc: "Factor applied to the tick.".into(),
    }];
    scale.values = vec![("gain".into(), ParamValue::Float(3.0))];
    let mut smooth = skill("smooth", Mode::Async, SkillState::Inactive, 600, 1100);
    smooth.inputs = vec![port("scaled", "skillfab.Scaled")];
    let mut sonar = skill("sonar", Mode::Sync, SkillState::Active, 1234, 1233);
    sonar.kind = "denning".into();
    sonar.outputs = vec![port("sonar", "denning.Sonar")];
    Snapshot {
        skills: vec![ticker, scale, smooth, sonar],
        stats: Stats {
            cycles: 1234,
            running: true,
            overruns: 1,
            latency_us: Percentiles {
                p50: 190.5,
                p99: 387.0,
                max: 1210.0,
            },
            skills: Vec::new(),
            deaths: 0,
            events: 17,
            channels: vec![ChannelStat {
                channel: "drive".into(),
                winner: "avoid".into(),
                cycle: 1234,
            }],
            bridges: Vec::new(),
            late_starts: 0,
        },
        latencies: (0..300)
            .map(|i| {
                let x = i as f32;
                let spike = if i % 97 == 40 { 180.0 } else { 0.0 };
                190.0 + 25.0 * (x / 9.0).sin() + 10.0 * (x / 2.3).cos() + spike
            })
            .collect(),
        ports_of: Some("scale".into()),
        ports: vec![
            PortView {
                dir: Dir::In,
                port: "tick".into(),
                type_name: "skillfab.Tick".into(),
                source: "ticker.tick".into(),
                value: Ok((
                    Value::Struct(vec![("value".into(), Value::UInt(1234))]),
                    1234,
                )),
            },
            PortView {
                dir: Dir::Out,
                port: "scaled".into(),
                type_name: "skillfab.Scaled".into(),
                source: "topic scaled".into(),
                value: Ok((
                    Value::Struct(vec![("value".into(), Value::Float(3702.0))]),
                    1234,
                )),
            },
        ],
        log_file: Some("/tmp/skillfab/default/params.jsonl".into()),
        io_skills: vec!["scale".into()],
    }
}

fn key(c: char) -> KeyEvent {
    KeyEvent::from(KeyCode::Char(c))
}

/// The screen as text, one line per row, trailing blanks trimmed.
pub(crate) fn screen(app: &App, w: u16, h: u16) -> String {
    let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
    t.draw(|f| render(app, f)).unwrap();
    let buf = t.backend().buffer().clone();
    (0..h)
        .map(|y| {
            let row: String = (0..w).map(|x| buf[(x, y)].symbol().to_string()).collect();
            row.trim_end().to_string()
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// A connected console with the hello network, `scale` selected.
fn connected() -> App {
    let mut app = App::new("default");
    assert_eq!(
        app.apply(Update::Snapshot(Box::new(hello()))),
        Some(Command::Select(Some("ticker".into())))
    );
    assert_eq!(
        app.on_key(key('j')),
        Some(Command::Select(Some("scale".into())))
    );
    app.apply(Update::Logs(vec![
        LogLine {
            skill: "scale".into(),
            pid: 1,
            level: Level::Info,
            target: "scale".into(),
            message: "parameter set param=gain value=3".into(),
            time_ns: 1,
            dropped: 0,
        },
        LogLine {
            skill: "scale".into(),
            pid: 1,
            level: Level::Warn,
            target: "scale".into(),
            message: "run failed cycle=17 error=input out of range".into(),
            time_ns: 2,
            dropped: 3,
        },
    ]));
    app
}

#[test]
fn connected_with_skills() {
    let app = connected();
    let s = screen(&app, 110, 34);
    if std::env::var_os("SKILLFAB_PRINT_CONSOLE").is_some() {
        println!("{s}");
    }
    for want in [
        "domain default",
        "running",
        "cycle 1234",
        "overruns 1",
        "p50 190 µs p99 387 µs max 1210 µs",
        "ticker",
        "smooth",
        "inactive",
        "▶ scale",
        "drive → avoid",
        "in  tick",
        "ticker.tick",
        "value      1234",
        "out scaled",
        "value      3702",
        "gain",
        "gain       3 float [-1e6, 1e6]",
        "run failed cycle=17",
        "fabric log: /tmp/skillfab/default/params.jsonl",
        "a (de)activate",
        "q quit",
    ] {
        assert!(s.contains(want), "missing {want:?} in\n{s}");
    }
    // Not verbose: the info line is hidden, the warning shown.
    assert!(!s.contains("parameter set param=gain"), "{s}");
}

#[test]
fn deadline_misses_and_cycle_allocations_are_in_the_skills_table() {
    let mut snap = hello();
    snap.skills[0].figures.deadline_misses = 0;
    snap.skills[0].figures.cycle_allocs = Some(0);
    snap.skills[1].figures.deadline_misses = 7;
    snap.skills[1].figures.cycle_allocs = Some(42);
    snap.stats.late_starts = 3;
    let mut app = App::new("default");
    app.apply(Update::Snapshot(Box::new(snap)));
    let s = screen(&app, 110, 34);
    if std::env::var_os("SKILLFAB_PRINT_CONSOLE").is_some() {
        println!("{s}");
    }
    let header = s.lines().find(|l| l.contains("skill ")).unwrap();
    let row = |name: &str| -> Vec<String> {
        let line = s
            .lines()
            .find(|l| l.split_whitespace().any(|w| w == name) && l.contains("sync"))
            .unwrap_or_else(|| panic!("no row of {name} in\n{s}"));
        line.split_whitespace().map(str::to_string).collect()
    };
    // The columns after compute (a number and its unit): late, allocs, last out.
    let after_compute = |cells: Vec<String>| -> Vec<String> {
        let at = cells.iter().position(|c| c == "µs").unwrap();
        cells[at + 1..at + 3].to_vec()
    };
    assert!(
        header.contains("late") && header.contains("allocs"),
        "{header}"
    );
    assert_eq!(after_compute(row("ticker")), ["0", "0"]);
    assert_eq!(after_compute(row("scale")), ["7", "42"]);
    assert_eq!(
        after_compute(row("sonar")),
        ["0", "-"],
        "not counted is not 0"
    );
    assert!(s.contains("overruns 1 · late starts 3"), "{s}");
}

#[test]
fn the_sonar_ring_is_a_bar_strip() {
    let mut app = connected();
    for _ in 0..2 {
        app.on_key(key('j'));
    }
    assert_eq!(app.selected_name.as_deref(), Some("sonar"));
    let ring: Vec<Value> = (0..24)
        .map(|i| {
            Value::Float(if (9..14).contains(&i) {
                0.4
            } else {
                1.0 + f64::from(i % 6) * 0.8
            })
        })
        .collect();
    let mut snap = hello();
    snap.ports_of = Some("sonar".into());
    snap.ports = vec![PortView {
        dir: Dir::Out,
        port: "sonar".into(),
        type_name: "denning.Sonar".into(),
        source: "topic sonar".into(),
        value: Ok((
            Value::Struct(vec![
                ("range".into(), Value::Array(ring)),
                ("age_ms".into(), Value::UInt(40)),
            ]),
            1233,
        )),
    }];
    app.apply(Update::Snapshot(Box::new(snap)));
    let s = screen(&app, 110, 34);
    if std::env::var_os("SKILLFAB_PRINT_CONSOLE").is_some() {
        println!("{s}");
    }
    // 24 ranges, 24 cells, scaled from 0 to the largest.
    assert!(
        s.contains("range      ▂▄▅▆▇█▂▄▅▂▂▂▂▂▅▆▇█▂▄▅▆▇█ 0.400..5"),
        "{s}"
    );
    assert!(s.contains("age_ms     40"), "{s}");
}

#[test]
fn verbose_shows_every_level() {
    let mut app = connected();
    assert_eq!(app.on_key(key('v')), None);
    let s = screen(&app, 110, 34);
    assert!(s.contains("parameter set param=gain"), "{s}");
}

#[test]
fn no_manager() {
    let mut app = App::new("lab");
    app.apply(Update::Disconnected(
        "no manager is running in domain 'lab'".into(),
    ));
    let s = screen(&app, 100, 20);
    assert!(
        s.contains("no manager (no manager is running in domain 'lab'); retrying"),
        "{s}"
    );
    assert!(s.contains("waiting for the manager"), "{s}");
    // Keys that need the manager say so instead of doing anything.
    assert_eq!(app.on_key(key('r')), None);
    assert!(screen(&app, 100, 20).contains("error: not connected to a manager"));
}

#[test]
fn lost_manager_keeps_the_last_view() {
    let mut app = connected();
    app.apply(Update::Disconnected(
        "no answer from the manager within 2s".into(),
    ));
    assert_eq!(
        app.link,
        Link::Down("no answer from the manager within 2s".into())
    );
    let s = screen(&app, 110, 34);
    assert!(s.contains("skills (last known)"), "{s}");
    assert!(s.contains("retrying"), "{s}");
    assert_eq!(app.on_key(key('a')), None);
}

#[test]
fn error_in_the_status_line() {
    let mut app = connected();
    // e opens the prompt with the current value; type a bad one; the manager refuses it.
    assert_eq!(app.on_key(key('e')), None);
    assert!(screen(&app, 110, 34).contains("set scale.gain = 3▏"));
    for _ in 0..2 {
        app.on_key(KeyEvent::from(KeyCode::Backspace));
    }
    for c in "1e9".chars() {
        app.on_key(key(c));
    }
    assert_eq!(
        app.on_key(KeyEvent::from(KeyCode::Enter)),
        Some(Command::SetParam(
            "scale".into(),
            "gain".into(),
            "1e9".into()
        ))
    );
    app.apply(Update::Failed(
        "scale: parameter 'gain' = 1000000000 is out of range [-1000000, 1000000]".into(),
    ));
    let s = screen(&app, 110, 34);
    assert!(
        s.contains("error: scale: parameter 'gain' = 1000000000 is out of range"),
        "{s}"
    );
    // A priority that is not a number never reaches the manager.
    app.on_key(key('p'));
    app.on_key(key('x'));
    assert_eq!(app.on_key(KeyEvent::from(KeyCode::Enter)), None);
    assert!(screen(&app, 110, 34).contains("error: priority must be an integer, got '0x'"));
}

#[test]
fn keys_make_commands() {
    let mut app = connected();
    assert_eq!(
        app.on_key(key('a')),
        Some(Command::Activate("scale".into(), false))
    );
    assert_eq!(
        app.on_key(key('l')),
        Some(Command::IoLog("scale".into(), false))
    );
    assert_eq!(app.on_key(key('r')), Some(Command::Stop));
    assert_eq!(app.on_key(key('s')), Some(Command::Step));
    assert_eq!(
        app.on_key(key('j')),
        Some(Command::Select(Some("smooth".into())))
    );
    assert_eq!(
        app.on_key(key('a')),
        Some(Command::Activate("smooth".into(), true))
    );
    assert_eq!(app.on_key(key('e')), None);
    assert_eq!(app.status, Some((true, "smooth has no parameters".into())));
    // The selection follows its skill when the list changes order.
    let mut snap = hello();
    snap.skills.reverse();
    assert_eq!(app.apply(Update::Snapshot(Box::new(snap))), None);
    assert_eq!(
        app.selected_skill().map(|s| s.name.as_str()),
        Some("smooth")
    );
    assert_eq!(app.selected, 1);
    // The selected skill dies: the selection moves on, and comes back when it is restarted...
    let mut gone = hello();
    gone.skills.retain(|s| s.name != "smooth");
    app.apply(Update::Snapshot(Box::new(gone.clone())));
    assert_ne!(
        app.selected_skill().map(|s| s.name.as_str()),
        Some("smooth")
    );
    assert_eq!(
        app.apply(Update::Snapshot(Box::new(hello()))),
        Some(Command::Select(Some("smooth".into())))
    );
    assert_eq!(
        app.selected_skill().map(|s| s.name.as_str()),
        Some("smooth")
    );
    // ...unless a key moved it meanwhile.
    app.apply(Update::Snapshot(Box::new(gone)));
    app.on_key(key('k'));
    let chosen = app.selected_skill().map(|s| s.name.clone());
    app.apply(Update::Snapshot(Box::new(hello())));
    assert_eq!(app.selected_skill().map(|s| s.name.clone()), chosen);
    app.on_key(key('q'));
    assert!(app.quit);
}

#[test]
fn tiny_and_huge_terminals_draw() {
    let app = connected();
    for (w, h) in [(1, 1), (20, 5), (40, 12), (300, 100)] {
        let _ = screen(&app, w, h);
    }
}

#[test]
fn values_are_compact() {
    assert_eq!(compact(&Value::Float(0.25)), "0.250");
    assert_eq!(compact(&Value::Float(2.0)), "2");
    assert_eq!(
        compact(&Value::Array(vec![Value::Int(1), Value::Int(2)])),
        "[1, 2]"
    );
    assert_eq!(
        bar_strip(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]),
        "▁▂▃▄▅▆▇█ 0..7"
    );
    assert_eq!(bar_strip(&[f64::NAN]), "[1 × null]");
    assert_eq!(
        compact(&Value::Struct(vec![
            ("seen".into(), Value::Bool(true)),
            ("range".into(), Value::Float(1.5)),
        ])),
        "seen=true range=1.500"
    );
}

/// A delivery-sized plan: a root sequence of `legs` legs, each a sequence of an `Activate`
/// and a `WaitFor` (1 + 3 × legs nodes); the legs before `at` succeeded, leg `at` waits.
fn big_plan(legs: u32, at: u32) -> PlanView {
    let mut nodes = vec![PlanNode {
        id: 0,
        parent: None,
        name: "deliver".into(),
        kind: "Sequence".into(),
        detail: String::new(),
    }];
    let mut status = vec![(NodeStatus::Running, 10)];
    for leg in 0..legs {
        let id = 1 + 3 * leg;
        let done = leg < at;
        let s = |running| match (done, leg == at) {
            (true, _) => (NodeStatus::Success, 20 + u64::from(leg)),
            (false, true) => (running, 30),
            (false, false) => (NodeStatus::Idle, 0),
        };
        nodes.push(PlanNode {
            id,
            parent: Some(0),
            name: format!("leg {leg}"),
            kind: "Sequence".into(),
            detail: String::new(),
        });
        status.push(s(NodeStatus::Running));
        nodes.push(PlanNode {
            id: id + 1,
            parent: Some(id),
            name: "Activate".into(),
            kind: "Activate".into(),
            detail: "hall_follow, avoid".into(),
        });
        status.push(s(NodeStatus::Success));
        nodes.push(PlanNode {
            id: id + 2,
            parent: Some(id),
            name: format!("arrived {leg}"),
            kind: "WaitFor".into(),
            detail: format!("deliver.progress.leg > {leg}"),
        });
        status.push(s(NodeStatus::Running));
    }
    PlanView {
        tree: PlanTree {
            plan: "deliver.xml".into(),
            nodes,
            status,
        },
        ended: None,
    }
}

#[test]
fn the_plan_view_shows_every_node_follows_the_running_branch_and_scrolls() {
    let mut app = connected();
    app.apply(Update::Plan(Some(Box::new(big_plan(40, 30)))));
    assert_eq!(app.on_key(key('t')), None);
    assert_eq!(app.pane, Pane::Plan);
    let s = screen(&app, 110, 34);
    if std::env::var_os("SKILLFAB_PRINT_CONSOLE").is_some() {
        println!("{s}");
    }
    // The title says where the plan is; the view follows the running branch, deep in a
    // tree far larger than 20 nodes.
    for want in [
        "plan deliver.xml · 121 nodes · at arrived 30",
        "▶   R leg 30 Sequence · cycle 30",
        "▶     R arrived 30 WaitFor · deliver.progress.leg > 30 · cycle 30",
        "S Activate · hall_follow, avoid · cycle 49",
        "· arrived 31 WaitFor · deliver.progress.leg > 31",
        "t skills",
        "f follow",
    ] {
        assert!(s.contains(want), "missing {want:?} in\n{s}");
    }
    assert!(!s.contains("leg 0 "), "the top is scrolled away:\n{s}");
    // Scrolled to the top: the root, and the first legs that succeeded, not marked running.
    app.on_key(key('g'));
    let s = screen(&app, 110, 34);
    assert!(s.contains("│▶ R deliver Sequence · cycle 10"), "{s}");
    assert!(s.contains("│    S leg 0 Sequence · cycle 20"), "{s}");
    assert!(!s.contains("leg > 30"), "{s}");
    // To the end: the last leg, never ticked.
    app.on_key(key('G'));
    let s = screen(&app, 110, 34);
    assert!(s.contains("· arrived 39 WaitFor"), "{s}");
    // Follow again, then the plan ends: the last tree stays, marked so.
    app.on_key(key('f'));
    let mut ended = big_plan(40, 40);
    ended.tree.status[0] = (NodeStatus::Success, 99);
    ended.ended = Some(NodeStatus::Success);
    app.apply(Update::Plan(Some(Box::new(ended))));
    let s = screen(&app, 110, 34);
    assert!(s.contains("121 nodes · ended: success"), "{s}");
    // Back to the skills; no plan at all says so.
    app.on_key(key('t'));
    assert_eq!(app.pane, Pane::Skills);
    assert!(screen(&app, 110, 34).contains("▶ scale"));
    let mut none = connected();
    none.on_key(key('t'));
    assert!(screen(&none, 110, 34).contains("no plan has run since the console connected"));
}
