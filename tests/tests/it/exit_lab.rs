//! The exit-lab experiment end to end, in fast time: `skillfab demo exit-lab` starts the
//! simulator on a pty, the Denning device process, every standard skill and a manager in a
//! private domain, and its plan (`skills/plans/exit-lab.xml`) drives the robot out through the
//! door. A small room keeps the run short.

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
    let plan = skillfab_tests::repo_root().join("skills/plans/exit-lab.xml");
    c.args(["demo", "exit-lab", "--world", w.to_str().unwrap()])
        .args(["--plan", plan.to_str().unwrap()])
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
fn the_plan_drives_the_robot_out_of_the_room() {
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
    // The paper's sequence (skills/plans/exit-lab.xml), in order. The barcode is in view from
    // the start, and a skill's first output comes in the cycle it is activated in, so
    // "barcode seen" may share explore's cycle; each later step comes at a later cycle.
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
    assert!(order[0].1 <= order[1].1, "cycles increase: {run}");
    assert!(
        order[1..].windows(2).all(|w| w[0].1 < w[1].1),
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

/// What a run's records hold of the host rather than of the run: the host's clock (events'
/// times, samples' publication stamps), process ids, the domain's name, clients' names (process
/// ids in them), a sample's raw bytes (its decoded value is compared; its padding bytes
/// are whatever its producer's stack held), and the running plan's name (its file: the demo's
/// copy of it, in a directory named after the demo's process).
const OF_THE_HOST: [&str; 9] = [
    "time_ns", "unix_ms", "stamp_ns", "pid", "domain", "client", "by", "raw", "plan",
];

/// The device's serial-link statistics (frames, connections), counted from before the first
/// cycle, when the device may connect twice as the simulator's pty appears: of the host too.
const LINK_TOPIC: &str = "link";

/// Takes [`OF_THE_HOST`] out of `v`, at any depth.
fn without_host(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Object(o) => {
            for k in OF_THE_HOST {
                o.remove(k);
            }
            o.values_mut().for_each(without_host);
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(without_host),
        _ => {}
    }
}

/// Every record of an MCAP recording, in order (a CDR sample as the JSON record of its
/// decoded value and bytes), without what is of the host ([`OF_THE_HOST`]).
fn records(file: &std::path::Path) -> Vec<serde_json::Value> {
    let text = skillfab_manager::recorder::read_records(file).unwrap();
    text.lines()
        .map(|l| {
            let mut r: serde_json::Value = serde_json::from_str(l).unwrap();
            without_host(&mut r);
            r
        })
        .filter(|r| r["topic"] != LINK_TOPIC)
        .collect()
}

/// `records` with those of the host's start-up and shut-down (before the first cycle, after
/// the last cycle's marker: processes register and leave in the order the host starts and
/// stops them) sorted, without their events' numbers.
fn ends_as_sets(mut records: Vec<serde_json::Value>) -> Vec<serde_json::Value> {
    let sorted = |part: Vec<serde_json::Value>| {
        let mut text: Vec<String> = part
            .into_iter()
            .map(|mut r| {
                if let Some(o) = r.as_object_mut() {
                    o.remove("seq");
                }
                r.to_string()
            })
            .collect();
        text.sort();
        text.iter()
            .map(|r| serde_json::from_str(r).unwrap())
            .collect::<Vec<serde_json::Value>>()
    };
    let first = records.iter().take_while(|r| r["cycle"] == 0).count();
    let last = records
        .iter()
        .rposition(|r| r["kind"] == "cycle")
        .unwrap_or(0)
        + 1;
    let end = sorted(records.split_off(last.max(first)));
    let mut out = sorted(records.drain(..first).collect());
    out.extend(records);
    out.extend(end);
    out
}

#[test]
fn two_lockstep_runs_of_one_seed_take_the_same_steps_and_record_the_same_run() {
    let t = TestDomain::new("exitlabtwice");
    let files = |i: u32| {
        (
            t.dir.join(format!("run{i}.mcap")),
            t.dir.join(format!("truth{i}.csv")),
        )
    };
    // Lock-step runs do not depend on the host's load: both at once.
    let [a, b] = std::thread::scope(|s| {
        [0, 1]
            .map(|i| {
                let t = &t;
                s.spawn(move || {
                    let (rec, truth) = files(i);
                    let summary = lockstep_run(
                        t,
                        &[
                            "--record",
                            rec.to_str().unwrap(),
                            "--truth",
                            truth.to_str().unwrap(),
                        ],
                    );
                    (
                        summary["runs_detail"][0].clone(),
                        records(&rec),
                        std::fs::read_to_string(&truth).unwrap(),
                    )
                })
            })
            .map(|h| h.join().unwrap())
    });
    assert_eq!(a.0["success"], true, "{}", a.0);
    let outside = a.0["steps"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s[0] == "outside the lab: stop");
    assert!(outside.is_some(), "the judge's step is in the log: {}", a.0);
    // The plan lowered avoid's distance for the passage and restored it when halted.
    let steps = a.0["steps"].to_string();
    assert!(
        steps.contains("avoid.safe_distance = 0.2")
            && steps.contains("avoid.safe_distance restored to 0.6"),
        "{steps}"
    );
    // Every step at the same cycle and robot time, the judge's included.
    assert_eq!(a.0["steps"], b.0["steps"]);
    assert_eq!((&a.0["time_s"], &a.0["end"]), (&b.0["time_s"], &b.0["end"]));
    // Every sample, control change, event and cycle marker of the recordings.
    let (a1, b1) = (ends_as_sets(a.1), ends_as_sets(b.1));
    let (a, b) = ((a.0, a1, a.2), (b.0, b1, b.2));
    assert!(
        a.1.len() > 10_000,
        "a whole run recorded: {} records",
        a.1.len()
    );
    let n = a.1.len().min(b.1.len());
    if let Some(i) = (0..n).find(|&i| a.1[i] != b.1[i]) {
        panic!(
            "record {i} of {} / {} differs:\n{}\n{}\nbefore it:\n{}",
            a.1.len(),
            b.1.len(),
            a.1[i],
            b.1[i],
            a.1[i.saturating_sub(3)..i]
                .iter()
                .map(|r| r.to_string())
                .collect::<Vec<_>>()
                .join("\n")
        );
    }
    assert_eq!(
        a.1.len(),
        b.1.len(),
        "as many records; the rest of the longer: {:?}",
        &a.1.get(n..).or(b.1.get(n..))
    );
    // The ground truth, row for row.
    assert!(a.2.lines().count() > 150, "{}", a.2);
    assert_eq!(a.2, b.2, "the same trajectory");
}
