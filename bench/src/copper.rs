//! `latency-report --peer copper`: the same chain at the same pacing in Copper (copper-rs) 1.2,
//! measured in the same run as skillfab's, repeats interleaved. Not part of CI: it builds the
//! peer (`bench/copper/`, a workspace of its own on the `cu29` crates) on first use.
//!
//! The chain of depth D, after Copper's caterpillar example: a source task stamps
//! `CLOCK_MONOTONIC` and sends it; D tasks pass it on, the last one (the sink) stamping its
//! arrival. Copper paces the loop at 100 Hz with its own limiter (`runtime.rate_target_hz`).
//! The endpoints are skillfab's `chain-D@100Hz` figure's (the manager's cycle start → the
//! last skill's end), but every Copper task is a call in one thread of one process: D calls
//! where skillfab makes D cross-process wake-ups. Copper wires its graph at compile time, so
//! the depths are the missions of `bench/copper/copperconfig.ron` ([`DEPTHS`]), chosen by
//! name when the app starts. Copper's unified log (its copperlists, on by default) goes to
//! the run's temporary directory; it is written after each cycle's tasks ran.

use crate::peer::{self, Compared};
use std::path::Path;
use std::process::Command;

/// The depths the app has a mission for.
pub const DEPTHS: [usize; 5] = [1, 2, 4, 8, 16];

/// One Copper run of depth `depth`: `cycles` latencies (µs) after 10 unmeasured ones.
fn run_copper(app: &Path, depth: usize, cycles: usize) -> Result<Vec<f64>, String> {
    let dir = std::env::temp_dir().join(format!("skillfab-copper-{}-{depth}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    // In its own directory: the app writes its log there, and reads no `copperconfig.ron`
    // there (Copper would take one in the working directory over the one it was built with).
    let output = Command::new(app)
        .arg(depth.to_string())
        .arg((cycles + 10).to_string())
        .current_dir(&dir)
        .output()
        .map_err(|e| format!("{}: {e}", app.display()))?;
    let _ = std::fs::remove_dir_all(&dir);
    if !output.status.success() {
        return Err(format!(
            "the Copper app failed: {}",
            String::from_utf8_lossy(&output.stderr)
        ));
    }
    Ok(peer::ns_lines(&String::from_utf8_lossy(&output.stdout), 10))
}

/// skillfab's `chain-D@100Hz` and Copper's chain of the same depth, `repeats` times each,
/// interleaved, `cycles` cycles a run. Every depth must be one of [`DEPTHS`].
pub fn compare(depths: &[usize], cycles: usize, repeats: usize) -> Result<Vec<Compared>, String> {
    if let Some(d) = depths.iter().find(|d| !DEPTHS.contains(d)) {
        return Err(format!("no Copper chain of depth {d} (depths: {DEPTHS:?})"));
    }
    let app = peer::build("copper", "skillfab-copper-peer")?;
    eprintln!("peer: Copper, cu29 {}", version());
    peer::compare("copper", depths, cycles, repeats, |depth, cycles| {
        run_copper(&app, depth, cycles)
    })
}

/// The `cu29` version the peer is built on.
fn version() -> String {
    peer::locked_version("copper", "cu29").unwrap_or_else(|| "?".into())
}

/// The comparison as a table for people.
pub fn to_text(rows: &[Compared]) -> String {
    peer::to_text(
        &format!(
            "skillfab against Copper (cu29 {}), same chain, same 100 Hz pacing, one run: source's \
             start stamp → last task's stamp (D wake-ups in skillfab, D calls in one Copper \
             thread), µs",
            version()
        ),
        "copper",
        rows,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One mission of the config: its connections and its tasks.
    #[derive(Default)]
    struct Mission {
        /// `(src, dst)`.
        cnx: Vec<(String, String)>,
        /// `(id, type)`.
        tasks: Vec<(String, String)>,
    }

    /// Mission `mission` of the config (each task and connection is on a line of its own).
    fn mission(ron: &str, mission: &str) -> Mission {
        // The value of `key: "…"` on a line.
        let field = |l: &str, key: &str| {
            let rest = &l[l.find(&format!("{key}: \""))? + key.len() + 3..];
            Some(rest[..rest.find('"')?].to_string())
        };
        let mut m = Mission::default();
        for l in ron
            .lines()
            .filter(|l| l.contains(&format!("\"{mission}\"")))
        {
            if let (Some(s), Some(d)) = (field(l, "src"), field(l, "dst")) {
                m.cnx.push((s, d));
            } else if let (Some(id), Some(t)) = (field(l, "id"), field(l, "type")) {
                m.tasks.push((id, t));
            }
        }
        m
    }

    #[test]
    fn each_mission_chains_the_source_through_its_depth_to_one_sink() {
        let ron = include_str!("../copper/copperconfig.ron");
        assert!(ron.contains("rate_target_hz: 100"), "paced at 100 Hz");
        assert_eq!(crate::PACE.as_millis(), 10);
        for d in DEPTHS {
            let Mission { cnx, tasks } = mission(ron, &format!("d{d}"));
            let kind = |id: &str| tasks.iter().find(|t| t.0 == id).map(|t| t.1.as_str());
            // Walk from the source: every task has one successor until the sink.
            let mut at = "src".to_string();
            let mut path = Vec::new();
            while let Some((_, next)) = cnx.iter().find(|c| c.0 == at) {
                assert_eq!(cnx.iter().filter(|c| c.0 == at).count(), 1, "d{d} forks");
                path.push(next.clone());
                at = next.clone();
            }
            assert_eq!(path.len(), d, "d{d}: {path:?}");
            assert_eq!(kind("src"), Some("Source"));
            assert_eq!(kind(&at), Some("Sink"), "d{d} ends at {at}");
            assert!(path[..d - 1].iter().all(|id| kind(id) == Some("Link")));
            assert_eq!(
                tasks.len(),
                d + 1,
                "d{d} has tasks off its chain: {tasks:?}"
            );
            assert_eq!(cnx.len(), d);
        }
    }

    #[test]
    fn a_depth_without_a_mission_is_refused_before_anything_is_built() {
        let e = compare(&[3], 10, 1).unwrap_err();
        assert!(e.contains("depth 3"), "{e}");
    }
}
