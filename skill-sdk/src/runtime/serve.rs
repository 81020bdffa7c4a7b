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
use skillfab_proto::header::now_ns;
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
        common.allocs.begin();
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
            common.allocs.skip();
            if !board.manager_alive()
                || slot.state() != SlotState::Ready
                || slot.pid.load(Ordering::Acquire) != me
            {
                return Ok(End::ManagerGone);
            }
        }
        if let Some((generation, bytes)) = slot.read_params(common.param_gen) {
            common.param_gen = generation;
            common.allocs.skip();
            apply_params(&mut common.params, &bytes);
        }
        if slot.active.load(Ordering::Acquire) != 0 {
            unit.step(link, io, common);
        }
        // The next run's samples, loaned while nothing waits for this unit.
        for o in io.outputs.iter_mut() {
            o.prepare();
        }
        common.allocs.end(slot);
        // A signal during the wait ends it (EINTR) and the next check sees it; one that lands
        // in the few instructions between this check and the wait is seen within a tick.
        if services::termination_requested() {
            return Ok(End::Terminated);
        }
        if common.spin_ns != 0 && spin(board, idx, seen, common.spin_ns) {
            continue;
        }
        slot.bell
            .wait(seen, next_tick.saturating_duration_since(Instant::now()));
    }
}

/// How many polls of the doorbell between two looks at the clock (a poll is a load and a
/// pause: ~10–40 ns).
const POLLS_PER_CLOCK: u32 = 64;

/// Spin mode: while this unit is expected in the running cycle and has not finished it, polls
/// its doorbell instead of sleeping, until `spin_ns` after the cycle's start. True when the
/// doorbell was rung (look for work again); false when there is nothing to spin for or the
/// budget ran out (sleep on the doorbell: a ring after `seen` still ends that sleep at once).
///
/// The CPU is yielded between polls (`sched_yield`), so a spinner shares its core with a
/// runnable process of the fabric (its producer, on a machine with fewer cores than
/// processes) instead of holding it until its budget ends.
fn spin(board: &Board, idx: usize, seen: u32, spin_ns: u64) -> bool {
    let slot = board.slot(idx);
    let h = board.header();
    let k = h.cycle.load(Ordering::Acquire);
    if slot.expected_cycle.load(Ordering::Acquire) != k
        || slot.done_cycle.load(Ordering::Acquire) == k
        || slot.cancelled_cycle.load(Ordering::Acquire) == k
    {
        return false;
    }
    let until = h
        .cycle_start_ns
        .load(Ordering::Acquire)
        .saturating_add(spin_ns);
    loop {
        for _ in 0..POLLS_PER_CLOCK {
            if slot.bell.seen() != seen {
                return true;
            }
            std::hint::spin_loop();
        }
        if now_ns() >= until
            || services::termination_requested()
            || slot.cancelled_cycle.load(Ordering::Acquire) == k
        {
            return slot.bell.seen() != seen;
        }
        std::thread::yield_now();
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use std::sync::Arc;
    use std::time::Duration;

    /// A board whose cycle 5 started now and expects slot 0.
    fn board(tag: &str) -> Arc<Board> {
        let prefix = format!("sf_unit-spin-{tag}-{}_", std::process::id());
        let b = Board::create(&prefix).unwrap();
        b.slot(0).expected_cycle.store(5, Ordering::Release);
        b.header().cycle_start_ns.store(now_ns(), Ordering::Release);
        b.header().cycle.store(5, Ordering::Release);
        Arc::new(b)
    }

    #[test]
    fn a_ring_during_the_spin_ends_it_without_a_sleep() {
        let b = board("ring");
        let seen = b.slot(0).bell.seen();
        let ringer = {
            let b = b.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(2));
                b.slot(0).bell.ring();
            })
        };
        let t = Instant::now();
        assert!(spin(&b, 0, seen, 5_000_000_000), "rung while spinning");
        assert!(t.elapsed() < Duration::from_secs(4), "{:?}", t.elapsed());
        ringer.join().unwrap();
    }

    #[test]
    fn the_budget_counts_from_the_cycles_start() {
        let b = board("budget");
        let seen = b.slot(0).bell.seen();
        let t = Instant::now();
        assert!(!spin(&b, 0, seen, 3_000_000), "no ring: the budget ends it");
        let spun = t.elapsed();
        assert!(spun >= Duration::from_micros(2_500), "{spun:?}");
        // Past the budget already: no spin at all.
        let t = Instant::now();
        assert!(!spin(&b, 0, seen, 1_000));
        assert!(t.elapsed() < spun);
    }

    #[test]
    fn a_unit_not_expected_or_done_does_not_spin() {
        let b = board("idle");
        let seen = b.slot(0).bell.seen();
        let slot = b.slot(0);
        slot.done_cycle.store(5, Ordering::Release);
        assert!(!spin(&b, 0, seen, u64::MAX), "done in this cycle");
        slot.done_cycle.store(4, Ordering::Release);
        slot.cancelled_cycle.store(5, Ordering::Release);
        assert!(!spin(&b, 0, seen, u64::MAX), "cancelled in this cycle");
        slot.cancelled_cycle.store(0, Ordering::Release);
        slot.expected_cycle.store(4, Ordering::Release);
        assert!(!spin(&b, 0, seen, u64::MAX), "not expected in this cycle");
    }
}
