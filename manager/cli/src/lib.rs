//! `skillfab`: the one user-facing binary (its `main` calls [`main`]). `ctl`, `console`,
//! `schema` and `demo` run here; `manager` and `up` hand over to the `skillfab-manager`
//! binary.
//!
//! Layout: this file parses the command line and hands each command to its module — [`ctl`],
//! `sequence` (plans), `plan` (the planner: a route map to a plan), `demo` (the missions on
//! the simulator, with `faults`), `replay`,
//! `new` (skill and message templates). `bridge` and `--remote` are compiled in with the
//! `bridge` feature (Zenoh, through `skillfab-bridge`); without it they say how to build them.

#![warn(missing_docs)]

mod check;
pub mod ctl;
mod demo;
mod faults;
mod new;
mod plan;
mod replan;
mod replay;
mod sequence;

use clap::{Args, Parser, Subcommand};
use skillfab_client::Address;
use skillfab_manager::args::{DomainArg, ManagerArgs, UpArgs, init_tracing};
use skillfab_proto::domain::Domain;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "skillfab",
    version,
    about = "A zero-copy shared-memory multi-process skill fabric"
)]
struct Cli {
    #[command(flatten)]
    domain: DomainArg,
    #[command(subcommand)]
    command: Cmd,
}

/// How to build `skillfab` with the bridge, for a build without it.
#[cfg(not(feature = "bridge"))]
const NO_BRIDGE: &str = "this skillfab was built without the bridge (Zenoh): build it with \
                         `cargo build --features skillfab/bridge` (and --release for a \
                         release build)";

/// Reaching a domain on another host through its bridge.
#[derive(clap::Args, Debug, Clone)]
struct RemoteArg {
    /// The Zenoh endpoint of the domain's bridge, e.g. `tcp/10.0.0.2:7447` (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    remote: Vec<String>,
    /// A Zenoh configuration file for the remote link (TLS, user/password).
    #[arg(long, value_name = "FILE")]
    zenoh_config: Option<PathBuf>,
}

impl RemoteArg {
    /// Where the manager of `domain` is: here, or through the bridge these options name.
    fn address(&self, domain: &Domain) -> anyhow::Result<Address> {
        if self.remote.is_empty() && self.zenoh_config.is_none() {
            return Ok(Address::Local(domain.clone()));
        }
        #[cfg(feature = "bridge")]
        return Ok(skillfab_bridge::address(
            domain.name(),
            skillfab_bridge::ZenohOptions {
                mode: skillfab_bridge::ZenohMode::Client,
                connect: self.remote.clone(),
                listen: Vec::new(),
                config_file: self.zenoh_config.clone(),
            },
        ));
        #[cfg(not(feature = "bridge"))]
        anyhow::bail!("--remote: {NO_BRIDGE}")
    }
}

/// `skillfab bridge`'s options.
#[cfg(feature = "bridge")]
use skillfab_bridge::BridgeArgs;

/// `skillfab bridge`'s options, in a build without the bridge: taken whatever they are, to
/// say how to build it.
#[cfg(not(feature = "bridge"))]
#[derive(clap::Args, Debug)]
struct BridgeArgs {
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
    args: Vec<String>,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Run the skill manager of a domain (the skillfab-manager binary).
    Manager(ManagerArgs),
    /// Start a manager and the processes of a launch file; supervise them (the
    /// skillfab-manager binary).
    Up(UpArgs),
    /// The debugging interface: a terminal UI over a running fabric.
    Console {
        #[command(flatten)]
        remote: RemoteArg,
    },
    /// Serve the running fabric to Foxglove (WebSocket protocol, `ws://127.0.0.1:8765`):
    /// every topic, transforms, the world as a 3-D scene, the sonar ring, events, logs, the
    /// plan tree, parameters, activation (docs/view.md). `--snapshot F.svg` draws one moment.
    View(skillfab_view::ViewArgs),
    /// Carry topics, the control plane, events and logs between this domain and other hosts
    /// over Zenoh (docs/bridge.md). Remote producers feed local skills as async producers do.
    Bridge(BridgeArgs),
    /// Every known message type with its size and the file it is declared in — the shipped
    /// catalog and the packages on SKILLFAB_MSG_PATH or --msg-path —; or one package's types as
    /// JSON schemas, a C header or a Python module.
    Schema {
        /// Print the package's C header (for skillfab: skill-sdk/capi/include/skillfab_msgs.h).
        #[arg(long, conflicts_with_all = ["python", "json"])]
        c: bool,
        /// Print the package's Python ctypes module (for skillfab: python/skillfab/msgs.py).
        #[arg(long, conflicts_with = "json")]
        python: bool,
        /// Print the package's schemas as JSON.
        #[arg(long)]
        json: bool,
        /// Message package directories (a package, or a directory of packages), before those
        /// of SKILLFAB_MSG_PATH.
        #[arg(long, value_name = "DIR")]
        msg_path: Vec<PathBuf>,
        /// The package --c, --python and --json print (default: the only package of
        /// --msg-path, else skillfab).
        #[arg(long)]
        package: Option<String>,
    },
    /// Remove what fabrics left on this machine: with processes of the domain alive, only the
    /// resources of its dead iceoryx2 nodes; with none, every file of the domain.
    Clean {
        /// Every domain of this user whose processes are all gone (instead of --domain).
        #[arg(long)]
        all_dead: bool,
        /// Print one JSON object per domain.
        #[arg(long)]
        json: bool,
    },
    /// The paper's experiment.
    Demo {
        #[command(subcommand)]
        which: DemoCmd,
    },
    /// Run skills again against a recording (`up --record`): their binaries as built now, in
    /// a private lock-step domain, fed the recorded samples of what they read, with their
    /// recorded activations and parameter changes; compares their outputs with the recorded
    /// ones. Exit status 1 on a divergence (it can gate CI).
    Replay {
        #[command(flatten)]
        opts: replay::ReplayOptions,
        /// Print the report as one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// A new skill, ready to build, test and run outside this repository, or a new message
    /// file in a package of one's own.
    New {
        #[command(subcommand)]
        what: NewCmd,
    },
    /// Run a plan (BehaviorTree.CPP v4 XML: docs/sequence.md) as this domain's sequencer:
    /// activate, set parameters, wait for monitors, with timeouts, retries and fallbacks.
    /// Exit status 0 when the plan succeeds, 1 when it fails; Ctrl-C halts it (parameters it
    /// set for a while are restored, its monitors removed).
    Sequence {
        /// The plan file.
        file: PathBuf,
        /// The tree to run (default: the plan's main_tree_to_execute).
        #[arg(long)]
        tree: Option<String>,
        /// Only check the plan: its form, then every skill, parameter (and value), output
        /// and field it names against the skills of --launch, else of the domain's running
        /// manager if there is one. Exit status 1 if a name does not fit.
        #[arg(long)]
        check: bool,
        /// With --check: the launch file whose skills the plan drives (each skill binary is
        /// asked for its declaration with `--describe`).
        #[arg(long, value_name = "FILE.toml", requires = "check")]
        launch: Option<PathBuf>,
        /// Do not resume the plan a runner that died left (same plan, same domain): restore
        /// what it had set and start from the first node.
        #[arg(long)]
        fresh: bool,
        /// Wait for these skills to have registered (comma-separated) before starting.
        #[arg(long, value_delimiter = ',')]
        wait_for: Vec<String>,
        /// How long to wait for the manager and the skills of --wait-for (s).
        #[arg(long, default_value_t = 60.0)]
        wait_timeout_s: f64,
        /// The plan is the planner's route on this map (`skillfab plan --map MAP [--to ROOM]
        /// [--and-back]`): when a step fails where the route says the robot still is
        /// (a car that does not come: its floor's lobby; a missed turn: the dead end straight
        /// on), plan again from there and run that plan (docs/maps.md, "Planning again").
        #[arg(long, value_name = "FILE.map.toml", conflicts_with_all = ["tree", "check"])]
        replan: Option<PathBuf>,
        /// With --replan: the route's room (default: the map's office).
        #[arg(long, value_name = "ROOM", requires = "replan")]
        to: Option<u32>,
        /// With --replan: the route goes back to the lab too.
        #[arg(long, requires = "replan")]
        and_back: bool,
        /// With --replan: the subtrees the plans are built from.
        #[arg(
            long,
            value_name = "FILE.xml",
            default_value = "skills/plans/deliver.xml",
            requires = "replan"
        )]
        library: PathBuf,
        #[command(flatten)]
        remote: RemoteArg,
    },
    /// The planner: the route from the lab to a room on a building's route map (docs/maps.md),
    /// from a room back to the lab, or both, printed as a plan (BehaviorTree.CPP v4 XML) built
    /// from the delivery mission's subtrees, ready for `skillfab sequence`. The map is checked
    /// first: one that contradicts itself is refused, each problem one sentence naming the
    /// place.
    Plan {
        /// The route map (TOML; a building's is beside it: NAME.map.toml).
        #[arg(long, value_name = "FILE.map.toml")]
        map: PathBuf,
        /// Where the route goes: a room (default: the map's office), or `lab` from a room.
        #[arg(long, value_name = "ROOM|lab")]
        to: Option<plan::Place>,
        /// Where the route starts: `lab`; a room (its number) with `--to lab`: the way
        /// back, from the room's door where the message was said; to a room, `lobby:F` (floor
        /// F's lobby), `end:N` (the dead end of the map's N-th leg, the robot facing it) or
        /// `car:F` (in a car boarded on floor F, its ride failed).
        #[arg(
            long,
            value_name = "lab|ROOM|lobby:F|end:N|car:F",
            default_value = "lab"
        )]
        from: plan::Place,
        /// To the room and back to the lab: one tree with both ways.
        #[arg(long)]
        and_back: bool,
        /// The subtrees the plan is built from.
        #[arg(
            long,
            value_name = "FILE.xml",
            default_value = "skills/plans/deliver.xml"
        )]
        library: PathBuf,
        /// Print the route in words instead of the plan.
        #[arg(long)]
        words: bool,
        /// Only check the map.
        #[arg(long, conflicts_with_all = ["to", "words"])]
        check: bool,
    },
    /// Talk to a running manager: the sequencer's link, from the shell.
    Ctl {
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        remote: RemoteArg,
        #[command(subcommand)]
        cmd: ctl::CtlCmd,
    },
}

/// The faults a demo can inject ([`faults::Faults`]).
#[derive(Args, Debug, Clone)]
struct FaultArgs {
    /// Fault injection: SIGKILL to a random fabric process (the manager, the device, a
    /// skill, or the plan's runner when a plan drives) every this many simulated seconds;
    /// each is restarted at once.
    #[arg(long, value_name = "SECONDS")]
    kill_every: Option<f64>,
    /// With --kill-every: kill only these (`manager`, `plan`, or a unit's name such as
    /// `denning`: the device hot-swapped).
    #[arg(
        long,
        value_name = "NAME,...",
        value_delimiter = ',',
        requires = "kill_every"
    )]
    kill_only: Vec<String>,
    /// Fault injection: SIGKILL to the simulator every this many simulated seconds; it is
    /// restarted and resumes the robot where it was, the device reconnects.
    #[arg(long, value_name = "SECONDS")]
    kill_sim_every: Option<f64>,
    /// Fault injection: share of the serial bytes with a flipped bit (0..=0.5).
    #[arg(long, default_value_t = 0.0)]
    corrupt_rate: f64,
    /// Fault injection: share of the serial bytes dropped (0..=0.5).
    #[arg(long, default_value_t = 0.0)]
    drop_rate: f64,
    /// Fault injection, in a building: no car answers a hall call before this many
    /// simulated seconds, and none moves with its doors closed (the button is pressed, none
    /// comes).
    #[arg(long, value_name = "SECONDS", default_value_t = 0.0)]
    cars_out_until: f64,
    /// With --cars-out-until: the cars are out from this many simulated seconds on.
    #[arg(long, value_name = "SECONDS", default_value_t = 0.0)]
    cars_out_from: f64,
}

impl FaultArgs {
    /// The faults, checked (`seed`: the run's, for the killer's choices).
    fn faults(&self, lockstep: bool, seed: u64) -> anyhow::Result<faults::Faults> {
        for (name, k) in [
            ("--kill-every", self.kill_every),
            ("--kill-sim-every", self.kill_sim_every),
        ] {
            if k.is_some_and(|k| k.is_nan() || k < 1.0) {
                anyhow::bail!("{name} must be at least 1 simulated second");
            }
        }
        for (name, r) in [
            ("--corrupt-rate", self.corrupt_rate),
            ("--drop-rate", self.drop_rate),
        ] {
            if !(0.0..=0.5).contains(&r) {
                anyhow::bail!("{name} must be in [0, 0.5], got {r}");
            }
        }
        for (name, s) in [
            ("--cars-out-from", self.cars_out_from),
            ("--cars-out-until", self.cars_out_until),
        ] {
            if !(s.is_finite() && s >= 0.0) {
                anyhow::bail!("{name} must be a number of simulated seconds, got {s}");
            }
        }
        if lockstep && (self.kill_every.is_some() || self.kill_sim_every.is_some()) {
            anyhow::bail!(
                "--kill-every and --kill-sim-every time their kills on the host's clock; \
                 they do not go with --lockstep"
            );
        }
        Ok(faults::Faults {
            kill_every_s: self.kill_every,
            kill_only: self.kill_only.clone(),
            kill_sim_every_s: self.kill_sim_every,
            corrupt_rate: self.corrupt_rate,
            drop_rate: self.drop_rate,
            cars_out: self.cars_out_from..self.cars_out_until,
            seed,
        })
    }
}

#[derive(Subcommand, Debug)]
enum DemoCmd {
    /// A plan drives the simulated Denning robot out of the lab (the paper's experiment).
    ExitLab {
        /// World file.
        #[arg(long, default_value = "devices/denning-sim/worlds/exit-lab.toml")]
        world: PathBuf,
        #[command(flatten)]
        run: DemoRuns,
        /// Simulated seconds before a run counts as failed.
        #[arg(long, default_value_t = 300.0)]
        limit_s: f64,
        #[command(flatten)]
        faults: FaultArgs,
        /// The plan that drives the robot (`skillfab sequence`'s format, docs/sequence.md).
        #[arg(
            long,
            value_name = "FILE.xml",
            default_value = "skills/plans/exit-lab.xml"
        )]
        plan: PathBuf,
    },
    /// The paper's whole mission: a plan takes the simulated robot out of the basement lab,
    /// through corridors to the elevators, up to the fourth floor and to an office (the
    /// department head's unless --to says), where it delivers a message. The plan is the
    /// planner's, on the building's route map (docs/maps.md).
    Deliver(demo::deliver::DeliverArgs),
}

/// How the demos run: the arguments `demo exit-lab` and `demo deliver` share.
#[derive(clap::Args, Debug)]
struct DemoRuns {
    /// Seed of the first run (run i uses seed + i): the robot's start, the sensors' noise, the
    /// elevators' schedules.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Number of runs.
    #[arg(long, default_value_t = 1)]
    runs: u32,
    /// Simulated seconds per real second (real time; ignored with --lockstep).
    #[arg(long, default_value_t = 4.0)]
    time_factor: f64,
    /// Write the first run's picture (SVG: a map per floor it was on, and the steps).
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Print one JSON object: runs, successes, median time, each run.
    #[arg(long)]
    json: bool,
    /// Lock-step: the simulator advances 10 ms per cycle and cycles run back to back, as fast
    /// as the host allows; the same seed gives the same run (--time-factor ignored).
    #[arg(long)]
    lockstep: bool,
    /// Record the first run at full rate into this MCAP file (see `skillfab replay`).
    #[arg(long, value_name = "FILE.mcap")]
    record: Option<PathBuf>,
    /// With --record: samples in `cdr` (with ros2msg schemas) or `json`.
    #[arg(
        long,
        value_enum,
        value_name = "ENCODING",
        default_value_t,
        requires = "record"
    )]
    record_encoding: skillfab_manager::recorder::SampleEncoding,
    /// Copy the first run's ground truth here (the simulator's CSV: time, pose, speeds,
    /// collisions, … every 100 ms of the robot's time).
    #[arg(long, value_name = "FILE.csv")]
    truth: Option<PathBuf>,
}

impl DemoRuns {
    /// The demo's options for these runs, `site`, `plan` and `limit_s` given; faults none.
    fn options(
        self,
        site: demo::Site,
        plan: PathBuf,
        limit_s: f64,
    ) -> anyhow::Result<demo::DemoOptions> {
        let t = self.time_factor;
        if !(t > 0.0 && t <= 50.0) {
            anyhow::bail!("--time-factor must be in (0, 50], got {t}");
        }
        Ok(demo::DemoOptions {
            site,
            seed: self.seed,
            runs: self.runs.max(1),
            time_factor: t,
            plot: self.plot,
            verbose: !self.json,
            limit_s,
            faults: faults::Faults {
                seed: self.seed,
                ..faults::Faults::default()
            },
            lockstep: self.lockstep,
            record: self.record.map(std::path::absolute).transpose()?,
            record_encoding: self.record_encoding,
            truth: self.truth,
            plan,
            tree: None,
            and_back: false,
            replan: None,
        })
    }
}

#[derive(Subcommand, Debug)]
enum NewCmd {
    /// A skill that reads the sonar ring and proposes on `drive`, with a launch file that runs
    /// it in the exit-lab network and a test: DIR/NAME/.
    Skill {
        /// Its name (lower case, digits, _).
        name: String,
        /// Its language.
        #[arg(long, value_enum, default_value = "rust")]
        lang: new::Lang,
        /// Where to create it.
        #[arg(long, default_value = ".")]
        dir: PathBuf,
    },
    /// A message file, DIR/PACKAGE/NAME.msg (see `skillfab schema --msg-path DIR`).
    Msg {
        /// The package (lower case, digits, _).
        package: String,
        /// The type's name (an upper-case letter first).
        name: String,
        /// The directory of packages.
        #[arg(long, default_value = ".")]
        dir: PathBuf,
    },
}

/// Hands `manager` and `up` over to the `skillfab-manager` binary (beside this one, else on
/// `PATH`) with this process's own arguments, as cargo does with its external subcommands:
/// the same pid, signals, standard streams and exit status.
fn exec_manager() -> anyhow::Result<()> {
    use std::os::unix::process::CommandExt;
    let beside = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|dir| dir.join("skillfab-manager")))
        .filter(|p| p.is_file());
    let program = beside.unwrap_or_else(|| PathBuf::from("skillfab-manager"));
    let err = std::process::Command::new(&program)
        .args(std::env::args_os().skip(1))
        .exec();
    Err(anyhow::Error::from(err).context(format!("running {}", program.display())))
}

/// `skillfab clean`: one domain, or every dead one of this user.
fn clean(domain: &Domain, all_dead: bool, json: bool) -> anyhow::Result<()> {
    use skillfab_proto::clean;
    let domains = if all_dead {
        clean::domains_on_machine()
            .into_iter()
            .filter(|d| clean::live_pids(d).is_empty())
            .collect()
    } else {
        vec![domain.clone()]
    };
    for d in &domains {
        let c = clean::clean(d)?;
        if json {
            println!("{}", serde_json::to_string(&c)?);
        } else if c.alive.is_empty() {
            println!(
                "{}: removed {} files ({} bytes){}, {} dead nodes",
                c.domain,
                c.files,
                c.bytes,
                if c.root {
                    " and its root directory"
                } else {
                    ""
                },
                c.dead_nodes
            );
        } else {
            println!(
                "{}: still running (pids {:?}): removed the resources of {} dead nodes, kept the rest",
                c.domain, c.alive, c.dead_nodes
            );
        }
    }
    if domains.is_empty() && !json {
        println!("nothing to clean");
    }
    Ok(())
}

fn run(cli: Cli) -> anyhow::Result<()> {
    let domain = Domain::new(&cli.domain.domain)?;
    match cli.command {
        Cmd::Manager(_) => exec_manager(),
        Cmd::Up(args) => {
            // Said once, here, rather than by a bridge process `up` would restart 5 times.
            #[cfg(not(feature = "bridge"))]
            if let Ok(l) = skillfab_manager::launch::Launch::load(&args.launch)
                && l.processes.iter().any(|p| {
                    p.program.file_name() == Some(std::ffi::OsStr::new("skillfab"))
                        && p.args.first().map(String::as_str) == Some("bridge")
                })
            {
                anyhow::bail!("{}: [bridge]: {NO_BRIDGE}", args.launch.display());
            }
            #[cfg(feature = "bridge")]
            let _ = args;
            exec_manager()
        }
        Cmd::Ctl { json, remote, cmd } => ctl::run(remote.address(&domain)?, json, cmd),
        Cmd::Plan {
            map,
            to,
            from,
            library,
            words,
            check,
            and_back,
        } => plan::run(
            &map,
            plan::Trip { from, to, and_back },
            &library,
            words,
            check,
        ),
        Cmd::Sequence {
            file,
            tree,
            check,
            launch,
            fresh,
            wait_for,
            wait_timeout_s,
            replan,
            to,
            and_back,
            library,
            remote,
        } => sequence::run(
            &domain,
            remote.address(&domain)?,
            &file,
            &sequence::RunOptions {
                tree,
                check,
                launch,
                fresh,
                wait_for,
                wait: std::time::Duration::from_secs_f64(wait_timeout_s.max(0.0)),
                replan: replan.map(|map| replan::Replanning {
                    map,
                    to,
                    and_back,
                    library,
                }),
            },
        ),
        #[cfg(feature = "bridge")]
        Cmd::Bridge(args) => Ok(skillfab_bridge::run(&domain, &args)?),
        #[cfg(not(feature = "bridge"))]
        Cmd::Bridge(_) => anyhow::bail!("bridge: {NO_BRIDGE}"),
        Cmd::New {
            what: NewCmd::Skill { name, lang, dir },
        } => {
            let out = new::new_skill(&name, lang, &dir)?;
            println!("{}", std::fs::read_to_string(out.join("README.md"))?);
            println!("created {}", out.display());
            Ok(())
        }
        Cmd::New {
            what: NewCmd::Msg { package, name, dir },
        } => {
            let file = new::new_msg(&package, &name, &dir)?;
            println!(
                "created {}
  list it:  skillfab schema --msg-path {}
  C header: skillfab schema --c --msg-path {0} --package {package}
  Python:   skillfab schema --python --msg-path {0} --package {package}
  at run time (C, C++, Python skills): SKILLFAB_MSG_PATH={0}
  Rust: a build script calling skillfab_msggen::build (docs/messages.md)",
                file.display(),
                dir.display()
            );
            Ok(())
        }
        Cmd::Replay { opts, json } => replay(&opts, json),
        Cmd::Console { remote } => skillfab_console::run(remote.address(&domain)?),
        Cmd::View(args) => Ok(skillfab_view::run(&domain, &args, &|addr| {
            if args.snapshot.is_none() {
                eprintln!(
                    "skillfab view: serving ws://{addr} (Foxglove: Open connection → Foxglove WebSocket)"
                );
            }
        })?),
        Cmd::Clean { all_dead, json } => clean(&domain, all_dead, json),
        Cmd::Schema {
            c,
            python,
            json,
            msg_path,
            package,
        } => schema(&msg_path, package, c, python, json),
        Cmd::Demo {
            which:
                DemoCmd::ExitLab {
                    world,
                    run,
                    limit_s,
                    faults,
                    plan,
                },
        } => {
            let json = run.json;
            // Read and checked here: a mistake is refused before anything starts.
            sequence::read_plan(&plan)?;
            let mut opts = run.options(demo::Site::World(world), plan, limit_s)?;
            opts.faults = faults.faults(opts.lockstep, opts.seed)?;
            let summary = demo::demo(&opts)?;
            report(&summary, json, "left the lab")?;
            if summary.successes == 0 {
                anyhow::bail!("the robot did not leave the lab");
            }
            Ok(())
        }
        Cmd::Demo {
            which: DemoCmd::Deliver(args),
        } => demo::deliver::run(args),
    }
}

/// Prints a demo's summary: one JSON object, or a line.
fn report(summary: &demo::Summary, json: bool, what: &str) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        println!(
            "{} of {} runs {what}; median time {}{}",
            summary.successes,
            summary.runs,
            summary
                .median_time_s
                .map_or("-".into(), |t| format!("{t:.1} s simulated")),
            match summary.errors {
                0 => String::new(),
                n => format!("; {n} ended in an error (see above)"),
            }
        );
    }
    Ok(())
}

/// `skillfab schema`.
fn schema(
    msg_path: &[PathBuf],
    package: Option<String>,
    c: bool,
    python: bool,
    json: bool,
) -> anyhow::Result<()> {
    use skillfab_msgs::dynamic;
    let mut dirs = msg_path.to_vec();
    dirs.extend(dynamic::msg_path());
    let (catalog, packages) = dynamic::catalog(&dirs)?;
    // Default: the only package loaded from --msg-path (already read with the rest).
    let package = package.unwrap_or_else(|| {
        let given: Vec<&str> = packages
            .iter()
            .filter(|p| msg_path.iter().any(|d| p.dir.starts_with(d)))
            .map(|p| p.name.as_str())
            .collect();
        match given[..] {
            [only] => only.to_string(),
            _ => "skillfab".into(),
        }
    });
    if !packages.iter().any(|p| p.name == package) {
        anyhow::bail!(
            "no message package '{package}' (known: {})",
            packages
                .iter()
                .map(|p| p.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let schemas: Vec<_> = catalog
        .types
        .iter()
        .map(|t| dynamic::schema(&catalog, t))
        .collect();
    if c {
        print!("{}", skillfab_codegen::c_header_for(&schemas, &package));
    } else if python {
        print!(
            "{}",
            skillfab_codegen::python_module_for(&schemas, &package)
        );
    } else if json {
        let prefix = format!("{package}.");
        let ours: Vec<_> = schemas
            .iter()
            .filter(|s| s.type_name.starts_with(&prefix))
            .collect();
        println!("{}", serde_json::to_string_pretty(&ours)?);
    } else {
        println!("{:<28} {:>7}  declared in", "type", "bytes");
        for (t, s) in catalog.types.iter().zip(&schemas) {
            println!("{:<28} {:>7}  {}", s.type_name, s.size, t.file.display());
        }
    }
    Ok(())
}

/// `skillfab replay`: prints the report; a divergence is an error (exit status 1).
fn replay(opts: &replay::ReplayOptions, json: bool) -> anyhow::Result<()> {
    let r = replay::replay(opts)?;
    if json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        println!(
            "replayed {} over cycles {}..={} in {:.1} s: {} of {} cycles identical ({} samples compared)",
            r.skills.join(", "),
            r.from,
            r.to,
            r.wall_s,
            r.identical_cycles,
            r.cycles,
            r.samples
        );
        for k in &r.kills {
            println!(
                "killed {} after cycle {} (pid {} → {}{})",
                k.skill,
                k.cycle,
                k.pid,
                k.new_pid,
                if k.forgot {
                    ", its kept state removed"
                } else {
                    ""
                }
            );
        }
        match &r.divergence {
            None => println!("no divergence"),
            Some(d) => println!(
                "first divergence: cycle {}, {}.{} field {}: recorded {}, replayed {}",
                d.cycle, d.skill, d.port, d.field, d.recorded, d.replayed
            ),
        }
    }
    match &r.divergence {
        None => Ok(()),
        Some(d) => anyhow::bail!(
            "{}.{} diverged from the recording at cycle {}",
            d.skill,
            d.port,
            d.cycle
        ),
    }
}

/// The `skillfab` command: parses the arguments, runs the command, prints an error as one
/// line (with its causes) and maps it to the exit code.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    // The console owns the terminal: log lines on stderr would scribble over it.
    if !matches!(cli.command, Cmd::Console { .. }) {
        init_tracing();
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the refusal (and its cause chain) for scripts and people alike.
            eprintln!("skillfab: error: {}", format!("{e:#}").replace('\n', " "));
            match e.downcast_ref::<sequence::Unfinished>() {
                Some(_) => ExitCode::from(sequence::UNFINISHED),
                None => ExitCode::FAILURE,
            }
        }
    }
}
