//! Control-plane round trips and monitor latency, against a running hello network.
//!
//! `cargo build --release --workspace --bins && cargo bench -p skillfab-bench --bench control`
//!
//! - `activate_ack`: `activate scale` (already active) sent → answer received.
//! - `set_visible`: `set scale.gain=g` sent → the first output computed with g reaches the
//!   client (a monitor on `scale.scaled.value == g × ticker.tick.value` fires).
//! - `monitor_latency`: a condition becomes true in a skill's output (sample sent) → the
//!   monitor's event is received (free-running and 100 Hz cycles).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use criterion::{Criterion, criterion_group, criterion_main};
use skillfab_client::Client;
use skillfab_proto::control::{EventKind, MonitorMode};
use skillfab_proto::header::now_ns;
use skillfab_tests::TestDomain;
use std::time::{Duration, Instant};

fn hello(tag: &str, period_ms: &str) -> TestDomain {
    let mut t = TestDomain::new(tag);
    let launch = t.launch_file(&format!(
        "[manager]\nperiod_ms = {period_ms}\ndeadline_ms = 1000\n[[process]]\nname = \"ticker\"\nbin = \"{{bin:ticker}}\"\n[[process]]\nname = \"scale\"\nbin = \"{{bin:scale}}\"\n[[process]]\nname = \"smooth\"\nbin = \"{{bin:smooth}}\"\n"
    ));
    t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let board = t.board();
    t.wait_until("the hello network", || {
        skillfab_tests::registered(&board, "smooth").is_some_and(|s| s.runs > 10)
    });
    t
}

fn wait_fired(c: &mut Client, id: u64) -> u64 {
    loop {
        let ev = c
            .next_event(Duration::from_secs(10))
            .unwrap()
            .expect("monitor event");
        if let EventKind::MonitorFired {
            id: m, stamp_ns, ..
        } = ev.kind
            && m == id
        {
            return stamp_ns;
        }
    }
}

fn control(cr: &mut Criterion) {
    let t = hello("benchctl", "0");
    let mut c = Client::connect(&t.domain).unwrap();
    c.subscribe().unwrap();
    let mut g = cr.benchmark_group("control");
    g.sample_size(30).measurement_time(Duration::from_secs(4));

    g.bench_function("activate_ack", |b| {
        b.iter(|| c.activate(&["scale"]).unwrap())
    });

    let mut gain = 2.0;
    g.bench_function("set_visible", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                gain += 1.0;
                let expr = format!("scale.scaled.value == {gain} * ticker.tick.value");
                let id = c.add_monitor(&expr, MonitorMode::Once, 0).unwrap();
                let start = Instant::now();
                c.set_param("scale", "gain", &gain.to_string()).unwrap();
                wait_fired(&mut c, id);
                total += start.elapsed();
            }
            total
        })
    });

    for (label, period) in [("free-run", "0"), ("100Hz", "10")] {
        let t2 = if period == "0" {
            None
        } else {
            Some(hello("benchmon", period))
        };
        let mut c2 = match &t2 {
            Some(t2) => Client::connect(&t2.domain).unwrap(),
            None => Client::connect(&t.domain).unwrap(),
        };
        c2.subscribe().unwrap();
        g.bench_function(format!("monitor_latency/{label}"), |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let (now, _) = c2.query("ticker.tick.value").unwrap();
                    let target = now.as_f64().unwrap() + 5.0;
                    let id = c2
                        .add_monitor(
                            &format!("ticker.tick.value >= {target}"),
                            MonitorMode::Once,
                            0,
                        )
                        .unwrap();
                    let stamp = wait_fired(&mut c2, id);
                    total += Duration::from_nanos(now_ns().saturating_sub(stamp));
                }
                total
            })
        });
    }
    g.finish();
}

criterion_group!(benches, control);
criterion_main!(benches);
