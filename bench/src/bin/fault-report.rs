//! `fault-report`: the exit-lab mission under injected faults, and what they cost.
//!
//! ```text
//! fault-report [--json] [--runs N] [--seed S] [--time-factor F] [--world FILE] [--kill-every S]
//!              [--only NAME] [--plan FILE.xml] [--mission deliver [--building FILE]]
//! fault-report --soak CYCLES [--json]
//! fault-report --clients [SECS] [--json]
//! ```
//!
//! Each scenario is one `skillfab demo exit-lab --runs N --json` (with `--mission deliver`,
//! `skillfab demo deliver`; with `--plan`, the exit-lab mission driven by that plan) with its
//! faults (release binaries beside this one): `kill` — SIGKILL to a random fabric process
//! (the manager, the Denning device, any skill, and the plan's runner when a plan drives:
//! each is restarted at once, a plan runner resumes the plan) every S simulated seconds;
//! `swap` — the device alone killed (hot-swapped by `up`) every 12 s with the robot in real
//! time (time factor 1 whatever `--time-factor` says);
//! `corrupt-1`, `corrupt-5` — 1 % / 5 % of the serial bytes with a flipped bit; `drop-1` —
//! 1 % of them dropped; `sim-restart` — the simulator (the robot's serial side) killed every
//! 60 simulated seconds and restarted where the robot was. Per scenario: missions out of the lab, median mission time, the longest time
//! without a drive command at the robot and the longest it moved on a stale one (from the
//! simulator's ground truth), kills and their recovery (signal → the new instance registered
//! and, if active, its first run), cycles the killed units missed, and the serial link's
//! frames, bad frames, garbage bytes and connects.
//!
//! `--clients SECS` runs the hello network at 100 Hz for SECS alone and SECS under
//! misbehaving clients ([`skillfab_bench::crowd`]): cycles, overruns and latency per window.
//!
//! `--soak CYCLES` instead runs the hello and the exit-lab networks back to back for that many
//! cycles each and samples every process of the domain (resident memory, open fds, threads)
//! and the domain's `/dev/shm` bytes; it reports the slopes after warm-up
//! ([`skillfab_bench::soak`]).

use serde_json::{Value, json};
use std::path::PathBuf;
use std::process::Command;

struct Scenario {
    name: &'static str,
    args: Vec<String>,
}

fn arg_value(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Runs one scenario; returns its summary.
fn run(
    skillfab: &PathBuf,
    mission: &str,
    s: &Scenario,
    common: &[String],
) -> Result<Value, String> {
    eprintln!("fault-report: {mission} {} ({})", s.name, s.args.join(" "));
    let out = Command::new(skillfab)
        .args(["demo", mission, "--json"])
        .args(common)
        .args(&s.args)
        .output()
        .map_err(|e| format!("{}: {e}", skillfab.display()))?;
    // A scenario where no run left the lab exits non-zero but still prints its summary.
    let demo: Value = serde_json::from_slice(&out.stdout).map_err(|e| {
        format!(
            "{}: no summary ({e}): {}",
            s.name,
            String::from_utf8_lossy(&out.stderr)
        )
    })?;
    let runs = demo["runs_detail"].as_array().cloned().unwrap_or_default();
    let max_of = |key: &str| {
        runs.iter()
            .filter_map(|r| r[key].as_f64())
            .fold(0.0, f64::max)
    };
    let kills: Vec<&Value> = runs
        .iter()
        .flat_map(|r| r["kills"].as_array().into_iter().flatten())
        .collect();
    let mut recovery: Vec<f64> = kills
        .iter()
        .filter_map(|k| k["recovery_ms"].as_f64())
        .collect();
    let unrecovered = kills.len() - recovery.len();
    // Recovery by what was killed: the manager, the device, the simulator, the plan's
    // runner, a skill.
    let class = |t: &str| match t {
        "manager" | "denning" | "denning-sim" | "plan" => t.to_string(),
        _ => "skill".to_string(),
    };
    let mut by_target: std::collections::BTreeMap<String, Vec<f64>> = Default::default();
    for k in &kills {
        let t = class(k["target"].as_str().unwrap_or(""));
        let v = by_target.entry(t).or_default();
        if let Some(ms) = k["recovery_ms"].as_f64() {
            v.push(ms);
        }
    }
    let by_target: serde_json::Map<String, Value> = by_target
        .into_iter()
        .map(|(t, mut v)| {
            let n = v.len();
            (t, json!({"recovered": n, "ms_p50": quantile(&mut v, 0.5), "ms_max": quantile(&mut v, 1.0)}))
        })
        .collect();
    let cycles_lost: u64 = kills.iter().filter_map(|k| k["cycles_lost"].as_u64()).sum();
    let sum_of = |field: &str, i: usize| -> u64 {
        runs.iter()
            .filter_map(|r| r[field].as_array().and_then(|l| l.get(i)?.as_u64()))
            .sum()
    };
    let link_sum = |i: usize| sum_of("link", i);
    let failures: Vec<Value> = runs
        .iter()
        .filter(|r| r["success"] != json!(true))
        .map(|r| json!({"seed": r["seed"], "time_s": r["time_s"], "last_step": r["steps"].as_array().and_then(|s| s.iter().rev().nth(1)).cloned()}))
        .collect();
    Ok(json!({
        "mission": mission,
        "scenario": s.name,
        "args": s.args.join(" "),
        "runs": demo["runs"],
        // Out of the lab (exit-lab), or the message delivered (deliver).
        "out_of_the_lab": demo["successes"],
        "median_time_s": demo["median_time_s"],
        "collisions": runs.iter().filter_map(|r| r["collisions"].as_u64()).sum::<u64>(),
        "safety_slowed": sum_of("safety", 0),
        "safety_stopped": sum_of("safety", 1),
        "safety_blind": sum_of("safety", 2),
        "max_command_gap_s": max_of("max_command_gap_s"),
        "max_stale_drive_s": max_of("max_stale_drive_s"),
        "kills": kills.len(),
        "unrecovered": unrecovered,
        "recovery_ms_p50": quantile(&mut recovery, 0.5),
        "recovery_ms_max": quantile(&mut recovery, 1.0),
        "recovery_by_target": by_target,
        "cycles_lost": cycles_lost,
        "frames": link_sum(0),
        "bad_frames": link_sum(1),
        "garbage_bytes": link_sum(2),
        "connects": link_sum(3),
        "failures": failures,
    }))
}

fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--help" || a == "-h") {
        println!(
            "usage: fault-report [--json] [--runs N] [--seed S] [--time-factor F] [--world FILE] [--kill-every S]\n                    [--only NAME] [--plan FILE.xml] [--mission deliver [--building FILE]]\n       fault-report --soak CYCLES [--json]\n       fault-report --clients [SECS] [--json]"
        );
        return std::process::ExitCode::SUCCESS;
    }
    let json_out = args.iter().any(|a| a == "--json");
    if args.iter().any(|a| a == "--clients") {
        let secs: f64 = arg_value(&args, "--clients")
            .and_then(|v| v.parse().ok())
            .unwrap_or(10.0);
        eprintln!(
            "fault-report: hello at 100 Hz, {secs} s alone, then {secs} s under misbehaving clients"
        );
        return match skillfab_bench::crowd::crowd(secs) {
            Ok((alone, abused)) => {
                let w = |name: &str, w: &skillfab_bench::crowd::Window| {
                    json!({"window": name, "cycles": w.cycles, "overruns": w.overruns,
                        "cycle_latency_us_p50": w.latency_us.0, "cycle_latency_us_p99": w.latency_us.1,
                        "answer_us_p50": w.answer_us.0, "answer_us_p99": w.answer_us.1,
                        "answers": w.answers, "abuse_answered": w.abuse_answered,
                        "abuse_failed": w.abuse_failed})
                };
                let out = [w("alone", &alone), w("misbehaving clients", &abused)];
                if json_out {
                    println!("{}", Value::Array(out.to_vec()));
                } else {
                    println!(
                        "{:<20} {:>7} {:>9} {:>22} {:>24} {:>16}",
                        "window",
                        "cycles",
                        "overruns",
                        "cycle p50/p99 µs",
                        "good client p50/p99 µs",
                        "abuse ok/failed"
                    );
                    for r in &out {
                        let f = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
                        println!(
                            "{:<20} {:>7} {:>9} {:>22} {:>24} {:>16}",
                            r["window"].as_str().unwrap_or(""),
                            r["cycles"],
                            r["overruns"],
                            format!(
                                "{:.0}/{:.0}",
                                f("cycle_latency_us_p50"),
                                f("cycle_latency_us_p99")
                            ),
                            format!("{:.0}/{:.0}", f("answer_us_p50"), f("answer_us_p99")),
                            format!("{}/{}", r["abuse_answered"], r["abuse_failed"]),
                        );
                    }
                }
                std::process::ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("fault-report: {e}");
                std::process::ExitCode::FAILURE
            }
        };
    }
    if let Some(n) = arg_value(&args, "--soak") {
        let Ok(cycles) = n.parse::<u64>() else {
            eprintln!("fault-report: --soak takes a number of cycles, got '{n}'");
            return std::process::ExitCode::FAILURE;
        };
        let mut out = Vec::new();
        for network in ["hello", "exit-lab"] {
            eprintln!("fault-report: soak {network}, {cycles} cycles back to back");
            match skillfab_bench::soak::soak(network, cycles, std::time::Duration::from_secs(1)) {
                Ok(s) => out.push(s.json()),
                Err(e) => {
                    eprintln!("fault-report: {e}");
                    return std::process::ExitCode::FAILURE;
                }
            }
        }
        if json_out {
            println!("{}", Value::Array(out));
        } else {
            println!(
                "{:<9} {:>9} {:>7} {:>6} {:>28} {:>34}",
                "network",
                "cycles",
                "secs",
                "procs",
                "after warm-up rss/fds/thr/shm",
                "slope per 100k cycles rss/fds/thr/shm"
            );
            for s in &out {
                let a = &s["after_warm_up"];
                let d = &s["slope_per_100k_cycles"];
                let f = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
                println!(
                    "{:<9} {:>9} {:>7.0} {:>6} {:>28} {:>34}",
                    s["network"].as_str().unwrap_or(""),
                    s["cycles"],
                    f(&s["secs"]),
                    a["processes"],
                    format!(
                        "{:.0}K/{}/{}/{:.0}K",
                        f(&a["rss_kib"]),
                        a["fds"],
                        a["threads"],
                        f(&a["shm_kib"])
                    ),
                    format!(
                        "{:+.1}K/{:+.2}/{:+.2}/{:+.1}K",
                        f(&d["rss_kib"]),
                        f(&d["fds"]),
                        f(&d["threads"]),
                        f(&d["shm_kib"])
                    ),
                );
            }
        }
        return std::process::ExitCode::SUCCESS;
    }
    let runs = arg_value(&args, "--runs").unwrap_or_else(|| "20".into());
    let tf = arg_value(&args, "--time-factor").unwrap_or_else(|| "4".into());
    let every = arg_value(&args, "--kill-every").unwrap_or_else(|| "5".into());
    let only = arg_value(&args, "--only");
    let mut common = vec!["--runs".to_string(), runs];
    if let Some(seed) = arg_value(&args, "--seed") {
        common.extend(["--seed".into(), seed]);
    }
    let mission = arg_value(&args, "--mission").unwrap_or_else(|| "exit-lab".into());
    match mission.as_str() {
        "exit-lab" => {
            if let Some(w) = arg_value(&args, "--world") {
                common.extend(["--world".into(), w]);
            }
        }
        "deliver" => {
            if let Some(b) = arg_value(&args, "--building") {
                common.extend(["--building".into(), b]);
            }
        }
        other => {
            eprintln!("fault-report: --mission is exit-lab or deliver, not '{other}'");
            return std::process::ExitCode::FAILURE;
        }
    }
    if let Some(p) = arg_value(&args, "--plan") {
        common.extend(["--plan".into(), p]);
    }
    let scenarios = [
        Scenario {
            name: "kill",
            args: vec![
                "--kill-every".into(),
                every,
                "--time-factor".into(),
                tf.clone(),
            ],
        },
        // The device hot-swapped: SIGKILL every 12 s with the robot in real time.
        Scenario {
            name: "swap",
            args: [
                "--kill-every",
                "12",
                "--kill-only",
                "denning",
                "--time-factor",
                "1",
            ]
            .map(String::from)
            .to_vec(),
        },
        Scenario {
            name: "corrupt-1",
            args: vec![
                "--corrupt-rate".into(),
                "0.01".into(),
                "--time-factor".into(),
                tf.clone(),
            ],
        },
        Scenario {
            name: "corrupt-5",
            args: vec![
                "--corrupt-rate".into(),
                "0.05".into(),
                "--time-factor".into(),
                tf.clone(),
            ],
        },
        Scenario {
            name: "drop-1",
            args: vec![
                "--drop-rate".into(),
                "0.01".into(),
                "--time-factor".into(),
                tf.clone(),
            ],
        },
        Scenario {
            name: "sim-restart",
            args: vec![
                "--kill-sim-every".into(),
                "60".into(),
                "--time-factor".into(),
                tf,
            ],
        },
    ];
    let skillfab = skillfab_tests::bin("skillfab");
    let mut results = Vec::new();
    for s in scenarios
        .iter()
        .filter(|s| only.as_deref().is_none_or(|o| s.name.contains(o)))
    {
        match run(&skillfab, &mission, s, &common) {
            Ok(r) => results.push(r),
            Err(e) => {
                eprintln!("fault-report: {e}");
                return std::process::ExitCode::FAILURE;
            }
        }
    }
    if json_out {
        println!("{}", Value::Array(results));
    } else {
        println!(
            "{:<10} {:>9} {:>8} {:>7} {:>9} {:>9} {:>6} {:>14} {:>8} {:>22}",
            "scenario",
            "out/runs",
            "median",
            "coll",
            "cmd gap",
            "stale",
            "kills",
            "recovery p50/max",
            "cyc lost",
            "frames/bad/garb/conn"
        );
        for r in &results {
            println!(
                "{:<10} {:>4}/{:<4} {:>7.1}s {:>7} {:>8.2}s {:>8.2}s {:>6} {:>7.0}/{:<6.0}ms {:>8} {:>22}",
                r["scenario"].as_str().unwrap_or(""),
                r["out_of_the_lab"],
                r["runs"],
                r["median_time_s"].as_f64().unwrap_or(f64::NAN),
                r["collisions"],
                r["max_command_gap_s"].as_f64().unwrap_or(f64::NAN),
                r["max_stale_drive_s"].as_f64().unwrap_or(f64::NAN),
                r["kills"],
                r["recovery_ms_p50"].as_f64().unwrap_or(f64::NAN),
                r["recovery_ms_max"].as_f64().unwrap_or(f64::NAN),
                r["cycles_lost"],
                format!(
                    "{}/{}/{}/{}",
                    r["frames"], r["bad_frames"], r["garbage_bytes"], r["connects"]
                ),
            );
        }
    }
    std::process::ExitCode::SUCCESS
}
