//! `skillfab-copper-peer DEPTH CYCLES`: the chain of depth DEPTH (a mission of
//! `copperconfig.ron`) run CYCLES times at the config's 100 Hz, all tasks in this one process
//! and thread, as Copper runs them. The source stamps `CLOCK_MONOTONIC` and sends it; the links
//! pass it on; the sink stamps its arrival. Prints `end - start` (ns), one cycle a line — the
//! endpoints of skillfab's cycle latency (the manager's start stamp → the last skill's end
//! stamp). Copper's unified log (copperlists and its own text log) goes to `chain.copper` in
//! the working directory, written after each cycle's tasks ran.

use cu29::curuntime::LoopRateLimiter;
use cu29::prelude::*;
use std::io::Write;
use std::sync::Mutex;

fn now_ns() -> u64 {
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC).map_or(0, |t| {
        (t.tv_sec() as u64) * 1_000_000_000 + t.tv_nsec() as u64
    })
}

/// The sink's latencies (ns), read by `main` once the app stopped: Copper builds the tasks, so
/// the sink cannot be handed a buffer of `main`'s. Reserved before the run; the lock is never
/// contended (one thread).
static LATENCIES: Mutex<Vec<u64>> = Mutex::new(Vec::new());

/// Stamps the cycle's start.
#[derive(Reflect)]
struct Source;

impl Freezable for Source {}

impl CuSrcTask for Source {
    type Resources<'r> = ();
    type Output<'m> = output_msg!(u64);

    fn new(_: Option<&ComponentConfig>, _: ()) -> CuResult<Self> {
        Ok(Self)
    }

    fn process(&mut self, _: &CuContext, out: &mut Self::Output<'_>) -> CuResult<()> {
        out.set_payload(now_ns());
        Ok(())
    }
}

/// Passes the stamp on.
#[derive(Reflect)]
struct Link;

impl Freezable for Link {}

impl CuTask for Link {
    type Resources<'r> = ();
    type Input<'m> = input_msg!(u64);
    type Output<'m> = output_msg!(u64);

    fn new(_: Option<&ComponentConfig>, _: ()) -> CuResult<Self> {
        Ok(Self)
    }

    fn process(
        &mut self,
        _: &CuContext,
        input: &Self::Input<'_>,
        out: &mut Self::Output<'_>,
    ) -> CuResult<()> {
        if let Some(&start) = input.payload() {
            out.set_payload(start);
        }
        Ok(())
    }
}

/// Stamps the arrival and keeps the latency.
#[derive(Reflect)]
struct Sink;

impl Freezable for Sink {}

impl CuSinkTask for Sink {
    type Resources<'r> = ();
    type Input<'m> = input_msg!(u64);

    fn new(_: Option<&ComponentConfig>, _: ()) -> CuResult<Self> {
        Ok(Self)
    }

    fn process(&mut self, _: &CuContext, input: &Self::Input<'_>) -> CuResult<()> {
        let end = now_ns();
        let start = input
            .payload()
            .ok_or_else(|| CuError::from("the sink got no stamp"))?;
        let mut v = LATENCIES
            .lock()
            .map_err(|_| CuError::from("latencies poisoned"))?;
        v.push(end.saturating_sub(*start));
        Ok(())
    }
}

#[copper_runtime(config = "copperconfig.ron")]
struct Chain {}

/// Builds and starts mission `$m`'s app, runs `$cycles` iterations paced by Copper's own loop
/// limiter at the config's `runtime.rate_target_hz` (what the generated `run()` does between
/// iterations; `run()` itself loops until Ctrl-C), and stops it.
macro_rules! run_mission {
    ($m:ident, $cycles:expr) => {{
        // Copper's unified log, its default preallocation.
        let mut app = $m::Chain::builder()
            .with_log_path("chain.copper", None)?
            .build()?;
        let rate = app
            .copper_runtime_mut()
            .runtime_config
            .rate_target_hz
            .ok_or_else(|| CuError::from("copperconfig.ron sets no runtime.rate_target_hz"))?;
        let mut app = app.start().map_err(|e| CuError::from(e.to_string()))?;
        let clock = app.clock();
        let mut limiter = LoopRateLimiter::from_rate_target_hz(rate, &clock)?;
        for _ in 0..$cycles {
            app.run_one_iteration()?;
            limiter.limit(&clock);
        }
        app.stop().map_err(|e| CuError::from(e.to_string()))?;
    }};
}

fn run(depth: usize, cycles: usize) -> CuResult<()> {
    match depth {
        1 => run_mission!(d1, cycles),
        2 => run_mission!(d2, cycles),
        4 => run_mission!(d4, cycles),
        8 => run_mission!(d8, cycles),
        16 => run_mission!(d16, cycles),
        _ => return Err(CuError::from(format!("no mission of depth {depth}"))),
    }
    Ok(())
}

fn main() -> std::process::ExitCode {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let [depth, cycles] = args[..] else {
        eprintln!("usage: skillfab-copper-peer DEPTH CYCLES  (DEPTH: 1, 2, 4, 8 or 16)");
        return std::process::ExitCode::from(2);
    };
    if let Ok(mut v) = LATENCIES.lock() {
        v.reserve(cycles);
    }
    if let Err(e) = run(depth, cycles) {
        eprintln!("skillfab-copper-peer: {e}");
        return std::process::ExitCode::FAILURE;
    }
    let v = LATENCIES.lock().map(|v| v.clone()).unwrap_or_default();
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for ns in v {
        if writeln!(out, "{ns}").is_err() {
            return std::process::ExitCode::FAILURE;
        }
    }
    std::process::ExitCode::SUCCESS
}
