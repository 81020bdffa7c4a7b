//! Cycle latency against the transport and OS floors, each case back to back and paced at
//! 100 Hz (see `skillfab_bench`). One criterion iteration is one cycle (skillfab: the
//! manager's own measurement, cycle start → last sync skill done) or one round trip of the
//! token around the floor's ring.
//!
//! `cargo build --release --workspace && cargo bench -p skillfab-bench --bench cycle`
//! (`-- chain` for a subset). `target/release/latency-report` is the short version of all of
//! it in one table.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use criterion::{Criterion, criterion_group, criterion_main};
use skillfab_bench::floors::{Iox, Pipes, Shape, Threads, hops};
use skillfab_bench::{Case, Fabric};
use std::time::Duration;

fn us_sum(v: &[f64]) -> Duration {
    Duration::from_secs_f64(v.iter().sum::<f64>() / 1e6)
}

fn cycle(cr: &mut Criterion) {
    for paced in [false, true] {
        let suffix = if paced { "@100Hz" } else { "" };
        let mut g = cr.benchmark_group(format!("cycle{suffix}"));
        g.sample_size(10)
            .warm_up_time(Duration::from_millis(500))
            .measurement_time(Duration::from_secs(if paced { 10 } else { 3 }));
        for case in Case::all() {
            let mut f = Fabric::start(case, paced);
            g.bench_function(format!("{}/skillfab", case.name()), |b| {
                b.iter_custom(|iters| us_sum(&f.latencies(iters as usize)))
            });
            drop(f);
            let shape: Shape = case.floor();
            let mut iox = Iox::start(shape);
            g.bench_function(format!("{}/iceoryx2_ring", case.name()), |b| {
                b.iter_custom(|iters| us_sum(&hops(&iox.rounds(iters as usize, paced))))
            });
            drop(iox);
            let mut pipes = Pipes::start(shape);
            g.bench_function(format!("{}/pipe_ring", case.name()), |b| {
                b.iter_custom(|iters| us_sum(&hops(&pipes.rounds(iters as usize, paced))))
            });
            drop(pipes);
            let mut threads = Threads::start(shape);
            g.bench_function(format!("{}/threads", case.name()), |b| {
                b.iter_custom(|iters| us_sum(&hops(&threads.rounds(iters as usize, paced))))
            });
        }
        g.finish();
    }
}

criterion_group!(benches, cycle);
criterion_main!(benches);
