//! Faults injected into a run of the exit-lab demo (`--kill-every`, `--corrupt-rate`,
//! `--drop-rate`), and what they cost: the `fault-report` benchmark runs the demo with them.
//!
//! The killer takes a process of the fabric at random — the manager, the device process or a
//! skill — every `kill_every_s` simulated seconds and sends it SIGKILL; `skillfab up` restarts
//! it (the manager always, the others by their launch entries), and the killer times the
//! recovery, read on the cycle board: for a unit, the signal → the new instance registered and,
//! if it is active, its first run done; for the manager, the signal → a new manager's first
//! cycle with every unit that was registered back.

use serde::Serialize;
use skillfab_proto::board::{Board, MAX_SLOTS, SlotState};
use skillfab_proto::decl::SkillDecl;
use skillfab_proto::domain::Domain;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// What to inject.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Faults {
    /// SIGKILL to a random unit (device or skill) every this many simulated seconds.
    pub kill_every_s: Option<f64>,
    /// The killer's targets by name (`manager`, `plan`, a unit's name); empty: every process
    /// of the fabric. `["denning"]` is the device hot-swapped.
    pub kill_only: Vec<String>,
    /// SIGKILL to the simulator (the robot's serial side) every this many simulated seconds;
    /// it comes back where the robot was (`denning-sim --state`).
    pub kill_sim_every_s: Option<f64>,
    /// Share of the simulator's bytes with a flipped bit.
    pub corrupt_rate: f64,
    /// Share of the simulator's bytes dropped.
    pub drop_rate: f64,
    /// While the simulated time (s) is in this range no car answers a hall call, and none
    /// moves with its doors closed.
    pub cars_out: std::ops::Range<f64>,
    /// Seed of the killer's choices.
    pub seed: u64,
}

/// One kill and its recovery.
#[derive(Debug, Clone, Serialize)]
pub struct Kill {
    /// The unit killed.
    pub target: String,
    /// Real seconds since the run's first kill was armed.
    pub at_s: f64,
    /// Signal → the new instance registered and (if active) its first run done, ms; `None`
    /// if that did not happen within 10 s.
    pub recovery_ms: Option<f64>,
    /// Cycles the manager completed in that time (the cycles the unit missed).
    pub cycles_lost: Option<u64>,
}

/// The process whose command line holds every one of `words` (the simulator of one run is
/// found by its program name and its link path).
pub(crate) fn process_with_args(words: &[&str]) -> Option<u32> {
    std::fs::read_dir("/proc").ok()?.flatten().find_map(|e| {
        let pid: u32 = e.file_name().to_str()?.parse().ok()?;
        let cmdline = std::fs::read(e.path().join("cmdline")).ok()?;
        let text = String::from_utf8_lossy(&cmdline);
        words.iter().all(|w| text.contains(w)).then_some(pid)
    })
}

/// Sends SIGKILL to `pid` (the fault's `target`); when it was sent, if it was.
fn sigkill(pid: u32, target: &str) -> Option<Instant> {
    let at = Instant::now();
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(i32::try_from(pid).ok()?),
        nix::sys::signal::Signal::SIGKILL,
    )
    .ok()?;
    tracing::info!(%target, pid, "fault: killed");
    Some(at)
}

/// The manager's place in the killer's list (not a board slot).
const MANAGER: usize = usize::MAX;
const MANAGER_NAME: &str = "manager";
/// The plan runner as a kill target (no slot).
const PLAN: usize = usize::MAX - 1;
const PLAN_NAME: &str = "plan";

/// Whether the runner `pid` has taken `domain`'s plan over: the kept state names it (a
/// client id is `<pid>-<n>`) as its last runner.
fn plan_taken_over(domain: &Domain, pid: u32) -> bool {
    match skillfab_sequence::PlanStore::of(domain).load() {
        skillfab_sequence::Kept::State(s) => s
            .runners
            .last()
            .is_some_and(|r| r.starts_with(&format!("{pid}-"))),
        _ => false,
    }
}

/// Whether a manager other than `dead` runs in `domain`, has cycled past `k0` and has every
/// unit of `names` registered again; the cycles since `k0` if so.
fn manager_back(domain: &Domain, dead: u32, k0: u64, names: &[String]) -> Option<u64> {
    let board = Board::open(&domain.prefix()).ok()?;
    let h = board.header();
    if !board.manager_alive() || h.manager_pid.load(Ordering::Acquire) == dead {
        return None;
    }
    let k = h.cycle.load(Ordering::Acquire);
    let registered: Vec<String> = units(&board).into_iter().map(|u| u.1).collect();
    (k > k0 && names.iter().all(|n| registered.contains(n))).then_some(k - k0)
}

/// The killer thread of one run.
pub struct Killer {
    stop: Arc<AtomicBool>,
    kills: Arc<Mutex<Vec<Kill>>>,
    thread: Option<JoinHandle<()>>,
}

/// A registered unit on the board: slot, name, pid, active.
fn units(board: &Board) -> Vec<(usize, String, u32, bool)> {
    (0..MAX_SLOTS)
        .filter_map(|i| {
            let s = board.slot(i);
            if s.state() != SlotState::Ready {
                return None;
            }
            let decl: SkillDecl = postcard::from_bytes(&s.read_decl()).ok()?;
            Some((
                i,
                decl.name,
                s.pid.load(Ordering::Acquire),
                s.active.load(Ordering::Acquire) != 0,
            ))
        })
        .collect()
}

impl Killer {
    /// Starts killing in `domain` every `every` (real time): a unit, the manager, or the
    /// plan runner running the plan file `plan` (its recovery: a new runner resumed it);
    /// only those named in `only` if it names any.
    pub fn start(
        domain: &Domain,
        every: Duration,
        period: Duration,
        seed: u64,
        plan: Option<String>,
        only: Vec<String>,
    ) -> Killer {
        let domain = domain.clone();
        Killer::spawn(move |st, ks| {
            let mut rng = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
            let armed = Instant::now();
            let mut next = armed + every;
            let mut warned = false;
            while !st.load(Ordering::Acquire) {
                if Instant::now() < next {
                    std::thread::sleep(Duration::from_millis(5));
                    continue;
                }
                next += every;
                let Ok(board) = Board::open(&domain.prefix()) else {
                    continue;
                };
                // Only processes that still run (one killed a moment ago may still be listed).
                let mut list: Vec<_> = units(&board)
                    .into_iter()
                    .filter(|u| skillfab_proto::board::pid_alive(u.2))
                    .collect();
                let unit_names: Vec<String> = list.iter().map(|u| u.1.clone()).collect();
                if board.manager_alive() {
                    let pid = board.header().manager_pid.load(Ordering::Acquire);
                    list.push((MANAGER, MANAGER_NAME.to_string(), pid, true));
                }
                let runner = |plan: &str| process_with_args(&["sequence", plan]);
                if let Some(pid) = plan.as_deref().and_then(runner) {
                    list.push((PLAN, PLAN_NAME.to_string(), pid, true));
                }
                if !only.is_empty() {
                    let running = !list.is_empty();
                    list.retain(|u| only.contains(&u.1));
                    if running && list.is_empty() && !warned {
                        warned = true;
                        tracing::warn!(?only, "fault: no process of the fabric by these names");
                    }
                }
                if list.is_empty() {
                    continue;
                }
                // xorshift64: a reproducible choice per seed.
                rng ^= rng << 13;
                rng ^= rng >> 7;
                rng ^= rng << 17;
                let (slot, name, pid, active) = list[(rng % list.len() as u64) as usize].clone();
                let k0 = board.header().cycle.load(Ordering::Acquire);
                let Some(killed_at) = sigkill(pid, &name) else {
                    continue;
                };
                let mut kill = Kill {
                    target: name.clone(),
                    at_s: killed_at.duration_since(armed).as_secs_f64(),
                    recovery_ms: None,
                    cycles_lost: None,
                };
                let deadline = killed_at + Duration::from_secs(10);
                let since_k0 = || {
                    board
                        .header()
                        .cycle
                        .load(Ordering::Acquire)
                        .saturating_sub(k0)
                };
                while Instant::now() < deadline && !st.load(Ordering::Acquire) {
                    let back = if slot == MANAGER {
                        manager_back(&domain, pid, k0, &unit_names)
                    } else if slot == PLAN {
                        // A new runner that has taken the plan over (its state file
                        // rewritten by it: it names the new runner's client id).
                        plan.as_deref()
                            .and_then(runner)
                            .filter(|p| *p != pid && plan_taken_over(&domain, *p))
                            .map(|_| since_k0())
                    } else {
                        units(&board)
                            .into_iter()
                            .find(|(s, n, p, _)| {
                                *n == name
                                    && *p != pid
                                    && (!active || board.slot(*s).runs.load(Ordering::Acquire) > 0)
                            })
                            .map(|_| since_k0())
                    };
                    if let Some(cycles) = back {
                        let elapsed = killed_at.elapsed();
                        kill.recovery_ms = Some(elapsed.as_secs_f64() * 1000.0);
                        // A unit misses the cycles run without it; while the manager is away
                        // no cycle runs: those due in that time are lost.
                        kill.cycles_lost = Some(if slot == MANAGER || slot == PLAN {
                            (elapsed.as_secs_f64() / period.as_secs_f64()) as u64
                        } else {
                            cycles
                        });
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
                if let Ok(mut k) = ks.lock() {
                    k.push(kill);
                }
            }
        })
    }

    /// Starts killing the simulator linked at `link` every `every` (real time): the recovery
    /// is the signal → the device connected to the new one (its `link.connects` counts it).
    pub fn start_sim(domain: &Domain, link: &std::path::Path, every: Duration) -> Killer {
        let domain = domain.clone();
        let link = link.to_string_lossy().into_owned();
        Killer::spawn(move |st, ks| {
            let armed = Instant::now();
            let mut next = armed + every;
            let mut client = None;
            while !st.load(Ordering::Acquire) {
                if Instant::now() < next {
                    std::thread::sleep(Duration::from_millis(5));
                    continue;
                }
                next += every;
                if client.is_none() {
                    client = skillfab_client::Client::connect(&domain).ok();
                }
                let Some(c) = client.as_ref() else { continue };
                let connects = |c: &skillfab_client::Client| -> Option<(f64, bool)> {
                    let n = c.query("denning.link.connects").ok()?.0.as_f64()?;
                    let up = c.query("denning.link.connected").ok()?.0.as_f64()? != 0.0;
                    Some((n, up))
                };
                let (Some(pid), Some((before, _))) =
                    (process_with_args(&["denning-sim", &link]), connects(c))
                else {
                    continue;
                };
                let Some(killed_at) = sigkill(pid, "denning-sim") else {
                    continue;
                };
                let mut kill = Kill {
                    target: "denning-sim".into(),
                    at_s: killed_at.duration_since(armed).as_secs_f64(),
                    recovery_ms: None,
                    cycles_lost: None,
                };
                let deadline = killed_at + Duration::from_secs(10);
                while Instant::now() < deadline && !st.load(Ordering::Acquire) {
                    if connects(c).is_some_and(|(n, up)| up && n > before) {
                        kill.recovery_ms = Some(killed_at.elapsed().as_secs_f64() * 1000.0);
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(2));
                }
                if let Ok(mut k) = ks.lock() {
                    k.push(kill);
                }
            }
        })
    }

    /// Runs `body` on a thread of its own with the stop flag and the list of kills.
    fn spawn(body: impl FnOnce(Arc<AtomicBool>, Arc<Mutex<Vec<Kill>>>) + Send + 'static) -> Killer {
        let stop = Arc::new(AtomicBool::new(false));
        let kills = Arc::new(Mutex::new(Vec::new()));
        let (st, ks) = (stop.clone(), kills.clone());
        Killer {
            stop,
            kills,
            thread: Some(std::thread::spawn(move || body(st, ks))),
        }
    }

    /// Stops killing; the kills so far.
    pub fn finish(mut self) -> Vec<Kill> {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.kills.lock().map(|k| k.clone()).unwrap_or_default()
    }
}

impl Drop for Killer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
