//! Deterministic runs: the lock-step simulator (`denning-sim --lockstep`, `up --lockstep`),
//! full-rate recording (`--record`, `ctl record`) and `skillfab replay`.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use nix::sys::signal::Signal;
use serde_json::Value as Json;
use skillfab_client::Client;
use skillfab_manager::recorder::{ReadRecord, read_file};
use skillfab_tests::{TestDomain, bin};
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::atomic::Ordering;

fn world(t: &TestDomain) -> PathBuf {
    t.doorway()
}

/// The robot wandering with avoid in the room, in lock-step, its ground truth in `traj`.
fn wandering(t: &TestDomain, seed: u64, traj: &Path) -> String {
    format!(
        "[manager]\nperiod_ms = 10\n\
         [[process]]\nname = \"denning-sim\"\nbin = \"{{bin:denning-sim}}\"\nregisters = false\n\
         args = [\"--world\", \"{}\", \"--link\", \"{}\", \"--seed\", \"{seed}\", \"--lockstep\", \"--trajectory\", \"{}\"]\n\
         [[process]]\nname = \"denning\"\nbin = \"{{bin:denning}}\"\nargs = [\"--port\", \"{}\"]\n\
         [[process]]\nname = \"avoid\"\nbin = \"{{bin:avoid}}\"\n\
         [[process]]\nname = \"wander\"\nbin = \"{{bin:wander}}\"\nparams = {{ seed = {seed} }}\n",
        world(t).display(),
        t.dir.join("robot").display(),
        traj.display(),
        t.dir.join("robot").display(),
    )
}

#[test]
fn two_lockstep_runs_with_the_same_seed_give_identical_trajectories() {
    let run = |seed: u64, n: u32| {
        let t = TestDomain::new(&format!("lockstep{seed}{n}"));
        let traj = t.dir.join("truth.csv");
        let report = t.up_json(
            &wandering(&t, seed, &traj),
            &["--lockstep", "--cycles", "1500"],
        );
        assert_eq!(report["overruns"], 0, "{report}");
        std::fs::read_to_string(&traj).unwrap()
    };
    let (a, b, c) = (run(4, 0), run(4, 1), run(5, 0));
    // 15 s of robot time, one ground-truth row per 100 ms status period.
    assert!(a.lines().count() > 140, "{a}");
    let moved = a
        .lines()
        .skip(1)
        .filter_map(|l| l.split(',').nth(4)?.parse::<f64>().ok())
        .any(|v| v > 0.1);
    assert!(moved, "the robot drove: {a}");
    assert_eq!(a, b, "the same seed gives the same trajectory");
    assert_ne!(a, c, "another seed another");
}

/// Runs `skillfab replay` with `args`; returns its JSON report and exit status.
pub(crate) fn replay(t: &TestDomain, file: &Path, args: &[&str]) -> (Json, Output) {
    let out = t.run(
        "skillfab",
        &[&["replay", file.to_str().unwrap(), "--json"], args].concat(),
    );
    let report = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "replay report is not JSON ({e}): {} / {}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (report, out)
}

/// Every record of an MCAP recording, in order (a CDR sample as the JSON record of its
/// decoded value and bytes); of a file still being written, those of its closed chunks (none
/// before the first).
pub(crate) fn records(file: &Path) -> Vec<Json> {
    let mut out = Vec::new();
    let _ = read_file(file, |r| {
        out.push(match r {
            ReadRecord::Json(j) => j,
            ReadRecord::Sample(s) => s.to_json(),
        });
    });
    out
}

/// The cycle after which to kill each of `skills` in a replay of `rec`: the middle of the
/// cycles it published in (it runs then, with what it learnt since its activation), in the
/// order of those cycles; and the `--kill` argument that asks for them. A skill of `silent`
/// may have published nothing (active all through, it proposed nothing in this run): it is
/// killed at the middle of the recording's cycles.
pub(crate) fn mid_mission_kills(
    rec: &Path,
    skills: &[&str],
    silent: &[&str],
) -> (Vec<(String, u64)>, String) {
    // Who published in which cycle (a long mission's samples are many: no value decoded).
    let mut heads: Vec<(String, u64)> = Vec::new();
    read_file(rec, |r| {
        if let ReadRecord::Sample(s) = r {
            heads.push((s.channel.skill.clone(), s.cycle));
        }
    })
    .unwrap();
    let mut kills: Vec<(String, u64)> = skills
        .iter()
        .map(|skill| {
            let cycles: Vec<u64> = heads
                .iter()
                .filter(|h| h.0 == *skill)
                .map(|h| h.1)
                .collect();
            // (`deliver` publishes only when its progress changes: a few samples.)
            if cycles.is_empty() && silent.contains(skill) {
                return (skill.to_string(), heads[heads.len() / 2].1);
            }
            assert!(cycles.len() >= 3, "{skill} ran in the recorded mission");
            (skill.to_string(), cycles[cycles.len() / 2])
        })
        .collect();
    kills.sort_by_key(|k| k.1);
    let arg = kills
        .iter()
        .map(|(s, c)| format!("{s}@{c}"))
        .collect::<Vec<_>>()
        .join(",");
    (kills, arg)
}

/// How long a replay with kills goes on after the last one: what a restarted skill forgot
/// shows within a few simulated seconds, and the mission's tail would only add minutes to CI.
const AFTER_LAST_KILL: u64 = 500;

/// `--to` for a replay with `kills`: [`AFTER_LAST_KILL`] cycles after the last.
pub(crate) fn through_last_kill(kills: &[(String, u64)]) -> String {
    let last = kills.iter().map(|k| k.1).max().unwrap_or(0);
    (last + AFTER_LAST_KILL).to_string()
}

/// Asserts that a replay with kills (`--kill`) did them all and diverged nowhere.
pub(crate) fn assert_identical_through(r: &Json, kills: &[(String, u64)]) {
    assert_eq!(r["divergence"], Json::Null, "{r}");
    assert_eq!(r["identical_cycles"], r["cycles"], "{r}");
    let done = r["kills"].as_array().unwrap();
    assert_eq!(done.len(), kills.len(), "every kill done: {r}");
    for (k, (skill, cycle)) in done.iter().zip(kills) {
        assert_eq!(
            (k["skill"].as_str(), k["cycle"].as_u64()),
            (Some(skill.as_str()), Some(*cycle))
        );
        assert_ne!(k["pid"], k["new_pid"], "a new process: {k}");
    }
}

#[test]
fn a_recorded_lockstep_mission_replays_identically_through_kills_and_a_changed_default_is_named() {
    let t = TestDomain::new("replaymission");
    let rec = t.dir.join("mission.mcap");
    // The shipped lab: every skill of the mission has its part in it.
    let exit_lab = skillfab_tests::repo_root().join("devices/denning-sim/worlds/exit-lab.toml");
    let plan = skillfab_tests::repo_root().join("skills/plans/exit-lab.xml");
    let out = t.run(
        "skillfab",
        &[
            "demo",
            "exit-lab",
            "--world",
            exit_lab.to_str().unwrap(),
            "--plan",
            plan.to_str().unwrap(),
            "--lockstep",
            "--record",
            rec.to_str().unwrap(),
            "--json",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let skills = ["--skills", "avoid,explore,barcode_track,home"];

    // Each skill of the mission killed (SIGKILL) mid-mission, between two runs, and started
    // again: its first run after the restart starts from the state of its last completed run,
    // so every output it makes from there on is the one the uninterrupted run made.
    let ours = [
        "avoid",
        "explore",
        "barcode_track",
        "home",
        "wall_follow",
        "door_locate",
        "go_through",
    ];
    // (`avoid` proposes only with something near the way ahead: in this run, since the lab
    // plan lowered its `beside` while `explore` and `home` drive, nothing.)
    let (kills, kill_list) = mid_mission_kills(&rec, &ours, &["avoid"]);
    let to = through_last_kill(&kills);
    let all = [
        "--skills",
        &ours.join(","),
        "--kill",
        &kill_list,
        "--to",
        &to,
    ];
    let (r, out) = replay(&t, &rec, &all);
    assert!(out.status.success(), "{r}");
    assert_identical_through(&r, &kills);
    assert!(r["cycles"].as_u64().unwrap() > 1000, "{r}");
    assert!(
        r["samples"].as_u64().unwrap() > 1000,
        "outputs compared: {r}"
    );
    // The same kills, the kept state removed before each restart (as a skill that keeps
    // nothing): the replay diverges after a kill — the comparison sees a forgotten state.
    let (r, out) = replay(&t, &rec, &[&all[..], &["--forget"]].concat());
    assert!(!out.status.success(), "a skill that forgot diverges: {r}");
    let first_kill = kills.iter().map(|k| k.1).min().unwrap();
    assert!(
        r["divergence"]["cycle"].as_u64().unwrap() > first_kill,
        "not before the first kill: {r}"
    );

    // home as if rebuilt with another default speed (0.3 m/s instead of 0.35): a wrapper
    // that passes it, in a directory of its own.
    let bins = t.dir.join("rebuilt");
    std::fs::create_dir_all(&bins).unwrap();
    for b in ["avoid", "explore", "barcode_track"] {
        std::os::unix::fs::symlink(bin(b), bins.join(b)).unwrap();
    }
    let wrapper = bins.join("home");
    std::fs::write(
        &wrapper,
        format!(
            "#!/bin/sh\nexec {} \"$@\" --param speed=0.3\n",
            bin("home").display()
        ),
    )
    .unwrap();
    std::fs::set_permissions(
        &wrapper,
        std::os::unix::fs::PermissionsExt::from_mode(0o755),
    )
    .unwrap();
    let (r, out) = replay(
        &t,
        &rec,
        &[&skills[..], &["--bin-dir", bins.to_str().unwrap()]].concat(),
    );
    assert!(!out.status.success(), "a divergence fails the replay: {r}");
    let d = &r["divergence"];
    // The first cycle whose recorded proposal of home drives forward: the speed's first use.
    let first_use = records(&rec)
        .into_iter()
        .find(|j| {
            j["kind"] == "sample"
                && j["skill"] == "home"
                && j["port"] == "drive"
                && j["value"]["translate"].as_f64().unwrap_or(0.0) != 0.0
        })
        .expect("home drove");
    assert_eq!(d["cycle"], first_use["cycle"], "{r}");
    assert_eq!(
        (d["skill"].as_str(), d["port"].as_str()),
        (Some("home"), Some("drive"))
    );
    assert_eq!(d["field"], "translate", "{r}");
    let ratio = d["replayed"].as_f64().unwrap() / d["recorded"].as_f64().unwrap();
    assert!(
        (ratio - 0.3 / 0.35).abs() < 1e-6,
        "scaled by the speed: {r}"
    );
}

#[test]
fn a_recording_cut_short_by_kill_9_replays_to_its_last_complete_cycle_wander_killed_on_the_way() {
    let mut t = TestDomain::new("replaykill");
    let traj = t.dir.join("truth.csv");
    let launch = t.launch_file(&wandering(&t, 2, &traj));
    t.spawn(
        "skillfab",
        &["up", launch.to_str().unwrap(), "--lockstep", "--paused"],
    );
    let board = t.board();
    let c = Client::connect(&t.domain).unwrap();
    t.wait_until("the network cycles", || {
        c.list().is_ok_and(|l| l.len() == 3)
    });
    let rec = t.dir.join("cut.mcap");
    let out = t.run(
        "skillfab",
        &["ctl", "record", "start", rec.to_str().unwrap()],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(t.run("skillfab", &["ctl", "run"]).status.success());
    let start = 0;
    // Killed once the file on disk holds more than 500 complete cycles (the recorder writes
    // behind the cycles; how far behind depends on the machine's load).
    let complete = |rec: &std::path::Path| {
        records(rec)
            .iter()
            .filter(|j| j["kind"] == "cycle")
            .filter_map(|j| j["cycle"].as_u64())
            .max()
            .unwrap_or(0)
    };
    t.wait_until("recorded cycles", || complete(&rec) > start + 600);
    let pid = board.header().manager_pid.load(Ordering::Acquire);
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), Signal::SIGKILL).unwrap();
    let recorded: Vec<Json> = records(&rec);
    let last = recorded
        .iter()
        .filter(|j| j["kind"] == "cycle")
        .filter_map(|j| j["cycle"].as_u64())
        .max()
        .expect("complete cycles");
    assert!(
        last > start + 500,
        "cycles recorded before the kill: {last}"
    );
    // From the first cycle on, so wander's memory is replayed too; wander killed half-way
    // and started again goes on with it (its visit map, its generator).
    let (kills, kill_list) = mid_mission_kills(&rec, &["wander"], &[]);
    let (r, out) = replay(
        &t,
        &rec,
        &["--skills", "avoid,wander", "--kill", &kill_list],
    );
    assert!(
        out.status.success(),
        "{r} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(r["to"], last, "up to the last complete cycle: {r}");
    assert_identical_through(&r, &kills);
    assert!(
        r["samples"].as_u64().unwrap() > 500,
        "proposals compared: {r}"
    );
}

#[test]
fn a_recording_of_json_samples_holds_what_a_cdr_one_holds_and_replays_as_well() {
    let t = TestDomain::new("replayjson");
    let traj = t.dir.join("truth.csv");
    let launch = wandering(&t, 3, &traj);
    let (json, cdr) = (t.dir.join("json.mcap"), t.dir.join("cdr.mcap"));
    for (file, encoding) in [(&json, "json"), (&cdr, "cdr")] {
        let report = t.up_json(
            &launch,
            &[
                "--lockstep",
                "--cycles",
                "800",
                "--record",
                file.to_str().unwrap(),
                "--record-encoding",
                encoding,
            ],
        );
        assert_eq!(report["overruns"], 0, "{report}");
    }
    // Each file's samples in its encoding.
    let encodings = |file: &Path| {
        let bytes = std::fs::read(file).unwrap();
        let mut seen = std::collections::BTreeSet::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            if m.channel.topic == "/wander/out/drive" {
                seen.insert(m.channel.message_encoding.clone());
            }
        }
        seen.into_iter().collect::<Vec<_>>()
    };
    assert_eq!(encodings(&json), ["json"]);
    assert_eq!(encodings(&cdr), ["cdr"]);
    // One seed, one run: every sample's cycle, producer and bytes alike in both (a JSON
    // file's `raw` holds the padding the publisher's memory held, a CDR one zeros: the JSON
    // sample's padding is zeroed through its schema).
    let samples = |file: &Path| -> Vec<(u64, String, String, String, Vec<u8>)> {
        let mut out = Vec::new();
        read_file(file, |r| match r {
            ReadRecord::Sample(s) => out.push((
                s.cycle,
                s.channel.skill.clone(),
                s.channel.port.clone(),
                s.channel.schema.type_name.clone(),
                s.bytes,
            )),
            ReadRecord::Json(j) if j["kind"] == "sample" => {
                let text = |k: &str| j[k].as_str().unwrap().to_string();
                let schema = skillfab_msgs::registry()
                    .iter()
                    .find(|t| t.type_name == j["type"])
                    .map(|t| (t.schema)())
                    .unwrap();
                let raw = skillfab_manager::recorder::unhex(j["raw"].as_str().unwrap()).unwrap();
                let mut cdr = Vec::new();
                skillfab_proto::cdr::encode(&schema, &raw, &mut cdr);
                out.push((
                    j["cycle"].as_u64().unwrap(),
                    text("skill"),
                    text("port"),
                    text("type"),
                    skillfab_proto::cdr::decode(&schema, &cdr).unwrap(),
                ));
            }
            ReadRecord::Json(_) => {}
        })
        .unwrap();
        out
    };
    let (a, b) = (samples(&json), samples(&cdr));
    assert!(a.len() > 2000, "{} samples", a.len());
    if let Some(i) = (0..a.len().min(b.len())).find(|&i| a[i] != b[i]) {
        panic!("sample {i}: JSON {:?} / CDR {:?}", a[i], b[i]);
    }
    assert_eq!(a.len(), b.len());
    // Both replay, cycle for cycle.
    for file in [&json, &cdr] {
        let (r, out) = replay(&t, file, &["--skills", "avoid,wander"]);
        assert!(out.status.success(), "{}: {r}", file.display());
        assert_eq!(r["divergence"], Json::Null, "{r}");
        assert_eq!(r["identical_cycles"], r["cycles"], "{r}");
        assert!(
            r["samples"].as_u64().unwrap() >= 800,
            "outputs compared: {r}"
        );
    }
}
