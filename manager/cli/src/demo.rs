//! `skillfab demo exit-lab`: the paper's experiment. A sequencer written against the client
//! library drives the simulated Denning robot out of the lab:
//!
//! 1. activate wander + avoid + barcode_track; a monitor waits for the door's barcode;
//! 2. switch wander for home (drive to the barcode) and let door_locate look;
//! 3. near the barcode, follow its wall (on the left; after 4 m without a door, home again
//!    and follow it the other way) while door_locate gathers evidence;
//! 4. once the door is located, lower `avoid.safe_distance` for the tight passage (the
//!    paper's example of parameterising a skill) and let go_through drive; when the
//!    simulator's ground truth says the robot is outside, stop it, restore the parameter,
//!    and report.

use anyhow::{Context, bail};
use denning_sim::truth::TruthRecord;
use denning_sim::world::World;
use serde::Serialize;
use skillfab_client::Client;
use skillfab_manager::launch::{LaunchFile, ManagerSection, ProcessEntry, Restart, find_program};
use skillfab_proto::control::{EventKind, MonitorMode, SkillState};
use skillfab_proto::domain::Domain;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::faults::{Faults, Kill, Killer};

/// Options of `skillfab demo exit-lab`.
#[derive(Debug, Clone)]
pub struct DemoOptions {
    /// World file.
    pub world: PathBuf,
    /// Seed of the first run (run i uses seed + i).
    pub seed: u64,
    /// Number of runs.
    pub runs: u32,
    /// Simulated seconds per real second.
    pub time_factor: f64,
    /// Write the first run's trajectory picture here.
    pub plot: Option<PathBuf>,
    /// Print progress (false with `--json`).
    pub verbose: bool,
    /// Give up after this much simulated time.
    pub limit_s: f64,
    /// Faults injected into every run.
    pub faults: Faults,
    /// Lock-step: the simulator advances one period per cycle and the manager runs cycles
    /// back to back (`--time-factor` does not apply); the run is a function of world and seed.
    pub lockstep: bool,
    /// Record the first run here (MCAP, every topic).
    pub record: Option<PathBuf>,
    /// A plan (`skillfab sequence`'s format) that drives the robot instead of the sequencer
    /// written in Rust here.
    pub plan: Option<skillfab_sequence::Plan>,
}

/// One run's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct RunOutcome {
    /// Seed.
    pub seed: u64,
    /// World name.
    pub world: String,
    /// Left the lab within the limit.
    pub success: bool,
    /// Simulated time at the end (s): when the robot was first outside, else the last.
    pub time_s: f64,
    /// Host time the run took (s), start-up included.
    pub wall_s: f64,
    /// Collisions the simulator reported.
    pub collisions: u64,
    /// Sequencer steps: (what, cycle, simulated time).
    pub steps: Vec<(String, u64, f64)>,
    /// Processes killed, and their recovery (with `--kill-every`).
    pub kills: Vec<Kill>,
    /// Longest time without a drive command reaching the robot (simulated s, from the
    /// simulator's ground truth at its status period).
    pub max_command_gap_s: f64,
    /// Longest time a non-zero drive command stayed in force at the robot after it was 500 ms
    /// old (simulated s): how long a stale command drove it (until the robot's watchdog or a
    /// new command).
    pub max_stale_drive_s: f64,
    /// The serial link as the device reported it last: (frames, bad frames, garbage bytes,
    /// connects).
    pub link: Option<(u64, u64, u64, u64)>,
    #[serde(skip)]
    trajectory: Vec<TruthRecord>,
}

/// What `--json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Runs.
    pub runs: u32,
    /// Successful runs.
    pub successes: u32,
    /// Median simulated time of the successful runs (s).
    pub median_time_s: Option<f64>,
    /// Each run.
    pub runs_detail: Vec<RunOutcome>,
}

/// The simulator's newest ground-truth record.
fn latest(path: &Path) -> Option<TruthRecord> {
    TruthRecord::read(path).ok()?.pop()
}

struct Network {
    child: Child,
    dir: PathBuf,
    domain: Domain,
}

impl Drop for Network {
    fn drop(&mut self) {
        if let Ok(pid) = i32::try_from(self.child.id()) {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(pid),
                nix::sys::signal::Signal::SIGTERM,
            );
        }
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if matches!(self.child.try_wait(), Ok(Some(_))) {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
        self.domain.remove_all_files();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

const SKILLS: [&str; 8] = [
    "avoid",
    "wander",
    "wall_follow",
    "barcode_track",
    "home",
    "door_locate",
    "go_through",
    "stop",
];

fn start(opts: &DemoOptions, seed: u64, run: u32) -> anyhow::Result<(Network, PathBuf)> {
    let domain = Domain::new(&format!("demo-{}-{run}", std::process::id()))?;
    domain.remove_all_files();
    let dir = std::env::temp_dir().join(format!("skillfab-demo-{}-{run}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let world = std::fs::canonicalize(&opts.world)
        .with_context(|| format!("world {}", opts.world.display()))?;
    let link = dir.join("robot");
    let traj = dir.join("trajectory.csv");
    let robot_state = dir.join("robot.state");
    let program = |name: &str| {
        find_program(name, Path::new("."))
            .with_context(|| format!("program '{name}' not found next to skillfab"))
    };
    // In lock-step a cycle is 10 ms of the robot's time however long it takes.
    let time_factor = if opts.lockstep { 1.0 } else { opts.time_factor };
    let period_ms = 10.0 / time_factor;
    // Under injected kills every process comes back at once, every time (as on a robot with
    // a supervisor); otherwise the launch file's defaults.
    let killing = opts.faults.kill_every_s.is_some();
    let (restarts, backoff_ms) = if killing { (100_000, 20) } else { (5, 200) };
    let text = |p: &Path| p.to_string_lossy().into_owned();
    let mut launch = LaunchFile {
        bridge: None,
        manager: ManagerSection {
            period_ms: Some(period_ms),
            // (Lock-step: the manager's own, 10 s.)
            deadline_ms: (!opts.lockstep).then_some((period_ms * 5.0).max(20.0)),
        },
        process: vec![
            ProcessEntry {
                name: "denning-sim".into(),
                bin: text(&program("denning-sim")?),
                registers: Some(false),
                args: vec![
                    "--world".into(),
                    text(&world),
                    "--link".into(),
                    text(&link),
                    "--seed".into(),
                    seed.to_string(),
                    "--time-factor".into(),
                    time_factor.to_string(),
                    "--trajectory".into(),
                    text(&traj),
                    "--corrupt-rate".into(),
                    opts.faults.corrupt_rate.to_string(),
                    "--drop-rate".into(),
                    opts.faults.drop_rate.to_string(),
                    "--state".into(),
                    text(&robot_state),
                ],
                // Killed on purpose, the robot's link comes back (where the robot was).
                restart: if opts.faults.kill_sim_every_s.is_some() {
                    Restart::Always
                } else {
                    Restart::Never
                },
                max_restarts: Some(100_000),
                backoff_ms: Some(20),
                ..ProcessEntry::default()
            },
            ProcessEntry {
                name: "denning".into(),
                bin: text(&program("denning")?),
                args: vec!["--port".into(), text(&link)],
                // Blind after 500 ms of the robot's time.
                params: [(
                    "blind_ms".to_string(),
                    toml::Value::Float(500.0 / time_factor),
                )]
                .into(),
                restart: Restart::Always,
                max_restarts: Some(restarts),
                backoff_ms: Some(backoff_ms),
                ..ProcessEntry::default()
            },
        ],
    };
    for s in SKILLS {
        let mut params = std::collections::BTreeMap::new();
        if s == "wander" {
            // The seed varies the wandering between runs (an i64 in TOML).
            params.insert("seed".to_string(), toml::Value::Integer(seed as i64));
        }
        launch.process.push(ProcessEntry {
            name: s.into(),
            bin: text(&program(s)?),
            active: Some(false),
            params,
            restart: if killing {
                Restart::OnFailure
            } else {
                Restart::Never
            },
            max_restarts: Some(restarts),
            backoff_ms: Some(backoff_ms),
            ..ProcessEntry::default()
        });
    }
    if opts.lockstep {
        launch.process[0].args.push("--lockstep".into());
    }
    let launch = toml::to_string(&launch).context("writing the launch file")?;
    let path = dir.join("exit-lab.toml");
    std::fs::write(&path, launch)?;
    let log = std::fs::File::create(dir.join("up.log"))?;
    let mut cmd = Command::new(std::env::current_exe()?);
    cmd.args([
        "up",
        path.to_str().unwrap_or_default(),
        "--domain",
        domain.name(),
    ])
    // Lock-step: paused until the sequencer has set up, so the run does not depend on when
    // it connected.
    .args(if opts.lockstep {
        &["--lockstep", "--paused"][..]
    } else {
        &[]
    });
    if let Some(r) = opts.record.as_ref().filter(|_| run == 0) {
        cmd.arg("--record").arg(r);
    }
    cmd.env_remove("SKILLFAB_DOMAIN")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(log);
    // If the demo dies, `up` gets SIGTERM and shuts the network down cleanly.
    // SAFETY: only async-signal-safe system calls between fork and exec.
    unsafe {
        use std::os::unix::process::CommandExt;
        cmd.pre_exec(|| {
            let _ = nix::sys::prctl::set_pdeathsig(nix::sys::signal::Signal::SIGTERM);
            Ok(())
        });
    }
    let child = cmd.spawn().context("starting skillfab up")?;
    Ok((Network { child, dir, domain }, traj))
}

fn connect(net: &Network) -> anyhow::Result<Client> {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if let Ok(c) = Client::connect(&net.domain)
            && let Ok(list) = c.list()
            && list.len() == SKILLS.len() + 1
            && list.iter().all(|s| s.state != SkillState::Starting)
        {
            return Ok(c);
        }
        if Instant::now() > deadline {
            bail!("the exit-lab network did not come up within 60 s (see the log of skillfab up)");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Where the sequencer is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Wandering until the barcode is seen.
    Search,
    /// Homing on the barcode.
    Home,
    /// Following the wall from the barcode with the wall on this side (-1 left, 1 right).
    Follow(i32),
    /// Back to the barcode after following the wall on the left in vain.
    Return,
    /// Driving through the located door.
    Through,
}

/// The exit-lab sequencer: which skills run in each phase, and the monitor that ends it.
/// Barcode seen: wander -> home (and door_locate looks). Near the barcode: follow the wall
/// with it on the left; 4 m away without a door, home again and follow it on the right. Door
/// located (in any phase): lower `avoid.safe_distance` for the tight passage, go_through.
struct Sequencer {
    phase: Phase,
    seen: u64,
    near: Option<u64>,
    far: Option<u64>,
    found: Option<u64>,
}

impl Sequencer {
    /// Reacts to a monitor firing; returns the step to report.
    fn on_monitor(&mut self, c: &Client, id: u64) -> anyhow::Result<Option<String>> {
        let near_code =
            |c: &Client| c.add_monitor("barcode_track.target.range < 1.7", MonitorMode::Once, 2);
        let step = match self.phase {
            _ if Some(id) == self.found && self.phase != Phase::Through => {
                self.phase = Phase::Through;
                c.set_param("avoid", "safe_distance", "0.2")?;
                c.deactivate(&["home", "wall_follow"])?;
                c.activate(&["go_through"])?;
                "door located: avoid.safe_distance = 0.2 for the passage; go_through drives"
                    .to_string()
            }
            Phase::Search if id == self.seen => {
                self.phase = Phase::Home;
                c.deactivate(&["wander"])?;
                c.activate(&["home", "door_locate"])?;
                self.near = Some(near_code(c)?);
                self.found =
                    Some(c.add_monitor("door_locate.door.found == 1", MonitorMode::Once, 0)?);
                "barcode seen: wander -> home; door_locate looks".to_string()
            }
            Phase::Home | Phase::Return if Some(id) == self.near => {
                let side = if self.phase == Phase::Home { -1 } else { 1 };
                self.phase = Phase::Follow(side);
                c.deactivate(&["home"])?;
                c.set_param("wall_follow", "side", &side.to_string())?;
                c.activate(&["wall_follow"])?;
                if side < 0 {
                    self.far = Some(c.add_monitor(
                        "barcode_track.target.range > 4.0",
                        MonitorMode::Once,
                        2,
                    )?);
                }
                format!(
                    "near the barcode: home -> wall_follow, wall on the {}",
                    if side < 0 { "left" } else { "right" }
                )
            }
            Phase::Follow(-1) if Some(id) == self.far => {
                self.phase = Phase::Return;
                c.deactivate(&["wall_follow"])?;
                c.activate(&["home"])?;
                self.near = Some(near_code(c)?);
                "no door within 4 m that way: wall_follow -> home, then the other way".to_string()
            }
            _ => return Ok(None),
        };
        Ok(Some(step))
    }
}

/// What drives the robot: the sequencer written here, or a plan.
enum Driver {
    Code(Sequencer),
    /// With its lock-step pacing, if the manager runs in lock-step.
    Plan(skillfab_sequence::Sequencer),
}

/// How long a run waits for the simulator's first ground truth.
const NO_TRUTH: Duration = Duration::from_secs(30);

/// How a run ended, by the simulator's ground truth.
#[derive(Debug, Clone, Copy)]
enum Verdict {
    /// The robot is outside the lab.
    Outside,
    /// The time limit passed.
    Limit,
}

/// How the run ended by ground truth `now`, if it has.
fn judge(now: &TruthRecord, limit_s: f64) -> Option<Verdict> {
    if now.outside {
        Some(Verdict::Outside)
    } else if now.t > limit_s {
        Some(Verdict::Limit)
    } else {
        None
    }
}

/// The newest ground truth into `out`; how the run ended, if it has.
fn watch(traj: &Path, out: &mut RunOutcome, limit_s: f64) -> Option<Verdict> {
    let now = latest(traj)?;
    out.time_s = now.t;
    out.collisions = now.collisions;
    judge(&now, limit_s)
}

const NO_TRUTH_ERROR: &str =
    "the simulator wrote no ground truth within 30 s (see the log of skillfab up)";

/// Acts on how the run ended: outside, the robot is stopped.
fn verdict(
    c: &Client,
    out: &mut RunOutcome,
    v: Verdict,
    step: &dyn Fn(&Client, &mut RunOutcome, &str),
) -> anyhow::Result<()> {
    match v {
        Verdict::Outside => {
            out.success = true;
            c.activate(&["stop"])?;
            step(c, out, "outside the lab: stop");
        }
        Verdict::Limit => step(c, out, "time limit reached"),
    }
    Ok(())
}

/// One run of the experiment.
pub fn run_once(opts: &DemoOptions, seed: u64, run: u32) -> anyhow::Result<RunOutcome> {
    let wall = Instant::now();
    let (net, traj) = start(opts, seed, run)?;
    let mut c = connect(&net)?;
    c.subscribe()?;
    let mut out = RunOutcome {
        seed,
        world: opts
            .world
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        success: false,
        time_s: 0.0,
        wall_s: 0.0,
        collisions: 0,
        steps: Vec::new(),
        kills: Vec::new(),
        max_command_gap_s: 0.0,
        max_stale_drive_s: 0.0,
        link: None,
        trajectory: Vec::new(),
    };
    let record = |c: &Client, steps: &mut Vec<(String, u64, f64)>, what: &str| {
        let cycle = c.stats().map(|s| s.cycles).unwrap_or(0);
        let t = latest(&traj).map_or(0.0, |r| r.t);
        if opts.verbose {
            println!("  [cycle {cycle:>6}, t = {t:>6.1} s] {what}");
        }
        steps.push((what.to_string(), cycle, t));
    };
    let step = |c: &Client, out: &mut RunOutcome, what: &str| record(c, &mut out.steps, what);
    // The plan (run below), or the Rust sequencer's first step.
    let mut driver = match &opts.plan {
        Some(plan) => Driver::Plan(skillfab_sequence::Sequencer::new(plan, None)?),
        None => {
            c.activate(&["wander", "avoid", "barcode_track"])?;
            step(
                &c,
                &mut out,
                "activate wander + avoid + barcode_track; monitor the door's barcode",
            );
            Driver::Code(Sequencer {
                phase: Phase::Search,
                seen: c.add_monitor("barcode_track.target.seen == 1", MonitorMode::Once, 0)?,
                near: None,
                far: None,
                found: None,
            })
        }
    };
    let sim_killer = opts.faults.kill_sim_every_s.map(|every| {
        Killer::start_sim(
            &net.domain,
            &net.dir.join("robot"),
            Duration::from_secs_f64(every / opts.time_factor),
        )
    });
    let killer = opts.faults.kill_every_s.map(|every| {
        Killer::start(
            &net.domain,
            Duration::from_secs_f64(every / opts.time_factor),
            // The manager's period: 10 ms of simulated time.
            Duration::from_secs_f64(0.01 / opts.time_factor),
            opts.faults.seed ^ seed,
        )
    });
    if opts.lockstep && matches!(driver, Driver::Code(_)) {
        c.run()?;
    }
    let started = Instant::now();
    match &mut driver {
        Driver::Code(seq) => loop {
            if interrupted() {
                bail!("interrupted");
            }
            if out.time_s == 0.0 && started.elapsed() > NO_TRUTH {
                bail!(NO_TRUTH_ERROR);
            }
            let ev = c.next_event(Duration::from_millis(100))?;
            if let Some(EventKind::MonitorFired { id, .. }) = ev.map(|e| e.kind) {
                if let Some(what) = seq.on_monitor(&c, id)? {
                    step(&c, &mut out, &what);
                }
                // Lock-step: the manager paused after the cycle the monitor fired in.
                if opts.lockstep {
                    c.run()?;
                }
            }
            if let Some(v) = watch(&traj, &mut out, opts.limit_s) {
                verdict(&c, &mut out, v, &step)?;
                break;
            }
        },
        // The plan runs (and paces a lock-step manager) until it ends or the ground truth
        // ends the run; it is then halted: what it set is restored, its monitors removed.
        Driver::Plan(p) => {
            let mut looked = Instant::now();
            let mut last: Option<TruthRecord> = None;
            let mut stop = || {
                if interrupted() {
                    return true;
                }
                // The trajectory file is read whole: ten times a second is enough.
                if looked.elapsed() >= Duration::from_millis(100) {
                    looked = Instant::now();
                    last = latest(&traj).or(last);
                }
                match &last {
                    Some(now) => judge(now, opts.limit_s).is_some(),
                    None => started.elapsed() > NO_TRUTH,
                }
            };
            let steps = &mut out.steps;
            let mut on_step = |c: &Client, what: &str| record(c, steps, what);
            let ended = skillfab_sequence::run(&mut c, p, &mut stop, &mut on_step)?;
            if interrupted() {
                bail!("interrupted");
            }
            if let Some(status) = ended {
                step(&c, &mut out, &format!("the plan ended: {status:?}"));
            }
            let Some(now) = latest(&traj).or(last) else {
                bail!(NO_TRUTH_ERROR);
            };
            (out.time_s, out.collisions) = (now.t, now.collisions);
            if let Some(v) = judge(&now, opts.limit_s) {
                verdict(&c, &mut out, v, &step)?;
            }
        }
    }
    if let Some(k) = killer {
        out.kills = k.finish();
    }
    if let Some(k) = sim_killer {
        out.kills.extend(k.finish());
    }
    let link = |field: &str| {
        c.query(&format!("denning.link.{field}"))
            .ok()
            .and_then(|(v, _)| v.as_f64())
            .map(|x| x as u64)
    };
    out.link = (|| {
        Some((
            link("frames")?,
            link("bad_frames")?,
            link("garbage")?,
            link("connects")?,
        ))
    })();
    match &mut driver {
        Driver::Code(_) => {
            c.set_param("avoid", "safe_distance", "0.6")?;
            step(&c, &mut out, "avoid.safe_distance restored");
        }
        // Halted already when the run ended.
        Driver::Plan(_) => {}
    }
    let all: Vec<&str> = SKILLS.iter().copied().filter(|s| *s != "stop").collect();
    c.deactivate(&all)?;
    step(&c, &mut out, "skills deactivated");
    out.trajectory = TruthRecord::read(&traj).unwrap_or_default();
    // The robot may have gone on a little while the sequencer looked: the time it first was
    // outside is the mission's.
    if let Some(first) = out.trajectory.iter().find(|r| r.outside) {
        out.time_s = first.t;
    }
    out.wall_s = wall.elapsed().as_secs_f64();
    (out.max_command_gap_s, out.max_stale_drive_s) = command_gaps(&out.trajectory);
    drop(c);
    drop(net);
    Ok(out)
}

/// From the ground truth: the longest time without a drive command at the robot, and the
/// longest a non-zero command stayed in force at the robot after it was older than
/// 500 ms (the Denning driver's `COMMAND_TIMEOUT`): the device re-sends the fabric's command
/// every 100 ms and replaces it by stop after 500 ms, so only a dead link or device lets a
/// command go stale at the robot (whose own watchdog stops it after 2 s).
fn command_gaps(rows: &[TruthRecord]) -> (f64, f64) {
    let stale = 0.5;
    let gap = rows.iter().map(|r| r.cmd_age).fold(0.0, f64::max);
    let driven = rows
        .iter()
        .filter(|r| r.driven && r.cmd_age > stale)
        .map(|r| r.cmd_age - stale)
        .fold(0.0, f64::max);
    (gap, driven)
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: nix::libc::c_int) {
    INTERRUPTED.store(true, Ordering::Release);
}

/// From now on SIGINT and SIGTERM only set a flag: [`interrupted`] says whether one came.
pub fn catch_interrupts() -> anyhow::Result<()> {
    for sig in [
        nix::sys::signal::Signal::SIGINT,
        nix::sys::signal::Signal::SIGTERM,
    ] {
        // SAFETY: the handler only stores to an atomic.
        unsafe { nix::sys::signal::signal(sig, nix::sys::signal::SigHandler::Handler(on_signal)) }?;
    }
    Ok(())
}

/// Whether SIGINT or SIGTERM came since [`catch_interrupts`].
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::Acquire)
}

/// Runs the experiment `opts.runs` times. Ctrl-C or SIGTERM ends it cleanly: the network is
/// shut down and its shared memory and files removed.
pub fn demo(opts: &DemoOptions) -> anyhow::Result<Summary> {
    catch_interrupts()?;
    let mut detail = Vec::new();
    for run in 0..opts.runs {
        let seed = opts.seed + u64::from(run);
        if opts.verbose {
            println!(
                "run {} of {}: world {}, seed {seed}",
                run + 1,
                opts.runs,
                opts.world.display()
            );
        }
        let r = run_once(opts, seed, run)?;
        if opts.verbose {
            println!(
                "  => {} in {:.1} s simulated ({:.1} s of host time), {} collisions",
                if r.success { "SUCCESS" } else { "FAILURE" },
                r.time_s,
                r.wall_s,
                r.collisions
            );
        }
        if run == 0
            && let Some(p) = &opts.plot
        {
            let world = World::load(&opts.world)?;
            std::fs::write(p, svg(&world, &r))?;
            if opts.verbose {
                println!("  trajectory picture: {}", p.display());
            }
        }
        detail.push(r);
    }
    let mut times: Vec<f64> = detail
        .iter()
        .filter(|r| r.success)
        .map(|r| r.time_s)
        .collect();
    times.sort_by(f64::total_cmp);
    Ok(Summary {
        runs: opts.runs,
        successes: detail.iter().filter(|r| r.success).count() as u32,
        median_time_s: (!times.is_empty()).then(|| times[times.len() / 2]),
        runs_detail: detail,
    })
}

/// The trajectory over the world map, with the sequencer's switches marked.
fn svg(w: &World, r: &RunOutcome) -> String {
    // The map's top edge (m) sets the picture's; the steps are listed below the map.
    let top = w
        .wall
        .iter()
        .flat_map(|s| [s.from[1], s.to[1]])
        .fold(0.0f64, f64::max);
    let (sx, sy, ox, oy, h) = (50.0, 50.0, 50.0, 50.0, top + 0.5);
    let px = |x: f64| ox + x * sx;
    let py = |y: f64| oy + (h - y) * sy;
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
        px(14.0),
        py(-1.2) + 16.0 * r.steps.len() as f64
    );
    for seg in &w.wall {
        s.push_str(&format!(
            "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"black\" stroke-width=\"4\"/>\n",
            px(seg.from[0]), py(seg.from[1]), px(seg.to[0]), py(seg.to[1])
        ));
    }
    for seg in &w.door {
        s.push_str(&format!(
            "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#2a2\" stroke-width=\"2\" stroke-dasharray=\"4 3\"/>\n",
            px(seg.from[0]), py(seg.from[1]), px(seg.to[0]), py(seg.to[1])
        ));
    }
    for b in &w.boxes {
        s.push_str(&format!(
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#bbb\" stroke=\"#555\"/>\n",
            px(b.min[0]), py(b.max[1]), (b.max[0] - b.min[0]) * sx, (b.max[1] - b.min[1]) * sy
        ));
    }
    for c in &w.barcode {
        s.push_str(&format!(
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"8\" height=\"8\" fill=\"#d22\"/><text x=\"{:.1}\" y=\"{:.1}\">barcode {}</text>\n",
            px(c.at[0]) - 4.0, py(c.at[1]) - 4.0, px(c.at[0]) + 8.0, py(c.at[1]) - 6.0, c.id
        ));
    }
    let pts: Vec<String> = r
        .trajectory
        .iter()
        .map(|p| format!("{:.1},{:.1}", px(p.x), py(p.y)))
        .collect();
    s.push_str(&format!(
        "<polyline points=\"{}\" fill=\"none\" stroke=\"#15c\" stroke-width=\"2\"/>\n",
        pts.join(" ")
    ));
    for (i, (what, _, t)) in r.steps.iter().enumerate() {
        if let Some(p) = r.trajectory.iter().find(|p| p.t >= *t) {
            s.push_str(&format!(
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"5\" fill=\"#f80\"/><text x=\"{:.1}\" y=\"{:.1}\">{}</text>\n",
                px(p.x), py(p.y), px(p.x) + 7.0, py(p.y) + 4.0, i + 1
            ));
        }
        s.push_str(&format!(
            "<text x=\"{:.1}\" y=\"{:.1}\">{}. t={:.1}s {}</text>\n",
            px(0.0),
            py(-0.8) + 16.0 * i as f64,
            i + 1,
            t,
            what.replace('<', "&lt;").replace('>', "&gt;")
        ));
    }
    s.push_str(&format!(
        "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"16\">{} — {} in {:.1} s (seed {})</text>\n</svg>\n",
        px(0.0),
        oy - 20.0,
        r.world,
        if r.success { "success" } else { "failure" },
        r.time_s,
        r.seed
    ));
    s
}
