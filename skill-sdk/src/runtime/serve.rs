//! Waiting for the manager, registering, and the wait loop of a registered unit.

use super::{BOARD_POLL, Common, Io, LIVENESS_TICK, Unit};
use crate::SdkError;
use crate::board::{Board, MAX_SLOTS, SlotState};
use crate::decl::SkillDecl;
use crate::domain::Domain;
use crate::params::Params;
use crate::services;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use std::sync::atomic::Ordering;

/// What a registered unit uses to talk to its manager.
pub(crate) struct Link<'a> {
    pub(super) node: &'a Node<ipc::Service>,
    pub(crate) board: &'a Board,
    pub(crate) idx: usize,
    pub(super) trigger: &'a Listener<ipc::Service>,
    pub(super) listeners: &'a [Listener<ipc::Service>],
    pub(crate) wake: &'a Notifier<ipc::Service>,
}

pub(super) enum Registration {
    Accepted(usize),
    ManagerGone,
    Terminated,
}

pub(super) enum End {
    Terminated,
    ManagerGone,
}

fn terminated(node: &Node<ipc::Service>) -> bool {
    services::termination_requested(node)
}

pub(super) fn wait_for_board(
    node: &Node<ipc::Service>,
    domain: &Domain,
) -> Result<Option<Board>, SdkError> {
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

pub(super) fn register(
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

pub(super) fn serve<U: Unit>(
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
