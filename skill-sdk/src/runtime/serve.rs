//! Waiting for the manager, registering, and the wait loop of a registered unit.

use super::{BOARD_POLL, Common, Io, LIVENESS_TICK, Unit};
use crate::SdkError;
use crate::board::{Board, MAX_SLOTS, SlotState};
use crate::decl::SkillDecl;
use crate::domain::Domain;
use crate::params::Params;
use crate::services;
use iceoryx2::node::Node;
use iceoryx2::prelude::*;
use skillfab_proto::registration::Refusal;
use std::sync::atomic::Ordering;
use std::time::Instant;

/// What a registered unit uses to talk to its manager.
pub(crate) struct Link<'a> {
    pub(crate) board: &'a Board,
    pub(crate) idx: usize,
}

impl Link<'_> {
    /// Rings the doorbells of output `o`'s consumers (after its sample was sent).
    pub(crate) fn wake_consumers(&self, o: usize) {
        if let Some(c) = self.board.slot(self.idx).consumers.get(o) {
            self.board.ring(c.load(Ordering::Acquire));
        }
    }
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
    board: &Board,
    decl: &SkillDecl,
    encoded: &[u8],
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
    board.ring_manager();
    loop {
        let seen = slot.bell.seen();
        match slot.state() {
            SlotState::Accepted => return Ok(Registration::Accepted(idx)),
            SlotState::Refused => {
                let reason = Box::new(Refusal::decode(&slot.read_msg()));
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
        if services::termination_requested() {
            slot.set_state(SlotState::Leaving);
            board.ring_manager();
            return Ok(Registration::Terminated);
        }
        slot.bell.wait(seen, BOARD_POLL);
    }
}

/// The wait loop of a registered unit: it sleeps on its slot's doorbell, which the manager
/// rings at cycle start and the producers of its inputs ring when they publish; on every
/// wake-up it receives its inputs, takes new parameter values, and runs if a run is due. Once
/// per liveness tick it checks that its manager still runs and still holds its slot.
pub(super) fn serve<U: Unit>(
    link: &Link<'_>,
    io: &mut Io,
    unit: &mut U,
    common: &mut Common<U::Params>,
) -> Result<End, SdkError> {
    let Link { board, idx } = *link;
    let slot = board.slot(idx);
    let me = std::process::id();
    let mut next_tick = Instant::now() + LIVENESS_TICK;
    loop {
        // Read before looking for work: a ring from here on ends the wait below at once.
        let seen = slot.bell.seen();
        for i in io.inputs.iter_mut() {
            i.poll()?;
        }
        for c in io.channels.iter_mut() {
            c.poll()?;
        }
        let now = Instant::now();
        // A closed board is checked at once: its manager left, or died and was replaced.
        if now >= next_tick || !board.is_open() {
            next_tick = now + LIVENESS_TICK;
            if !board.manager_alive()
                || slot.state() != SlotState::Ready
                || slot.pid.load(Ordering::Acquire) != me
            {
                return Ok(End::ManagerGone);
            }
        }
        if let Some((generation, bytes)) = slot.read_params(common.param_gen) {
            common.param_gen = generation;
            apply_params(&mut common.params, &bytes);
        }
        if slot.active.load(Ordering::Acquire) != 0 {
            unit.step(link, io, common);
        }
        // The next run's samples, loaned while nothing waits for this unit.
        for o in io.outputs.iter_mut() {
            o.prepare();
        }
        // A signal during the wait ends it (EINTR) and the next check sees it; one that lands
        // in the few instructions between this check and the wait is seen within a tick.
        if services::termination_requested() {
            return Ok(End::Terminated);
        }
        slot.bell
            .wait(seen, next_tick.saturating_duration_since(Instant::now()));
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
