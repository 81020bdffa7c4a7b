//! `latency-report --peer dora`: the same chain at the same pacing in dora-rs 1.1, measured in
//! the same run as skillfab's, repeats interleaved. Not part of CI: it needs the `dora` CLI
//! (`pip install dora-rs-cli==1.1.0`) and builds the peer node (`bench/dora/`, a workspace of
//! its own on `dora-node-api` 1.1) on first use.
//!
//! The graph of depth D: a driver node on dora's 10 ms timer stamps `CLOCK_MONOTONIC` and sends
//! it; D nodes pass it on, one after the other; the last one stamps its arrival. That is D
//! wake-ups from the driver's start stamp to the last node's stamp — the endpoints of
//! skillfab's `chain-D@100Hz` figure (the manager's cycle start to the last run's end).
//! dora routes each message through its daemon, as it does for every message of a dataflow on
//! one machine; that is part of what is measured.

use crate::peer::{self, Compared};
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// The dataflow of depth `depth`, sending `cycles` stamps, the sink writing to `out`.
fn dataflow(peer: &Path, depth: usize, cycles: usize, out: &Path) -> String {
    let peer = peer.display();
    let mut y = format!(
        "nodes:\n  - id: driver\n    path: {peer}\n    inputs:\n      tick: dora/timer/millis/{}\n    outputs:\n      - out\n    env:\n      DORA_ROLE: driver\n      CYCLES: \"{cycles}\"\n",
        crate::PACE.as_millis()
    );
    for i in 1..=depth {
        let from = if i == 1 {
            "driver".to_string()
        } else {
            format!("n{}", i - 1)
        };
        let role = if i == depth { "sink" } else { "link" };
        y.push_str(&format!(
            "  - id: n{i}\n    path: {peer}\n    inputs:\n      in: {from}/out\n    outputs:\n      - out\n    env:\n      DORA_ROLE: {role}\n      LATENCY_OUT: {}\n",
            out.display()
        ));
    }
    y
}

/// One dora run of depth `depth`: `cycles` latencies (µs) after 10 unmeasured ones.
fn run_dora(peer: &Path, depth: usize, cycles: usize) -> Result<Vec<f64>, String> {
    let dir = std::env::temp_dir().join(format!("skillfab-dora-{}-{depth}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let out = dir.join("latency.txt");
    let flow = dir.join("dataflow.yml");
    std::fs::write(&flow, dataflow(peer, depth, cycles + 10, &out))
        .map_err(|e| format!("{}: {e}", flow.display()))?;
    let output = Command::new("dora")
        .arg("run")
        .arg(&flow)
        .current_dir(&dir)
        .output()
        .map_err(|e| format!("dora: {e} (pip install dora-rs-cli==1.1.0)"))?;
    if !output.status.success() {
        return Err(format!(
            "dora run failed: {}",
            String::from_utf8_lossy(&output.stderr)
        ));
    }
    let text = std::fs::read_to_string(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    let _ = std::fs::remove_dir_all(&dir);
    // Let dora's daemon and coordinator go before the next fabric starts.
    std::thread::sleep(Duration::from_millis(200));
    Ok(peer::ns_lines(&text, 10))
}

/// skillfab's `chain-D@100Hz` and dora's chain of the same depth, `repeats` times each,
/// interleaved, `cycles` cycles a run.
pub fn compare(depths: &[usize], cycles: usize, repeats: usize) -> Result<Vec<Compared>, String> {
    let version = Command::new("dora")
        .arg("--version")
        .output()
        .map_err(|e| format!("no dora CLI ({e}): pip install dora-rs-cli==1.1.0"))?;
    eprintln!("peer: {}", String::from_utf8_lossy(&version.stdout).trim());
    let node = peer::build("dora", "skillfab-dora-peer")?;
    peer::compare("dora", depths, cycles, repeats, |depth, cycles| {
        run_dora(&node, depth, cycles)
    })
}

/// The comparison as a table for people.
pub fn to_text(rows: &[Compared]) -> String {
    peer::to_text(
        "skillfab against dora-rs 1.1, same chain, same 100 Hz pacing, one run: driver's start \
         stamp → last node's stamp (D wake-ups), µs",
        "dora",
        rows,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dataflow_chains_its_nodes_from_the_driver_to_the_sink() {
        let y = dataflow(Path::new("/p"), 3, 5, Path::new("/o"));
        assert!(y.contains("tick: dora/timer/millis/10"), "{y}");
        assert!(
            y.contains("in: driver/out") && y.contains("in: n1/out") && y.contains("in: n2/out")
        );
        assert_eq!(y.matches("DORA_ROLE: sink").count(), 1);
        assert_eq!(y.matches("DORA_ROLE: link").count(), 2);
        assert!(y.contains("CYCLES: \"5\""));
    }
}
