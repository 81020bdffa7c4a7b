//! Turns a [`Skill`] into a process: arguments, registration, cycles, shutdown.
//!
//! The life of a skill process:
//! 1. parse `--name/--domain/--param/--priority/--inactive/--remap`, validate parameters;
//! 2. wait for the domain's manager (launch order does not matter);
//! 3. register: claim a board slot, write the declaration, wake the manager, wait for its
//!    answer (a refusal, e.g. a type mismatch, ends the process with that error);
//! 4. open the data ports, tell the manager it is ready, and serve cycles: a sync skill runs when the manager expects it in
//!    cycle k and every same-cycle input carries cycle k; an async skill runs whenever an
//!    input changed (or once per cycle without inputs). Outputs are sent, then the topic's
//!    listeners are woken directly; the run is stamped on the board; the manager is woken
//!    only by the run that completes the cycle, or by a run that passed nothing on;
//! 5. on SIGINT/SIGTERM leave the slot cleanly; if the manager goes away, go back to 2.

use crate::SdkError;
use crate::board::{Board, MAX_CHANNELS, MAX_SLOTS, RunStatus, SlotState};
use crate::decl::{Mode, Policy, PortDecl, PortKind, SkillDecl};
use crate::device::Device;
use crate::domain::{DOMAIN_ENV, Domain};
use crate::header::{SampleHeader, now_ns};
use crate::names;
use crate::params::Params;
use crate::ports::Candidate;
use crate::ports::{
    ErasedInput, ErasedOutput, InputMeta, InputSet, InputSource, OutputSet, PortMaker,
};
use crate::services;
use crate::skill::SkillResult;
use crate::skill::{Ctx, Skill};
use clap::Parser;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use std::any::Any;
use std::collections::HashMap;
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
    /// A device's serial port (a tty, or a simulator's pty link).
    #[arg(long)]
    pub port: Option<String>,
    /// A device's baud rate.
    #[arg(long)]
    pub baud: Option<u32>,
    /// A device's arbitration policy for a channel: `priority` or `blend` (repeatable).
    #[arg(long = "policy", value_name = "CHANNEL=POLICY")]
    pub policies: Vec<String>,
}

/// A skill binary's whole `main`: `fn main() -> ExitCode { skill_sdk::main::<MySkill>() }`.
pub fn main<S: Skill>() -> ExitCode {
    main_unit::<SkillUnit<S>>()
}

/// A device binary's whole `main`: `fn main() -> ExitCode { skill_sdk::device_main::<MyDevice>() }`.
pub fn device_main<D: Device>() -> ExitCode {
    main_unit::<DeviceUnit<D>>()
}

fn main_unit<U: Unit>() -> ExitCode {
    let args = SkillArgs::parse();
    init_tracing();
    let kind = std::env::args()
        .next()
        .and_then(|a| {
            std::path::Path::new(&a)
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
        })
        .unwrap_or_else(|| "skill".to_string());
    // The skill's log lines go to the domain's log stream too (console, `ctl logs`).
    let _forward = Domain::new(&args.domain).ok().and_then(|d| {
        let name = args.name.clone().unwrap_or_else(|| kind.clone());
        crate::logs::forward(&d, &name)
    });
    match run::<U>(args, &kind) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{kind}: error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Installs the tracing subscriber (`RUST_LOG`, default `info`) and quiets iceoryx2's own
/// logger to errors (`IOX2_LOG_LEVEL` overrides). Events that pass the filter go to stderr
/// and, once [`crate::logs::forward`] ran (skill processes), to the domain's log stream.
pub fn init_tracing() {
    use std::io::IsTerminal;
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
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

/// What the runtime drives: a skill or a device. Internal; authors implement [`Skill`] or
/// [`Device`].
pub trait Unit: 'static {
    /// Parameters.
    type Params: Params;
    /// Scheduling mode.
    fn mode() -> Mode;
    /// Default priority.
    fn priority() -> i32;
    /// A fresh instance.
    fn create() -> Self;
    /// Input ports (for a device: its channels).
    fn input_ports() -> Vec<PortDecl>;
    /// Output ports.
    fn output_ports() -> Vec<PortDecl>;
    /// Runtime input ports.
    fn make_inputs(m: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedInput>>, SdkError>;
    /// Runtime output ports.
    fn make_outputs(m: &PortMaker<'_>) -> Result<Vec<ErasedOutput>, SdkError>;
    /// Runs whatever is due now.
    fn step(&mut self, link: &Link<'_>, io: &mut Io, common: &mut Common<Self::Params>);
    /// Once, before registration.
    fn init(&mut self, _args: &SkillArgs) -> Result<(), SdkError> {
        Ok(())
    }
}

/// The wrapper that runs a [`Skill`].
pub struct SkillUnit<S: Skill>(S);

/// The wrapper that runs a [`Device`].
pub struct DeviceUnit<D: Device> {
    device: D,
    /// Last cycle whose sample phase ran.
    sampled: u64,
    /// Proposer names by slot, with the slot generation they belong to.
    names: HashMap<u32, (u32, String)>,
}

/// Parameters and cycle bookkeeping shared by skills and devices.
pub struct Common<P> {
    params: P,
    /// Generation of the last parameter snapshot applied.
    param_gen: u64,
    /// Last cycle this unit finished (ran, skipped or failed) for.
    last_cycle: u64,
    name: String,
}

/// A unit's runtime ports.
pub struct Io {
    inputs: Vec<Box<dyn ErasedInput>>,
    outputs: Vec<ErasedOutput>,
    /// Indexes of the outputs that are proposals.
    proposals: Vec<usize>,
}

/// Builds the declaration of unit `U` from its arguments.
pub fn declare<U: Unit>(args: &SkillArgs, kind: &str) -> Result<(SkillDecl, U::Params), SdkError> {
    let name = args.name.clone().unwrap_or_else(|| kind.to_string());
    names::check_name("skill", &name, false)?;
    let mut params = U::Params::default();
    for a in &args.params {
        params.assign(a)?;
    }
    let mut inputs = U::input_ports();
    let mut outputs = U::output_ports();
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
    for a in &args.policies {
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
        mode: U::mode(),
        priority: args.priority.unwrap_or(U::priority()),
        start_active: !args.inactive,
        pid: std::process::id(),
        inputs,
        outputs,
        params: U::Params::specs(),
        param_values: params.values(),
    };
    Ok((decl, params))
}

/// Runs unit `U` (a [`SkillUnit`] or [`DeviceUnit`]) until SIGINT/SIGTERM.
pub fn run<U: Unit>(args: SkillArgs, kind: &str) -> Result<(), SdkError> {
    let (decl, params) = declare::<U>(&args, kind)?;
    let domain = Domain::new(&args.domain)?;
    let span = tracing::info_span!("skill", name = %decl.name, domain = %domain);
    let _enter = span.enter();
    let node = services::node(&domain, &decl.name)?;
    let trigger = services::listener(&node, &names::skill_trigger(&decl.name))?;
    let wake = services::notifier(&node, &names::manager_wake())?;

    let mut io: Option<Io> = None;
    let listeners = decl
        .inputs
        .iter()
        .map(|p| services::listener(&node, &names::topic(&p.topic)))
        .collect::<Result<Vec<_>, _>>()?;
    let mut unit = U::create();
    unit.init(&args)?;
    let mut common = Common {
        params,
        param_gen: 0,
        last_cycle: 0,
        name: decl.name.clone(),
    };
    let mut decl = decl;
    loop {
        let Some(board) = wait_for_board(&node, &domain)? else {
            return Ok(());
        };
        // A new manager learns the values the previous one set.
        decl.param_values = common.params.values();
        let encoded = postcard::to_allocvec(&decl).map_err(skillfab_proto::Error::from)?;
        let idx = match register(&node, &board, &decl, &encoded, &trigger, &wake)? {
            Registration::Accepted(idx) => idx,
            Registration::ManagerGone => continue,
            Registration::Terminated => return Ok(()),
        };
        tracing::info!(slot = idx, "registered");
        if io.is_none() {
            io = Some(Io {
                inputs: U::make_inputs(&PortMaker {
                    node: Some(&node),
                    ports: decl.inputs.clone(),
                })?,
                outputs: U::make_outputs(&PortMaker {
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
        if !board
            .slot(idx)
            .transition(SlotState::Accepted, SlotState::Ready)
        {
            continue;
        }
        let _ = wake.notify();
        common.last_cycle = 0;
        common.param_gen = 0;
        let link = Link {
            node: &node,
            board: &board,
            idx,
            trigger: &trigger,
            listeners: &listeners,
            wake: &wake,
        };
        match serve(&link, io, &mut unit, &mut common)? {
            End::Terminated => {
                let slot = board.slot(idx);
                if slot.pid.load(Ordering::Acquire) == std::process::id() {
                    slot.set_state(SlotState::Leaving);
                    let _ = wake.notify();
                }
                tracing::info!("leaving");
                return Ok(());
            }
            End::ManagerGone => {
                tracing::warn!("manager gone; waiting for a new one");
            }
        }
    }
}

/// What a registered unit uses to talk to its manager.
pub struct Link<'a> {
    node: &'a Node<ipc::Service>,
    board: &'a Board,
    idx: usize,
    trigger: &'a Listener<ipc::Service>,
    listeners: &'a [Listener<ipc::Service>],
    wake: &'a Notifier<ipc::Service>,
}

enum Registration {
    Accepted(usize),
    ManagerGone,
    Terminated,
}

enum End {
    Terminated,
    ManagerGone,
}

fn terminated(node: &Node<ipc::Service>) -> bool {
    services::termination_requested(node)
}

fn wait_for_board(node: &Node<ipc::Service>, domain: &Domain) -> Result<Option<Board>, SdkError> {
    let mut told = false;
    loop {
        match Board::open(&domain.prefix()) {
            Ok(b) if b.manager_alive() => return Ok(Some(b)),
            _ => {}
        }
        if !told {
            tracing::info!("waiting for the manager of domain '{domain}'");
            told = true;
        }
        if node.wait(BOARD_POLL).is_err() {
            return Ok(None);
        }
    }
}

fn register(
    node: &Node<ipc::Service>,
    board: &Board,
    decl: &SkillDecl,
    encoded: &[u8],
    trigger: &Listener<ipc::Service>,
    wake: &Notifier<ipc::Service>,
) -> Result<Registration, SdkError> {
    let idx = (0..MAX_SLOTS)
        .find(|&i| {
            board
                .slot(i)
                .transition(SlotState::Free, SlotState::Claimed)
        })
        .ok_or(SdkError::BoardFull { max: MAX_SLOTS })?;
    let slot = board.slot(idx);
    slot.pid.store(std::process::id(), Ordering::Release);
    if let Err(e) = slot.write_decl(encoded) {
        slot.set_state(SlotState::Free);
        return Err(e.into());
    }
    slot.set_state(SlotState::Pending);
    let _ = wake.notify();
    loop {
        match slot.state() {
            SlotState::Accepted => return Ok(Registration::Accepted(idx)),
            SlotState::Refused => {
                let reason = slot.read_msg();
                slot.set_state(SlotState::Free);
                return Err(SdkError::Refused {
                    name: decl.name.clone(),
                    reason,
                });
            }
            _ => {}
        }
        if !board.manager_alive() {
            return Ok(Registration::ManagerGone);
        }
        if terminated(node) {
            slot.set_state(SlotState::Leaving);
            let _ = wake.notify();
            return Ok(Registration::Terminated);
        }
        let _ = trigger.timed_wait(|_| {}, BOARD_POLL);
    }
}

struct RuntimeInputs<'a> {
    inputs: &'a [Box<dyn ErasedInput>],
    cycle: u64,
}

impl InputSource for RuntimeInputs<'_> {
    fn get(&self, idx: usize) -> Option<(&dyn Any, InputMeta)> {
        let port = self.inputs.get(idx)?;
        let h = port.latest_header()?;
        Some((
            port.latest_any()?,
            InputMeta {
                cycle: h.cycle,
                age: self.cycle.saturating_sub(h.cycle),
                source: (h.slot != u32::MAX).then_some(h.slot),
            },
        ))
    }
}

fn serve<U: Unit>(
    link: &Link<'_>,
    io: &mut Io,
    unit: &mut U,
    common: &mut Common<U::Params>,
) -> Result<End, SdkError> {
    let Link {
        board,
        idx,
        trigger,
        listeners,
        ..
    } = *link;
    let transport = |what: &str, e: &dyn std::fmt::Debug| crate::SdkError::transport(what, e);
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(|e| transport("create waitset", &e))?;
    let trigger_guard = waitset
        .attach_notification(trigger)
        .map_err(|e| transport("attach trigger", &e))?;
    let mut input_guards = Vec::new();
    for l in listeners {
        input_guards.push(
            waitset
                .attach_notification(l)
                .map_err(|e| transport("attach input", &e))?,
        );
    }
    let tick = waitset
        .attach_interval(LIVENESS_TICK)
        .map_err(|e| transport("attach interval", &e))?;
    let slot = board.slot(idx);
    let me = std::process::id();
    loop {
        let mut ticked = false;
        // Which listeners fired: only those are drained (each drain is a system call that
        // ends in EAGAIN; a skill is usually woken by one of them).
        let mut triggered = false;
        let mut fired = 0u64;
        let result = waitset
            .wait_and_process_once(|id| {
                if id.has_event_from(&tick) {
                    ticked = true;
                } else if id.has_event_from(&trigger_guard) {
                    triggered = true;
                } else if let Some(i) = input_guards.iter().position(|g| id.has_event_from(g)) {
                    fired |= 1 << i.min(63);
                }
                CallbackProgression::Continue
            })
            .map_err(|e| transport("wait", &e))?;
        match result {
            WaitSetRunResult::TerminationRequest => return Ok(End::Terminated),
            // A wait cut short by a signal: only SIGINT/SIGTERM end the skill.
            WaitSetRunResult::Interrupt if terminated(link.node) => return Ok(End::Terminated),
            WaitSetRunResult::Interrupt => continue,
            _ => {}
        }
        // Only the listeners that fired are drained; a listener that fired after the wait is
        // drained at the next one (the WaitSet reports it again at once). On the liveness
        // tick every listener is drained: iceoryx2 0.10's listener can be left with its
        // "notified" flag set and its socket empty by a drain that races two notifiers, after
        // which no notifier sends to it (see the manager's loop); the tick's drain clears
        // that, so a deaf listener recovers within a second.
        if triggered || ticked {
            let _ = trigger.try_wait(|_| {});
        }
        for (i, l) in listeners.iter().enumerate() {
            if ticked || fired & (1 << i.min(63)) != 0 {
                let _ = l.try_wait(|_| {});
            }
        }
        for i in io.inputs.iter_mut() {
            i.poll()?;
        }
        if ticked
            && (!board.manager_alive()
                || slot.state() != SlotState::Ready
                || slot.pid.load(Ordering::Acquire) != me)
        {
            return Ok(End::ManagerGone);
        }
        let s = board.slot(idx);
        if let Some((generation, bytes)) = s.read_params(common.param_gen) {
            common.param_gen = generation;
            apply_params(&mut common.params, &bytes);
        }
        if s.active.load(Ordering::Acquire) != 0 {
            unit.step(link, io, common);
        }
    }
}

/// Applies a parameter snapshot from the manager (which already checked every value).
fn apply_params<P: Params>(params: &mut P, bytes: &[u8]) {
    match postcard::from_bytes::<Vec<(String, crate::params::ParamValue)>>(bytes) {
        Ok(values) => {
            for (name, value) in values {
                if params.get(&name) != Some(value) {
                    match params.set(&name, value) {
                        Ok(()) => tracing::info!(param = %name, %value, "parameter set"),
                        Err(e) => tracing::warn!(error = %e, "parameter refused"),
                    }
                }
            }
        }
        Err(e) => tracing::warn!(error = %e, "unreadable parameter snapshot"),
    }
}

/// Outcome of running a body once (error or panic logged).
pub(crate) fn guarded(cycle: u64, body: impl FnOnce() -> SkillResult) -> RunStatus {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(body)) {
        Ok(Ok(())) => RunStatus::Ok,
        Ok(Err(e)) => {
            tracing::warn!(cycle, error = %e, "run failed");
            RunStatus::Failed
        }
        Err(_) => {
            tracing::error!(cycle, "run panicked");
            RunStatus::Failed
        }
    }
}

/// Sends the written outputs of a successful run (or drops them); returns the sent mask.
fn commit_outputs(outputs: &mut [ErasedOutput], status: RunStatus, header: SampleHeader) -> u64 {
    let mut mask = 0u64;
    for (i, o) in outputs.iter_mut().enumerate() {
        if status != RunStatus::Ok {
            o.discard();
            continue;
        }
        match o.commit(header) {
            Ok(true) => mask |= 1 << i,
            Ok(false) => {}
            Err(e) => tracing::warn!(cycle = header.cycle, error = %e, "publish failed"),
        }
    }
    mask
}

/// Stamps a finished run on the board and, for a sync unit, takes it off the cycle's counter
/// (waking the manager if that finished the cycle or the run passed nothing on).
/// One finished run, as stamped on the board.
struct RunRecord {
    k: u64,
    status: RunStatus,
    /// Outputs sent.
    mask: u64,
    /// Number of outputs.
    outputs: usize,
    start: u64,
    end: u64,
    /// Whether the cycle waits for this unit.
    sync: bool,
}

fn finish_run(link: &Link<'_>, r: RunRecord) {
    let RunRecord {
        k,
        status,
        mask,
        outputs,
        start,
        end,
        sync,
    } = r;
    let slot = link.board.slot(link.idx);
    let counter = match status {
        RunStatus::Ok => &slot.runs,
        RunStatus::Skipped => &slot.skips,
        _ => &slot.failures,
    };
    counter.fetch_add(1, Ordering::Relaxed);
    slot.compute_ns_total
        .fetch_add(end - start, Ordering::Relaxed);
    slot.last_compute_ns.store(end - start, Ordering::Relaxed);
    slot.published_mask.store(mask, Ordering::Relaxed);
    slot.status.store(status as u32, Ordering::Relaxed);
    slot.last_end_ns.store(now_ns(), Ordering::Relaxed);
    slot.done_cycle.store(k, Ordering::Release);
    if sync {
        let all = if outputs >= 64 {
            u64::MAX
        } else {
            (1u64 << outputs) - 1
        };
        let finished = link.board.complete(k, 1);
        if finished || status != RunStatus::Ok || mask != all {
            let _ = link.wake.notify();
        }
    }
}

impl<S: Skill> Unit for SkillUnit<S> {
    type Params = S::Params;
    fn mode() -> Mode {
        S::MODE
    }
    fn priority() -> i32 {
        S::PRIORITY
    }
    fn create() -> Self {
        SkillUnit(S::default())
    }
    fn input_ports() -> Vec<PortDecl> {
        <S::Inputs<'static> as InputSet<'static>>::ports()
    }
    fn output_ports() -> Vec<PortDecl> {
        <S::Outputs<'static> as OutputSet<'static>>::ports()
    }
    fn make_inputs(m: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedInput>>, SdkError> {
        <S::Inputs<'static> as InputSet<'static>>::make(m)
    }
    fn make_outputs(m: &PortMaker<'_>) -> Result<Vec<ErasedOutput>, SdkError> {
        <S::Outputs<'static> as OutputSet<'static>>::make(m)
    }

    fn step(&mut self, link: &Link<'_>, io: &mut Io, common: &mut Common<S::Params>) {
        let skill = &mut self.0;
        step_skill(link, io, common, S::MODE, |src, outputs, ctx| {
            match <S::Inputs<'_> as InputSet<'_>>::fetch(src) {
                None => RunStatus::Skipped,
                Some(input) => {
                    let mut out = <S::Outputs<'_> as OutputSet<'_>>::bind(outputs);
                    guarded(ctx.cycle, || skill.compute(ctx, input, &mut out))
                }
            }
        });
    }
}

/// One run of a skill, if one is due: a sync skill runs when the manager expects it in cycle
/// k and every same-cycle input carries cycle k; an async one when an input changed (or once
/// per cycle without inputs). `run` runs the body on the inputs and outputs; the outputs of a
/// successful run are sent, the run stamped, and proposals not made are announced.
pub(crate) fn step_skill<P: Params>(
    link: &Link<'_>,
    io: &mut Io,
    common: &mut Common<P>,
    mode: Mode,
    run: impl FnOnce(&dyn InputSource, &mut [ErasedOutput], &Ctx<'_, P>) -> RunStatus,
) {
    let board = link.board;
    let slot = board.slot(link.idx);
    let k = board.header().cycle.load(Ordering::Acquire);
    let inputs = &mut io.inputs;
    let due = match mode {
        Mode::Sync => {
            let fresh = slot.fresh_mask.load(Ordering::Acquire);
            k > common.last_cycle
                && slot.expected_cycle.load(Ordering::Acquire) == k
                && inputs.iter().enumerate().all(|(i, p)| {
                    fresh & (1 << i) == 0 || p.latest_header().is_some_and(|h| h.cycle == k)
                })
        }
        Mode::Async if inputs.is_empty() => k > common.last_cycle,
        Mode::Async => inputs.iter().any(|p| p.is_fresh()),
    };
    if !due {
        return;
    }
    let start = now_ns();
    slot.last_start_ns.store(start, Ordering::Relaxed);
    let status = {
        let src = RuntimeInputs { inputs, cycle: k };
        let ctx = Ctx {
            params: &common.params,
            cycle: k,
            name: &common.name,
        };
        run(&src, &mut io.outputs, &ctx)
    };
    let end = now_ns();
    let header = SampleHeader {
        cycle: k,
        stamp_ns: end,
        slot: link.idx as u32,
        reserved: 0,
    };
    let mask = commit_outputs(&mut io.outputs, status, header);
    for i in io.inputs.iter_mut() {
        i.consume();
    }
    common.last_cycle = k;
    finish_run(
        link,
        RunRecord {
            k,
            status,
            mask,
            outputs: io.outputs.len(),
            start,
            end,
            sync: mode == Mode::Sync,
        },
    );
    // A proposal not made: the device waiting for it learns from the board, once woken.
    for &i in &io.proposals {
        if mask & (1 << i) == 0 {
            io.outputs[i].wake();
        }
    }
}

impl<D: Device> Unit for DeviceUnit<D> {
    type Params = D::Params;
    fn mode() -> Mode {
        Mode::Sync
    }
    fn priority() -> i32 {
        0
    }
    fn init(&mut self, args: &SkillArgs) -> Result<(), SdkError> {
        let options = crate::device::DeviceOptions {
            port: args.port.clone(),
            baud: args.baud,
        };
        self.device
            .init(&options)
            .map_err(|e| SdkError::DeviceInit {
                reason: e.to_string(),
            })
    }
    fn create() -> Self {
        DeviceUnit {
            device: D::default(),
            sampled: 0,
            names: HashMap::new(),
        }
    }
    fn input_ports() -> Vec<PortDecl> {
        <D::Commands<'static> as InputSet<'static>>::ports()
    }
    fn output_ports() -> Vec<PortDecl> {
        <D::Outputs<'static> as OutputSet<'static>>::ports()
    }
    fn make_inputs(m: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedInput>>, SdkError> {
        <D::Commands<'static> as InputSet<'static>>::make(m)
    }
    fn make_outputs(m: &PortMaker<'_>) -> Result<Vec<ErasedOutput>, SdkError> {
        <D::Outputs<'static> as OutputSet<'static>>::make(m)
    }

    /// Cycle k: at the start, publish the latest sample at once; then, when every proposer
    /// the manager expects in k has finished (or was cancelled), arbitrate each channel, hand
    /// the commands to the body, publish them, and finish the cycle's run.
    fn step(&mut self, link: &Link<'_>, io: &mut Io, common: &mut Common<D::Params>) {
        let board = link.board;
        let me = board.slot(link.idx);
        let k = board.header().cycle.load(Ordering::Acquire);
        if k <= common.last_cycle || me.expected_cycle.load(Ordering::Acquire) != k {
            return;
        }
        let ctx_name = common.name.clone();
        if self.sampled < k {
            self.sampled = k;
            let start = now_ns();
            me.last_start_ns.store(start, Ordering::Relaxed);
            let status = {
                let mut out = <D::Outputs<'_> as OutputSet<'_>>::bind(&mut io.outputs);
                let ctx = Ctx {
                    params: &common.params,
                    cycle: k,
                    name: &ctx_name,
                };
                let device = &mut self.device;
                guarded(k, || device.sample(&ctx, &mut out))
            };
            let header = SampleHeader {
                cycle: k,
                stamp_ns: now_ns(),
                slot: link.idx as u32,
                reserved: 0,
            };
            let mask = commit_outputs(&mut io.outputs, status, header);
            me.published_mask.store(mask, Ordering::Relaxed);
        }
        // Who may still propose in this cycle? A proposer is settled once its proposal for k
        // is in, or it finished k without proposing (it then wakes us), or it was cancelled.
        let mut channels: Vec<Vec<(u32, i32, String)>> = Vec::new();
        for c in 0..io.inputs.len().min(MAX_CHANNELS) {
            let mask = me.channel_proposers[c].load(Ordering::Acquire);
            let mut cands = Vec::new();
            for s in (0..MAX_SLOTS).filter(|s| mask & (1 << s) != 0) {
                let p = board.slot(s);
                if p.expected_cycle.load(Ordering::Acquire) != k {
                    continue;
                }
                let proposed = io.inputs[c]
                    .as_channel()
                    .is_some_and(|ch| ch.has_proposal(s as u32, k));
                let done = proposed
                    || p.done_cycle.load(Ordering::Acquire) == k
                    || p.cancelled_cycle.load(Ordering::Acquire) == k;
                if !done {
                    return;
                }
                let generation = p.generation.load(Ordering::Acquire);
                let name = match self.names.get(&(s as u32)) {
                    Some((g, n)) if *g == generation => n.clone(),
                    _ => {
                        let n = postcard::from_bytes::<SkillDecl>(&p.read_decl())
                            .map(|d| d.name)
                            .unwrap_or_else(|_| format!("slot{s}"));
                        self.names.insert(s as u32, (generation, n.clone()));
                        n
                    }
                };
                cands.push((s as u32, p.priority.load(Ordering::Acquire), name));
            }
            channels.push(cands);
        }
        // A proposer publishes its proposal before it marks its run done, but the proposal
        // may have landed after the poll of this wake-up: receive again now that everyone has
        // settled, or a proposal made in time would count as none.
        for i in io.inputs.iter_mut() {
            if let Err(e) = i.poll() {
                tracing::warn!(cycle = k, error = %e, "proposals not received");
            }
        }
        let start = now_ns();
        for (c, cands) in channels.iter().enumerate() {
            let Some(ch) = io.inputs[c].as_channel() else {
                continue;
            };
            let list: Vec<Candidate<'_>> = cands
                .iter()
                .map(|(slot, priority, name)| Candidate {
                    slot: *slot,
                    priority: *priority,
                    name,
                })
                .collect();
            let arb = ch.arbitrate(k, &list);
            me.channel_winner[c].store(arb.winner.map_or(0, |w| w + 1), Ordering::Relaxed);
            me.channel_mask[c].store(
                arb.weights.iter().fold(0u64, |m, (s, _)| m | (1 << s)),
                Ordering::Relaxed,
            );
            me.channel_cycle[c].store(k, Ordering::Release);
        }
        let status = {
            let src = RuntimeInputs {
                inputs: &io.inputs,
                cycle: k,
            };
            match <D::Commands<'_> as InputSet<'_>>::fetch(&src) {
                None => RunStatus::Skipped,
                Some(cmds) => {
                    let ctx = Ctx {
                        params: &common.params,
                        cycle: k,
                        name: &ctx_name,
                    };
                    let device = &mut self.device;
                    guarded(k, || device.command(&ctx, cmds))
                }
            }
        };
        let header = SampleHeader {
            cycle: k,
            stamp_ns: now_ns(),
            slot: link.idx as u32,
            reserved: 0,
        };
        for i in io.inputs.iter_mut() {
            if let Some(ch) = i.as_channel()
                && let Err(e) = ch.publish(header)
            {
                tracing::warn!(cycle = k, error = %e, "command not published");
            }
        }
        let end = now_ns();
        common.last_cycle = k;
        let mask = me.published_mask.load(Ordering::Relaxed);
        finish_run(
            link,
            RunRecord {
                k,
                status,
                mask,
                outputs: io.outputs.len(),
                start,
                end,
                sync: true,
            },
        );
    }
}
