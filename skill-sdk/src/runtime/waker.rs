//! Waking a registered unit from another thread: a gateway (`skillfab bridge`) receives
//! samples on its own threads and has its async unit publish them at once, not at the next
//! cycle.

use crate::board::Board;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// A handle that makes the unit run now (an async unit with a waker runs when woken, and
/// only then). Cheap to clone; `Send` and `Sync`.
#[derive(Clone, Default)]
pub struct Waker(Arc<State>);

#[derive(Default)]
struct State {
    pending: AtomicBool,
    /// The board and slot of the current registration (none between registrations).
    at: Mutex<Option<(Arc<Board>, usize)>>,
}

impl std::fmt::Debug for Waker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Waker")
            .field("pending", &self.0.pending.load(Ordering::Relaxed))
            .finish()
    }
}

impl Waker {
    /// Marks a run due and rings the unit's doorbell.
    pub fn wake(&self) {
        self.0.pending.store(true, Ordering::Release);
        if let Ok(at) = self.0.at.lock()
            && let Some((board, idx)) = at.as_ref()
        {
            board.slot(*idx).bell.ring();
        }
    }

    /// Whether a wake came since the last call (and forgets it).
    pub(crate) fn take(&self) -> bool {
        self.0.pending.swap(false, Ordering::AcqRel)
    }

    /// Rings this board's slot from now on (`None`: the registration ended).
    pub(crate) fn attach(&self, at: Option<(Arc<Board>, usize)>) {
        if let Ok(mut slot) = self.0.at.lock() {
            *slot = at;
        }
    }
}
