//! Benchmarks of skillfab: `benches/` holds the criterion benchmarks and `latency-report`
//! (a binary of this package) a short run of all cases with their floors. Every case starts
//! real processes in a private domain (through the tests' `TestDomain` fixture). Build the
//! binaries first: `cargo build --release --workspace` (the language cases also need
//! libskillfab and build the C examples themselves with `make -C skills`).
//!
//! - [`Fabric`]: a skillfab network of one [`Case`]; its cycle latencies are the manager's
//!   own (cycle start → last sync skill done), fetched over the control plane after the
//!   cycles ran, so measuring adds nothing to a cycle.
//! - [`floors`]: the same topology without fabric logic — a token passed around a ring (or
//!   out to a star and back) by raw iceoryx2 publish + event, by pipes, and by threads.

#![warn(missing_docs)]
// Benchmark set-up: a failed step should stop the run right there, with its message.
#![allow(clippy::unwrap_used, clippy::expect_used)]

pub mod copper;
pub mod crowd;
pub mod dora;
pub mod floors;
pub mod futex;
pub mod network;
pub mod peer;
pub mod report;
pub mod soak;

use skillfab_client::Client;
use skillfab_proto::board::Board;
use skillfab_proto::realtime::RealTime;
use skillfab_tests::TestDomain;
use std::time::Duration;

/// Period of the paced runs: 100 Hz, cores idle between cycles as on a robot.
pub const PACE: Duration = Duration::from_millis(10);

/// The payload sizes of the payload cases: label, bytes, binary suffix.
pub const PAYLOADS: [(&str, usize, &str); 4] = [
    ("64B", 64, "64"),
    ("64KiB", 64 << 10, "64K"),
    ("1MiB", 1 << 20, "1M"),
    ("4MiB", 4 << 20, "4M"),
];

/// A network measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Case {
    /// A sync chain of this depth: `ticker` → `relay` → ... (depth skill processes).
    Chain(usize),
    /// This many independent sync skills (`ticker`s), all started by the cycle.
    Fanout(usize),
    /// A depth-2 chain carrying a payload of `PAYLOADS[i]`: source → sink.
    Payload(usize),
    /// The exit-lab network: simulator, Denning device process, avoid, wander, barcode_track,
    /// `drive` arbitrated by the device.
    ExitLab,
    /// `ticker` → `scale` with `scale` written in another language (the same work: gain ×
    /// tick): what a skill in C or Python costs per cycle next to a Rust one.
    Lang(Lang),
}

/// The language of [`Case::Lang`]'s `scale`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lang {
    /// `skills/src/bin/scale.rs`.
    Rust,
    /// `skills/c/scale_c.c` through libskillfab.
    C,
    /// `skills/python/scale_py.py`: ctypes over libskillfab.
    Python,
}

impl Case {
    /// Every case, in report order.
    pub fn all() -> Vec<Case> {
        let mut v: Vec<Case> = [1, 2, 4, 8].into_iter().map(Case::Chain).collect();
        v.extend([1, 2, 4, 8].into_iter().map(Case::Fanout));
        v.extend((0..PAYLOADS.len()).map(Case::Payload));
        v.push(Case::ExitLab);
        v.extend([Lang::Rust, Lang::C, Lang::Python].map(Case::Lang));
        v
    }

    /// Its name in reports: `chain-4`, `fanout-2`, `payload-1MiB`, `exit-lab`.
    pub fn name(&self) -> String {
        match self {
            Case::Chain(d) => format!("chain-{d}"),
            Case::Fanout(n) => format!("fanout-{n}"),
            Case::Payload(i) => format!("payload-{}", PAYLOADS[*i].0),
            Case::ExitLab => "exit-lab".into(),
            Case::Lang(l) => format!("lang-{}", format!("{l:?}").to_lowercase()),
        }
    }

    /// The floor topology of the same shape.
    pub fn floor(&self) -> floors::Shape {
        match self {
            Case::Chain(d) => floors::Shape::Ring(*d),
            Case::Fanout(n) => floors::Shape::Star(*n),
            Case::Payload(_) => floors::Shape::Ring(2),
            // Cycle start → device → the skills reading it → their proposals → device → done:
            // a ring of depth 3 (4 hops).
            Case::ExitLab => floors::Shape::Ring(3),
            Case::Lang(_) => floors::Shape::Ring(2),
        }
    }

    /// The skill processes that register (names).
    pub fn skills(&self) -> Vec<String> {
        match self {
            Case::Chain(d) => (0..*d).map(|i| format!("l{i}")).collect(),
            Case::Fanout(n) => (0..*n).map(|i| format!("f{i}")).collect(),
            Case::Payload(_) => vec!["src".into(), "sink".into()],
            Case::ExitLab => ["denning", "avoid", "wander", "barcode_track"]
                .map(String::from)
                .to_vec(),
            Case::Lang(_) => vec!["ticker".into(), "scale".into()],
        }
    }

    /// [`Case::launch`], tuned: every registering process with a spin budget (`[manager]
    /// spin_us`, 0: none) and, with `rt`, in real-time mode (its `[realtime]` section: the
    /// skills at its priority, the manager one above, all pinned to its CPUs).
    pub fn launch_tuned(&self, period_ms: u64, rt: Option<&RealTime>, spin_us: u64) -> String {
        let mut s = self.launch(period_ms);
        if spin_us > 0 {
            s = s.replacen(
                "[manager]\n",
                &format!("[manager]\nspin_us = {spin_us}\n"),
                1,
            );
        }
        if let Some(rt) = rt {
            s.push_str(&format!(
                "[realtime]\npolicy = \"{}\"\npriority = {}\nlock_memory = {}\n",
                rt.policy.short_name(),
                rt.priority,
                rt.lock_memory
            ));
            if let Some(cpus) = &rt.cpus {
                s.push_str(&format!("cpus = {:?}\n", cpus.cpus()));
            }
        }
        s
    }

    /// The launch file (with `{bin:x}` placeholders) at `period_ms` (0: back to back).
    pub fn launch(&self, period_ms: u64) -> String {
        let mut s = format!("[manager]\nperiod_ms = {period_ms}\ndeadline_ms = 1000\n");
        let mut proc = |name: &str, bin: &str, extra: &str| {
            s.push_str(&format!(
                "[[process]]\nname = \"{name}\"\nbin = \"{{bin:{bin}}}\"\n{extra}"
            ));
        };
        match self {
            Case::Chain(d) => {
                proc("l0", "ticker", "remap = { tick = \"c0\" }\n");
                for i in 1..*d {
                    let remap = format!("remap = {{ prev = \"c{}\", tick = \"c{i}\" }}\n", i - 1);
                    proc(&format!("l{i}"), "relay", &remap);
                }
            }
            Case::Fanout(n) => {
                for i in 0..*n {
                    proc(
                        &format!("f{i}"),
                        "ticker",
                        &format!("remap = {{ tick = \"f{i}\" }}\n"),
                    );
                }
            }
            Case::Payload(i) => {
                let size = PAYLOADS[*i].2;
                proc("src", &format!("blob-src-{size}"), "");
                proc("sink", &format!("blob-sink-{size}"), "");
            }
            Case::ExitLab => {
                let world = concat!(
                    env!("CARGO_MANIFEST_DIR"),
                    "/../devices/denning-sim/worlds/exit-lab.toml"
                );
                proc(
                    "denning-sim",
                    "denning-sim",
                    &format!(
                        "registers = false\nargs = [\"--world\", {world:?}, \"--link\", \"{{dir}}/robot\"]\n"
                    ),
                );
                proc(
                    "denning",
                    "denning",
                    "args = [\"--port\", \"{dir}/robot\"]\nrestart = \"always\"\n",
                );
                for skill in ["avoid", "wander", "barcode_track"] {
                    proc(skill, skill, "");
                }
            }
            Case::Lang(l) => {
                proc("ticker", "ticker", "");
                match l {
                    Lang::Rust => proc("scale", "scale", ""),
                    Lang::C => proc("scale", "scale_c", ""),
                    Lang::Python => s.push_str(&format!(
                        "[[process]]\nname = \"scale\"\nbin = {:?}\n",
                        concat!(env!("CARGO_MANIFEST_DIR"), "/../skills/python/scale_py.py")
                    )),
                }
            }
        }
        s
    }
}

/// p50 / p99 / max of a set of latencies (µs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary {
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl Summary {
    /// The summary of `us` (not empty).
    pub fn of(us: &[f64]) -> Summary {
        let mut v = us.to_vec();
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Summary {
            p50: at(0.5),
            p99: at(0.99),
            max: at(1.0),
        }
    }
}

/// A running skillfab network of one case.
pub struct Fabric {
    // Fields drop in order: the client and the board before the domain's files go.
    client: Client,
    board: Board,
    /// The `skillfab up` child.
    up: usize,
    /// The cycle up to which latencies were taken.
    taken: u64,
    /// Its private domain (processes killed and files removed on drop).
    pub t: TestDomain,
}

impl Fabric {
    /// Starts `case` paced at [`PACE`] or back to back; returns once every skill runs.
    pub fn start(case: Case, paced: bool) -> Fabric {
        Fabric::start_every(case, paced.then_some(PACE))
    }

    /// Starts `case` with a cycle every `period` (whole milliseconds; `None`: back to back);
    /// returns once every skill runs.
    pub fn start_every(case: Case, period: Option<Duration>) -> Fabric {
        Fabric::start_with(case, period, None, 0)
    }

    /// [`Fabric::start_every`], in real-time mode `rt` if given, with every skill in spin
    /// mode if `spin_us` > 0 (`[manager] spin_us`).
    pub fn start_with(
        case: Case,
        period: Option<Duration>,
        rt: Option<&RealTime>,
        spin_us: u64,
    ) -> Fabric {
        if matches!(case, Case::Lang(_)) {
            skillfab_tests::build_foreign_examples();
        }
        let mut t = TestDomain::new(&case.name());
        let period = period.map_or(0, |p| p.as_millis().max(1) as u64);
        let text = case
            .launch_tuned(period, rt, spin_us)
            .replace("{dir}", t.dir.to_str().unwrap());
        let launch = t.launch_file(&text);
        let up = t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
        let board = t.board();
        let names = case.skills();
        t.wait_until(&format!("{} to run", case.name()), || {
            names
                .iter()
                .all(|n| skillfab_tests::registered(&board, n).is_some_and(|s| s.runs > 20))
        });
        if case == Case::ExitLab {
            let c = Client::connect(&t.domain).unwrap();
            c.activate(&["avoid", "wander", "barcode_track"]).unwrap();
        }
        let client = Client::connect(&t.domain).unwrap();
        let taken = skillfab_tests::cycle(&board);
        Fabric {
            t,
            client,
            board,
            up,
            taken,
        }
    }

    /// The latencies (µs) of `n` cycles after the previous call, as the manager measured
    /// them (cycle start → last run done). See [`Fabric::times`].
    pub fn latencies(&mut self, n: usize) -> Vec<f64> {
        self.times(n).into_iter().map(|t| t.hops_us).collect()
    }

    /// `n` cycles after the previous call, as the manager measured them: latency (cycle start
    /// → last run done) and round trip (→ the manager handling the completion). Waits for the
    /// cycles by reading the board (shared memory: no wake-up of the fabric), then asks for
    /// the most recent ones in batches the manager keeps (≤ 1024).
    pub fn times(&mut self, n: usize) -> Vec<floors::Timing> {
        const BATCH: u64 = 1000;
        let mut out = Vec::with_capacity(n);
        let mut left = n as u64;
        while left > 0 {
            let want = left.min(BATCH);
            let until = self.taken + want;
            while skillfab_tests::cycle(&self.board) < until + 1 {
                std::thread::sleep(Duration::from_millis(20));
            }
            // The most recent `want` cycles, all after the previous batch (back to back, the
            // manager may be far ahead by the time it answers).
            let t = self.client.cycle_times(want as u32).unwrap();
            out.extend(
                t.latency_us
                    .iter()
                    .zip(&t.round_trip_us)
                    .map(|(&l, &r)| floors::Timing {
                        hops_us: f64::from(l),
                        round_trip_us: f64::from(r),
                    }),
            );
            self.taken = t.cycle;
            left -= t.latency_us.len().min(want as usize) as u64;
        }
        out
    }

    /// The cycle in progress (read from the board).
    pub fn cycle(&self) -> u64 {
        skillfab_tests::cycle(&self.board)
    }

    /// The manager's statistics now.
    pub fn stats(&self) -> skillfab_proto::control::Stats {
        self.client.stats().unwrap()
    }

    /// Failed runs of each skill so far (a payload sink fails when it reads another cycle's
    /// payload).
    pub fn failures(&self) -> Vec<(String, u64)> {
        let stats = self.client.stats().unwrap();
        stats
            .skills
            .into_iter()
            .map(|s| (s.name, s.figures.failures))
            .collect()
    }

    /// Mean compute time of a run of each skill so far (µs; for a skill in another language:
    /// its body and the crossing into it).
    pub fn compute_us(&self) -> Vec<(String, f64)> {
        let stats = self.client.stats().unwrap();
        stats
            .skills
            .into_iter()
            .map(|s| (s.name, s.figures.compute_us_mean))
            .collect()
    }

    /// Processes of the network: the manager (the process that created the board: `skillfab
    /// up` runs it as a child of its own) and every skill.
    pub fn pids(&self) -> (u32, Vec<u32>) {
        let manager = self
            .board
            .header()
            .manager_pid
            .load(std::sync::atomic::Ordering::Acquire);
        let skills = (0..skillfab_proto::board::MAX_SLOTS)
            .map(|i| self.board.slot(i))
            .filter(|s| s.state() == skillfab_proto::board::SlotState::Ready)
            .map(|s| s.pid.load(std::sync::atomic::Ordering::Acquire))
            .collect();
        (manager, skills)
    }

    /// Every process of the network whose CPU is the fabric's cost: the manager, the skills
    /// and `skillfab up`, the supervisor.
    pub fn all_pids(&self) -> Vec<u32> {
        let (manager, skills) = self.pids();
        let up = self.t.pid(self.up);
        std::iter::once(manager)
            .chain(skills)
            .chain((up != manager).then_some(up))
            .collect()
    }
}

/// CPU time a process used so far: the scheduler's own account of every thread
/// (`/proc/PID/task/*/schedstat`, ns), not the tick-sampled `stat` figures, which are biased
/// for processes woken in step with the timer tick — as a 100 Hz cycle is.
pub fn cpu_time(pid: u32) -> Duration {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return Duration::ZERO;
    };
    let ns: u64 = tasks
        .filter_map(Result::ok)
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum();
    Duration::from_nanos(ns)
}

/// Resident memory of a process (MiB).
pub fn rss_mib(pid: u32) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .unwrap_or_default()
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        .map_or(0.0, |kb| kb / 1024.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use floors::{Shape, Transport};

    #[test]
    fn summaries_are_order_statistics() {
        let v: Vec<f64> = (1..=100).rev().map(f64::from).collect();
        let s = Summary::of(&v);
        assert_eq!((s.p50, s.p99, s.max), (51.0, 99.0, 100.0));
        assert_eq!(Summary::of(&[3.0]).p99, 3.0);
    }

    #[test]
    fn every_floor_passes_its_token_around() {
        for shape in [Shape::Ring(3), Shape::Star(3)] {
            for t in [
                Transport::Iceoryx2,
                Transport::Pipe,
                Transport::Threads,
                Transport::Futex,
            ] {
                let v = floors::measure(shape, t, false, 20);
                assert_eq!(v.len(), 20, "{shape:?} {t:?}");
                // The last node's stamp lies between the start and the driver's wake-up.
                assert!(
                    v.iter()
                        .all(|x| x.hops_us > 0.0 && x.hops_us <= x.round_trip_us),
                    "{shape:?} {t:?}: {v:?}"
                );
            }
        }
    }

    #[test]
    fn a_fabric_case_gives_the_managers_latency_of_each_cycle() {
        for case in [Case::Chain(3), Case::Payload(3), Case::Lang(Lang::Python)] {
            let mut f = Fabric::start(case, false);
            let v = f.times(50);
            assert_eq!(v.len(), 50, "{}", case.name());
            // The manager handles a completion after the last run ended.
            assert!(
                v.iter()
                    .all(|x| x.hops_us > 0.0 && x.hops_us <= x.round_trip_us),
                "{}: {v:?}",
                case.name()
            );
            // The sink found the payload of its own cycle in every run, written in place.
            assert!(
                f.failures().iter().all(|(_, n)| *n == 0),
                "{:?}",
                f.failures()
            );
            let (manager, skills) = f.pids();
            assert!(manager > 0);
            assert_eq!(skills.len(), case.skills().len());
            assert!(rss_mib(skills[0]) > 0.0);
        }
    }

    #[test]
    fn launch_files_chain_their_topics() {
        let l = Case::Chain(3).launch(10);
        assert!(l.contains("period_ms = 10"));
        assert!(
            l.contains("remap = { prev = \"c1\", tick = \"c2\" }"),
            "{l}"
        );
        assert_eq!(Case::all().len(), 16);
        assert_eq!(Case::Payload(2).name(), "payload-1MiB");
        assert_eq!(Case::Lang(Lang::Python).name(), "lang-python");
        let py = Case::Lang(Lang::Python).launch(0);
        assert!(py.contains("skills/python/scale_py.py\""), "{py}");
        assert!(Case::Lang(Lang::C).launch(0).contains("{bin:scale_c}"));
    }
}
