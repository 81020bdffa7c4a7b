//! Cycle statistics: count, overruns, latency percentiles, per-skill figures.

use serde::Serialize;
use std::collections::VecDeque;

/// How many recent cycle latencies percentiles are computed over.
const WINDOW: usize = 100_000;

/// Cycle latency record.
#[derive(Debug, Default)]
pub struct CycleStats {
    /// Cycles completed.
    pub cycles: u64,
    /// Cycles whose deadline passed before every expected run finished.
    pub overruns: u64,
    /// Paced cycles that started more than a period after their scheduled start.
    pub late_starts: u64,
    latencies_ns: VecDeque<u64>,
    max_ns: u64,
    /// Cycle start → the manager handling the cycle's completion (ns): the latency plus the
    /// wake-up of the manager, i.e. the round trip back to the driver.
    round_trips_ns: VecDeque<u64>,
    /// The manager's own work (ns of its thread's CPU time) per cycle, between waits.
    work_ns: VecDeque<u64>,
    work_max_ns: u64,
    /// Work since the last recorded cycle.
    work_pending: u64,
}

pub use skillfab_proto::control::Percentiles;

impl CycleStats {
    /// Records a finished cycle: its latency (start → last run done) and round trip (start →
    /// the manager handling its completion).
    pub fn record(&mut self, latency_ns: u64, round_trip_ns: u64, overrun: bool) {
        self.cycles += 1;
        if self.round_trips_ns.len() == WINDOW {
            self.round_trips_ns.pop_front();
        }
        self.round_trips_ns.push_back(round_trip_ns);
        if overrun {
            self.overruns += 1;
        }
        if self.latencies_ns.len() == WINDOW {
            self.latencies_ns.pop_front();
        }
        self.latencies_ns.push_back(latency_ns);
        self.max_ns = self.max_ns.max(latency_ns);
        if self.work_ns.len() == WINDOW {
            self.work_ns.pop_front();
        }
        self.work_ns.push_back(self.work_pending);
        self.work_max_ns = self.work_max_ns.max(self.work_pending);
        self.work_pending = 0;
    }

    /// Adds time the manager spent awake (handling a wake-up) to the cycle in progress.
    pub fn add_work(&mut self, ns: u64) {
        self.work_pending += ns;
    }

    /// The manager's own work per cycle (readiness, arbitration reads, monitors, events,
    /// control requests; everything between two of its waits), percentiles in µs.
    pub fn work_us(&self) -> Percentiles {
        percentiles(&self.work_ns, self.work_max_ns)
    }

    /// The latencies of the `n` most recent cycles in µs, oldest first (the console's history).
    pub fn recent_us(&self, n: usize) -> Vec<f32> {
        recent(&self.latencies_ns, n)
    }

    /// The round trips of the `n` most recent cycles in µs, oldest first.
    pub fn recent_round_trips_us(&self, n: usize) -> Vec<f32> {
        recent(&self.round_trips_ns, n)
    }

    /// Latency percentiles over the recent window (max over all cycles).
    pub fn latency_us(&self) -> Percentiles {
        percentiles(&self.latencies_ns, self.max_ns)
    }
}

/// The `n` newest of `window` (ns) in µs, oldest first.
fn recent(window: &VecDeque<u64>, n: usize) -> Vec<f32> {
    let skip = window.len().saturating_sub(n);
    window
        .iter()
        .skip(skip)
        .map(|&ns| ns as f32 / 1000.0)
        .collect()
}

/// Percentiles (µs) of a window of nanoseconds; `max_ns` is the all-time largest.
fn percentiles(window: &VecDeque<u64>, max_ns: u64) -> Percentiles {
    let mut v: Vec<u64> = window.iter().copied().collect();
    if v.is_empty() {
        return Percentiles::default();
    }
    v.sort_unstable();
    let at = |q: f64| {
        let i = ((v.len() as f64 - 1.0) * q).round() as usize;
        v[i.min(v.len() - 1)] as f64 / 1000.0
    };
    Percentiles {
        p50: at(0.50),
        p99: at(0.99),
        max: max_ns as f64 / 1000.0,
    }
}

/// One skill's figures in a report.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SkillReport {
    /// Instance name.
    pub name: String,
    /// Skill kind (program).
    pub kind: String,
    /// `sync` or `async`.
    pub mode: String,
    /// Whether it is active.
    pub active: bool,
    /// Arbitration priority.
    pub priority: i32,
    /// Process id.
    pub pid: u32,
    /// Its run figures (flattened: `runs`, `skips`, `failures`, `compute_us_mean`, … in JSON).
    #[serde(flatten)]
    pub figures: skillfab_proto::control::SkillFigures,
}

/// What `skillfab up --json` prints.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Report {
    /// Cycles completed.
    pub cycles: u64,
    /// Cycles that overran their deadline.
    pub overruns: u64,
    /// Cycle latency: start to last expected run done.
    pub latency_us: Percentiles,
    /// The manager's own work per cycle (its thread's CPU time between waits).
    pub manager_work_us: Percentiles,
    /// Per skill, in registration order.
    pub skills: Vec<SkillReport>,
    /// Skills that died while the fabric ran.
    pub deaths: u64,
    /// Paced cycles that started more than a period after their scheduled start.
    pub late_starts: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles() {
        let mut s = CycleStats::default();
        for i in 1..=100 {
            s.record(i * 1000, i * 1000 + 10, i == 100);
        }
        let p = s.latency_us();
        assert_eq!(s.cycles, 100);
        assert_eq!(s.overruns, 1);
        assert_eq!(p.p50, 51.0);
        assert_eq!(p.p99, 99.0);
        assert_eq!(p.max, 100.0);
    }
}
