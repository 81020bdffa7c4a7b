//! `fault-report --clients`: the hello network at 100 Hz, first left alone, then for the same
//! time under misbehaving clients — 100 clients asking at once, 4 flooding threads, random
//! bytes on the control service, a client that never reads its answers — while one
//! well-behaved client keeps asking. Reports, per window, the cycles run, the overruns, the
//! cycle latency the manager measured, and the well-behaved client's answer times.

use skillfab_client::Client;
use skillfab_proto::{names, services};
use skillfab_tests::{HELLO, TestDomain};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// One window's figures.
#[derive(Debug, Clone, Default)]
pub struct Window {
    /// Cycles run in the window.
    pub cycles: u64,
    /// Overruns in the window.
    pub overruns: u64,
    /// Cycle latency p50 / p99 over the window's last cycles (µs).
    pub latency_us: (f64, f64),
    /// The well-behaved client's answer time p50 / p99 (µs) and how many it got.
    pub answer_us: (f64, f64),
    /// Answers the well-behaved client got.
    pub answers: usize,
    /// Requests the misbehaving clients had answered.
    pub abuse_answered: u64,
    /// Requests of the misbehaving clients that failed (timeouts, refusals).
    pub abuse_failed: u64,
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Runs one window of `secs` with or without abuse.
fn window(t: &TestDomain, secs: f64, abuse: bool) -> Result<Window, String> {
    let good = Client::connect(&t.domain).map_err(|e| e.to_string())?;
    let before = good.stats().map_err(|e| e.to_string())?;
    let stop = AtomicBool::new(false);
    let (answered, failed) = (AtomicU64::new(0), AtomicU64::new(0));
    let mut times = Vec::new();
    std::thread::scope(|s| {
        if abuse {
            for i in 0..104 {
                let (stop, answered, failed, domain) = (&stop, &answered, &failed, &t.domain);
                s.spawn(move || {
                    let Ok(mut c) = Client::connect(domain) else {
                        failed.fetch_add(1, Ordering::Relaxed);
                        return;
                    };
                    c.set_timeout(Duration::from_secs(60));
                    // 100 clients ask now and then; 4 flood.
                    let nap = if i < 100 {
                        Duration::from_millis(50)
                    } else {
                        Duration::ZERO
                    };
                    while !stop.load(Ordering::Relaxed) {
                        match c.list() {
                            Ok(_) => answered.fetch_add(1, Ordering::Relaxed),
                            Err(_) => failed.fetch_add(1, Ordering::Relaxed),
                        };
                        std::thread::sleep(nap);
                    }
                });
            }
            // Random bytes, and requests whose answers are never read.
            let (stop, domain) = (&stop, &t.domain);
            s.spawn(move || {
                let Ok(node) = services::node(domain, "garbage") else {
                    return;
                };
                let Ok(factory) = services::control_service(&node) else {
                    return;
                };
                let Ok(port) = factory
                    .client_builder()
                    .initial_max_slice_len(skillfab_proto::control::MAX_REQUEST_BYTES)
                    .create()
                else {
                    return;
                };
                let Ok(wake) = services::notifier(&node, &names::control()) else {
                    return;
                };
                let mut x = 0x2545_f491_4f6c_dd1du64;
                let mut held = Vec::new();
                while !stop.load(Ordering::Relaxed) {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    let bytes = x.to_le_bytes();
                    if let Ok(s) = port.loan_slice_uninit(bytes.len())
                        && let Ok(p) = s.write_from_slice(&bytes).send()
                    {
                        held.push(p);
                        held.truncate(1);
                    }
                    let _ = wake.notify();
                    std::thread::sleep(Duration::from_millis(5));
                }
            });
        }
        let end = Instant::now() + Duration::from_secs_f64(secs);
        while Instant::now() < end {
            let t0 = Instant::now();
            if good.get_param("scale", "gain").is_ok() {
                times.push(t0.elapsed().as_secs_f64() * 1e6);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        stop.store(true, Ordering::Relaxed);
    });
    let after = good.stats().map_err(|e| e.to_string())?;
    let cycles = after.cycles.saturating_sub(before.cycles);
    let recent = good
        .cycle_times(cycles.min(u32::MAX as u64) as u32)
        .map_err(|e| e.to_string())?;
    let mut lat: Vec<f64> = recent.latency_us.iter().map(|&v| f64::from(v)).collect();
    let answers = times.len();
    Ok(Window {
        cycles,
        overruns: after.overruns.saturating_sub(before.overruns),
        latency_us: (percentile(&mut lat, 0.5), percentile(&mut lat, 0.99)),
        answer_us: (percentile(&mut times, 0.5), percentile(&mut times, 0.99)),
        answers,
        abuse_answered: answered.into_inner(),
        abuse_failed: failed.into_inner(),
    })
}

/// The hello network at 100 Hz: `secs` alone, then `secs` under misbehaving clients.
pub fn crowd(secs: f64) -> Result<(Window, Window), String> {
    let mut t = TestDomain::new("crowd-bench");
    let launch = t.launch_file(&HELLO.replace("period_ms = 5", "period_ms = 10"));
    t.spawn("skillfab", &["up", launch.to_str().unwrap_or_default()]);
    let board = t.board();
    t.wait_until("the hello network to run", || {
        ["ticker", "scale", "smooth"]
            .iter()
            .all(|n| skillfab_tests::registered(&board, n).is_some_and(|s| s.runs > 10))
    });
    let alone = window(&t, secs, false)?;
    let abused = window(&t, secs, true)?;
    Ok((alone, abused))
}
