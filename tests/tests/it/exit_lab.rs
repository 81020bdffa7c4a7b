//! The exit-lab experiment end to end, in fast time: `skillfab demo exit-lab` starts the
//! simulator on a pty, the Denning device process, every standard skill and a manager in a
//! private domain, and its sequencer drives the robot out through the door. A small room
//! keeps the run short.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use nix::sys::signal::Signal;
use skillfab_tests::TestDomain;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

fn world(t: &TestDomain) -> PathBuf {
    t.doorway()
}

fn demo(t: &TestDomain, args: &[&str]) -> Child {
    let w = world(t);
    let mut c = t.command("skillfab");
    c.args(["demo", "exit-lab", "--world", w.to_str().unwrap()])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    c.spawn().unwrap()
}

/// Nothing of the demo with process id `pid` is left: no process whose command line names
/// its domain or directory, no shared-memory file, no iceoryx2 root.
fn assert_nothing_left(pid: u32) {
    let tag = format!("demo-{pid}-");
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let procs: Vec<String> = std::fs::read_dir("/proc")
            .unwrap()
            .flatten()
            .filter_map(|e| std::fs::read(e.path().join("cmdline")).ok())
            .map(|c| String::from_utf8_lossy(&c).replace('\0', " "))
            .filter(|c| c.contains(&tag))
            .collect();
        let shm: Vec<String> = std::fs::read_dir("/dev/shm")
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(&tag))
            .collect();
        let root = PathBuf::from(format!("/tmp/skillfab/{tag}0"));
        if procs.is_empty() && shm.is_empty() && !root.exists() {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "left behind: processes {procs:?}, shared memory {shm:?}, root {} exists: {}",
            root.display(),
            root.exists()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn the_sequencer_drives_the_robot_out_of_the_room() {
    let t = TestDomain::new("exitlab");
    let child = demo(
        &t,
        &[
            "--seed",
            "1",
            "--runs",
            "1",
            "--time-factor",
            "2",
            "--limit-s",
            "150",
            "--json",
        ],
    );
    let pid = child.id();
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "demo failed: {stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(summary["runs"], 1);
    assert_eq!(summary["successes"], 1, "{summary}");
    let run = &summary["runs_detail"][0];
    assert_eq!(run["collisions"], 0, "{run}");
    let t_out = run["time_s"].as_f64().unwrap();
    assert!(t_out > 5.0 && t_out < 150.0, "{run}");
    assert_eq!(summary["median_time_s"].as_f64(), Some(t_out));
    // The paper's sequence, in order, each at a later cycle.
    let order = skillfab_tests::steps_at(
        run,
        &[
            "activate explore",
            "barcode seen",
            "door located",
            "outside the lab",
        ],
    );
    assert!(order.windows(2).all(|w| w[0].0 < w[1].0), "{run}");
    assert!(
        order.windows(2).all(|w| w[0].1 < w[1].1),
        "cycles increase: {run}"
    );
    assert_nothing_left(pid);
}

#[test]
fn ctrl_c_leaves_no_process_or_shared_memory_behind() {
    let t = TestDomain::new("exitlabint");
    let mut child = demo(&t, &["--seed", "2", "--time-factor", "2"]);
    let pid = child.id();
    // Interrupt once the sequencer has started.
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let line = lines.next().expect("demo output").unwrap();
        if line.contains("activate explore") {
            break;
        }
        assert!(Instant::now() < deadline, "the sequencer did not start");
    }
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), Signal::SIGINT).unwrap();
    let status = child.wait().unwrap();
    assert!(!status.success(), "an interrupted demo is not a success");
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert!(err.contains("interrupted"), "{err}");
    assert_nothing_left(pid);
}

/// One lock-step run of the demo (seed 1) in the doorway world: its JSON summary.
fn lockstep_run(t: &TestDomain, extra: &[&str]) -> serde_json::Value {
    let args = [
        &[
            "--lockstep",
            "--seed",
            "1",
            "--runs",
            "1",
            "--limit-s",
            "150",
            "--json",
        ][..],
        extra,
    ]
    .concat();
    let out = demo(t, &args).wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "demo {extra:?} failed: {stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&stdout).unwrap()
}

#[test]
fn the_exit_lab_plan_takes_the_same_steps_in_the_same_cycles_as_the_rust_sequencer() {
    let t = TestDomain::new("exitlabplan");
    let plan = skillfab_tests::repo_root().join("skills/plans/exit-lab.xml");
    let by_plan = lockstep_run(&t, &["--plan", plan.to_str().unwrap()]);
    let by_code = lockstep_run(&t, &[]);
    let (p, c) = (&by_plan["runs_detail"][0], &by_code["runs_detail"][0]);
    assert_eq!(p["success"], true, "{p}");
    assert_eq!(p["collisions"], 0, "{p}");
    assert_eq!(p["time_s"], c["time_s"], "plan {p}\ncode {c}");
    let cycle = |run: &serde_json::Value, what: &str| {
        run["steps"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s[0].as_str().unwrap().starts_with(what))
            .map(|s| s[1].as_u64().unwrap())
            .unwrap_or_else(|| panic!("no step '{what}' in {run}"))
    };
    // (The demo notices "outside" whenever it looks: that step's cycle is not the plan's.)
    for what in ["barcode seen", "door located"] {
        assert_eq!(cycle(p, what), cycle(c, what), "{what}: plan {p}\ncode {c}");
    }
    // The plan lowered avoid's distance for the passage and restored it when halted.
    let steps = p["steps"].to_string();
    assert!(
        steps.contains("avoid.safe_distance = 0.2")
            && steps.contains("avoid.safe_distance restored to 0.6"),
        "{steps}"
    );
}
