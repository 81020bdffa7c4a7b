//! `record-report`: what full-rate recording (`skillfab up --record`) costs the cycle.
//!
//! ```text
//! record-report [--pairs N] [--cycles C] [--world FILE] [--record-encoding cdr|json] [--json]
//! ```
//!
//! The exit-lab network in real time at 100 Hz — simulator, Denning device, wander, avoid and
//! barcode_track active, every other standard skill registered and idle — runs C cycles
//! (default 3000) without and with recording every topic, N times each (default 5),
//! interleaved and alternating which goes first, on release binaries beside this one. Per run:
//! the manager's cycle latency (cycle start → last run done) p50/p99 and overruns; per
//! recorded run: complete cycles in the file, samples, cycles in which a device output is
//! missing, samples out of order, bytes per cycle. `--record-encoding` is passed to `up`
//! (samples as CDR, the default, or JSON).

use serde_json::{Value, json};
use skillfab_bench::network::{arg_value, arg_world, because, launch, median};
use std::path::Path;
use std::process::Command;

/// One `skillfab up` run; returns the manager's report.
fn run(
    skillfab: &Path,
    dir: &Path,
    tag: &str,
    cycles: u64,
    record: Option<&Path>,
) -> Result<Value, String> {
    let link = dir.join(format!("robot-{tag}"));
    let file = dir.join(format!("{tag}.toml"));
    let world = arg_world()?;
    std::fs::write(&file, launch(&world, &link)).map_err(because("launch file"))?;
    let mut c = Command::new(skillfab);
    c.arg("up")
        .arg(&file)
        .args(["--cycles", &cycles.to_string(), "--json"])
        .args(["--domain", &format!("rec-{}-{tag}", std::process::id())])
        .env_remove("SKILLFAB_DOMAIN");
    if let Some(r) = record {
        c.arg("--record").arg(r);
        let args: Vec<String> = std::env::args().collect();
        if let Some(e) = arg_value(&args, "--record-encoding") {
            c.args(["--record-encoding", &e]);
        }
    }
    let out = c.output().map_err(because("skillfab up"))?;
    serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("no report ({e}): {}", String::from_utf8_lossy(&out.stderr)))
}

/// What a recording holds: complete cycles, samples, cycles missing a device output,
/// out-of-order samples, bytes.
fn inspect(path: &Path) -> Result<Value, String> {
    let text = skillfab_manager::recorder::read_records(path).map_err(because("recording"))?;
    let mut cycles = std::collections::BTreeMap::<u64, u64>::new();
    let mut overruns = std::collections::BTreeSet::new();
    let (mut samples, mut out_of_order, mut sonar) =
        (0u64, 0u64, std::collections::BTreeSet::new());
    for line in text.lines() {
        let j: Value = serde_json::from_str(line).map_err(because("a record"))?;
        match j["kind"].as_str() {
            Some("cycle") => {
                cycles.insert(
                    j["cycle"].as_u64().unwrap_or(0),
                    j["samples"].as_u64().unwrap_or(0),
                );
                out_of_order = j["out_of_order"].as_u64().unwrap_or(0);
            }
            Some("event") if j["event"] == "cycle_overrun" => {
                overruns.extend(j["cycle"].as_u64());
            }
            Some("sample") => {
                samples += 1;
                if j["skill"] == "denning" && j["port"] == "sonar" {
                    sonar.extend(j["cycle"].as_u64());
                }
            }
            _ => {}
        }
    }
    // The device publishes its sample at the start of every cycle it runs in: a cycle without
    // its sonar sample is one the device missed (an overrun closed the cycle before it ran)
    // or one the recording lost.
    let first = sonar.first().copied().unwrap_or(0);
    let (in_overruns, otherwise): (Vec<u64>, Vec<u64>) = cycles
        .keys()
        .filter(|k| **k >= first && !sonar.contains(k))
        .partition(|k| overruns.contains(k));
    let missing = in_overruns.len() + otherwise.len();
    let bytes = std::fs::metadata(path).map_or(0, |m| m.len());
    Ok(json!({
        "cycles": cycles.len(), "samples": samples, "device_cycles_missing": missing,
        "missing_in_overrun_cycles": in_overruns.len(), "missing_otherwise": otherwise.len(),
        "overruns": overruns.len(),
        "out_of_order": out_of_order, "bytes_per_cycle": bytes / (cycles.len().max(1) as u64),
    }))
}

fn main() -> std::process::ExitCode {
    match report() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("record-report: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn report() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    let pairs: u32 = arg_value(&args, "--pairs")
        .and_then(|v| v.parse().ok())
        .unwrap_or(5);
    let cycles: u64 = arg_value(&args, "--cycles")
        .and_then(|v| v.parse().ok())
        .unwrap_or(3000);
    let json_out = args.iter().any(|a| a == "--json");
    let here = std::env::current_exe().map_err(because("own path"))?;
    let skillfab = here.with_file_name("skillfab");
    let dir = std::env::temp_dir().join(format!("record-report-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(because("scratch directory"))?;
    let (mut plain, mut recorded, mut files) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..pairs {
        for with in if i % 2 == 0 {
            [false, true]
        } else {
            [true, false]
        } {
            let tag = format!("{i}-{}", if with { "rec" } else { "plain" });
            let file = dir.join(format!("{tag}.mcap"));
            eprintln!(
                "record-report: pair {} of {pairs}, {}",
                i + 1,
                if with { "recording" } else { "not recording" }
            );
            let r = run(
                &skillfab,
                &dir,
                &tag,
                cycles,
                with.then_some(file.as_path()),
            )?;
            let row = json!({
                "p50_us": r["latency_us"]["p50"], "p99_us": r["latency_us"]["p99"],
                "overruns": r["overruns"], "cycles": r["cycles"],
            });
            if with {
                let mut row = row;
                row["file"] = inspect(&file)?;
                let _ = std::fs::remove_file(&file);
                files.push(row["file"].clone());
                recorded.push(row);
            } else {
                plain.push(row);
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    let p50 = |rows: &[Value]| median(rows.iter().filter_map(|r| r["p50_us"].as_f64()).collect());
    let p99 = |rows: &[Value]| median(rows.iter().filter_map(|r| r["p99_us"].as_f64()).collect());
    let summary = json!({
        "pairs": pairs, "cycles": cycles,
        "plain": {"p50_us_median": p50(&plain), "p99_us_median": p99(&plain), "runs": plain},
        "recording": {"p50_us_median": p50(&recorded), "p99_us_median": p99(&recorded), "runs": recorded},
        "p50_ratio": p50(&recorded) / p50(&plain),
    });
    if json_out {
        println!("{summary}");
        return Ok(());
    }
    println!(
        "exit-lab network, 100 Hz, {cycles} cycles, {pairs} interleaved pairs (medians of the runs' figures)"
    );
    println!(
        "  not recording: cycle latency p50 {:.0} µs, p99 {:.0} µs",
        p50(&plain),
        p99(&plain)
    );
    println!(
        "  recording all: cycle latency p50 {:.0} µs, p99 {:.0} µs  (p50 ×{:.3})",
        p50(&recorded),
        p99(&recorded),
        p50(&recorded) / p50(&plain)
    );
    for f in files {
        println!(
            "  file: {} cycles, {} samples, {} overruns, {} device cycles missing ({} in overrun cycles), {} out of order, {} bytes/cycle",
            f["cycles"],
            f["samples"],
            f["overruns"],
            f["device_cycles_missing"],
            f["missing_in_overrun_cycles"],
            f["out_of_order"],
            f["bytes_per_cycle"]
        );
    }
    Ok(())
}
