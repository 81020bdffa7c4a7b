//! `skillfab up`: a manager plus the processes of a launch file, supervised.
//!
//! Children run in their own process groups (a terminal's Ctrl-C reaches only `up`, which
//! then stops them in order) and get SIGTERM if `up` itself dies (`PR_SET_PDEATHSIG`). A
//! child that exits is restarted by its policy with a doubling back-off. On shutdown every
//! child gets SIGTERM, then SIGKILL after a grace period; finally, when no process of the
//! domain is left, the manager removes its shared-memory files.

use crate::engine::Pace;
use crate::launch::{Launch, ProcessSpec, Restart};
use anyhow::Context;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use skillfab_proto::domain::{DOMAIN_ENV, Domain};
use skillfab_proto::services;
use std::os::fd::AsFd;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long children get to exit after SIGTERM before SIGKILL.
const GRACE: Duration = Duration::from_secs(5);
/// How often the supervisor looks at its children (a wake-up of `skillfab up` each time; a
/// restart waits at least this long, plus its back-off).
const POLL: Duration = Duration::from_millis(100);
/// A child that ran this long before it exited starts its restart count (and back-off) anew,
/// as systemd and Kubernetes do: a process killed now and then is restarted quickly every time.
const STABLE: Duration = Duration::from_secs(10);

/// Options of `skillfab up`.
#[derive(Debug, Clone)]
pub struct UpOptions {
    /// The launch file.
    pub launch: Launch,
    /// Domain to run in.
    pub domain: Domain,
    /// Stop after this many cycles.
    pub cycles: Option<u64>,
    /// Pacing (overrides the launch file).
    pub pace: Option<Pace>,
    /// Lock-step at the period of `pace`, else the launch file's, else 10 ms.
    pub lockstep: bool,
    /// The fabric's clock runs this many times faster than the host's (with a period, not in
    /// lock-step: see `ManagerConfig::time_factor`); overrides the launch file's.
    pub time_factor: Option<f64>,
    /// Start with cycling stopped.
    pub paused: bool,
    /// Run no cycle until a client holds the fabric at one.
    pub held: bool,
    /// The first cycle's number.
    pub first_cycle: u64,
    /// The full-rate recording.
    pub record: Option<crate::engine::RecordSpec>,
    /// How long to wait for every skill to register before cycling.
    pub wait_timeout: Duration,
    /// The fabric log file (`None`: the default, see [`crate::engine::default_log_path`]).
    pub param_log: Option<std::path::PathBuf>,
    /// The manager prints its report as JSON.
    pub json: bool,
}

struct Supervised {
    spec: ProcessSpec,
    child: Option<Child>,
    restarts: u32,
    restart_at: Option<Instant>,
    /// When the running child was started.
    started: Instant,
    gave_up: bool,
}

/// Starts, watches and stops the child processes.
pub struct Supervisor {
    children: Arc<Mutex<Vec<Supervised>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

fn spawn(spec: &ProcessSpec, domain: &Domain) -> std::io::Result<Child> {
    let mut cmd = Command::new(&spec.program);
    cmd.args(&spec.args)
        .env(DOMAIN_ENV, domain.name())
        .stdin(Stdio::null());
    // Skills in other languages find libskillfab next to this program (Python's skillfab
    // package looks there).
    if let Some(dir) = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(std::path::Path::to_path_buf))
    {
        cmd.env("SKILLFAB_BIN_DIR", dir);
    }
    if spec.registers {
        cmd.arg("--domain").arg(domain.name());
    }
    // Children's stdout goes to our stderr: our stdout is reserved for the report.
    if let Ok(err) = std::io::stderr().as_fd().try_clone_to_owned() {
        cmd.stdout(Stdio::from(err));
    }
    own_group_ended_with_us(&mut cmd);
    cmd.spawn()
}

/// Makes the child of `cmd` the leader of a process group of its own (a terminal's Ctrl-C
/// reaches only `up`) that gets SIGTERM when `up` dies.
fn own_group_ended_with_us(cmd: &mut Command) {
    let parent = nix::unistd::getpid();
    // SAFETY: only async-signal-safe system calls run between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            let _ = nix::unistd::setpgid(Pid::from_raw(0), Pid::from_raw(0));
            let _ = nix::sys::prctl::set_pdeathsig(Signal::SIGTERM);
            // The parent may have died before the line above: then exit now.
            if nix::unistd::getppid() != parent {
                return Err(std::io::Error::other("parent exited"));
            }
            Ok(())
        });
    }
}

impl Supervisor {
    /// Starts every process and a thread that watches them.
    pub fn start(specs: Vec<ProcessSpec>, domain: Domain) -> Supervisor {
        let children = Arc::new(Mutex::new(
            specs
                .into_iter()
                .map(|spec| Supervised {
                    spec,
                    child: None,
                    restarts: 0,
                    restart_at: Some(Instant::now()),
                    started: Instant::now(),
                    gave_up: false,
                })
                .collect::<Vec<_>>(),
        ));
        let stop = Arc::new(AtomicBool::new(false));
        let (c, s) = (children.clone(), stop.clone());
        // Children are spawned from this thread: PR_SET_PDEATHSIG follows the spawning thread.
        let thread = std::thread::spawn(move || {
            while !s.load(Ordering::Acquire) {
                if let Ok(mut list) = c.lock() {
                    for p in list.iter_mut() {
                        watch(p, &domain);
                    }
                }
                std::thread::sleep(POLL);
            }
            if let Ok(mut list) = c.lock() {
                terminate_all(&mut list);
            }
        });
        Supervisor {
            children,
            stop,
            thread: Some(thread),
        }
    }

    /// Names of registering processes that exited and will not be restarted.
    pub fn given_up(&self) -> Vec<String> {
        self.children
            .lock()
            .map(|l| {
                l.iter()
                    .filter(|p| p.gave_up && p.spec.registers)
                    .map(|p| p.spec.name.clone())
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Stops every child (SIGTERM, then SIGKILL after a grace period) and the watcher.
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Supervisor {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn watch(p: &mut Supervised, domain: &Domain) {
    if let Some(child) = p.child.as_mut() {
        match child.try_wait() {
            Ok(None) => return,
            Ok(Some(status)) => {
                p.child = None;
                if p.started.elapsed() >= STABLE {
                    p.restarts = 0;
                }
                // A plan that failed ended as much as one that succeeded.
                let ended = status.success() || (p.spec.plan && status.code() == Some(1));
                let failed = !ended;
                let again = match p.spec.restart {
                    Restart::Never => false,
                    Restart::OnFailure => failed,
                    Restart::Always => true,
                };
                if again && p.restarts < p.spec.max_restarts {
                    let backoff = (p.spec.backoff * 2u32.saturating_pow(p.restarts))
                        .min(Duration::from_secs(5));
                    tracing::warn!(process = %p.spec.name, %status, ?backoff, "process exited; restarting");
                    p.restart_at = Some(Instant::now() + backoff);
                    p.restarts += 1;
                } else {
                    if again {
                        tracing::error!(process = %p.spec.name, %status, restarts = p.restarts, "process exited; giving up");
                        tell_gave_up(domain, &p.spec.name, p.restarts, &status.to_string());
                    } else if failed {
                        tracing::warn!(process = %p.spec.name, %status, "process exited");
                    } else {
                        tracing::info!(process = %p.spec.name, "process finished");
                    }
                    p.gave_up = true;
                }
            }
            Err(e) => tracing::warn!(process = %p.spec.name, error = %e, "cannot poll process"),
        }
    }
    if p.restart_at.is_some_and(|t| Instant::now() >= t) {
        p.restart_at = None;
        match spawn(&p.spec, domain) {
            Ok(c) => {
                tracing::info!(process = %p.spec.name, pid = c.id(), "process started");
                p.child = Some(c);
                p.started = Instant::now();
            }
            Err(e) => {
                tracing::error!(process = %p.spec.name, program = %p.spec.program.display(), error = %e, "cannot start process");
                p.gave_up = true;
            }
        }
    }
}

/// Tells `domain`'s manager that `up` gave up restarting `process`: it publishes the event a
/// plan reacts to ([`EventKind::ProcessGaveUp`](skillfab_proto::control::EventKind)). A
/// manager that does not answer within 2 s is not told (said in the log).
fn tell_gave_up(domain: &Domain, process: &str, restarts: u32, status: &str) {
    use skillfab_proto::control::{self, Request};
    let request = Request::ProcessGaveUp {
        process: process.to_string(),
        restarts,
        status: status.to_string(),
    };
    let ask = || -> Result<(), String> {
        let node = services::node(domain, &format!("skillfab-up-{}", std::process::id()))
            .map_err(|e| e.to_string())?;
        let port = services::control_service(&node)
            .map_err(|e| e.to_string())?
            .client_builder()
            .initial_max_slice_len(control::MAX_REQUEST_BYTES)
            .allocation_strategy(iceoryx2::prelude::AllocationStrategy::Static)
            .create()
            .map_err(|e| format!("control port: {e:?}"))?;
        // A client id is `<pid>-<n>`: this one lives as long as `up`, and numbers its
        // requests (the manager answers a number it has seen from the client with the answer
        // it gave: a second report under number 1 would be taken for a repeat of the first).
        static SEQ: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let seq = SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        let id = format!("{}-up", std::process::id());
        let bytes = control::encode_request(&id, seq, &request).map_err(|e| e.to_string())?;
        let pending = port
            .loan_slice_uninit(bytes.len())
            .map_err(|e| format!("loan: {e:?}"))?
            .write_from_slice(&bytes)
            .send()
            .map_err(|e| format!("send: {e:?}"))?;
        services::notifier(&node, &skillfab_proto::names::control())
            .map_err(|e| e.to_string())?
            .notify()
            .map_err(|e| format!("wake: {e:?}"))?;
        let deadline = Instant::now() + Duration::from_secs(2);
        while Instant::now() < deadline {
            if let Some(answer) = pending.receive().map_err(|e| format!("receive: {e:?}"))? {
                return control::decode_response(answer.payload())
                    .map_err(|e| e.to_string())?
                    .1
                    .map(|_| ())
                    .map_err(|e| e.to_string());
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        Err("no answer within 2 s".into())
    };
    if let Err(e) = ask() {
        tracing::warn!(%process, error = %e, "the manager was not told that up gave up");
    }
}

fn group(child: &Child) -> Option<Pid> {
    i32::try_from(child.id()).ok().map(|id| Pid::from_raw(-id))
}

fn terminate_all(list: &mut [Supervised]) {
    for p in list.iter() {
        if let Some(g) = p.child.as_ref().and_then(group) {
            let _ = kill(g, Signal::SIGTERM);
        }
    }
    let deadline = Instant::now() + GRACE;
    for p in list.iter_mut() {
        let Some(child) = p.child.as_mut() else {
            continue;
        };
        loop {
            match child.try_wait() {
                Ok(Some(_)) | Err(_) => break,
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(5))
                }
                Ok(None) => {
                    tracing::warn!(process = %p.spec.name, "no exit after SIGTERM; killing");
                    if let Some(g) = group(child) {
                        let _ = kill(g, Signal::SIGKILL);
                    }
                    let _ = child.wait();
                    break;
                }
            }
        }
        // Anything the child left in its group goes too.
        if let Some(g) = group(child) {
            let _ = kill(g, Signal::SIGKILL);
        }
        p.child = None;
    }
}

/// How many times in a row a crashed manager is restarted before `up` gives up (the count
/// starts anew after [`STABLE`] of running, as for any child).
const MANAGER_RESTARTS: u32 = 20;

/// The arguments of the manager's own process: `skillfab-manager manager …` with the launch
/// file's pacing and the flags `up` was given. `restart` > 0 names a fresh fabric log file
/// when one was given (a file is never written by two managers).
fn manager_args(opts: &UpOptions, restart: u32) -> Vec<String> {
    let mut a: Vec<String> = vec![
        "manager".into(),
        "--domain".into(),
        opts.domain.name().into(),
    ];
    let pace = opts.pace.or(opts.launch.period.map(|p| {
        if p.is_zero() {
            Pace::FreeRun
        } else {
            Pace::Period(p)
        }
    }));
    match pace {
        _ if opts.lockstep => a.extend([
            "--lockstep".into(),
            "--period-ms".into(),
            ms(pace
                .and_then(Pace::period)
                .unwrap_or(crate::args::DEFAULT_PERIOD)),
        ]),
        Some(Pace::FreeRun) => a.push("--free-run".into()),
        Some(Pace::Period(p)) => a.extend(["--period-ms".into(), ms(p)]),
        Some(Pace::LockStep(p)) => a.extend(["--lockstep".into(), "--period-ms".into(), ms(p)]),
        None => {}
    }
    // (In lock-step the clock is the simulator's time already; free-running, the host's.)
    if let Some(f) = opts.time_factor
        && !opts.lockstep
        && !matches!(pace, Some(Pace::FreeRun | Pace::LockStep(_)))
    {
        a.extend(["--time-factor".into(), f.to_string()]);
    }
    // A restarted manager takes the pause, the holds and the cycle number from its predecessor.
    if restart == 0 && opts.paused {
        a.push("--paused".into());
    }
    if restart == 0 && opts.held {
        a.push("--held".into());
    }
    if restart == 0 && opts.first_cycle > 1 {
        a.extend(["--first-cycle".into(), opts.first_cycle.to_string()]);
    }
    if let Some(d) = opts.launch.deadline {
        a.extend(["--deadline-ms".into(), ms(d)]);
    }
    if let Some(rt) = &opts.launch.manager_realtime {
        a.extend(rt.flags());
    }
    if let Some(n) = opts.cycles {
        a.extend(["--cycles".into(), n.to_string()]);
    }
    let wait_for: Vec<&str> = opts
        .launch
        .processes
        .iter()
        .filter(|p| p.registers)
        .map(|p| p.name.as_str())
        .collect();
    if !wait_for.is_empty() {
        a.extend(["--wait-for".into(), wait_for.join(",")]);
    }
    a.extend([
        "--wait-timeout-s".into(),
        opts.wait_timeout.as_secs_f64().to_string(),
    ]);
    // A restarted manager writes new files next to its predecessor's (an MCAP file cannot
    // be appended to).
    let per_restart = |f: &std::path::Path| {
        if restart == 0 {
            return f.to_string_lossy().into_owned();
        }
        let stem = f.file_stem().map(|s| s.to_string_lossy().into_owned());
        let ext = f.extension().map(|e| format!(".{}", e.to_string_lossy()));
        f.with_file_name(format!(
            "{}-restart{restart}{}",
            stem.unwrap_or_default(),
            ext.unwrap_or_default()
        ))
        .to_string_lossy()
        .into_owned()
    };
    if let Some(f) = &opts.param_log {
        a.extend(["--param-log".into(), per_restart(f)]);
    }
    if let Some(r) = &opts.record {
        a.extend(["--record".into(), per_restart(&r.path)]);
        if !r.topics.is_empty() {
            a.extend(["--topics".into(), r.topics.join(",")]);
        }
        if r.encoding == crate::recorder::SampleEncoding::Json {
            a.extend(["--record-encoding".into(), "json".into()]);
        }
    }
    if opts.json {
        a.push("--json".into());
    }
    a
}

fn ms(d: Duration) -> String {
    (d.as_secs_f64() * 1000.0).to_string()
}

/// Starts the manager's process: in its own process group, with SIGTERM when `up` dies; its
/// stdout is ours (the report).
fn spawn_manager(opts: &UpOptions, restart: u32) -> anyhow::Result<Child> {
    let exe = std::env::current_exe().context("finding skillfab-manager")?;
    let mut cmd = Command::new(exe);
    cmd.args(manager_args(opts, restart))
        .env_remove(DOMAIN_ENV)
        .stdin(Stdio::null());
    own_group_ended_with_us(&mut cmd);
    cmd.spawn().context("starting the manager")
}

/// Whether a manager's exit was a crash to recover from (killed by a signal, or a panic),
/// not an answer (done, stopped, or refused with an error it printed).
fn crashed(status: std::process::ExitStatus) -> bool {
    use std::os::unix::process::ExitStatusExt;
    status.signal().is_some() || status.code() == Some(101)
}

/// Sends `signal` to a child's process group and waits for it (SIGKILL after [`GRACE`]).
fn stop_child(child: &mut Child, signal: Signal) -> Option<std::process::ExitStatus> {
    if let Some(g) = group(child) {
        let _ = kill(g, signal);
    }
    let deadline = Instant::now() + GRACE;
    loop {
        match child.try_wait() {
            Ok(Some(s)) => return Some(s),
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(5)),
            _ => {
                if let Some(g) = group(child) {
                    let _ = kill(g, Signal::SIGKILL);
                }
                return child.wait().ok();
            }
        }
    }
}

/// Runs `skillfab up` until Ctrl-C/SIGTERM or the manager's cycle budget is spent.
///
/// The manager is a process of its own, like the skills: a crashed manager (killed, or a
/// panic) is started again at once. It takes over the board and the state file its
/// predecessor left (see `engine::state`), the skills register with it again and get their
/// state back. The manager prints the report when it ends; `up` then stops the other
/// processes and, once none of the domain's processes is left, removes its files.
pub fn up(opts: UpOptions) -> anyhow::Result<()> {
    // Installs the SIGINT/SIGTERM handler before any child exists.
    let mut terminated = services::termination_requested();
    let supervisor = Supervisor::start(opts.launch.processes.clone(), opts.domain.clone());
    let mut manager = spawn_manager(&opts, 0)?;
    let (mut restarts, mut since) = (0u32, Instant::now());
    let mut failure = None;
    loop {
        terminated = terminated || services::termination_requested();
        if terminated {
            // The skills first (the manager sees them leave), then the manager.
            supervisor.stop();
            stop_child(&mut manager, Signal::SIGTERM);
            break;
        }
        match manager.try_wait() {
            Ok(None) => {}
            Ok(Some(status)) if crashed(status) => {
                if since.elapsed() >= STABLE {
                    restarts = 0;
                }
                if restarts >= MANAGER_RESTARTS {
                    failure = Some(anyhow::anyhow!(
                        "the manager crashed {restarts} times in a row ({status}); giving up"
                    ));
                    supervisor.stop();
                    break;
                }
                restarts += 1;
                tracing::warn!(%status, restarts, "manager crashed; restarting it");
                manager = spawn_manager(&opts, restarts)?;
                since = Instant::now();
                continue;
            }
            Ok(Some(status)) => {
                if !status.success() {
                    failure = Some(anyhow::anyhow!("the manager exited with {status}"));
                }
                supervisor.stop();
                break;
            }
            Err(e) => {
                failure = Some(anyhow::Error::from(e).context("watching the manager"));
                supervisor.stop();
                stop_child(&mut manager, Signal::SIGTERM);
                break;
            }
        }
        let given_up = supervisor.given_up();
        if !given_up.is_empty() && cycles_done(&opts.domain) == 0 {
            supervisor.stop();
            stop_child(&mut manager, Signal::SIGTERM);
            failure = Some(anyhow::anyhow!(
                "processes exited before the fabric started: {}",
                given_up.join(", ")
            ));
            break;
        }
        std::thread::sleep(POLL);
    }
    match skillfab_proto::clean::clean(&opts.domain) {
        Ok(c) if !c.alive.is_empty() => {
            tracing::info!(domain = %opts.domain, "other processes still use the domain; its files stay")
        }
        Ok(_) => {}
        Err(e) => tracing::warn!(domain = %opts.domain, error = %e, "domain not cleaned"),
    }
    failure.map_or(Ok(()), Err)
}

/// Cycles the domain's manager has run (0 before it starts cycling, or with no board).
fn cycles_done(domain: &Domain) -> u64 {
    skillfab_proto::board::Board::open(&domain.prefix()).map_or(0, |b| {
        b.header().cycle.load(std::sync::atomic::Ordering::Acquire)
    })
}
