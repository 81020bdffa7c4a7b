//! What the peers of `latency-report --peer` share ([`crate::dora`], [`crate::copper`]): each
//! peer is a cargo workspace of its own under `bench/` that CI never builds, built here on first
//! use; its chain of depth D is measured against skillfab's `chain-D@100Hz` in the same run,
//! one repeat of each after the other, and the two are reported side by side.

use crate::{Case, Fabric, Summary, floors};
use std::path::{Path, PathBuf};
use std::process::Command;

/// One depth measured both ways.
#[derive(Debug, Clone, PartialEq)]
pub struct Compared {
    /// Tasks after the source (skills after the manager): wake-ups, or calls, per cycle.
    pub depth: usize,
    /// skillfab `chain-D@100Hz`, µs, every repeat's cycles together.
    pub skillfab: Summary,
    /// The peer, same chain and pacing, µs, every repeat's cycles together.
    pub peer: Summary,
    /// skillfab, each repeat on its own (the spread between runs).
    pub skillfab_runs: Vec<Summary>,
    /// The peer, each repeat on its own.
    pub peer_runs: Vec<Summary>,
}

/// Builds the peer workspace `bench/<name>/` (release, its committed Cargo.lock, its own target
/// directory whatever `CARGO_TARGET_DIR` says) and returns its binary `bin`.
pub fn build(name: &str, bin: &str) -> Result<PathBuf, String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(name);
    let target = dir.join("target");
    let status = Command::new(env!("CARGO"))
        .args(["build", "--release", "--locked", "--manifest-path"])
        .arg(dir.join("Cargo.toml"))
        .arg("--target-dir")
        .arg(&target)
        .status()
        .map_err(|e| format!("cargo: {e}"))?;
    if !status.success() {
        return Err(format!("building bench/{name} failed"));
    }
    Ok(target.join("release").join(bin))
}

/// The version of `krate` that `bench/<name>/Cargo.lock` pins, if it pins one.
pub fn locked_version(name: &str, krate: &str) -> Option<String> {
    let lock = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(name)
        .join("Cargo.lock");
    let text = std::fs::read_to_string(lock).ok()?;
    let mut lines = text.lines();
    lines.find(|l| *l == format!("name = \"{krate}\""))?;
    let v = lines.next()?.strip_prefix("version = \"")?;
    Some(v.trim_end_matches('"').to_string())
}

/// A peer's latencies as it writes them, nanoseconds one a line, in µs; the first `warm_up`
/// dropped.
pub fn ns_lines(text: &str, warm_up: usize) -> Vec<f64> {
    text.lines()
        .filter_map(|l| l.trim().parse::<u64>().ok())
        .skip(warm_up)
        .map(|ns| ns as f64 / 1000.0)
        .collect()
}

/// skillfab's `chain-D@100Hz` and `run_peer(D, cycles)` (the peer's latencies, µs), `repeats`
/// times each, interleaved, `cycles` cycles a run. `name` labels the progress lines.
pub fn compare(
    name: &str,
    depths: &[usize],
    cycles: usize,
    repeats: usize,
    mut run_peer: impl FnMut(usize, usize) -> Result<Vec<f64>, String>,
) -> Result<Vec<Compared>, String> {
    let mut out = Vec::new();
    for &depth in depths {
        let (mut sf, mut peer) = (Vec::new(), Vec::new());
        let (mut skillfab_runs, mut peer_runs) = (Vec::new(), Vec::new());
        for _ in 0..repeats.max(1) {
            let mut f = Fabric::start_every(Case::Chain(depth), Some(crate::PACE));
            let run = floors::hops(&f.times(cycles));
            drop(f);
            skillfab_runs.push(Summary::of(&run));
            sf.extend(run);
            let run = run_peer(depth, cycles)?;
            if run.is_empty() {
                return Err(format!("{name} depth {depth}: the sink recorded nothing"));
            }
            peer_runs.push(Summary::of(&run));
            peer.extend(run);
        }
        let c = Compared {
            depth,
            skillfab: Summary::of(&sf),
            peer: Summary::of(&peer),
            skillfab_runs,
            peer_runs,
        };
        eprintln!(
            "chain-{depth}@100Hz: skillfab p50 {:.1} µs, {name} p50 {:.1} µs",
            c.skillfab.p50, c.peer.p50
        );
        out.push(c);
    }
    Ok(out)
}

/// The p50s of runs as `lowest–highest`.
fn spread(runs: &[Summary]) -> String {
    let lo = runs.iter().map(|s| s.p50).fold(f64::INFINITY, f64::min);
    let hi = runs.iter().map(|s| s.p50).fold(0.0, f64::max);
    format!("{}–{}", short(lo), short(hi))
}

/// µs to read: one decimal below 10, none above.
fn short(us: f64) -> String {
    if us < 10.0 {
        format!("{us:.1}")
    } else {
        format!("{us:.0}")
    }
}

/// A ratio to read: `13.1`, or `1/150` below one.
fn ratio(r: f64) -> String {
    if r >= 1.0 {
        format!("{r:.1}")
    } else {
        format!("1/{:.0}", 1.0 / r)
    }
}

/// The comparison as a table for people; `title` is its first line.
pub fn to_text(title: &str, name: &str, rows: &[Compared]) -> String {
    let mut s = format!("{title}\n");
    s.push_str(&format!(
        "{:<15} {:>22} {:>14} {:>22} {:>14} {:>10}\n",
        "case",
        "skillfab p50/p99/max",
        "p50 of runs",
        format!("{name} p50/p99/max"),
        "p50 of runs",
        format!("{name}÷sf p50")
    ));
    for r in rows {
        let cell = |x: &Summary| format!("{} / {} / {}", short(x.p50), short(x.p99), short(x.max));
        s.push_str(&format!(
            "{:<15} {:>22} {:>14} {:>22} {:>14} {:>10}\n",
            format!("chain-{}@100Hz", r.depth),
            cell(&r.skillfab),
            spread(&r.skillfab_runs),
            cell(&r.peer),
            spread(&r.peer_runs),
            ratio(r.peer.p50 / r.skillfab.p50)
        ));
    }
    s
}

/// The comparison as JSON: one object a depth, the peer's figures under `<name>_…`.
pub fn to_json(name: &str, rows: &[Compared]) -> serde_json::Value {
    let p50s = |runs: &[Summary]| runs.iter().map(|s| s.p50).collect::<Vec<_>>();
    rows.iter()
        .map(|r| {
            let mut o = serde_json::Map::new();
            o.insert("depth".into(), r.depth.into());
            o.insert("skillfab_p50".into(), r.skillfab.p50.into());
            o.insert("skillfab_p99".into(), r.skillfab.p99.into());
            o.insert("skillfab_max".into(), r.skillfab.max.into());
            o.insert("skillfab_p50s".into(), p50s(&r.skillfab_runs).into());
            o.insert(format!("{name}_p50"), r.peer.p50.into());
            o.insert(format!("{name}_p99"), r.peer.p99.into());
            o.insert(format!("{name}_max"), r.peer.max.into());
            o.insert(format!("{name}_p50s"), p50s(&r.peer_runs).into());
            serde_json::Value::Object(o)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_peers_lines_are_nanoseconds_after_its_warm_up() {
        assert_eq!(ns_lines("5000\n7000\n\n1500\n", 1), vec![7.0, 1.5]);
    }

    #[test]
    fn the_json_names_the_peer_and_keeps_every_runs_p50() {
        let s = |p50| Summary {
            p50,
            p99: 2.0 * p50,
            max: 3.0 * p50,
        };
        let rows = [Compared {
            depth: 2,
            skillfab: s(50.0),
            peer: s(0.5),
            skillfab_runs: vec![s(40.0), s(60.0)],
            peer_runs: vec![s(0.4), s(0.6)],
        }];
        let j = to_json("copper", &rows);
        assert_eq!(j[0]["copper_p99"], 1.0);
        assert_eq!(j[0]["skillfab_p50s"], serde_json::json!([40.0, 60.0]));
        let t = to_text("title", "copper", &rows);
        assert!(t.contains("40–60") && t.contains("0.4–0.6"), "{t}");
        assert!(t.contains("1/100"), "{t}");
        assert_eq!(ratio(13.14), "13.1");
    }
}
