//! `skillfab`: the one user-facing binary.

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use skill_sdk::domain::{DOMAIN_ENV, Domain};
use skillfab::engine::{Manager, ManagerConfig, Pace};
use skillfab::launch::Launch;
use skillfab::stats::Report;
use skillfab::up::{UpOptions, up};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

#[derive(Parser, Debug)]
#[command(
    name = "skillfab",
    version,
    about = "A zero-copy shared-memory multi-process skill fabric"
)]
struct Cli {
    /// Fabric domain: processes of different domains never see each other.
    #[arg(long, global = true, env = DOMAIN_ENV, default_value = "default")]
    domain: String,
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Args, Debug, Clone)]
struct PaceArgs {
    /// Cycle period in milliseconds (default 10: 100 Hz).
    #[arg(long, conflicts_with = "free_run")]
    period_ms: Option<f64>,
    /// Start the next cycle as soon as the previous one finished.
    #[arg(long)]
    free_run: bool,
    /// Stop after N cycles.
    #[arg(long, value_name = "N")]
    cycles: Option<u64>,
    /// Print the final report as one JSON object on stdout.
    #[arg(long)]
    json: bool,
    /// The fabric log: parameter changes and logged samples, as JSON lines, or MCAP for a
    /// FILE.mcap (default: <domain>-<unix seconds>-<pid>.jsonl in $SKILLFAB_LOG_DIR, else
    /// $XDG_STATE_HOME/skillfab/log, else ~/.local/state/skillfab/log; created with the first
    /// change).
    #[arg(long, value_name = "FILE")]
    param_log: Option<PathBuf>,
}

impl PaceArgs {
    fn pace(&self) -> anyhow::Result<Option<Pace>> {
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

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Run the skill manager of a domain.
    Manager {
        #[command(flatten)]
        pace: PaceArgs,
        /// Longest a cycle may take before it counts as an overrun (default: the period).
        #[arg(long)]
        deadline_ms: Option<f64>,
        /// Start with cycling stopped.
        #[arg(long)]
        paused: bool,
        /// Do not start cycling until these skills registered (comma-separated).
        #[arg(long, value_delimiter = ',')]
        wait_for: Vec<String>,
    },
    /// Start a manager and the processes of a launch file; supervise them.
    Up {
        /// The launch file (TOML).
        launch: PathBuf,
        #[command(flatten)]
        pace: PaceArgs,
        /// Seconds to wait for every skill to register before the first cycle.
        #[arg(long, default_value_t = 30.0)]
        wait_timeout_s: f64,
    },
    /// The debugging interface: a terminal UI over a running fabric.
    Console,
    /// The shared message types: their schemas as JSON, or as C or Python declarations.
    Schema {
        /// Print the C header (skill-sdk/capi/include/skillfab_msgs.h).
        #[arg(long, conflicts_with = "python")]
        c: bool,
        /// Print the Python ctypes module (python/skillfab/msgs.py).
        #[arg(long)]
        python: bool,
    },
    /// The paper's experiment.
    Demo {
        #[command(subcommand)]
        which: DemoCmd,
    },
    /// Talk to a running manager: the sequencer's link, from the shell.
    Ctl {
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        #[command(subcommand)]
        cmd: skillfab::ctl::CtlCmd,
    },
}

#[derive(Subcommand, Debug)]
enum DemoCmd {
    /// A sequencer drives the simulated Denning robot out of the lab.
    ExitLab {
        /// World file.
        #[arg(long, default_value = "devices/denning-sim/worlds/exit-lab.toml")]
        world: PathBuf,
        /// Seed of the first run (run i uses seed + i).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Number of runs.
        #[arg(long, default_value_t = 1)]
        runs: u32,
        /// Simulated seconds per real second.
        #[arg(long, default_value_t = 4.0)]
        time_factor: f64,
        /// Write the first run's trajectory picture (SVG).
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Print one JSON object: runs, successes, median time, each run.
        #[arg(long)]
        json: bool,
        /// Simulated seconds before a run counts as failed.
        #[arg(long, default_value_t = 300.0)]
        limit_s: f64,
    },
}

fn print_report(r: &Report, json: bool) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string(r)?);
        return Ok(());
    }
    println!(
        "{} cycles, {} overruns, latency p50 {:.1} µs  p99 {:.1} µs  max {:.1} µs",
        r.cycles, r.overruns, r.latency_us.p50, r.latency_us.p99, r.latency_us.max
    );
    println!(
        "{:<16} {:<10} {:<6} {:>8} {:>6} {:>6} {:>12}",
        "skill", "kind", "mode", "runs", "skips", "fails", "compute µs"
    );
    for s in &r.skills {
        println!(
            "{:<16} {:<10} {:<6} {:>8} {:>6} {:>6} {:>12.1}",
            s.name, s.kind, s.mode, s.runs, s.skips, s.failures, s.compute_us_mean
        );
    }
    Ok(())
}

fn run(cli: Cli) -> anyhow::Result<()> {
    let domain = Domain::new(&cli.domain)?;
    match cli.command {
        Cmd::Manager {
            pace,
            deadline_ms,
            paused,
            wait_for,
        } => {
            let mut config = ManagerConfig::new(domain.clone());
            if let Some(p) = pace.pace()? {
                config.pace = p;
            }
            config.deadline = deadline_ms.map(|ms| Duration::from_secs_f64(ms.max(0.0) / 1000.0));
            config.paused = paused;
            config.max_cycles = pace.cycles;
            config.wait_for = wait_for;
            config.param_log = pace.param_log.clone();
            let mut manager = Manager::new(config).context("starting the manager")?;
            let report = manager.run(&|_| false);
            manager.shutdown();
            print_report(&report?, pace.json)
        }
        Cmd::Up {
            launch,
            pace,
            wait_timeout_s,
        } => {
            let launch = Launch::load(&launch)?;
            let report = up(UpOptions {
                launch,
                domain,
                cycles: pace.cycles,
                pace: pace.pace()?,
                wait_timeout: Duration::from_secs_f64(wait_timeout_s.max(0.0)),
                param_log: pace.param_log.clone(),
            })?;
            print_report(&report, pace.json)
        }
        Cmd::Ctl { json, cmd } => skillfab::ctl::run(&domain, json, cmd),
        Cmd::Console => skillfab::console::run(&domain),
        Cmd::Schema { c, python } => {
            use skill_sdk::codegen;
            let schemas = codegen::shared_schemas();
            if c {
                print!("{}", codegen::c_header(&schemas));
            } else if python {
                print!("{}", codegen::python_module(&schemas));
            } else {
                println!("{}", serde_json::to_string_pretty(&schemas)?);
            }
            Ok(())
        }
        Cmd::Demo {
            which:
                DemoCmd::ExitLab {
                    world,
                    seed,
                    runs,
                    time_factor,
                    plot,
                    json,
                    limit_s,
                },
        } => {
            if !(time_factor > 0.0 && time_factor <= 50.0) {
                anyhow::bail!("--time-factor must be in (0, 50], got {time_factor}");
            }
            let opts = skillfab::demo::DemoOptions {
                world,
                seed,
                runs: runs.max(1),
                time_factor,
                plot,
                verbose: !json,
                limit_s,
            };
            let summary = skillfab::demo::demo(&opts)?;
            if json {
                println!("{}", serde_json::to_string(&summary)?);
            } else {
                println!(
                    "{} of {} runs left the lab; median time {}",
                    summary.successes,
                    summary.runs,
                    summary
                        .median_time_s
                        .map_or("-".into(), |t| format!("{t:.1} s simulated"))
                );
            }
            if summary.successes == 0 {
                anyhow::bail!("the robot did not leave the lab");
            }
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // The console owns the terminal: log lines on stderr would scribble over it.
    if !matches!(cli.command, Cmd::Console) {
        skill_sdk::runtime::init_tracing();
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the refusal (and its cause chain) for scripts and people alike.
            eprintln!("skillfab: error: {}", format!("{e:#}").replace('\n', " "));
            ExitCode::FAILURE
        }
    }
}
