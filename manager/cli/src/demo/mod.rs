//! `skillfab demo exit-lab` and `skillfab demo deliver`: the paper's experiment and its whole
//! mission, each driven by a plan ([`crate::sequence`]'s format) that runs as the `[plan]` of
//! the network's launch file: a process of its own, supervised by `up`, resumed where it was
//! if it dies.
//!
//! In `exit-lab` the plan `skills/plans/exit-lab.xml` drives the simulated Denning robot out of
//! the lab (the paper's section 6): explore until the door's barcode is seen, home on it,
//! follow its wall (one way, then the other) while door_locate gathers evidence, and once the
//! door is located lower `avoid.safe_distance` for the tight passage and let go_through drive.
//! In `deliver` a plan — the planner's (`crate::plan`), built on the building's route map from
//! the subtrees of `skills/plans/deliver.xml` — takes the robot from the lab through a
//! simulated building — corridors, an elevator lobby with four cars, the fourth floor — to an
//! office, where it says its message.
//!
//! The demo is the judge: the simulator's ground truth says when the robot is outside the lab
//! or the message is delivered; the robot is then stopped and the plan halted. In lock-step
//! the judge looks at cycles of its own choosing ([`Judge`]), so a seed decides the whole run.

use anyhow::{Context, bail};
use denning_sim::building::Building;
use denning_sim::truth::TruthRecord;
use denning_sim::world::World;
use serde::Serialize;
use skillfab_client::Client;
use skillfab_manager::launch::{
    LaunchFile, ManagerSection, PlanSection, ProcessEntry, Restart, find_program,
};
use skillfab_proto::control::SkillState;
use skillfab_proto::domain::Domain;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::faults::{Faults, Kill, Killer};

pub(crate) mod deliver;
mod judge;
mod plot;

use judge::{
    Judge, NO_TRUTH, NO_TRUTH_ERROR, StepLog, judge_back, judge_truth, truth_after, verdict,
};

/// Where a demo's robot is: a one-room world (the exit-lab experiment) or a building (the
/// delivery mission).
#[derive(Debug, Clone)]
pub enum Site {
    /// A world file (`denning-sim --world`).
    World(PathBuf),
    /// A building file (`denning-sim --building`).
    Building(PathBuf),
}

impl Site {
    /// The file.
    pub fn path(&self) -> &Path {
        match self {
            Site::World(p) | Site::Building(p) => p,
        }
    }

    /// The skills of its network (all inactive at first).
    fn skills(&self) -> &'static [&'static str] {
        match self {
            Site::World(_) => &SKILLS[..EXIT_LAB_SKILLS],
            Site::Building(_) => &SKILLS,
        }
    }
}

/// Options of `skillfab demo exit-lab`.
#[derive(Debug, Clone)]
pub struct DemoOptions {
    /// The world or building.
    pub site: Site,
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
    /// How the recording's samples are written.
    pub record_encoding: skillfab_manager::recorder::SampleEncoding,
    /// Copy the first run's ground truth (the simulator's trajectory CSV) here.
    pub truth: Option<PathBuf>,
    /// The plan file (`skillfab sequence`'s format, checked) that drives the robot. It runs
    /// as the `[plan]` of the network's launch file: a process of its own, supervised by
    /// `up`, resumed where it was if it dies.
    pub plan: PathBuf,
    /// The plan's tree to run (default: its main tree).
    pub tree: Option<String>,
    /// A round trip (deliver `--and-back`): the message delivered does not end the run; it
    /// succeeds when the plan ends with the message delivered and the robot back at the lab.
    pub and_back: bool,
    /// The plan is the planner's route: its runner plans again when a step fails.
    pub replan: Option<skillfab_manager::launch::ReplanSection>,
}

/// One run's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct RunOutcome {
    /// Seed.
    pub seed: u64,
    /// World name.
    pub world: String,
    /// Left the lab (exit-lab) or delivered the message (deliver) within the limit.
    pub success: bool,
    /// Simulated time at the end (s): when the robot was first outside (exit-lab) or the
    /// message was delivered (deliver), else the last.
    pub time_s: f64,
    /// Host time the run took (s), start-up included.
    pub wall_s: f64,
    /// Collisions the simulator reported.
    pub collisions: u64,
    /// The plan's steps and the judge's: (what, cycle, simulated time).
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
    /// What the device's safety layer did, as it reported last: cycles (slowed, stopped,
    /// capped for a way ahead not seen or a bad link). Counted since the device started: a
    /// restarted device counts afresh.
    pub safety: Option<(u64, u64, u64)>,
    /// Where the robot was at the end (ground truth): floor, x, y (m). A failed run's
    /// first clue.
    pub end: Option<(i32, f64, f64)>,
    /// A round trip's: when the message was delivered (simulated s), if it was.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delivered_s: Option<f64>,
    /// A failed run's directory, kept for its diagnosis: `up.log` (every process's log and
    /// the plan's steps), the simulator's ground truth (`trajectory.csv`), the launch file
    /// and the plan. A run that succeeded leaves nothing.
    pub run_dir: Option<PathBuf>,
    /// Why the run ended in an error instead of a judgement (the network did not come up,
    /// the judge lost the manager): such a run counts as not successful, and the batch goes
    /// on with the next seed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    #[serde(skip)]
    trajectory: Vec<TruthRecord>,
}

impl RunOutcome {
    /// A run of `seed` on `site` with nothing judged yet.
    fn new(seed: u64, site: &Site) -> RunOutcome {
        RunOutcome {
            seed,
            world: site
                .path()
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
            safety: None,
            end: None,
            delivered_s: None,
            run_dir: None,
            error: None,
            trajectory: Vec::new(),
        }
    }
}

/// What `--json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Runs.
    pub runs: u32,
    /// Successful runs.
    pub successes: u32,
    /// Runs that ended in an error instead of a judgement (each run's `error` says why);
    /// counted as not successful.
    pub errors: u32,
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
    /// Keep `dir` when dropped (a run that failed, or ended in an error).
    keep: bool,
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
        // An interrupted demo leaves nothing behind.
        if self.keep && !interrupted() {
            tracing::info!(dir = %self.dir.display(), "the run's files are kept");
        } else {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// The skills of the networks: the exit-lab experiment's, then the delivery mission's own.
const SKILLS: [&str; 17] = [
    "avoid",
    "explore",
    "wall_follow",
    "barcode_track",
    "home",
    "door_locate",
    "go_through",
    "stop",
    "hall_follow",
    "intersection",
    "door_detect",
    "sign_read",
    "car_watch",
    "enter_car",
    "leave_car",
    "push_button",
    "deliver",
];
/// The skills with a `progress` output (remapped to `<skill>/progress`: a topic has one
/// producer).
const PROGRESS: [&str; 5] = [
    "go_through",
    "enter_car",
    "leave_car",
    "push_button",
    "deliver",
];
/// How many of [`SKILLS`] the exit-lab network has.
const EXIT_LAB_SKILLS: usize = 8;

fn start(opts: &DemoOptions, seed: u64, run: u32) -> anyhow::Result<(Network, PathBuf)> {
    let domain = Domain::new(&format!("demo-{}-{run}", std::process::id()))?;
    domain.remove_all_files();
    let dir = std::env::temp_dir().join(format!("skillfab-demo-{}-{run}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let (site_flag, site) = match &opts.site {
        Site::World(p) => ("--world", p),
        Site::Building(p) => ("--building", p),
    };
    let site = std::fs::canonicalize(site).with_context(|| format!("{}", site.display()))?;
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
        plan: None,
        realtime: None,
        manager: ManagerSection {
            period_ms: Some(period_ms),
            // (Lock-step: the manager's own, 10 s.)
            deadline_ms: (!opts.lockstep).then_some((period_ms * 5.0).max(20.0)),
            // The fabric's clock is the robot's: a cycle is 10 ms of it, so skills' timers
            // and the plan's timeouts mean at every time factor what they mean in lock-step.
            time_factor: (!opts.lockstep).then_some(time_factor),
            ..ManagerSection::default()
        },
        process: vec![
            ProcessEntry {
                name: "denning-sim".into(),
                bin: text(&program("denning-sim")?),
                registers: Some(false),
                args: vec![
                    site_flag.into(),
                    text(&site),
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
                    "--cars-out-from".into(),
                    opts.faults.cars_out.start.to_string(),
                    "--cars-out-until".into(),
                    opts.faults.cars_out.end.to_string(),
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
    for &s in opts.site.skills() {
        // Skills that report one job's progress each get a topic of their own for it.
        let remap = if PROGRESS.contains(&s) {
            [("progress".to_string(), format!("{s}/progress"))].into()
        } else {
            Default::default()
        };
        launch.process.push(ProcessEntry {
            name: s.into(),
            bin: text(&program(s)?),
            active: Some(false),
            remap,
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
    // The plan, copied into the run's directory: its runner is found by that path.
    let copy = dir.join(PLAN_FILE);
    std::fs::copy(&opts.plan, &copy).with_context(|| format!("{}", opts.plan.display()))?;
    launch.plan = Some(PlanSection {
        file: text(&copy),
        tree: opts.tree.clone(),
        max_restarts: Some(restarts),
        backoff_ms: Some(backoff_ms),
        replan: opts.replan.clone(),
    });
    let launch = toml::to_string(&launch).context("writing the launch file")?;
    let path = dir.join("exit-lab.toml");
    std::fs::write(&path, launch)?;
    // (The plan runner's steps are in it: `up` sends its children's stdout there.)
    let log = std::fs::File::create(dir.join(STEPS_FILE))?;
    let mut cmd = Command::new(std::env::current_exe()?);
    cmd.args([
        "up",
        path.to_str().unwrap_or_default(),
        "--domain",
        domain.name(),
    ])
    // Lock-step: paused until the plan has set up, and held until the judge's first hold, so
    // the run does not depend on when either connected.
    .args(if opts.lockstep {
        &["--lockstep", "--paused", "--held"][..]
    } else {
        &[]
    });
    if let Some(r) = opts.record.as_ref().filter(|_| run == 0) {
        cmd.arg("--record").arg(r);
        if opts.record_encoding == skillfab_manager::recorder::SampleEncoding::Json {
            cmd.args(["--record-encoding", "json"]);
        }
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
    Ok((
        Network {
            child,
            dir,
            domain,
            // Until the run is known to have succeeded.
            keep: true,
        },
        traj,
    ))
}

/// The plan's copy in a run's directory.
const PLAN_FILE: &str = "plan.xml";
/// `up`'s log in a run's directory, with the plan runner's steps.
const STEPS_FILE: &str = "up.log";

/// The plan runner of `net` (the process running its copy of the plan), if one runs.
fn plan_runner(net: &Network) -> Option<u32> {
    let plan = net.dir.join(PLAN_FILE);
    crate::faults::process_with_args(&["sequence", &plan.to_string_lossy()])
}

/// Halts the plan (SIGTERM to its runner: it restores what it set and removes its monitors)
/// and waits for its runner to exit (10 s at most).
fn halt_plan(net: &Network) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while let Some(pid) = plan_runner(net) {
        if let Ok(p) = i32::try_from(pid) {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(p),
                nix::sys::signal::Signal::SIGTERM,
            );
        }
        if Instant::now() > deadline {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn connect(net: &Network, skills: &[&str]) -> anyhow::Result<Client> {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if let Ok(c) = Client::connect(&net.domain)
            && let Ok(list) = c.list()
            && list.len() == skills.len() + 1
            && list.iter().all(|s| s.state != SkillState::Starting)
        {
            return Ok(c);
        }
        if Instant::now() > deadline {
            bail!("the demo's network did not come up within 60 s (see the log of skillfab up)");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// One run of the experiment.
pub fn run_once(opts: &DemoOptions, seed: u64, run: u32) -> anyhow::Result<RunOutcome> {
    let wall = Instant::now();
    let (mut net, traj) = start(opts, seed, run)?;
    let mut c = connect(&net, opts.site.skills())?;
    c.subscribe()?;
    let mut out = RunOutcome::new(seed, &opts.site);
    // The judge's own steps (the plan's are its runner's, read from its log).
    let step = |c: &Client, out: &mut RunOutcome, what: &str| {
        let cycle = c.stats().map(|s| s.cycles).unwrap_or(0);
        let t = latest(&traj).map_or(0.0, |r| r.t);
        if opts.verbose {
            println!("  [cycle {cycle:>6}, t = {t:>6.1} s] {what}");
        }
        out.steps.push((what.to_string(), cycle, t));
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
            // The plan runner is a process of the fabric too.
            Some(net.dir.join(PLAN_FILE).to_string_lossy().into_owned()),
            opts.faults.kill_only.clone(),
        )
    });
    // Lock-step: the judge holds the fabric before the plan's runner resumes it (`up --held`
    // keeps it from running until then).
    let mut judge = if opts.lockstep {
        Some(Judge::start(&c)?)
    } else {
        None
    };
    let started = Instant::now();
    // The plan runs (and paces a lock-step manager) until it ends or the ground truth ends
    // the run; it is then halted: what it set is restored, its monitors removed.
    let mut log = StepLog::default();
    let mut last: Option<TruthRecord> = None;
    let ended = loop {
        if interrupted() {
            bail!("interrupted");
        }
        // Real time: ten times a second (the trajectory file is read whole); lock-step: at
        // the judge's holds.
        let look = match judge.as_mut() {
            Some(j) => {
                let ev = c.next_event(Duration::from_millis(100))?.map(|e| e.kind);
                j.reached(&c, ev.as_ref())?
            }
            None => {
                std::thread::sleep(Duration::from_millis(100));
                true
            }
        };
        if look {
            last = latest(&traj).or(last);
        }
        log.read(&net.dir.join(STEPS_FILE), opts.verbose);
        match &last {
            Some(now)
                if look && judge_truth(&opts.site, now, opts.limit_s, opts.and_back).is_some() =>
            {
                break None;
            }
            None if started.elapsed() > NO_TRUTH => bail!(NO_TRUTH_ERROR),
            _ => {}
        }
        // (A lock-step plan that ended leaves the fabric paused short of the hold.)
        if let Some(how) = &log.ended {
            break Some(how.clone());
        }
        if look && let Some(j) = judge.as_mut() {
            j.next(&c)?;
        }
    };
    halt_plan(&net);
    log.read(&net.dir.join(STEPS_FILE), opts.verbose);
    out.steps = std::mem::take(&mut log.steps);
    if let Some(status) = &ended {
        step(&c, &mut out, &format!("the plan ended: {status}"));
    }
    let now = match judge {
        // Lock-step: the record at the hold, not a newer one.
        Some(_) if ended.is_none() => last,
        _ => latest(&traj).or(last),
    };
    let Some(mut now) = now else {
        bail!(NO_TRUTH_ERROR);
    };
    // A plan that ended before the ground truth says how: the simulator writes it once per
    // status period (100 ms), and a lock-step manager stays paused when a plan ends. Let the
    // robot's time go on until a record after the plan's end.
    if ended.is_some() && judge_truth(&opts.site, &now, opts.limit_s, opts.and_back).is_none() {
        now = truth_after(&mut c, &traj, now, judge.as_mut())?;
    }
    (out.time_s, out.collisions) = (now.t, now.collisions);
    let judged = judge_truth(&opts.site, &now, opts.limit_s, opts.and_back)
        .or_else(|| judge_back(ended.as_deref(), &now).filter(|_| opts.and_back));
    if let Some(v) = judged {
        verdict(&c, &mut out, v, &step)?;
    }
    if let Some(k) = killer {
        out.kills = k.finish();
    }
    if let Some(k) = sim_killer {
        out.kills.extend(k.finish());
    }
    let device = |field: &str| {
        c.query(&format!("denning.{field}"))
            .ok()
            .and_then(|(v, _)| v.as_f64())
            .map(|x| x as u64)
    };
    out.link = (|| {
        Some((
            device("link.frames")?,
            device("link.bad_frames")?,
            device("link.garbage")?,
            device("link.connects")?,
        ))
    })();
    out.safety = (|| {
        Some((
            device("safety.slowed")?,
            device("safety.stopped")?,
            device("safety.blind")?,
        ))
    })();
    let all: Vec<&str> = opts
        .site
        .skills()
        .iter()
        .copied()
        .filter(|s| *s != "stop")
        .collect();
    c.deactivate(&all)?;
    step(&c, &mut out, "skills deactivated");
    out.trajectory = TruthRecord::read(&traj).unwrap_or_default();
    if let Some(to) = opts.truth.as_ref().filter(|_| run == 0) {
        std::fs::copy(&traj, to)
            .with_context(|| format!("copying the ground truth to {}", to.display()))?;
    }
    out.end = out.trajectory.last().map(|r| (r.floor, r.x, r.y));
    // The robot may have gone on a little until the judge looked: the time it first was
    // outside (or the message was delivered) is the mission's. Back at the lab is a place,
    // not an event, and the robot may pass it before it stops there (its door not counted,
    // the count taken again from the dead end beyond): the time from which it held to the end.
    let done = |r: &&TruthRecord| match opts.site {
        Site::World(_) => r.outside,
        Site::Building(_) if opts.and_back => r.delivered && r.at_lab,
        Site::Building(_) => r.delivered,
    };
    let first = if opts.and_back {
        out.trajectory.iter().rev().take_while(done).last()
    } else {
        out.trajectory.iter().find(done)
    };
    if let Some(first) = first {
        out.time_s = first.t;
    }
    if opts.and_back {
        out.delivered_s = out.trajectory.iter().find(|r| r.delivered).map(|r| r.t);
    }
    out.wall_s = wall.elapsed().as_secs_f64();
    (out.max_command_gap_s, out.max_stale_drive_s) = command_gaps(&out.trajectory);
    drop(c);
    net.keep = !out.success;
    out.run_dir = net.keep.then(|| net.dir.clone());
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
                "run {} of {}: {}, seed {seed}",
                run + 1,
                opts.runs,
                opts.site.path().display()
            );
        }
        let wall = Instant::now();
        let r = match run_once(opts, seed, run) {
            Ok(r) => r,
            Err(e) if interrupted() => return Err(e),
            Err(e) => {
                // One run's error (a network that did not come up on a loaded host, say)
                // is that run's outcome, not the end of the batch.
                let mut r = RunOutcome::new(seed, &opts.site);
                r.wall_s = wall.elapsed().as_secs_f64();
                r.error = Some(format!("{e:#}"));
                eprintln!(
                    "run {} of {} (seed {seed}): error: {e:#}",
                    run + 1,
                    opts.runs
                );
                r
            }
        };
        if opts.verbose && r.error.is_none() {
            println!(
                "  => {} in {:.1} s simulated ({:.1} s of host time), {} collisions",
                if r.success { "SUCCESS" } else { "FAILURE" },
                r.time_s,
                r.wall_s,
                r.collisions
            );
            if let Some(d) = &r.run_dir {
                println!("  its files (up.log, trajectory.csv): {}", d.display());
            }
        }
        if run == 0
            && r.error.is_none()
            && let Some(p) = &opts.plot
        {
            let picture = match &opts.site {
                Site::World(w) => plot::svg(&World::load(w)?, &r),
                Site::Building(b) => plot::building_svg(&Building::load(b)?, &r),
            };
            std::fs::write(p, picture)?;
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
    let errors = detail.iter().filter(|r| r.error.is_some()).count() as u32;
    if errors == opts.runs
        && let Some(e) = detail.first().and_then(|r| r.error.clone())
    {
        bail!("every run ended in an error; the first: {e}");
    }
    Ok(Summary {
        runs: opts.runs,
        successes: detail.iter().filter(|r| r.success).count() as u32,
        errors,
        median_time_s: (!times.is_empty()).then(|| times[times.len() / 2]),
        runs_detail: detail,
    })
}
