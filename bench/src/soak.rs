//! `fault-report --soak N`: a network cycling back to back for N cycles while every process of
//! its domain is sampled — resident memory, open file descriptors, threads — with the bytes
//! its domain holds in `/dev/shm`. After a warm-up each should be flat: the slope of a
//! least-squares line through the samples, per 100 000 cycles, says whether anything grows.

use crate::{Case, Fabric};
use skillfab_tests::{HELLO, TestDomain};
use std::os::unix::fs::MetadataExt;
use std::time::{Duration, Instant};

/// One sample, summed over the domain's processes.
#[derive(Debug, Clone, Copy, Default)]
pub struct Sample {
    /// The manager's cycle.
    pub cycle: u64,
    /// Resident memory (KiB).
    pub rss_kib: f64,
    /// Open file descriptors.
    pub fds: f64,
    /// Threads.
    pub threads: f64,
    /// Shared memory of the domain actually allocated (KiB, from the files' blocks).
    pub shm_kib: f64,
    /// Processes sampled.
    pub processes: usize,
}

/// What a soak found.
#[derive(Debug, Clone)]
pub struct Soak {
    /// The network.
    pub network: String,
    /// Cycles run.
    pub cycles: u64,
    /// Wall time (s).
    pub secs: f64,
    /// Samples taken (the first fifth is the warm-up, left out of the slopes).
    pub samples: Vec<Sample>,
}

impl Soak {
    /// Least-squares slope of `f` over the samples after warm-up, per 100 000 cycles.
    pub fn slope(&self, f: impl Fn(&Sample) -> f64) -> f64 {
        let s = &self.samples[self.samples.len() / 5..];
        if s.len() < 2 {
            return f64::NAN;
        }
        let n = s.len() as f64;
        let mx = s.iter().map(|x| x.cycle as f64).sum::<f64>() / n;
        let my = s.iter().map(&f).sum::<f64>() / n;
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for x in s {
            let dx = x.cycle as f64 - mx;
            sxy += dx * (f(x) - my);
            sxx += dx * dx;
        }
        if sxx == 0.0 {
            f64::NAN
        } else {
            sxy / sxx * 100_000.0
        }
    }

    /// The report as JSON.
    pub fn json(&self) -> serde_json::Value {
        let first = self
            .samples
            .get(self.samples.len() / 5)
            .copied()
            .unwrap_or_default();
        let last = self.samples.last().copied().unwrap_or_default();
        let at = |s: &Sample| {
            serde_json::json!({"cycle": s.cycle, "rss_kib": s.rss_kib, "fds": s.fds,
                "threads": s.threads, "shm_kib": s.shm_kib, "processes": s.processes})
        };
        serde_json::json!({
            "network": self.network,
            "cycles": self.cycles,
            "secs": self.secs,
            "samples": self.samples.len(),
            "after_warm_up": at(&first),
            "last": at(&last),
            "slope_per_100k_cycles": {
                "rss_kib": self.slope(|s| s.rss_kib),
                "fds": self.slope(|s| s.fds),
                "threads": self.slope(|s| s.threads),
                "shm_kib": self.slope(|s| s.shm_kib),
            },
        })
    }
}

fn status_field(pid: u32, key: &str) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .unwrap_or_default()
        .lines()
        .find_map(|l| l.strip_prefix(key))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or(0.0)
}

fn sample(t: &TestDomain, cycle: u64) -> Sample {
    let me = std::process::id();
    let pids: Vec<u32> = skillfab_proto::clean::live_pids(&t.domain)
        .into_iter()
        .filter(|&p| p != 0 && p != me)
        .collect();
    let mut s = Sample {
        cycle,
        processes: pids.len(),
        ..Sample::default()
    };
    for &p in &pids {
        s.rss_kib += status_field(p, "VmRSS:");
        s.threads += status_field(p, "Threads:");
        s.fds += std::fs::read_dir(format!("/proc/{p}/fd")).map_or(0, |d| d.count()) as f64;
    }
    s.shm_kib = t
        .domain
        .shm_files()
        .iter()
        .filter_map(|f| std::fs::metadata(f).ok())
        .map(|m| (m.blocks() * 512) as f64 / 1024.0)
        .sum();
    s
}

/// Runs `network` (`hello` or `exit-lab`) back to back for `cycles` cycles, sampling every
/// `every`.
pub fn soak(network: &str, cycles: u64, every: Duration) -> Result<Soak, String> {
    let started = Instant::now();
    let mut samples = Vec::new();
    match network {
        "hello" => {
            let mut t = TestDomain::new("soak-hello");
            let launch = t.launch_file(&HELLO.replace("period_ms = 5", "period_ms = 0"));
            let n = cycles.to_string();
            t.spawn(
                "skillfab",
                &["up", launch.to_str().unwrap_or_default(), "--cycles", &n],
            );
            let board = t.board();
            loop {
                let k = skillfab_tests::cycle(&board);
                if k >= cycles || !board.manager_alive() {
                    break;
                }
                samples.push(sample(&t, k));
                std::thread::sleep(every);
            }
        }
        "exit-lab" => {
            let f = Fabric::start_every(Case::ExitLab, None);
            loop {
                let k = f.cycle();
                if k >= cycles {
                    break;
                }
                samples.push(sample(&f.t, k));
                std::thread::sleep(every);
            }
        }
        other => return Err(format!("no soak network '{other}' (hello, exit-lab)")),
    }
    Ok(Soak {
        network: network.to_string(),
        cycles,
        secs: started.elapsed().as_secs_f64(),
        samples,
    })
}
