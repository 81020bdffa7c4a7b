//! Turns a unit — a [`Skill`], a [`Device`] or a skill declared at run time — into a process:
//! arguments, registration, cycles, shutdown. Private to the SDK: authors call
//! [`crate::main`] / [`crate::device_main`], other languages go through [`crate::foreign`].
//!
//! The life of a skill process:
//! 1. parse `--name/--domain/--param/--priority/--inactive/--remap` (devices also
//!    `--port/--baud/--policy`), validate parameters; in real-time mode (`--realtime`,
//!    `--cpus`, `--lock-memory`) set the thread's scheduling, affinity and locked memory,
//!    saying what the machine refused;
//! 2. wait for the domain's manager (launch order does not matter);
//! 3. register: claim a board slot, write the declaration, wake the manager, wait for its
//!    answer (a refusal, e.g. a type mismatch, ends the process with that error);
//! 4. open the data ports, tell the manager it is ready, and serve cycles: a sync skill runs when the manager expects it in
//!    cycle k and every same-cycle input carries cycle k; an async skill runs whenever an
//!    input changed (or once per cycle without inputs). Outputs are sent, then the doorbells
//!    of their consumers are rung directly (and the topic's iceoryx2 event service notified,
//!    for readers outside the fabric); the run is stamped on the board; the manager is woken
//!    only by the run that completes the cycle, or by a run that passed nothing on;
//! 5. on SIGINT/SIGTERM leave the slot cleanly; if the manager goes away, go back to 2.

//! ## Layout
//! - here: the arguments, the [`Unit`] trait (a unit declares itself by value), the one
//!   start-up path [`start`], the declaration and the registration loop;
//! - `serve`: waiting for the manager, registering, and the wait loop of a registered unit;
//! - `skill_unit`: a skill's run (shared by Rust and foreign skills): inputs due, body,
//!   outputs sent, the run stamped on the board;
//! - `device_unit`: a device's cycle: sample at once, then arbitrate and command;
//!   `arbiter`: which proposers have settled, and each channel's command from them.

mod alloc_watch;
mod arbiter;
mod device_unit;
mod kept;
mod serve;
mod skill_unit;
mod waker;

pub use waker::Waker;

pub(crate) use skill_unit::{guarded, step_skill};

use crate::SdkError;
use crate::actuation::ErasedChannel;
use crate::board::SlotState;
use crate::decl::{Mode, Policy, PortDecl, PortKind, SkillDecl};
use crate::device::{Device, DeviceOptions};
use crate::domain::{DOMAIN_ENV, Domain};
use crate::names;
use crate::params::Params;
use crate::ports::{ErasedInput, ErasedOutput, PortMaker};
use crate::services;
use crate::skill::Skill;
use crate::state::StateError;
use alloc_watch::AllocWatch;
use clap::Parser;
use device_unit::DeviceUnit;
use kept::{Found, Kept};
pub(crate) use serve::Link;
use serve::{End, Registration, register, serve, wait_for_board};
use skill_unit::SkillUnit;
use skillfab_proto::realtime::{CpuList, RealTime, Sched};
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// How often a skill checks that its manager is still there: a manager that stops wakes its
/// skills itself, so this only bounds how long a skill outlives a manager that crashed. It
/// is a wake-up of every skill process, so it is rare (a tenth of the wake-ups of a skill
/// cycling at 100 Hz when it was 100 ms).
const LIVENESS_TICK: Duration = Duration::from_secs(1);
/// How often a skill looks for a manager that is not there yet.
const BOARD_POLL: Duration = Duration::from_millis(20);

/// Options every skill binary accepts.
#[derive(Parser, Debug, Clone)]
#[command(about = "A skillfab skill process")]
pub struct SkillArgs {
    /// Instance name, unique in the domain (default: the program name).
    #[arg(long)]
    pub name: Option<String>,
    /// Fabric domain.
    #[arg(long, env = DOMAIN_ENV, default_value = "default")]
    pub domain: String,
    /// Parameter value, checked against its declared type and bounds (repeatable).
    #[arg(long = "param", value_name = "NAME=VALUE")]
    pub params: Vec<String>,
    /// Arbitration priority (default: the skill's declared priority).
    #[arg(long, allow_negative_numbers = true)]
    pub priority: Option<i32>,
    /// Register inactive; a sequencer activates it later.
    #[arg(long)]
    pub inactive: bool,
    /// Wire a port to another topic, or a proposal/channel to another channel (repeatable).
    #[arg(long = "remap", value_name = "PORT=TOPIC")]
    pub remaps: Vec<String>,
    /// Spin budget (µs; 0, the default: sleep). A sync unit with a budget is woken at every
    /// cycle's start and polls its doorbell, instead of sleeping on it, until it has run or
    /// this long after the cycle's start: its producers' rings reach it without a kernel
    /// wake-up, at the price of a core spent polling (docs/realtime.md).
    #[arg(long = "spin-us", value_name = "MICROSECONDS", default_value_t = 0)]
    pub spin_us: u64,
    /// Print the declaration these options make (JSON: ports with topics and message
    /// schemas, parameters with values) and exit, without joining a fabric (`skillfab
    /// sequence --check --launch` reads it).
    #[arg(long)]
    pub describe: bool,
    /// Real-time mode of the skill's thread: a scheduling policy and priority, `fifo:80` or
    /// `rr:80` (docs/realtime.md). What the machine refuses is logged as a warning and the
    /// skill runs on without it.
    #[arg(long, value_name = "POLICY:PRIORITY")]
    pub realtime: Option<Sched>,
    /// With --realtime: pin the skill's thread to these CPUs (`1`, `0,1`, `0-3`).
    #[arg(long, value_name = "CPUS", requires = "realtime")]
    pub cpus: Option<CpuList>,
    /// With --realtime: lock the process's memory (mlockall) and pre-fault some stack.
    #[arg(long, requires = "realtime")]
    pub lock_memory: bool,
}

impl SkillArgs {
    /// The real-time mode the flags ask for, if any.
    pub fn real_time(&self) -> Option<RealTime> {
        self.realtime.map(|sched| RealTime {
            cpus: self.cpus.clone(),
            lock_memory: self.lock_memory,
            ..RealTime::new(sched)
        })
    }
}

/// Options every device binary accepts: a skill's, and where its hardware is and how its
/// channels are arbitrated.
#[derive(Parser, Debug, Clone)]
#[command(about = "A skillfab device process")]
pub struct DeviceArgs {
    /// What every skill process takes (domain, name, parameters).
    #[command(flatten)]
    pub skill: SkillArgs,
    /// The serial port (a tty, or a simulator's pty link).
    #[arg(long)]
    pub port: Option<String>,
    /// The baud rate.
    #[arg(long)]
    pub baud: Option<u32>,
    /// Arbitration policy of a channel: `priority` or `blend` (repeatable).
    #[arg(long = "policy", value_name = "CHANNEL=POLICY")]
    pub policies: Vec<String>,
}

/// A skill binary's whole `main`: `fn main() -> ExitCode { skill_sdk::main::<MySkill>() }`.
pub fn main<S: Skill>() -> ExitCode {
    let args = SkillArgs::parse();
    exit_code(start(SkillUnit(S::default()), &args, &[], &program_name()))
}

/// A device binary's whole `main`: `fn main() -> ExitCode { skill_sdk::device_main::<MyDevice>() }`.
pub fn device_main<D: Device>() -> ExitCode {
    let args = DeviceArgs::parse();
    let name = args.skill.name.clone().unwrap_or_else(program_name);
    let options = DeviceOptions {
        port: args.port.clone(),
        baud: args.baud,
        state_dir: skillfab_proto::domain::Domain::new(&args.skill.domain)
            .ok()
            .map(|d| d.root_path().join("devices").join(name)),
    };
    let unit = DeviceUnit::new(D::default(), options);
    exit_code(start(unit, &args.skill, &args.policies, &program_name()))
}

/// The program's file name: a skill's kind (and its default instance name).
fn program_name() -> String {
    std::env::args()
        .next()
        .and_then(|a| {
            std::path::Path::new(&a)
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
        })
        .unwrap_or_else(|| "skill".to_string())
}

fn exit_code(result: Result<(), (String, SdkError)>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err((kind, e)) => {
            eprintln!("{kind}: error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The one start-up path of every unit (Rust skills, devices, skills declared in C or
/// Python): tracing, the log stream, then [`run`] until SIGINT/SIGTERM. The error comes back
/// with the unit's kind, for the caller to report.
pub(crate) fn start<U: Unit>(
    unit: U,
    args: &SkillArgs,
    policies: &[String],
    kind: &str,
) -> Result<(), (String, SdkError)> {
    init_tracing();
    // The skill's log lines go to the domain's log stream too (console, `ctl logs`); a
    // skill asked only to `--describe` itself joins no fabric.
    let _forward = Domain::new(&args.domain)
        .ok()
        .filter(|_| !args.describe)
        .and_then(|d| {
            let name = args.name.clone().unwrap_or_else(|| kind.to_string());
            crate::logs::forward(&d, &name)
        });
    run(unit, args, policies, kind).map_err(|e| (kind.to_string(), e))
}

/// Installs the tracing subscriber (`RUST_LOG`, default `info`) and quiets iceoryx2's own
/// logger to errors (`IOX2_LOG_LEVEL` overrides). Events that pass the filter go to stderr
/// and, once [`crate::logs::forward`] ran (skill processes), to the domain's log stream.
pub fn init_tracing() {
    use std::io::IsTerminal;
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        tracing_subscriber::EnvFilter::new(skillfab_proto::log::DEFAULT_FILTER)
    });
    let _ = tracing_subscriber::registry()
        .with(filter)
        .with(
            tracing_subscriber::fmt::layer()
                .with_ansi(std::io::stderr().is_terminal())
                .with_writer(std::io::stderr),
        )
        .with(crate::logs::ForwardLayer)
        .try_init();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
}

/// What the runtime drives: a skill, a device, or a skill declared at run time. A unit
/// declares itself by value, so a declaration made at run time (C, Python) needs no global.
pub(crate) trait Unit: 'static {
    /// Parameters.
    type Params: Params;
    /// Scheduling mode.
    fn mode(&self) -> Mode;
    /// Default priority.
    fn priority(&self) -> i32;
    /// The parameters' declared defaults.
    fn default_params(&self) -> Self::Params;
    /// Input ports. A device has none but its channels, which its declaration lists as its
    /// inputs (the manager numbers a device's channels by their place there).
    fn input_ports(&self) -> Vec<PortDecl>;
    /// Output ports.
    fn output_ports(&self) -> Vec<PortDecl>;
    /// Runtime input ports.
    fn make_inputs(&self, m: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedInput>>, SdkError>;
    /// Runtime channel ports (a device's), made from the same declarations as the inputs.
    fn make_channels(&self, _m: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedChannel>>, SdkError> {
        Ok(Vec::new())
    }
    /// Runtime output ports.
    fn make_outputs(&self, m: &PortMaker<'_>) -> Result<Vec<ErasedOutput>, SdkError>;
    /// Runs whatever is due now.
    fn step(&mut self, link: &Link<'_>, io: &mut Io, common: &mut Common<Self::Params>);
    /// Once, before registration.
    fn init(&mut self) -> Result<(), SdkError> {
        Ok(())
    }
    /// The fingerprint of the state the unit keeps across the deaths of its process
    /// ([`crate::skill::Skill::STATE`]); `None`: it keeps none.
    fn state_fingerprint(&self) -> Option<u64> {
        None
    }
    /// Takes back the state an earlier instance of this name kept.
    fn restore_state(&mut self, _bytes: &[u8]) -> Result<(), StateError> {
        Ok(())
    }
    /// What other threads wake the unit with, if they may.
    fn waker(&self) -> Option<Waker> {
        None
    }
}

/// Parameters and cycle bookkeeping shared by skills and devices.
pub(crate) struct Common<P> {
    params: P,
    /// Generation of the last parameter snapshot applied.
    param_gen: u64,
    /// Last cycle this unit finished (ran, skipped or failed) for.
    last_cycle: u64,
    name: String,
    /// The unit's state object, if it keeps state (and it could be opened).
    kept: Option<Kept>,
    /// The state of the run just made, encoded (reused from run to run).
    state_buf: Vec<u8>,
    /// Whether a failure to keep the state was logged already (logged once, not every run).
    state_warned: bool,
    /// Wakes from other threads (a gateway's).
    waker: Option<Waker>,
    /// Spin budget after a cycle's start (ns; 0: sleep on the doorbell).
    spin_ns: u64,
    /// The cycle path's allocations, counted.
    allocs: AllocWatch,
}

/// A unit's runtime ports.
pub(crate) struct Io {
    /// A skill's inputs, read every run.
    inputs: Vec<Box<dyn ErasedInput>>,
    /// A device's channels, arbitrated every cycle (index c: the c-th channel the device
    /// declared, as the board's `channel_*` fields count them).
    channels: Vec<Box<dyn ErasedChannel>>,
    outputs: Vec<ErasedOutput>,
    /// Indexes of the outputs that are proposals.
    proposals: Vec<usize>,
}

/// Builds the declaration of `unit` from its arguments (`policies`: a device's `--policy`).
fn declare<U: Unit>(
    unit: &U,
    args: &SkillArgs,
    policies: &[String],
    kind: &str,
) -> Result<(SkillDecl, U::Params), SdkError> {
    let name = args.name.clone().unwrap_or_else(|| kind.to_string());
    names::check_name("skill", &name, false)?;
    let mut params = unit.default_params();
    for a in &args.params {
        params.assign(a)?;
    }
    let mut inputs = unit.input_ports();
    let mut outputs = unit.output_ports();
    for r in &args.remaps {
        let (port, topic) = r
            .split_once('=')
            .ok_or_else(|| SdkError::UnknownPort { port: r.clone() })?;
        names::check_name("topic", topic, true)?;
        let mut found = false;
        for p in inputs
            .iter_mut()
            .chain(outputs.iter_mut())
            .filter(|p| p.port == port)
        {
            p.topic = match p.kind {
                PortKind::Data => topic.to_string(),
                _ => names::channel_topic(topic),
            };
            found = true;
        }
        if !found {
            return Err(SdkError::UnknownPort {
                port: port.to_string(),
            });
        }
    }
    for a in policies {
        let (port, policy) = a
            .split_once('=')
            .ok_or_else(|| SdkError::UnknownPort { port: a.clone() })?;
        let policy = match policy {
            "priority" => Policy::Priority,
            "blend" => Policy::Blend,
            other => {
                return Err(SdkError::BadPolicy {
                    policy: other.to_string(),
                });
            }
        };
        let p = inputs
            .iter_mut()
            .find(|p| p.port == port && matches!(p.kind, PortKind::Channel(_)))
            .ok_or_else(|| SdkError::UnknownPort {
                port: port.to_string(),
            })?;
        p.kind = PortKind::Channel(policy);
    }
    let decl = SkillDecl {
        name,
        kind: kind.to_string(),
        mode: unit.mode(),
        priority: args.priority.unwrap_or(unit.priority()),
        start_active: !args.inactive,
        pid: std::process::id(),
        inputs,
        outputs,
        params: params.specs(),
        param_values: params.values(),
    };
    Ok((decl, params))
}

/// Runs `unit` until SIGINT/SIGTERM.
fn run<U: Unit>(
    mut unit: U,
    args: &SkillArgs,
    policies: &[String],
    kind: &str,
) -> Result<(), SdkError> {
    let (decl, params) = declare(&unit, args, policies, kind)?;
    if args.describe {
        let json = serde_json::to_string(&decl).map_err(SdkError::Describe)?;
        println!("{json}");
        return Ok(());
    }
    let domain = Domain::new(&args.domain)?;
    let span = tracing::info_span!("skill", name = %decl.name, domain = %domain);
    let _enter = span.enter();
    // Once, on the thread that serves cycles, before it registers (the log forwarder's thread
    // started earlier and stays an ordinary one).
    let realtime = args.real_time();
    if let Some(rt) = &realtime {
        rt.apply().log("the skill's thread");
    }
    let node = services::node(&domain, &decl.name)?;
    let mut io: Option<Io> = None;
    unit.init()?;
    let kept = unit
        .state_fingerprint()
        .and_then(|fp| take_back(&mut unit, &names::state(&domain.prefix(), &decl.name), fp));
    let mut common = Common {
        params,
        param_gen: 0,
        last_cycle: 0,
        name: decl.name.clone(),
        kept,
        state_buf: Vec::new(),
        state_warned: false,
        waker: unit.waker(),
        spin_ns: args.spin_us.saturating_mul(1000),
        allocs: AllocWatch::new(realtime.is_some()),
    };
    let mut decl = decl;
    loop {
        let Some(board) = wait_for_board(&node, &domain)? else {
            return Ok(());
        };
        let board = std::sync::Arc::new(board);
        // A new manager learns the values the previous one set.
        decl.param_values = common.params.values();
        let encoded = postcard::to_allocvec(&decl).map_err(skillfab_proto::Error::from)?;
        let idx = match register(&board, &decl, &encoded)? {
            Registration::Accepted(idx) => idx,
            Registration::ManagerGone => continue,
            Registration::Terminated => return Ok(()),
        };
        tracing::info!(slot = idx, "registered");
        if io.is_none() {
            let inputs = PortMaker {
                node: Some(&node),
                ports: decl.inputs.clone(),
            };
            io = Some(Io {
                inputs: unit.make_inputs(&inputs)?,
                channels: unit.make_channels(&inputs)?,
                outputs: unit.make_outputs(&PortMaker {
                    node: Some(&node),
                    ports: decl.outputs.clone(),
                })?,
                proposals: decl
                    .outputs
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| p.kind == PortKind::Proposal)
                    .map(|(i, _)| i)
                    .collect(),
            });
        }
        let Some(io) = io.as_mut() else {
            continue;
        };
        board
            .slot(idx)
            .spin_ns
            .store(common.spin_ns, Ordering::Release);
        if !board
            .slot(idx)
            .transition(SlotState::Accepted, SlotState::Ready)
        {
            continue;
        }
        board.ring_manager();
        common.last_cycle = 0;
        common.param_gen = 0;
        common.allocs.restart(board.slot(idx));
        if let Some(w) = &common.waker {
            w.attach(Some((board.clone(), idx)));
        }
        let link = Link { board: &board, idx };
        let end = serve(&link, io, &mut unit, &mut common);
        if let Some(w) = &common.waker {
            w.attach(None);
        }
        match end? {
            End::Terminated => {
                let slot = board.slot(idx);
                if slot.pid.load(Ordering::Acquire) == std::process::id() {
                    slot.set_state(SlotState::Leaving);
                    board.ring_manager();
                }
                tracing::info!("leaving");
                if let Some(kept) = common.kept.take() {
                    kept.remove();
                }
                return Ok(());
            }
            End::ManagerGone => {
                tracing::warn!("manager gone; waiting for a new one");
            }
        }
    }
}

/// Opens the state object `name` of a unit that keeps state and gives the unit what an
/// earlier instance of its name kept, saying in the log which of the four cases it was.
fn take_back<U: Unit>(unit: &mut U, name: &str, fingerprint: u64) -> Option<Kept> {
    let (kept, found) = match Kept::open(name, fingerprint) {
        Ok(k) => k,
        Err(e) => {
            tracing::warn!(error = %e, "the state cannot be kept: a restart will start afresh");
            return None;
        }
    };
    match found {
        Found::Nothing => {}
        Found::State { bytes, cycle } => match unit.restore_state(&bytes) {
            Ok(()) => tracing::info!(
                bytes = bytes.len(),
                cycle,
                "restored the state of the last completed run"
            ),
            Err(e) => tracing::warn!(
                error = %e,
                "the kept state does not decode: starting afresh"
            ),
        },
        Found::OtherVersion { fingerprint: old } => tracing::warn!(
            kept = format_args!("{old:016x}"),
            this = format_args!("{fingerprint:016x}"),
            "the kept state is another version's: starting afresh"
        ),
        Found::Unreadable => {
            tracing::warn!("the state object holds no whole state: starting afresh");
        }
    }
    Some(kept)
}
