//! The command-line arguments of the manager's two programs, `manager` (a domain's manager)
//! and `up` (a manager plus a launch file's processes), and the code that runs them. Both the
//! `skillfab-manager` binary and `skillfab` parse them, so `skillfab up --help` is complete and
//! a mistyped flag is refused before `skillfab` hands over to `skillfab-manager`.

use crate::engine::{Manager, ManagerConfig, Pace};
use crate::launch::Launch;
use crate::stats::Report;
use crate::up::{UpOptions, up};
use anyhow::Context;
use clap::Args;
use skillfab_proto::domain::{DOMAIN_ENV, Domain};
use skillfab_proto::realtime::{CpuList, RealTime, Sched};
use std::path::PathBuf;
use std::time::Duration;

/// The period when none is given: 100 Hz.
pub const DEFAULT_PERIOD: Duration = Duration::from_millis(10);

/// How cycles are paced: a period, free-running, or lock-step.
#[derive(Args, Debug, Clone)]
pub struct PaceArgs {
    /// Cycle period in milliseconds (default 10: 100 Hz).
    #[arg(long, conflicts_with = "free_run")]
    pub period_ms: Option<f64>,
    /// Start the next cycle as soon as the previous one finished.
    #[arg(long)]
    pub free_run: bool,
    /// The fabric's clock runs F times faster than the host's, as a simulator sped up F
    /// times does: each cycle, paced every --period-ms of the host's time, stands for F times
    /// that of the clock skills and plans time things in (default 1). Not with --lockstep
    /// (its clock is the simulator's already) or --free-run.
    #[arg(long, value_name = "F", conflicts_with_all = ["free_run", "lockstep"])]
    pub time_factor: Option<f64>,
    /// Stop after N cycles.
    #[arg(long, value_name = "N")]
    pub cycles: Option<u64>,
    /// Print the final report as one JSON object on stdout.
    #[arg(long)]
    pub json: bool,
    /// The fabric log: parameter changes and logged samples, as JSON lines, or MCAP for a
    /// FILE.mcap (default: <domain>-<unix seconds>-<pid>.jsonl in $SKILLFAB_LOG_DIR, else
    /// $XDG_STATE_HOME/skillfab/log, else ~/.local/state/skillfab/log; created with the first
    /// change).
    #[arg(long, value_name = "FILE")]
    pub param_log: Option<PathBuf>,
    /// Lock-step: cycles back to back, each one period of simulated time (the period of
    /// --period-ms, else the launch file's, else 10 ms); a simulator in lock-step advances one
    /// period per cycle. No overruns short of 10 s.
    #[arg(long, conflicts_with = "free_run")]
    pub lockstep: bool,
    /// Record every sample of the topics (default: all, see --topics) at full rate, with
    /// their cycles and stamps, the skills' declarations, activations, parameters, priorities
    /// and events, into this MCAP file (Foxglove, the `mcap` CLI, `skillfab replay`).
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// With --record: only these topics (comma-separated).
    #[arg(long, value_delimiter = ',', requires = "record")]
    pub topics: Vec<String>,
    /// With --record: how samples are written — `cdr` (ROS 2's encoding, with ros2msg
    /// schemas) or `json` (a record per sample: decoded value and bytes as hex).
    #[arg(
        long,
        value_enum,
        value_name = "ENCODING",
        default_value_t,
        requires = "record"
    )]
    pub record_encoding: crate::recorder::SampleEncoding,
    /// Number the first cycle N (a replay numbers cycles as its recording did).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub first_cycle: u64,
}

impl PaceArgs {
    /// The pace the flags ask for (`None`: the default).
    pub fn pace(&self) -> anyhow::Result<Option<Pace>> {
        let pace = self.paced()?;
        Ok(if self.lockstep {
            Some(Pace::LockStep(
                pace.and_then(Pace::period).unwrap_or(DEFAULT_PERIOD),
            ))
        } else {
            pace
        })
    }

    /// --time-factor, checked: a positive number.
    pub fn time_factor(&self) -> anyhow::Result<Option<f64>> {
        match self.time_factor {
            Some(f) if !(f.is_finite() && f > 0.0) => {
                anyhow::bail!("--time-factor must be a positive number, got {f}")
            }
            f => Ok(f),
        }
    }

    /// The pace of --period-ms and --free-run alone.
    pub fn paced(&self) -> anyhow::Result<Option<Pace>> {
        if self.free_run {
            return Ok(Some(Pace::FreeRun));
        }
        match self.period_ms {
            None => Ok(None),
            Some(ms) if ms.is_finite() && ms > 0.0 => {
                Ok(Some(Pace::Period(Duration::from_secs_f64(ms / 1000.0))))
            }
            Some(0.0) => Ok(Some(Pace::FreeRun)),
            Some(ms) => anyhow::bail!(
                "--period-ms must be positive (0 or --free-run: free-running), got {ms}"
            ),
        }
    }
}

/// `--domain` (or `SKILLFAB_DOMAIN`), for every subcommand of `skillfab` and
/// `skillfab-manager`.
#[derive(Args, Debug, Clone)]
pub struct DomainArg {
    /// Fabric domain: processes of different domains never see each other.
    #[arg(long, global = true, env = DOMAIN_ENV, default_value = "default")]
    pub domain: String,
}

/// The tracing subscriber of the `skillfab` and `skillfab-manager` binaries: `RUST_LOG`
/// (default `info`) to stderr, iceoryx2's own logger quieted to errors (`IOX2_LOG_LEVEL`
/// overrides).
pub fn init_tracing() {
    use std::io::IsTerminal;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        tracing_subscriber::EnvFilter::new(skillfab_proto::log::DEFAULT_FILTER)
    });
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .try_init();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
}

/// `manager`: run the skill manager of a domain.
#[derive(Args, Debug, Clone)]
pub struct ManagerArgs {
    /// How cycles are paced.
    #[command(flatten)]
    pub pace: PaceArgs,
    /// Longest a cycle may take before it counts as an overrun (default: the period).
    #[arg(long)]
    pub deadline_ms: Option<f64>,
    /// Start with cycling stopped.
    #[arg(long)]
    pub paused: bool,
    /// Run no cycle until a client holds the fabric at one (`Client::hold`): an observer
    /// that acts at cycles of its choosing connects before the first cycle runs.
    #[arg(long)]
    pub held: bool,
    /// Do not start cycling until these skills registered (comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub wait_for: Vec<String>,
    /// Seconds to wait for them before giving up.
    #[arg(long, default_value_t = 30.0)]
    pub wait_timeout_s: f64,
    /// Real-time mode of the manager's cycle thread: a scheduling policy and priority,
    /// `fifo:81` or `rr:81` (docs/realtime.md). What the machine refuses is logged as a
    /// warning and the manager runs on without it.
    #[arg(long, value_name = "POLICY:PRIORITY")]
    pub realtime: Option<Sched>,
    /// With --realtime: pin the cycle thread to these CPUs (`1`, `0,1`, `0-3`).
    #[arg(long, value_name = "CPUS", requires = "realtime")]
    pub cpus: Option<CpuList>,
    /// With --realtime: lock the process's memory (mlockall) and pre-fault some stack.
    #[arg(long, requires = "realtime")]
    pub lock_memory: bool,
}

/// `up`: start a manager and the processes of a launch file; supervise them.
#[derive(Args, Debug, Clone)]
pub struct UpArgs {
    /// The launch file (TOML).
    pub launch: PathBuf,
    /// How cycles are paced.
    #[command(flatten)]
    pub pace: PaceArgs,
    /// Seconds to wait for every skill to register before the first cycle.
    #[arg(long, default_value_t = 30.0)]
    pub wait_timeout_s: f64,
    /// Start with cycling stopped (`skillfab ctl resume` starts it): a sequencer sets up
    /// before the first cycle, so a lock-step run does not depend on when it connected.
    #[arg(long)]
    pub paused: bool,
    /// Run no cycle until a client holds the fabric at one (`Client::hold`), whatever else
    /// resumes it: a lock-step observer (the demos' judge) acts from the first cycle on.
    #[arg(long)]
    pub held: bool,
}

/// Runs a domain's manager until it is stopped (or its cycle budget is spent), then prints
/// its report.
pub fn run_manager(domain: Domain, args: ManagerArgs) -> anyhow::Result<()> {
    let ManagerArgs {
        pace,
        deadline_ms,
        paused,
        held,
        wait_for,
        wait_timeout_s,
        realtime,
        cpus,
        lock_memory,
    } = args;
    let mut config = ManagerConfig::new(domain);
    if let Some(p) = pace.pace()? {
        config.pace = p;
    }
    if let Some(f) = pace.time_factor()? {
        config.time_factor = f;
    }
    config.deadline = deadline_ms.map(|ms| Duration::from_secs_f64(ms.max(0.0) / 1000.0));
    config.paused = paused;
    config.held = held;
    config.max_cycles = pace.cycles;
    config.wait_for = wait_for;
    config.wait_timeout = Duration::from_secs_f64(wait_timeout_s.max(0.0));
    config.param_log = pace.param_log.clone();
    config.first_cycle = pace.first_cycle;
    config.record = pace.record.clone().map(|path| crate::engine::RecordSpec {
        path,
        topics: pace.topics.clone(),
        encoding: pace.record_encoding,
    });
    let mut manager = Manager::new(config).context("starting the manager")?;
    // The cycles run on this thread: real-time from here on (the control plane's thread,
    // started by `Manager::new`, stays an ordinary one).
    if let Some(sched) = realtime {
        let rt = RealTime {
            cpus,
            lock_memory,
            ..RealTime::new(sched)
        };
        rt.apply().log("the manager's cycle thread");
    }
    let report = manager.run(&|_| false);
    manager.shutdown();
    print_report(&report?, pace.json)
}

/// Runs a launch file: a manager plus its supervised processes; prints the manager's report.
pub fn run_up(domain: Domain, args: UpArgs) -> anyhow::Result<()> {
    let launch = Launch::load(&args.launch)?;
    up(UpOptions {
        time_factor: args.pace.time_factor()?.or(launch.time_factor),
        launch,
        domain,
        cycles: args.pace.cycles,
        pace: args.pace.paced()?,
        lockstep: args.pace.lockstep,
        paused: args.paused,
        held: args.held,
        first_cycle: args.pace.first_cycle,
        record: args
            .pace
            .record
            .clone()
            .map(|path| crate::engine::RecordSpec {
                path,
                topics: args.pace.topics.clone(),
                encoding: args.pace.record_encoding,
            }),
        wait_timeout: Duration::from_secs_f64(args.wait_timeout_s.max(0.0)),
        param_log: args.pace.param_log.clone(),
        json: args.pace.json,
    })
}

fn print_report(r: &Report, json: bool) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string(r)?);
        return Ok(());
    }
    println!(
        "{} cycles, {} overruns, {} late starts, latency p50 {:.1} µs  p99 {:.1} µs  max {:.1} µs",
        r.cycles, r.overruns, r.late_starts, r.latency_us.p50, r.latency_us.p99, r.latency_us.max
    );
    println!(
        "{:<16} {:<10} {:<6} {:>8} {:>6} {:>6} {:>12} {:>6} {:>6}",
        "skill", "kind", "mode", "runs", "skips", "fails", "compute µs", "late", "allocs"
    );
    for s in &r.skills {
        println!(
            "{:<16} {:<10} {:<6} {:>8} {:>6} {:>6} {:>12.1} {:>6} {:>6}",
            s.name,
            s.kind,
            s.mode,
            s.figures.runs,
            s.figures.skips,
            s.figures.failures,
            s.figures.compute_us_mean,
            s.figures.deadline_misses,
            allocs_text(s.figures.cycle_allocs)
        );
    }
    Ok(())
}

/// A unit's cycle-path allocations as shown in text: `-` when they are not counted.
fn allocs_text(allocs: Option<u64>) -> String {
    allocs.map_or_else(|| "-".to_string(), |n| n.to_string())
}
