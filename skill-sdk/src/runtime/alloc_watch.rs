//! The allocations of a unit's cycle path, counted: what its thread allocates from the moment
//! a wake-up starts looking for work (inputs received) to the moment it sleeps again (the run's
//! outputs sent, its consumers woken, the next run's samples loaned), attributed to the run
//! that wake-up (or the ones before it) led to, and added to the slot's `cycle_allocs`.
//!
//! Not counted:
//! - the allocations inside iceoryx2's loans ([`crate::allocs::in_loan`]: one per loaned
//!   sample, its bookkeeping; no use of its API avoids it), counted apart and logged at debug
//!   level with the warm-up's;
//! - the first [`WARM_UP_RUNS`] runs after a registration: first loans, first receives and
//!   lazily made caches allocate once (their count is logged at debug level);
//! - a wake-up that applied new parameter values or ran the liveness check (once a second):
//!   control-plane work that happens to share the thread, not the cycle's;
//! - the log line a warning writes (after the count is read).
//!
//! Counted, and worth knowing: a reader that joins or leaves one of the unit's topics (a new
//! skill, a `ctl query`, the console showing a port) makes the unit's next send update its
//! connections, which allocates, once per change.
//!
//! In real-time mode a run that allocated after the warm-up is a warning naming the count and
//! the cycle, at most one per [`WARN_EVERY`].

use crate::allocs::{thread_allocs, thread_loan_allocs};
use crate::board::Slot;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// Runs after a registration whose allocations are not counted. Measured with the shipped
/// skills (ticker, relay, scale, smooth): the first run allocates, 20 to 70 times (first
/// receives, iceoryx2's connections to the readers, the log's first-event caches), the ones
/// after it not at all; ten leave room for a run or two more in other units.
pub(super) const WARM_UP_RUNS: u64 = 10;
/// Least time between two warnings about allocating runs.
const WARN_EVERY: Duration = Duration::from_secs(10);

/// A unit's count of its cycle path's allocations, per registration.
pub(crate) struct AllocWatch {
    /// Real-time mode was asked for: an allocating run is a warning.
    realtime: bool,
    /// The thread's allocation count, and that of its loans, when this wake-up began
    /// (`None`: not counted).
    mark: Option<(u64, u64)>,
    /// This wake-up did control-plane work: its allocations are not the cycle's.
    skip: bool,
    /// Allocations of the wake-ups since the last finished run.
    pending: u64,
    /// Finished runs (completed, failed or skipped) the slot showed at the last look.
    finished: u64,
    /// Runs finished since the registration.
    since_registration: u64,
    /// Allocations of the warm-up runs.
    warm_up: u64,
    /// Allocations inside loans since the registration.
    loans: u64,
    /// When the last warning was logged.
    warned_at: Option<Instant>,
}

impl AllocWatch {
    pub(crate) fn new(realtime: bool) -> AllocWatch {
        AllocWatch {
            realtime,
            mark: None,
            skip: false,
            pending: 0,
            finished: 0,
            since_registration: 0,
            warm_up: 0,
            loans: 0,
            warned_at: None,
        }
    }

    /// A new registration in `slot`: counting starts again with a warm-up.
    pub(crate) fn restart(&mut self, slot: &Slot) {
        *self = AllocWatch {
            finished: finished_runs(slot),
            ..AllocWatch::new(self.realtime)
        };
        if thread_allocs().is_some() {
            slot.cycle_allocs.start(Ordering::Release);
        }
    }

    /// A wake-up begins (before its inputs are received).
    pub(crate) fn begin(&mut self) {
        self.mark = thread_allocs().zip(thread_loan_allocs());
        self.skip = false;
    }

    /// This wake-up does control-plane work (parameters, liveness): it is not counted.
    pub(crate) fn skip(&mut self) {
        self.skip = true;
    }

    /// The wake-up is done (before the unit sleeps): its allocations go to the runs it
    /// finished, if any, else they wait for the next one.
    pub(crate) fn end(&mut self, slot: &Slot) {
        let (Some((mark, loan_mark)), Some(now), Some(loans)) =
            (self.mark.take(), thread_allocs(), thread_loan_allocs())
        else {
            return;
        };
        let in_loans = loans.wrapping_sub(loan_mark);
        self.loans += in_loans;
        if !self.skip {
            self.pending += now.wrapping_sub(mark).wrapping_sub(in_loans);
        }
        let finished = finished_runs(slot);
        if finished == self.finished {
            return;
        }
        let before = self.since_registration;
        self.since_registration += finished.wrapping_sub(self.finished);
        self.finished = finished;
        let allocs = std::mem::take(&mut self.pending);
        if before < WARM_UP_RUNS {
            self.warm_up += allocs;
            if self.since_registration >= WARM_UP_RUNS {
                tracing::debug!(
                    allocations = self.warm_up,
                    in_loans = self.loans,
                    runs = WARM_UP_RUNS,
                    "warm-up done: allocations on the cycle's path are counted from now on"
                );
            }
            return;
        }
        if allocs == 0 {
            return;
        }
        slot.cycle_allocs.add(allocs, Ordering::Relaxed);
        if self.realtime && self.warned_at.is_none_or(|t| t.elapsed() >= WARN_EVERY) {
            self.warned_at = Some(Instant::now());
            tracing::warn!(
                allocations = allocs,
                cycle = slot.done_cycle.load(Ordering::Relaxed),
                total = slot.cycle_allocs.load(Ordering::Relaxed).unwrap_or(0),
                "a run allocated on the cycle's path in real-time mode (said at most every {} s)",
                WARN_EVERY.as_secs()
            );
        }
    }
}

/// Runs the slot counts as finished: completed, failed and skipped.
fn finished_runs(slot: &Slot) -> u64 {
    slot.runs.load(Ordering::Relaxed)
        + slot.failures.load(Ordering::Relaxed)
        + slot.skips.load(Ordering::Relaxed)
}
