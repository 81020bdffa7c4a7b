//! `latency-report`: a short run of every case, back to back and paced at 100 Hz, each next
//! to its floors measured in the same run (only ratios within one run are comparable on a
//! shared machine), plus the idle cost of six skill processes.
//!
//! Same endpoints: skillfab's figure is cycle start → last run done (D wake-ups for a chain
//! of depth D) and each floor's is the driver's start stamp → the last node's stamp over the
//! same number of wake-ups; the round trips (one wake-up more: the manager, or the driver,
//! woken at the end) are reported beside them. Each case is measured `repeats` times,
//! fabric and floors interleaved, and the spread of the per-repeat medians is kept.

use crate::floors::{self, Transport};
use crate::{Case, Fabric, Summary, cpu_time, rss_mib};
use serde_json::{Value as Json, json};
use std::time::{Duration, Instant};

/// One case of the report.
#[derive(Debug, Clone)]
pub struct Row {
    /// `chain-4`, `payload-1MiB@100Hz`, ...
    pub name: String,
    /// skillfab's cycle latency (cycle start → last run done), all repeats pooled.
    pub skillfab: Summary,
    /// Floors over the same wake-ups: iceoryx2 ring, pipe ring, threads (same topology).
    pub floors: Vec<(Transport, Summary)>,
    /// Round trips (one wake-up more): skillfab first, then each floor.
    pub round_trips: Vec<(String, Summary)>,
    /// The lowest and highest per-repeat p50 (µs): skillfab first, then each floor.
    pub p50_ranges: Vec<(String, (f64, f64))>,
    /// Mean compute time of a run per skill (µs), for the language cases.
    pub compute_us: Vec<(String, f64)>,
}

impl Row {
    /// skillfab p50 ÷ the iceoryx2 floor's p50 (same endpoints, same wake-ups).
    pub fn ratio_p50(&self) -> f64 {
        self.ratio_to(Transport::Iceoryx2)
    }

    /// skillfab p50 ÷ floor `t`'s p50.
    pub fn ratio_to(&self, t: Transport) -> f64 {
        self.floors
            .iter()
            .find(|(f, _)| *f == t)
            .map_or(f64::NAN, |(_, s)| self.skillfab.p50 / s.p50)
    }
}

fn summary_json(s: &Summary) -> Json {
    let r = |x: f64| (x * 10.0).round() / 10.0;
    json!({"p50": r(s.p50), "p99": r(s.p99), "max": r(s.max)})
}

/// Per-repeat p50s and all samples of one series.
#[derive(Default)]
struct Series {
    hops: Vec<f64>,
    round_trips: Vec<f64>,
    p50s: Vec<f64>,
}

impl Series {
    fn add(&mut self, t: &[floors::Timing]) {
        let hops = floors::hops(t);
        self.p50s.push(Summary::of(&hops).p50);
        self.hops.extend(hops);
        self.round_trips.extend(t.iter().map(|t| t.round_trip_us));
    }
    fn range(&self) -> (f64, f64) {
        let lo = self.p50s.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = self.p50s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    }
}

/// Measures `case`: `repeats` times `n` cycles of skillfab and `n` rounds of each floor,
/// interleaved (fabric, iceoryx2, pipe, threads, then again), so a noisy spell of the shared
/// machine hits all of them alike.
pub fn row(case: Case, paced: bool, n: usize, repeats: usize) -> Row {
    const FLOORS: [Transport; 4] = [
        Transport::Iceoryx2,
        Transport::Futex,
        Transport::Pipe,
        Transport::Threads,
    ];
    let mut fabric = Series::default();
    let mut floor: Vec<Series> = FLOORS.iter().map(|_| Series::default()).collect();
    let mut compute_us = Vec::new();
    for _ in 0..repeats.max(1) {
        let mut f = Fabric::start(case, paced);
        fabric.add(&f.times(n));
        if matches!(case, Case::Lang(_)) {
            compute_us = f.compute_us();
        }
        drop(f);
        for (t, series) in FLOORS.iter().zip(&mut floor) {
            series.add(&floors::measure(case.floor(), *t, paced, n));
        }
    }
    let named = std::iter::once(("skillfab".to_string(), &fabric))
        .chain(FLOORS.iter().map(|t| t.key().to_string()).zip(&floor));
    Row {
        name: if paced {
            format!("{}@100Hz", case.name())
        } else {
            case.name()
        },
        skillfab: Summary::of(&fabric.hops),
        floors: FLOORS
            .iter()
            .zip(&floor)
            .map(|(t, s)| (*t, Summary::of(&s.hops)))
            .collect(),
        round_trips: named
            .clone()
            .map(|(k, s)| (k, Summary::of(&s.round_trips)))
            .collect(),
        p50_ranges: named.map(|(k, s)| (k, s.range())).collect(),
        compute_us,
    }
}

/// Idle cost of six skills cycling at 100 Hz, next to its floor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Idle {
    /// CPU of the manager and six chained skill processes (% of one core).
    pub fabric_percent: f64,
    /// CPU of the floor: six bare processes woken in the same pattern (a futex ring of
    /// depth 6 driven at 100 Hz) and the driver (% of one core).
    pub floor_percent: f64,
    /// The manager's CPU per cycle (µs: the process's whole account, waits included).
    pub manager_us_per_cycle: f64,
    /// The floor driver's CPU per round (µs): it sleeps to the next period, wakes the first
    /// node and is woken by the last — the manager's part of a cycle, without the fabric.
    pub driver_us_per_round: f64,
    /// Resident memory per skill process (MiB).
    pub rss_mib_per_skill: f64,
}

impl Idle {
    /// Fabric CPU ÷ floor CPU.
    pub fn ratio(&self) -> f64 {
        self.fabric_percent / self.floor_percent
    }
    /// Manager CPU per cycle ÷ the floor driver's CPU per round.
    pub fn manager_ratio(&self) -> f64 {
        self.manager_us_per_cycle / self.driver_us_per_round
    }
}

/// Idle cost: a chain of six skill processes cycling at 100 Hz for `secs` (total CPU of the
/// manager and the skills, from the scheduler's account; the manager's CPU per cycle;
/// resident memory per skill process), then its floor for as long: six futex ring nodes and
/// their driver, paced the same. Repeated `repeats` times, fabric and floor interleaved; the
/// medians are kept.
pub fn idle(secs: f64, repeats: usize) -> Idle {
    let cpu = |pids: &[u32]| pids.iter().map(|&p| cpu_time(p)).sum::<Duration>();
    let mut runs = Vec::new();
    for _ in 0..repeats.max(1) {
        let f = Fabric::start(Case::Chain(6), true);
        let (manager, skills) = f.pids();
        let all = f.all_pids();
        let (c0, m0, k0, t0) = (cpu(&all), cpu_time(manager), f.cycle(), Instant::now());
        std::thread::sleep(Duration::from_secs_f64(secs));
        let (c1, m1, k1, t1) = (cpu(&all), cpu_time(manager), f.cycle(), Instant::now());
        let fabric_percent = (c1 - c0).as_secs_f64() / (t1 - t0).as_secs_f64() * 100.0;
        let manager_us_per_cycle = (m1 - m0).as_secs_f64() * 1e6 / (k1 - k0).max(1) as f64;
        let rss = skills.iter().map(|&p| rss_mib(p)).sum::<f64>() / skills.len().max(1) as f64;
        drop(f);

        let mut ring = crate::futex::Futex::start(floors::Shape::Ring(6));
        let nodes = ring.node_pids();
        let rounds = (secs * 100.0) as usize;
        let (n0, d0, t0) = (cpu(&nodes), thread_cpu(), Instant::now());
        ring.rounds_every(rounds, Some(crate::PACE));
        let (n1, d1, t1) = (cpu(&nodes), thread_cpu(), Instant::now());
        let floor_percent = ((n1 - n0) + (d1 - d0)).as_secs_f64() / (t1 - t0).as_secs_f64() * 100.0;
        // The 10 unmeasured warm-up rounds ran inside the window too.
        let driver_us_per_round = (d1 - d0).as_secs_f64() * 1e6 / (rounds + 10) as f64;
        runs.push(Idle {
            fabric_percent,
            floor_percent,
            manager_us_per_cycle,
            driver_us_per_round,
            rss_mib_per_skill: rss,
        });
    }
    let median = |f: fn(&Idle) -> f64| Summary::of(&runs.iter().map(f).collect::<Vec<_>>()).p50;
    Idle {
        fabric_percent: median(|i| i.fabric_percent),
        floor_percent: median(|i| i.floor_percent),
        manager_us_per_cycle: median(|i| i.manager_us_per_cycle),
        driver_us_per_round: median(|i| i.driver_us_per_round),
        rss_mib_per_skill: median(|i| i.rss_mib_per_skill),
    }
}

/// One point of the scale sweep: a chain of `skills` sync skills at `rate_hz`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalePoint {
    /// Skill processes in the chain.
    pub skills: usize,
    /// Cycles per second.
    pub rate_hz: u32,
    /// Cycle latency (start → last run done), µs.
    pub skillfab: Summary,
    /// The futex ring of the same depth, paced the same (same endpoints), µs.
    pub futex: Summary,
    /// CPU of the manager and every skill process while cycling (% of one core).
    pub cpu_percent: f64,
    /// CPU of the futex ring's nodes and driver (% of one core).
    pub floor_cpu_percent: f64,
    /// Cycles that ran past their period (the next one started late), of those measured.
    pub late: usize,
    /// Cycles measured.
    pub cycles: usize,
    /// The 99.9th percentile of the cycle latency, µs.
    pub p999: f64,
    /// Cycles the manager started more than a period late (over the whole run). (Deadline
    /// misses are not reported: the cases' deadline is 1 s, so a cycle is not closed early;
    /// `late` is what ran past the period.)
    pub late_starts: u64,
}

/// Cost against the number of skills and the rate: a chain of each size in `sizes` at each
/// rate in `rates` for `secs` seconds (in real-time mode `rt` if given), then its futex floor
/// for as many rounds.
pub fn scale(
    sizes: &[usize],
    rates: &[u32],
    secs: f64,
    rt: Option<&skillfab_proto::realtime::RealTime>,
) -> Vec<ScalePoint> {
    let cpu = |pids: &[u32]| pids.iter().map(|&p| cpu_time(p)).sum::<Duration>();
    let mut out = Vec::new();
    for &rate_hz in rates {
        let period = Duration::from_secs(1) / rate_hz.max(1);
        for &n in sizes {
            let cycles = ((secs * f64::from(rate_hz)) as usize).max(50);
            let mut f = Fabric::start_with(Case::Chain(n), Some(period), rt, 0);
            let all = f.all_pids();
            let (c0, t0) = (cpu(&all), Instant::now());
            let times = f.times(cycles);
            let cpu_percent = (cpu(&all) - c0).as_secs_f64() / t0.elapsed().as_secs_f64() * 100.0;
            let stats = f.stats();
            drop(f);
            let period_us = period.as_secs_f64() * 1e6;
            let late = times.iter().filter(|t| t.round_trip_us > period_us).count();

            let mut ring = crate::futex::Futex::start(floors::Shape::Ring(n));
            let nodes = ring.node_pids();
            let (n0, d0, t0) = (cpu(&nodes), thread_cpu(), Instant::now());
            let floor = ring.rounds_every(cycles, Some(period));
            let floor_cpu_percent = ((cpu(&nodes) - n0) + (thread_cpu() - d0)).as_secs_f64()
                / t0.elapsed().as_secs_f64()
                * 100.0;
            let point = ScalePoint {
                skills: n,
                rate_hz,
                skillfab: Summary::of(&floors::hops(&times)),
                futex: Summary::of(&floors::hops(&floor)),
                cpu_percent,
                floor_cpu_percent,
                late,
                cycles: times.len(),
                p999: percentile(&floors::hops(&times), 0.999),
                late_starts: stats.late_starts,
            };
            eprintln!(
                "scale: chain-{n}@{rate_hz}Hz{} p50 {:.0} µs p99.9 {:.0} max {:.0} (futex p50 {:.0}), CPU {:.1} % (floor {:.1} %), {late} late, {} late starts",
                rt.map_or(String::new(), |rt| format!(" {rt}")),
                point.skillfab.p50,
                point.p999,
                point.skillfab.max,
                point.futex.p50,
                cpu_percent,
                floor_cpu_percent,
                point.late_starts
            );
            out.push(point);
        }
    }
    out
}

/// The scale sweep as a table for people.
pub fn scale_text(points: &[ScalePoint]) -> String {
    let mut s = String::from(
        "scale: a chain of N sync skills; cycle latency (start → last run done) µs \
         p50/p99/p99.9/max, its futex ring floor (same endpoints) p50/p99, CPU of all \
         processes (% of one core), cycles whose round trip ran past the period, cycles started \
         more than a period late\n",
    );
    s.push_str(&format!(
        "{:>6} {:>7} {:>26} {:>14} {:>7} {:>10} {:>10} {:>14} {:>6}\n",
        "skills", "rate", "skillfab", "futex ring", "÷futex", "CPU", "floor CPU", "late", "starts"
    ));
    for p in points {
        s.push_str(&format!(
            "{:>6} {:>5}Hz {:>26} {:>14} {:>7.2} {:>9.1}% {:>9.1}% {:>6}/{:<7} {:>6}\n",
            p.skills,
            p.rate_hz,
            format!(
                "{:.0} / {:.0} / {:.0} / {:.0}",
                p.skillfab.p50, p.skillfab.p99, p.p999, p.skillfab.max
            ),
            format!("{:.0} / {:.0}", p.futex.p50, p.futex.p99),
            p.skillfab.p50 / p.futex.p50,
            p.cpu_percent,
            p.floor_cpu_percent,
            p.late,
            p.cycles,
            p.late_starts
        ));
    }
    s
}

/// The `q` quantile of `us` (not empty), as [`Summary::of`] takes its percentiles.
fn percentile(us: &[f64], q: f64) -> f64 {
    let mut v = us.to_vec();
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// The scale sweep as JSON.
pub fn scale_json(points: &[ScalePoint]) -> Json {
    points
        .iter()
        .map(|p| {
            json!({
                "skills": p.skills,
                "rate_hz": p.rate_hz,
                "skillfab": summary_json(&p.skillfab),
                "futex_ring": summary_json(&p.futex),
                "ratio_futex_p50": (p.skillfab.p50 / p.futex.p50 * 100.0).round() / 100.0,
                "cpu_percent": (p.cpu_percent * 10.0).round() / 10.0,
                "floor_cpu_percent": (p.floor_cpu_percent * 10.0).round() / 10.0,
                "late": p.late,
                "cycles": p.cycles,
                "p99_9": (p.p999 * 10.0).round() / 10.0,
                "late_starts": p.late_starts,
            })
        })
        .collect()
}

/// One point of the spin curve: a case at 100 Hz with every skill's spin budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpinPoint {
    /// The network.
    pub case: Case,
    /// Spin budget of every skill (µs; 0: they sleep, the default).
    pub spin_us: u64,
    /// Cycle latency (start → last run done), µs, over every repeat.
    pub latency: Summary,
    /// CPU of the manager and every skill process (% of one core), mean over the repeats.
    pub cpu_percent: f64,
}

/// Latency against CPU as the spin budget grows: each case at 100 Hz with every skill's
/// budget in `budgets_us` (0: sleeping), next to the futex ring of its shape (the second
/// element of a case's first point), `cycles` per run, the runs of one case interleaved
/// `repeats` times.
pub fn spin_curve(
    cases: &[Case],
    budgets_us: &[u64],
    cycles: usize,
    repeats: usize,
) -> Vec<(SpinPoint, Option<SpinPoint>)> {
    let cpu = |pids: &[u32]| pids.iter().map(|&p| cpu_time(p)).sum::<Duration>();
    let mut out = Vec::new();
    for &case in cases {
        let mut lat: Vec<Vec<f64>> = vec![Vec::new(); budgets_us.len() + 1];
        let mut cpu_pct: Vec<f64> = vec![0.0; budgets_us.len() + 1];
        for _ in 0..repeats.max(1) {
            // The floor first, then every budget.
            let mut ring = crate::futex::Futex::start(case.floor());
            let nodes = ring.node_pids();
            let (n0, d0, t0) = (cpu(&nodes), thread_cpu(), Instant::now());
            let floor = ring.rounds_every(cycles, Some(crate::PACE));
            cpu_pct[0] += ((cpu(&nodes) - n0) + (thread_cpu() - d0)).as_secs_f64()
                / t0.elapsed().as_secs_f64()
                * 100.0;
            lat[0].extend(floors::hops(&floor));
            drop(ring);
            for (i, &spin_us) in budgets_us.iter().enumerate() {
                let mut f = Fabric::start_with(case, Some(crate::PACE), None, spin_us);
                let all = f.all_pids();
                let (c0, t0) = (cpu(&all), Instant::now());
                let times = f.times(cycles);
                cpu_pct[i + 1] +=
                    (cpu(&all) - c0).as_secs_f64() / t0.elapsed().as_secs_f64() * 100.0;
                lat[i + 1].extend(floors::hops(&times));
            }
        }
        let reps = repeats.max(1) as f64;
        let point = |i: usize, spin_us: u64| SpinPoint {
            case,
            spin_us,
            latency: Summary::of(&lat[i]),
            cpu_percent: cpu_pct[i] / reps,
        };
        let floor = point(0, 0);
        for (i, &b) in budgets_us.iter().enumerate() {
            let p = point(i + 1, b);
            eprintln!(
                "spin: {}@100Hz spin {b} µs: p50 {:.0} µs (futex floor {:.0}), CPU {:.1} % (floor {:.1} %)",
                case.name(),
                p.latency.p50,
                floor.latency.p50,
                p.cpu_percent,
                floor.cpu_percent
            );
            out.push((p, (i == 0).then_some(floor)));
        }
    }
    out
}

/// The spin curve as a table for people (the futex floor on the first line of each depth).
pub fn spin_curve_text(points: &[(SpinPoint, Option<SpinPoint>)]) -> String {
    let mut s = String::from(
        "spin: each case at 100 Hz, every skill spinning up to the budget after cycle start; cycle \
         latency (start → last run done) µs, CPU of all processes (% of one core)\n",
    );
    s.push_str(&format!(
        "{:>9} {:>12} {:>18} {:>8} {:>8}\n",
        "case", "spin", "p50 / p99", "÷futex", "CPU"
    ));
    let mut floor_p50 = f64::NAN;
    for (p, floor) in points {
        if let Some(f) = floor {
            floor_p50 = f.latency.p50;
            s.push_str(&format!(
                "{:>9} {:>12} {:>18} {:>8} {:>7.1}%\n",
                f.case.name(),
                "futex floor",
                format!("{:.0} / {:.0}", f.latency.p50, f.latency.p99),
                "1.00",
                f.cpu_percent
            ));
        }
        s.push_str(&format!(
            "{:>9} {:>9} µs {:>18} {:>8.2} {:>7.1}%\n",
            p.case.name(),
            p.spin_us,
            format!("{:.0} / {:.0}", p.latency.p50, p.latency.p99),
            p.latency.p50 / floor_p50,
            p.cpu_percent
        ));
    }
    s
}

/// The spin curve as JSON.
pub fn spin_curve_json(points: &[(SpinPoint, Option<SpinPoint>)]) -> Json {
    let one = |p: &SpinPoint| {
        json!({"case": p.case.name(), "spin_us": p.spin_us, "latency": summary_json(&p.latency),
               "cpu_percent": (p.cpu_percent * 10.0).round() / 10.0})
    };
    points
        .iter()
        .map(|(p, floor)| {
            let mut v = one(p);
            if let Some(f) = floor {
                v["futex_floor"] = one(f);
            }
            v
        })
        .collect()
}

/// CPU time of the calling thread.
fn thread_cpu() -> Duration {
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_THREAD_CPUTIME_ID)
        .map_or(Duration::ZERO, |t| {
            Duration::new(t.tv_sec() as u64, t.tv_nsec() as u32)
        })
}

/// The wake-up strategy on the transport floor: iceoryx2 rings of depth 1, 2, 4 whose
/// participants poll for their sample for 0 (pure blocking), 20 or 100 µs before they block;
/// back to back and at 100 Hz; p50 / p99 and the CPU the ring used (% of one core).
pub fn spin_experiment(n: usize) -> String {
    let mut s =
        String::from("ring  spin     back to back p50/p99 (cpu)      100 Hz p50/p99 (cpu)\n");
    for depth in [1usize, 2, 4] {
        for spin_us in [0u64, 20, 100] {
            s.push_str(&format!("{depth:>4}  {spin_us:>3} µs"));
            for paced in [false, true] {
                let mut ring = floors::Iox::start_spinning(
                    floors::Shape::Ring(depth),
                    Duration::from_micros(spin_us),
                );
                let mut pids = ring.node_pids();
                pids.push(std::process::id());
                let cpu = |p: &[u32]| p.iter().map(|&p| cpu_time(p)).sum::<Duration>();
                let (c0, t0) = (cpu(&pids), Instant::now());
                let v = Summary::of(&floors::hops(&ring.rounds(n, paced)));
                let used = (cpu(&pids) - c0).as_secs_f64() / t0.elapsed().as_secs_f64() * 100.0;
                s.push_str(&format!(
                    "   {:>6.0} / {:>6.0} µs ({used:>5.1} %)",
                    v.p50, v.p99
                ));
            }
            s.push('\n');
        }
    }
    s
}

/// The manager's own work per cycle (µs of its thread's CPU time between waits) for `case`
/// at 100 Hz over `cycles` cycles, from `skillfab up --json`.
pub fn manager_work(case: Case, cycles: usize) -> Summary {
    let t = skillfab_tests::TestDomain::new("mwork");
    let text = case
        .launch(crate::PACE.as_millis() as u64)
        .replace("{dir}", t.dir.to_str().unwrap());
    let r = t.up_json(&text, &["--cycles", &cycles.to_string()]);
    let w = &r["manager_work_us"];
    let f = |k: &str| w[k].as_f64().unwrap_or(f64::NAN);
    Summary {
        p50: f("p50"),
        p99: f("p99"),
        max: f("max"),
    }
}

/// The report as one JSON object.
pub fn to_json(rows: &[Row], idle: &Idle, manager_work: &[(String, Summary)]) -> Json {
    let cases: Vec<Json> = rows
        .iter()
        .map(|r| {
            let mut o = json!({"name": r.name, "skillfab": summary_json(&r.skillfab)});
            for (t, s) in &r.floors {
                o[t.key()] = summary_json(s);
            }
            o["ratio_p50"] = json!((r.ratio_p50() * 100.0).round() / 100.0);
            o["ratio_futex_p50"] = json!((r.ratio_to(Transport::Futex) * 100.0).round() / 100.0);
            o["round_trip"] = r
                .round_trips
                .iter()
                .map(|(k, s)| (k.clone(), summary_json(s)))
                .collect::<serde_json::Map<String, Json>>()
                .into();
            o["p50_range"] = r
                .p50_ranges
                .iter()
                .map(|(k, (lo, hi))| (k.clone(), json!([lo.round(), hi.round()])))
                .collect::<serde_json::Map<String, Json>>()
                .into();
            if !r.compute_us.is_empty() {
                o["compute_us_per_run"] = r
                    .compute_us
                    .iter()
                    .map(|(n, us)| (n.clone(), json!((us * 100.0).round() / 100.0)))
                    .collect::<serde_json::Map<String, Json>>()
                    .into();
            }
            o
        })
        .collect();
    json!({
        "cases": cases,
        "idle_cpu_percent": (idle.fabric_percent * 100.0).round() / 100.0,
        "idle_floor_cpu_percent": (idle.floor_percent * 100.0).round() / 100.0,
        "idle_ratio": (idle.ratio() * 100.0).round() / 100.0,
        "manager_cpu_us_per_cycle": (idle.manager_us_per_cycle * 10.0).round() / 10.0,
        "floor_driver_cpu_us_per_round": (idle.driver_us_per_round * 10.0).round() / 10.0,
        "rss_mib_per_skill": (idle.rss_mib_per_skill * 100.0).round() / 100.0,
        "manager_work_us": manager_work
            .iter()
            .map(|(n, s)| (n.clone(), summary_json(s)))
            .collect::<serde_json::Map<String, Json>>(),
    })
}

/// The rows of a report printed with `--json` (to redraw its plot).
pub fn rows_from_json(j: &Json) -> Option<Vec<Row>> {
    let summary = |s: &Json| {
        Some(Summary {
            p50: s["p50"].as_f64()?,
            p99: s["p99"].as_f64()?,
            max: s["max"].as_f64()?,
        })
    };
    j["cases"]
        .as_array()?
        .iter()
        .map(|c| {
            Some(Row {
                name: c["name"].as_str()?.to_string(),
                skillfab: summary(&c["skillfab"])?,
                floors: [Transport::Iceoryx2, Transport::Pipe, Transport::Threads]
                    .into_iter()
                    .map(|t| Some((t, summary(&c[t.key()])?)))
                    .collect::<Option<Vec<_>>>()?,
                round_trips: Vec::new(),
                p50_ranges: Vec::new(),
                compute_us: c["compute_us_per_run"]
                    .as_object()
                    .map(|m| {
                        m.iter()
                            .filter_map(|(k, v)| Some((k.clone(), v.as_f64()?)))
                            .collect()
                    })
                    .unwrap_or_default(),
            })
        })
        .collect()
}

/// The report as a table for people.
pub fn to_text(rows: &[Row], idle: &Idle, manager_work: &[(String, Summary)]) -> String {
    let mut s = String::from(
        "cycle latency over the same wake-ups (skillfab: cycle start → last run done; floors: \
         start stamp → last node's stamp), µs p50/p99/max [lowest–highest p50 of the repeats]\n",
    );
    s.push_str(&format!("{:<22} {:>34}", "case", "skillfab"));
    for (t, _) in rows.first().map_or(&[][..], |r| &r.floors[..]) {
        let w = if *t == Transport::Iceoryx2 { 34 } else { 20 };
        s.push_str(&format!(" {:>w$}", t.key().replace('_', " ")));
    }
    s.push_str(&format!(
        " {:>6} {:>6}  {:>22}\n",
        "÷iox", "÷futex", "round trip p50 sf/iox"
    ));
    let cell = |x: &Summary| format!("{:.0} / {:.0} / {:.0}", x.p50, x.p99, x.max);
    let range = |r: &Row, k: &str| {
        r.p50_ranges
            .iter()
            .find(|(n, _)| n == k)
            .map_or(String::new(), |(_, (lo, hi))| format!(" [{lo:.0}–{hi:.0}]"))
    };
    let rt = |r: &Row, k: &str| {
        r.round_trips
            .iter()
            .find(|(n, _)| n == k)
            .map_or(f64::NAN, |(_, s)| s.p50)
    };
    for r in rows {
        s.push_str(&format!(
            "{:<22} {:>34}",
            r.name,
            format!("{}{}", cell(&r.skillfab), range(r, "skillfab"))
        ));
        for (t, f) in &r.floors {
            let c = if *t == Transport::Iceoryx2 {
                format!("{}{}", cell(f), range(r, t.key()))
            } else {
                cell(f)
            };
            let w = if *t == Transport::Iceoryx2 { 34 } else { 20 };
            s.push_str(&format!(" {c:>w$}"));
        }
        s.push_str(&format!(
            " {:>6.2} {:>6.2}  {:>10.0} / {:<10.0}\n",
            r.ratio_p50(),
            r.ratio_to(Transport::Futex),
            rt(r, "skillfab"),
            rt(r, Transport::Iceoryx2.key())
        ));
    }
    for r in rows.iter().filter(|r| !r.compute_us.is_empty()) {
        let runs: Vec<String> = r
            .compute_us
            .iter()
            .map(|(n, us)| format!("{n} {us:.1} µs"))
            .collect();
        s.push_str(&format!(
            "{}: compute per run: {}\n",
            r.name,
            runs.join(", ")
        ));
    }
    s.push_str(&format!(
        "idle: 6 skill processes at 100 Hz use {:.2} % of one core (manager included), their floor (6 futex ring nodes + driver, paced the same) {:.2} %: {:.2}x; {:.1} MiB resident per skill process\n",
        idle.fabric_percent, idle.floor_percent, idle.ratio(), idle.rss_mib_per_skill
    ));
    s.push_str(&format!(
        "manager CPU per cycle {:.1} µs (its process, waits included) against the floor driver's {:.1} µs per round: {:.2}x\n",
        idle.manager_us_per_cycle, idle.driver_us_per_round, idle.manager_ratio()
    ));
    for (n, w) in manager_work {
        s.push_str(&format!(
            "manager work per cycle, {n}: p50 {:.1} µs, p99 {:.1} µs (CPU time of its thread)\n",
            w.p50, w.p99
        ));
    }
    s
}

/// An SVG of p50 latency against chain depth and against payload size (back to back and
/// paced), skillfab next to its floors.
pub fn to_svg(rows: &[Row]) -> String {
    let series = |prefix: &str, suffix: &str, xs: &[&str]| -> Vec<(String, Vec<f64>)> {
        let get = |x: &str| {
            rows.iter()
                .find(|r| r.name == format!("{prefix}{x}{suffix}"))
        };
        let mut out = vec![(
            "skillfab".to_string(),
            xs.iter()
                .map(|x| get(x).map_or(f64::NAN, |r| r.skillfab.p50))
                .collect(),
        )];
        for t in [Transport::Iceoryx2, Transport::Pipe, Transport::Threads] {
            out.push((
                t.key().to_string(),
                xs.iter()
                    .map(|x| {
                        get(x)
                            .and_then(|r| r.floors.iter().find(|(k, _)| *k == t))
                            .map_or(f64::NAN, |(_, s)| s.p50)
                    })
                    .collect(),
            ));
        }
        out
    };
    let colours = ["#d62728", "#1f77b4", "#2ca02c", "#7f7f7f"];
    let (w, h) = (360.0, 240.0);
    let mut svg = format!(
        "<svg xmlns='http://www.w3.org/2000/svg' width='{}' height='{}' font-family='sans-serif' font-size='11'>\n<rect width='100%' height='100%' fill='white'/>\n",
        2.0 * w + 40.0,
        2.0 * h + 60.0
    );
    let panels = [
        (
            "p50 vs chain depth, back to back",
            "chain-",
            "",
            vec!["1", "2", "4", "8"],
        ),
        (
            "p50 vs chain depth, 100 Hz",
            "chain-",
            "@100Hz",
            vec!["1", "2", "4", "8"],
        ),
        (
            "p50 vs payload (depth 2), back to back",
            "payload-",
            "",
            vec!["64B", "64KiB", "1MiB", "4MiB"],
        ),
        (
            "p50 vs payload (depth 2), 100 Hz",
            "payload-",
            "@100Hz",
            vec!["64B", "64KiB", "1MiB", "4MiB"],
        ),
    ];
    for (k, (title, prefix, suffix, xs)) in panels.iter().enumerate() {
        let (ox, oy) = (
            20.0 + (k % 2) as f64 * (w + 10.0),
            20.0 + (k / 2) as f64 * (h + 20.0),
        );
        let data = series(prefix, suffix, xs);
        let top = data
            .iter()
            .flat_map(|(_, v)| v.iter().copied())
            .filter(|v| v.is_finite())
            .fold(1.0f64, f64::max)
            * 1.1;
        let (px, py, pw, ph) = (ox + 45.0, oy + 20.0, w - 60.0, h - 60.0);
        svg.push_str(&format!(
            "<text x='{}' y='{}' font-weight='bold'>{title}</text>\n<rect x='{px}' y='{py}' width='{pw}' height='{ph}' fill='none' stroke='#999'/>\n",
            ox + 5.0,
            oy + 12.0
        ));
        for g in 0..=4 {
            let v = top * f64::from(g) / 4.0;
            let y = py + ph - ph * f64::from(g) / 4.0;
            svg.push_str(&format!(
                "<text x='{}' y='{}' text-anchor='end'>{v:.0} µs</text><line x1='{px}' x2='{}' y1='{y}' y2='{y}' stroke='#eee'/>\n",
                px - 3.0,
                y + 4.0,
                px + pw
            ));
        }
        let xat = |i: usize| px + pw * (i as f64 + 0.5) / xs.len() as f64;
        for (i, x) in xs.iter().enumerate() {
            svg.push_str(&format!(
                "<text x='{}' y='{}' text-anchor='middle'>{x}</text>\n",
                xat(i),
                py + ph + 14.0
            ));
        }
        let mut legend_x = px;
        for (s, (label, v)) in data.iter().enumerate() {
            let pts: Vec<String> = v
                .iter()
                .enumerate()
                .filter(|(_, y)| y.is_finite())
                .map(|(i, y)| format!("{:.1},{:.1}", xat(i), py + ph - ph * y / top))
                .collect();
            svg.push_str(&format!(
                "<polyline points='{}' fill='none' stroke='{}' stroke-width='2'/>\n<text x='{}' y='{}' fill='{}'>{label}</text>\n",
                pts.join(" "),
                colours[s],
                legend_x,
                py + ph + 30.0,
                colours[s]
            ));
            legend_x += 6.5 * label.len() as f64 + 14.0;
        }
    }
    svg.push_str("</svg>\n");
    svg
}
