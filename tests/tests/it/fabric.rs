//! The core fabric, end to end: real processes, real iceoryx2 shared memory.

use nix::sys::signal::Signal;
use skillfab_tests::{TestDomain, cycle, registered, skill};

// Counting tests give cycles a deadline far above any run, so a loaded machine cannot turn a
// slow cycle into an overrun (what an overrun does is tested on its own).
const HELLO_CHECK: &str = r#"
[manager]
period_ms = 2
deadline_ms = 2000
[[process]]
name = "ticker"
bin = "{bin:ticker}"
[[process]]
name = "scale"
bin = "{bin:scale}"
params = { gain = 3.0 }
[[process]]
name = "check"
bin = "{bin:check}"
params = { gain = 3.0 }
[[process]]
name = "smooth"
bin = "{bin:smooth}"
"#;

/// `HELLO_CHECK`'s report after `cycles` cycles: every cycle ran, and every run of the sync
/// chain ran on its cycle's values (`check` fails a run on a wrong one).
fn every_sync_run_exact(r: &serde_json::Value, cycles: u64) {
    assert_eq!(r["cycles"], cycles, "{r}");
    for name in ["ticker", "scale", "check"] {
        let s = skill(r, name);
        assert_eq!(s["runs"], cycles, "{name}: {s}");
        assert_eq!(s["failures"], 0, "{name} saw a wrong value: {s}");
        assert_eq!(s["skips"], 0, "{name}: {s}");
    }
}

#[test]
fn a_sync_chain_gives_exactly_the_expected_values() {
    let t = TestDomain::new("chain");
    let r = t.up_json(HELLO_CHECK, &["--cycles", "150"]);
    every_sync_run_exact(&r, 150);
    for name in ["ticker", "scale", "check"] {
        let s = skill(&r, name);
        assert_eq!(s["last_cycle"], 150, "{name}: {s}");
    }
    assert_eq!(skill(&r, "smooth")["mode"], "async");
    assert_eq!(r["overruns"], 0, "{r}");
}

/// Spin mode changes how a skill waits, not what it computes: the same chain with every skill
/// polling its doorbell for up to 2 ms after cycle start gives the same values in every cycle.
#[test]
fn a_sync_chain_in_spin_mode_gives_exactly_the_expected_values() {
    let t = TestDomain::new("spinchain");
    let launch = HELLO_CHECK.replacen(
        "deadline_ms = 2000\n",
        "deadline_ms = 2000\nspin_us = 2000\n",
        1,
    );
    let r = t.up_json(&launch, &["--cycles", "150"]);
    every_sync_run_exact(&r, 150);
    assert_eq!(
        skill(&r, "smooth")["runs"].as_u64().map(|n| n > 0),
        Some(true),
        "{r}"
    );
    assert_eq!(r["overruns"], 0, "{r}");
}

#[test]
fn independent_sync_skills_run_in_parallel() {
    let t = TestDomain::new("parallel");
    let launch = r#"
[manager]
period_ms = 200
[[process]]
name = "ticker"
bin = "{bin:ticker}"
[[process]]
name = "a"
bin = "{bin:work}"
params = { sleep_ms = 25.0 }
remap = { out = "a" }
[[process]]
name = "b"
bin = "{bin:work}"
params = { sleep_ms = 25.0 }
remap = { out = "b" }
"#;
    let r = t.up_json(launch, &["--cycles", "3"]);
    let (a, b) = (skill(&r, "a"), skill(&r, "b"));
    assert_eq!(a["last_cycle"], 3);
    assert_eq!(b["last_cycle"], 3);
    let span = |s: &serde_json::Value| {
        (
            s["last_start_ns"].as_u64().unwrap(),
            s["last_end_ns"].as_u64().unwrap(),
        )
    };
    let ((a0, a1), (b0, b1)) = (span(a), span(b));
    assert!(
        a0 < b1 && b0 < a1,
        "runs of cycle 3 did not overlap: a {a0}..{a1}, b {b0}..{b1}"
    );
}

#[test]
fn a_slow_async_skill_does_not_slow_the_cycle() {
    let t = TestDomain::new("slowasync");
    let launch = r#"
[[process]]
name = "ticker"
bin = "{bin:ticker}"
[[process]]
name = "slow"
bin = "{bin:work-async}"
params = { sleep_ms = 300.0 }
"#;
    let r = t.up_json(launch, &["--cycles", "200", "--free-run"]);
    // Free-running: the deadline is 1 s, far above a tick's run even on a loaded machine.
    assert_eq!(r["cycles"], 200);
    assert_eq!(r["overruns"], 0, "{r}");
    assert_eq!(skill(&r, "ticker")["runs"], 200);
    let slow_runs = skill(&r, "slow")["runs"].as_u64().unwrap();
    // Had the cycle waited for it, it would have run once per cycle.
    assert!(
        slow_runs < 20,
        "the async skill ran {slow_runs} times in 200 cycles"
    );
}

#[test]
fn failed_runs_cancel_their_consumers_without_stalling_the_cycle() {
    let t = TestDomain::new("failing");
    let launch = r#"
[manager]
period_ms = 2
deadline_ms = 2000
[[process]]
name = "ticker"
bin = "{bin:ticker}"
[[process]]
name = "work"
bin = "{bin:work}"
params = { fail_every = 3, panic_every = 5 }
remap = { out = "mid" }
[[process]]
name = "sink"
bin = "{bin:sink}"
remap = { input = "mid" }
"#;
    let r = t.up_json(launch, &["--cycles", "30"]);
    assert_eq!(r["cycles"], 30);
    assert_eq!(
        r["overruns"], 0,
        "a failed producer must not make the cycle wait: {r}"
    );
    // Cycles divisible by 3 (10) or 5 (6), both (2): 14 failures, 16 good runs.
    let work = skill(&r, "work");
    assert_eq!(work["failures"], 14, "{work}");
    assert_eq!(work["runs"], 16, "{work}");
    let sink = skill(&r, "sink");
    assert_eq!(sink["runs"], 16, "{sink}");
    assert_eq!(sink["failures"], 0, "{sink}");
}

#[test]
fn a_killed_skill_is_dropped_and_rejoins_when_restarted() {
    let mut t = TestDomain::new("kill");
    t.spawn("skillfab", &["manager", "--period-ms", "2"]);
    let board = t.board();
    t.spawn("ticker", &[]);
    t.wait_until("ticker to run", || {
        registered(&board, "ticker").is_some_and(|s| s.runs > 5)
    });
    let files_without_scale = sorted(t.domain.shm_files());
    let scale = t.spawn("scale", &[]);
    t.wait_until("scale to run", || {
        registered(&board, "scale").is_some_and(|s| s.runs > 20)
    });
    assert_ne!(sorted(t.domain.shm_files()), files_without_scale);

    t.signal(scale, Signal::SIGKILL);
    t.wait_exit(scale);
    t.wait_until("the manager to drop scale", || {
        registered(&board, "scale").is_none()
    });
    // The manager's dead-node cleanup leaves no shared memory of the killed process.
    t.wait_until("the killed skill's shared memory to go", || {
        sorted(t.domain.shm_files()) == files_without_scale
    });
    let ticks = registered(&board, "ticker").unwrap().runs;
    let at = cycle(&board);
    t.wait_until("cycles to go on without scale", || {
        cycle(&board) > at + 50 && registered(&board, "ticker").unwrap().runs > ticks + 50
    });

    let again = t.spawn("scale", &[]);
    t.wait_until("scale to rejoin and run", || {
        registered(&board, "scale").is_some_and(|s| s.runs > 20 && s.decl.pid == t.pid(again))
    });
}

/// A stopped and continued process (Ctrl-Z and `fg`, a debugger attaching) sees its wait end
/// with EINTR, which iceoryx2 reports as an interrupt: only SIGINT/SIGTERM may end it.
#[test]
fn a_stopped_and_continued_skill_or_manager_goes_on() {
    let mut t = TestDomain::new("stopcont");
    let manager = t.spawn("skillfab", &["manager", "--period-ms", "2"]);
    let board = t.board();
    let ticker = t.spawn("ticker", &[]);
    let scale = t.spawn("scale", &[]);
    t.wait_until("scale to run", || {
        registered(&board, "scale").is_some_and(|s| s.runs > 5)
    });
    for who in [scale, ticker, manager] {
        t.signal(who, Signal::SIGSTOP);
        t.signal(who, Signal::SIGCONT);
        let runs = registered(&board, "scale").unwrap().runs;
        t.wait_until("cycles to go on after SIGSTOP/SIGCONT", || {
            registered(&board, "scale").is_some_and(|s| s.runs > runs + 20)
        });
    }
    let s = registered(&board, "scale").unwrap();
    assert_eq!(s.decl.pid, t.pid(scale));
    assert!(board.manager_alive());
}

fn sorted(mut v: Vec<std::path::PathBuf>) -> Vec<std::path::PathBuf> {
    v.sort();
    v
}

#[test]
fn a_type_mismatch_is_refused_naming_both_sides() {
    let mut t = TestDomain::new("mismatch");
    t.spawn("skillfab", &["manager", "--period-ms", "5"]);
    let board = t.board();
    t.spawn("ticker", &[]);
    t.wait_until("ticker", || registered(&board, "ticker").is_some());
    // smooth reads `scaled` (skillfab.Scaled); wire it to `tick` (skillfab.Tick).
    let out = t.run("smooth", &["--name", "wrong", "--remap", "scaled=tick"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("type mismatch on topic 'tick'"), "{err}");
    assert!(
        err.contains("'wrong' input 'scaled' is 'skillfab.Scaled"),
        "{err}"
    );
    assert!(
        err.contains("'ticker' output 'tick' is 'skillfab.Tick"),
        "{err}"
    );
    assert!(registered(&board, "wrong").is_none());
    let c = cycle(&board);
    t.wait_until("cycles to go on", || cycle(&board) > c + 10);
}

#[test]
fn skills_started_before_the_manager_join() {
    let mut t = TestDomain::new("early");
    t.spawn("ticker", &[]);
    t.spawn("scale", &["--param", "gain=0.5"]);
    let out = t.run(
        "skillfab",
        &[
            "manager",
            "--period-ms",
            "2",
            "--deadline-ms",
            "2000",
            "--cycles",
            "40",
            "--wait-for",
            "ticker,scale",
            "--json",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(skill(&r, "ticker")["runs"], 40, "{r}");
    assert_eq!(skill(&r, "scale")["runs"], 40, "{r}");
}

#[test]
fn a_clean_shutdown_leaves_no_files_and_no_processes() {
    let mut t = TestDomain::new("shutdown");
    let launch = t.launch_file(
        "[[process]]\nname = \"ticker\"\nbin = \"{bin:ticker}\"\n[[process]]\nname = \"scale\"\nbin = \"{bin:scale}\"\n[[process]]\nname = \"smooth\"\nbin = \"{bin:smooth}\"\n",
    );
    let up = t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let board = t.board();
    t.wait_until("the network to run", || {
        registered(&board, "smooth").is_some_and(|s| s.runs > 5)
    });
    let pids: Vec<u32> = ["ticker", "scale", "smooth"]
        .iter()
        .map(|n| registered(&board, n).unwrap().decl.pid)
        .collect();
    assert!(
        !t.domain.shm_files().is_empty(),
        "the running fabric has shared memory"
    );
    drop(board);

    t.signal(up, Signal::SIGTERM);
    assert!(t.wait_exit(up).success());
    for pid in pids {
        assert!(
            !skillfab_proto::board::pid_alive(pid),
            "skill process {pid} outlived skillfab up"
        );
    }
    assert_eq!(
        t.domain.shm_files(),
        Vec::<std::path::PathBuf>::new(),
        "files left in /dev/shm"
    );
    assert!(
        !t.domain.root_path().exists(),
        "iceoryx2 root {} left",
        t.domain.root_path().display()
    );
}

#[test]
fn a_bad_launch_file_is_a_clear_error() {
    let t = TestDomain::new("badlaunch");
    let path = t.launch_file(
        "[[process]]\nname = \"x\"\nbin = \"{bin:ticker}\"\nrestart = \"sometimes\"\n",
    );
    let out = t.run("skillfab", &["up", path.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("launch file") && err.contains("sometimes"),
        "{err}"
    );
}

/// A fabric paced for a simulator sped up four times (`time_factor` in the launch file):
/// each 5 ms cycle stands for 20 ms of the clock skills and plans time things in. A factor
/// that is not a positive number, or one given with --lockstep, is refused.
#[test]
fn a_time_factor_makes_each_cycle_stand_for_that_much_more_clock_time() {
    let mut t = TestDomain::new("timefactor");
    let launch = t.launch_file(
        "[manager]\nperiod_ms = 5\ntime_factor = 4.0\n[[process]]\nname = \"ticker\"\nbin = \"{bin:ticker}\"\n",
    );
    t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let board = t.board();
    t.wait_until("ticker to run", || {
        registered(&board, "ticker").is_some_and(|s| s.runs > 5)
    });
    let clock = board.header().clock();
    let period = clock.period.expect("a period").as_nanos();
    assert!(period.abs_diff(20_000_000) <= 1_000, "{clock:?}");
    assert!(!clock.lockstep);
    assert_eq!(clock.time.as_nanos() % period, 0, "{clock:?}");
    for (args, says) in [
        (
            &["--time-factor", "0"][..],
            "--time-factor must be a positive number",
        ),
        (&["--time-factor", "4", "--lockstep"][..], "--time-factor"),
    ] {
        let out = t.run("skillfab", &[&["manager", "--cycles", "1"], args].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(says),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn skillfab_up_restarts_a_killed_skill_by_its_policy() {
    let mut t = TestDomain::new("restart");
    let launch = t.launch_file(
        "[[process]]\nname = \"ticker\"\nbin = \"{bin:ticker}\"\n[[process]]\nname = \"scale\"\nbin = \"{bin:scale}\"\nrestart = \"on-failure\"\nbackoff_ms = 10\n",
    );
    t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let board = t.board();
    t.wait_until("scale to run", || {
        registered(&board, "scale").is_some_and(|s| s.runs > 5)
    });
    let first = registered(&board, "scale").unwrap().decl.pid;
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(first as i32), Signal::SIGKILL).unwrap();
    t.wait_until("a new scale process to run", || {
        registered(&board, "scale").is_some_and(|s| s.decl.pid != first && s.runs > 5)
    });
}

/// Written from the README's naming scheme alone, as a user of plain iceoryx2 would: no
/// skillfab type or function is used to find or read the topic.
#[test]
fn a_plain_iceoryx2_client_reads_a_skills_output_from_the_documented_names() {
    use iceoryx2::prelude::*;

    #[derive(Debug, Clone, Copy, ZeroCopySend)]
    #[type_name("skillfab.Tick")]
    #[repr(C)]
    struct Tick {
        value: u64,
    }
    #[derive(Debug, Clone, Copy, Default, ZeroCopySend)]
    #[type_name("skillfab.SampleHeader")]
    #[repr(C)]
    struct SampleHeader {
        cycle: u64,
        stamp_ns: u64,
        slot: u32,
        reserved: u32,
    }

    let mut t = TestDomain::new("plain");
    t.hello(&[]);
    let name = t.domain.name().to_string();
    let mut config = Config::default();
    config.global.prefix = FileName::new(format!("sf_{name}_").as_bytes()).unwrap();
    config
        .global
        .set_root_path(&Path::new(format!("/tmp/skillfab/{name}/").as_bytes()).unwrap());
    let node = NodeBuilder::new()
        .config(&config)
        .create::<ipc::Service>()
        .unwrap();
    let service = node
        .service_builder(&ServiceName::new("skillfab/topic/tick").unwrap())
        .publish_subscribe::<Tick>()
        .user_header::<SampleHeader>()
        .open()
        .unwrap();
    let subscriber = service
        .subscriber_builder()
        .history_request(1)
        .create()
        .unwrap();
    let mut seen = Vec::new();
    t.wait_until("two ticks read by a plain iceoryx2 subscriber", || {
        while let Some(s) = subscriber.receive().unwrap() {
            seen.push((s.user_header().cycle, s.payload().value));
        }
        seen.len() >= 2
    });
    // The ticker publishes its cycle number, in the header and in the payload.
    for (cycle, value) in &seen {
        assert!(*cycle > 0, "{seen:?}");
        assert_eq!(cycle, value, "{seen:?}");
    }
    // The topic's event service wakes a blocking listener outside the fabric after every
    // sample (the fabric's own consumers sleep on doorbells instead).
    let listener = node
        .service_builder(&ServiceName::new("skillfab/topic/tick").unwrap())
        .event()
        .open()
        .unwrap()
        .listener_builder()
        .create()
        .unwrap();
    let mut last = seen.last().map_or(0, |s| s.0);
    for _ in 0..5 {
        let mut woken = false;
        listener
            .timed_wait(|_| woken = true, skillfab_tests::WAIT)
            .unwrap();
        assert!(woken, "no event within {:?}", skillfab_tests::WAIT);
        let mut newest = None;
        while let Some(s) = subscriber.receive().unwrap() {
            newest = Some(s.user_header().cycle);
        }
        // Woken after the send: a newer sample is there (or was taken at the previous wake).
        if let Some(c) = newest {
            assert!(c > last, "sample of cycle {c} after {last}");
            last = c;
        }
    }
    assert!(
        last > seen.last().map_or(0, |s| s.0),
        "no new sample after the wake-ups"
    );
}

/// The pid of the registered skill `name`, once its process is another than `old`.
fn new_instance(
    t: &TestDomain,
    board: &skillfab_proto::board::Board,
    name: &str,
    old: Option<u32>,
) -> u32 {
    let mut pid = 0;
    t.wait_until("the skill to be registered by a new process", || {
        pid = skillfab_tests::registered(board, name).map_or(0, |s| s.decl.pid);
        pid != 0 && Some(pid) != old
    });
    pid
}

fn kill9(pid: u32) {
    let killed = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(pid as i32),
        nix::sys::signal::Signal::SIGKILL,
    );
    assert!(killed.is_ok(), "SIGKILL to {pid}: {killed:?}");
}

#[test]
fn a_killed_skill_goes_on_from_its_last_completed_run_and_a_clean_leave_drops_its_state() {
    let mut t = TestDomain::new("state");
    let launch = t.launch_file(
        "[manager]\nperiod_ms = 5\n[[process]]\nname = \"counter\"\nbin = \"{bin:counter}\"\nrestart = \"on-failure\"\n",
    );
    t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let board = t.board();
    let shm = std::path::Path::new("/dev/shm").join(format!("{}state_counter", t.domain.prefix()));
    let c = skillfab_client::Client::connect(&t.domain).unwrap();
    let count = || c.query("counter.count.value").unwrap().0.as_f64().unwrap() as u64;
    let first = new_instance(&t, &board, "counter", None);
    t.wait_until("some runs", || {
        skillfab_tests::registered(&board, "counter").is_some_and(|s| s.runs > 20)
    });

    // Killed between two runs: the manager holds the cycle, one step ends a whole run.
    c.stop().unwrap();
    c.step(1).unwrap();
    let before = count();
    assert!(shm.exists(), "the state object {}", shm.display());
    kill9(first);
    let second = new_instance(&t, &board, "counter", Some(first));
    c.step(1).unwrap();
    assert_eq!(
        count(),
        before + 1,
        "the first run after the restart counts on from the last one"
    );

    // Runs that fail (a panic after counting) are undone, as their outputs are dropped.
    c.set_param("counter", "panic_every", "3").unwrap();
    let from = count();
    let k = c.step(9).unwrap();
    let failed = ((k - 8)..=k).filter(|k| k % 3 == 0).count() as u64;
    assert_eq!(count(), from + 9 - failed, "only completed runs count");
    c.set_param("counter", "panic_every", "0").unwrap();

    // Killed inside a run: the run it was in never completed, so it is not kept.
    c.set_param("counter", "dwell_ms", "10000").unwrap();
    c.run().unwrap();
    t.wait_until("a run to be under way", || {
        let s = board.slot(skillfab_tests::registered(&board, "counter").unwrap().slot);
        s.last_start_ns.load(std::sync::atomic::Ordering::Acquire)
            > s.last_end_ns.load(std::sync::atomic::Ordering::Acquire)
    });
    c.stop().unwrap();
    let completed = count();
    kill9(second);
    let third = new_instance(&t, &board, "counter", Some(second));
    c.set_param("counter", "dwell_ms", "0").unwrap();
    c.step(2).unwrap();
    assert_eq!(
        count(),
        completed + 2,
        "the run it was killed in is not kept"
    );

    // A clean leave (SIGTERM; `on-failure` does not restart it): the next one starts afresh.
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(third as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    t.wait_until("the state to be dropped", || !shm.exists());
}
