//! `skillfab up`: a manager plus the processes of a launch file, supervised.
//!
//! Children run in their own process groups (a terminal's Ctrl-C reaches only `up`, which
//! then stops them in order) and get SIGTERM if `up` itself dies (`PR_SET_PDEATHSIG`). A
//! child that exits is restarted by its policy with a doubling back-off. On shutdown every
//! child gets SIGTERM, then SIGKILL after a grace period; finally, when no process of the
//! domain is left, the manager removes its shared-memory files.

use crate::engine::{Manager, ManagerConfig, Pace};
use crate::launch::{Launch, ProcessSpec, Restart};
use crate::stats::Report;
use anyhow::{Context, bail};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use skillfab_proto::domain::{DOMAIN_ENV, Domain};
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
    /// How long to wait for every skill to register before cycling.
    pub wait_timeout: Duration,
    /// The fabric log file (`None`: the default, see [`crate::engine::default_log_path`]).
    pub param_log: Option<std::path::PathBuf>,
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
    cmd.spawn()
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
                let failed = !status.success();
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

/// Runs `skillfab up` until Ctrl-C/SIGTERM or `cycles`; returns the report.
pub fn up(opts: UpOptions) -> anyhow::Result<Report> {
    let mut config = ManagerConfig::new(opts.domain.clone());
    if let Some(p) = opts.launch.period {
        config.pace = if p.is_zero() {
            Pace::FreeRun
        } else {
            Pace::Period(p)
        };
    }
    if let Some(p) = opts.pace {
        config.pace = p;
    }
    config.deadline = opts.launch.deadline;
    config.max_cycles = opts.cycles;
    config.wait_timeout = opts.wait_timeout;
    config.param_log = opts.param_log.clone();
    config.wait_for = opts
        .launch
        .processes
        .iter()
        .filter(|p| p.registers)
        .map(|p| p.name.clone())
        .collect();
    let mut manager = Manager::new(config).context("starting the manager")?;
    let supervisor = Supervisor::start(opts.launch.processes.clone(), opts.domain.clone());
    let result = manager.run(&|cycles| cycles == 0 && !supervisor.given_up().is_empty());
    let given_up = supervisor.given_up();
    supervisor.stop();
    let cycles = manager.cycle();
    if !manager.shutdown() {
        tracing::info!(domain = %opts.domain, "other processes still use the domain; its files stay");
    }
    let report = result.context("running the manager")?;
    if cycles == 0 && !given_up.is_empty() {
        bail!(
            "processes exited before the fabric started: {}",
            given_up.join(", ")
        );
    }
    Ok(report)
}
