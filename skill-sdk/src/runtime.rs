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
use crate::board::{Board, MAX_SLOTS, RunStatus, SlotState};
use crate::decl::{Mode, SkillDecl};
use crate::domain::{DOMAIN_ENV, Domain};
use crate::header::{SampleHeader, now_ns};
use crate::names;
use crate::params::Params;
use crate::ports::{
    ErasedInput, ErasedOutput, InputMeta, InputSet, InputSource, OutputSet, PortMaker,
};
use crate::services;
use crate::skill::{Ctx, Skill};
use clap::Parser;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use std::any::Any;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// How often a waiting or idle skill checks that its manager is still there.
const LIVENESS_TICK: Duration = Duration::from_millis(100);
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
    /// Wire a port to another topic (repeatable).
    #[arg(long = "remap", value_name = "PORT=TOPIC")]
    pub remaps: Vec<String>,
}

/// A skill binary's whole `main`: `fn main() -> ExitCode { skill_sdk::main::<MySkill>() }`.
pub fn main<S: Skill>() -> ExitCode {
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
    match run::<S>(args, &kind) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{kind}: error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Installs the tracing subscriber (`RUST_LOG`, default `info`) and quiets iceoryx2's own
/// logger to errors (`IOX2_LOG_LEVEL` overrides).
pub fn init_tracing() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    use std::io::IsTerminal;
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .try_init();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
}

/// Builds the declaration of skill `S` from its arguments.
pub fn declare<S: Skill>(args: &SkillArgs, kind: &str) -> Result<(SkillDecl, S::Params), SdkError> {
    let name = args.name.clone().unwrap_or_else(|| kind.to_string());
    names::check_name("skill", &name, false)?;
    let mut params = S::Params::default();
    for a in &args.params {
        params.assign(a)?;
    }
    let mut inputs = <S::Inputs<'static> as InputSet<'static>>::ports();
    let mut outputs = <S::Outputs<'static> as OutputSet<'static>>::ports();
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
            p.topic = topic.to_string();
            found = true;
        }
        if !found {
            return Err(SdkError::UnknownPort {
                port: port.to_string(),
            });
        }
    }
    let decl = SkillDecl {
        name,
        kind: kind.to_string(),
        mode: S::MODE,
        priority: args.priority.unwrap_or(S::PRIORITY),
        start_active: !args.inactive,
        pid: std::process::id(),
        inputs,
        outputs,
        params: S::Params::specs(),
        param_values: params.values(),
    };
    Ok((decl, params))
}

/// Runs skill `S` until SIGINT/SIGTERM.
pub fn run<S: Skill>(args: SkillArgs, kind: &str) -> Result<(), SdkError> {
    let (decl, params) = declare::<S>(&args, kind)?;
    let domain = Domain::new(&args.domain)?;
    let span = tracing::info_span!("skill", name = %decl.name, domain = %domain);
    let _enter = span.enter();
    let node = services::node(&domain, &decl.name)?;
    let trigger = services::listener(&node, &names::skill_trigger(&decl.name))?;
    let wake = services::notifier(&node, &names::manager_wake())?;

    let mut ports: Option<Ports> = None;
    let listeners = decl
        .inputs
        .iter()
        .map(|p| services::listener(&node, &names::topic(&p.topic)))
        .collect::<Result<Vec<_>, _>>()?;
    let mut state = State::<S> {
        skill: S::default(),
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
        decl.param_values = state.params.values();
        let encoded = postcard::to_allocvec(&decl)?;
        let idx = match register(&node, &board, &decl, &encoded, &trigger, &wake)? {
            Registration::Accepted(idx) => idx,
            Registration::ManagerGone => continue,
            Registration::Terminated => return Ok(()),
        };
        tracing::info!(slot = idx, "registered");
        if ports.is_none() {
            let topics = |p: &[crate::decl::PortDecl]| p.iter().map(|p| p.topic.clone()).collect();
            let ins = <S::Inputs<'static> as InputSet<'static>>::make(&PortMaker {
                node: Some(&node),
                topics: topics(&decl.inputs),
            })?;
            let outs = <S::Outputs<'static> as OutputSet<'static>>::make(&PortMaker {
                node: Some(&node),
                topics: topics(&decl.outputs),
            })?;
            ports = Some((ins, outs));
        }
        let Some((inputs, outputs)) = ports.as_mut() else {
            continue;
        };
        if !board
            .slot(idx)
            .transition(SlotState::Accepted, SlotState::Ready)
        {
            continue;
        }
        let _ = wake.notify();
        state.last_cycle = 0;
        state.param_gen = 0;
        let link = Link {
            board: &board,
            idx,
            trigger: &trigger,
            listeners: &listeners,
            wake: &wake,
        };
        match serve(&link, inputs, outputs, &mut state)? {
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

/// A skill's runtime input and output ports, opened once and kept across managers.
type Ports = (Vec<Box<dyn ErasedInput>>, Vec<ErasedOutput>);

/// What a registered skill uses to talk to its manager.
struct Link<'a> {
    board: &'a Board,
    idx: usize,
    trigger: &'a Listener<ipc::Service>,
    listeners: &'a [Listener<ipc::Service>],
    wake: &'a Notifier<ipc::Service>,
}

struct State<S: Skill> {
    skill: S,
    params: S::Params,
    /// Generation of the last parameter snapshot applied.
    param_gen: u64,
    /// Last cycle this skill ran (or skipped) for.
    last_cycle: u64,
    name: String,
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
    node.wait(Duration::ZERO).is_err()
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
        return Err(e);
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
            },
        ))
    }
}

fn serve<S: Skill>(
    link: &Link<'_>,
    inputs: &mut [Box<dyn ErasedInput>],
    outputs: &mut [ErasedOutput],
    state: &mut State<S>,
) -> Result<End, SdkError> {
    let Link {
        board,
        idx,
        trigger,
        listeners,
        ..
    } = *link;
    let transport = |what: &str, e: &dyn std::fmt::Debug| SdkError::Transport {
        what: what.to_string(),
        detail: format!("{e:?}"),
    };
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(|e| transport("create waitset", &e))?;
    let _trigger_guard = waitset
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
        let result = waitset
            .wait_and_process_once(|id| {
                if id.has_event_from(&tick) {
                    ticked = true;
                }
                CallbackProgression::Continue
            })
            .map_err(|e| transport("wait", &e))?;
        if matches!(
            result,
            WaitSetRunResult::Interrupt | WaitSetRunResult::TerminationRequest
        ) {
            return Ok(End::Terminated);
        }
        let _ = trigger.try_wait(|_| {});
        for l in listeners {
            let _ = l.try_wait(|_| {});
        }
        for i in inputs.iter_mut() {
            i.poll()?;
        }
        if ticked
            && (!board.manager_alive()
                || slot.state() != SlotState::Ready
                || slot.pid.load(Ordering::Acquire) != me)
        {
            return Ok(End::ManagerGone);
        }
        step(link, inputs, outputs, state);
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

/// Runs the skill if it is due; see the module docs for when that is.
fn step<S: Skill>(
    link: &Link<'_>,
    inputs: &mut [Box<dyn ErasedInput>],
    outputs: &mut [ErasedOutput],
    state: &mut State<S>,
) {
    let (board, wake) = (link.board, link.wake);
    let slot = board.slot(link.idx);
    if let Some((generation, bytes)) = slot.read_params(state.param_gen) {
        state.param_gen = generation;
        apply_params(&mut state.params, &bytes);
    }
    if slot.active.load(Ordering::Acquire) == 0 {
        return;
    }
    let k = board.header().cycle.load(Ordering::Acquire);
    let due = match S::MODE {
        Mode::Sync => {
            let fresh = slot.fresh_mask.load(Ordering::Acquire);
            k > state.last_cycle
                && slot.expected_cycle.load(Ordering::Acquire) == k
                && inputs.iter().enumerate().all(|(i, p)| {
                    fresh & (1 << i) == 0 || p.latest_header().is_some_and(|h| h.cycle == k)
                })
        }
        Mode::Async if inputs.is_empty() => k > state.last_cycle,
        Mode::Async => inputs.iter().any(|p| p.is_fresh()),
    };
    if !due {
        return;
    }
    let start = now_ns();
    slot.last_start_ns.store(start, Ordering::Relaxed);
    let status = {
        let src = RuntimeInputs { inputs, cycle: k };
        match <S::Inputs<'_> as InputSet<'_>>::fetch(&src) {
            None => RunStatus::Skipped,
            Some(input) => {
                let mut out = <S::Outputs<'_> as OutputSet<'_>>::bind(outputs);
                let ctx = Ctx {
                    params: &state.params,
                    cycle: k,
                    name: &state.name,
                };
                let skill = &mut state.skill;
                match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    skill.compute(&ctx, input, &mut out)
                })) {
                    Ok(Ok(())) => RunStatus::Ok,
                    Ok(Err(e)) => {
                        tracing::warn!(cycle = k, error = %e, "run failed");
                        RunStatus::Failed
                    }
                    Err(_) => {
                        tracing::error!(cycle = k, "run panicked");
                        RunStatus::Failed
                    }
                }
            }
        }
    };
    let end = now_ns();
    let mut mask = 0u64;
    let header = SampleHeader {
        cycle: k,
        stamp_ns: end,
    };
    for (i, o) in outputs.iter_mut().enumerate() {
        if status != RunStatus::Ok {
            o.discard();
            continue;
        }
        match o.commit(header) {
            Ok(true) => mask |= 1 << i,
            Ok(false) => {}
            Err(e) => tracing::warn!(cycle = k, error = %e, "publish failed"),
        }
    }
    for i in inputs.iter_mut() {
        i.consume();
    }
    state.last_cycle = k;
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
    if S::MODE == Mode::Sync {
        let all = if outputs.len() >= 64 {
            u64::MAX
        } else {
            (1u64 << outputs.len()) - 1
        };
        let finished = board.complete(k, 1);
        if finished || status != RunStatus::Ok || mask != all {
            let _ = wake.notify();
        }
    }
}
