//! Counting allocations per thread: the check that a cycle's path does not allocate.
//!
//! With the `count-allocs` feature (on by default) the SDK is the program's global allocator:
//! [`std::alloc::System`] behind a per-thread counter of allocations (`alloc`, `alloc_zeroed`
//! and `realloc`; frees are not counted). The counter is a `const` thread-local `Cell`, so
//! counting takes no lock, makes no system call and never allocates itself. The runtime reads
//! it around each wake-up of a unit and publishes what its cycle's path allocated on the board
//! (`ctl stats`, the console); see docs/realtime.md.
//!
//! A program has one global allocator: one that wants its own (jemalloc, mimalloc) builds the
//! SDK with `default-features = false`, and its skills' allocations then read as not counted.
//! Counted are the allocations through Rust's allocator: the runtime's and a Rust body's; a C,
//! C++ or Python body's own `malloc` is not seen.

/// Allocations made by the calling thread so far; `None` when the SDK was built without the
/// `count-allocs` feature.
pub fn thread_allocs() -> Option<u64> {
    imp::thread_allocs()
}

/// Of [`thread_allocs`], those made inside iceoryx2's loans ([`in_loan`]).
pub fn thread_loan_allocs() -> Option<u64> {
    imp::thread_loan_allocs()
}

/// Runs `loan`, a loan of an iceoryx2 sample, and books the allocations it makes as the
/// transport's. iceoryx2 0.10 allocates its sample's bookkeeping (one small block, an `Rc` of
/// the chunk's shared state) on every loan, whichever of its publisher calls loans: no use of
/// its API avoids it, and in a steady state the block freed by the last send is the next
/// loan's (glibc's per-thread cache: no lock, no system call). The runtime counts these apart
/// from the cycle path's other allocations (docs/realtime.md; the one-per-loan is checked by
/// the tests).
pub(crate) fn in_loan<R>(loan: impl FnOnce() -> R) -> R {
    let before = thread_allocs();
    let r = loan();
    if let (Some(before), Some(after)) = (before, thread_allocs()) {
        imp::add_loan_allocs(after.wrapping_sub(before));
    }
    r
}

#[cfg(feature = "count-allocs")]
mod imp {
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;

    thread_local! {
        /// This thread's allocations. `const`-initialised and without a destructor: reading
        /// or bumping it never allocates and works in any thread state.
        static ALLOCS: Cell<u64> = const { Cell::new(0) };
    }

    #[cfg_attr(test, allow(dead_code))]
    fn count() {
        let _ = ALLOCS.try_with(|c| c.set(c.get().wrapping_add(1)));
    }

    pub(super) fn thread_allocs() -> Option<u64> {
        ALLOCS.try_with(Cell::get).ok()
    }

    thread_local! {
        /// Of this thread's allocations, those made inside iceoryx2's loans.
        static LOAN_ALLOCS: Cell<u64> = const { Cell::new(0) };
    }

    pub(super) fn thread_loan_allocs() -> Option<u64> {
        LOAN_ALLOCS.try_with(Cell::get).ok()
    }

    pub(super) fn add_loan_allocs(n: u64) {
        let _ = LOAN_ALLOCS.try_with(|c| c.set(c.get().wrapping_add(n)));
    }

    /// The system allocator, counted.
    // (Not the allocator of this crate's own unit tests: they link a second copy of the SDK,
    // through skillfab-msgs, whose allocator it would collide with; the counting is tested in
    // tests/allocs.rs.)
    #[cfg_attr(test, allow(dead_code))]
    struct Counting;

    // SAFETY: every call is passed on unchanged to `System`, which upholds GlobalAlloc's
    // contract; the counting touches only a thread-local integer.
    unsafe impl GlobalAlloc for Counting {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            count();
            // SAFETY: the caller's contract, passed on.
            unsafe { System.alloc(layout) }
        }

        unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
            count();
            // SAFETY: the caller's contract, passed on.
            unsafe { System.alloc_zeroed(layout) }
        }

        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            count();
            // SAFETY: the caller's contract, passed on.
            unsafe { System.realloc(ptr, layout, new_size) }
        }

        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            // SAFETY: the caller's contract, passed on.
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    #[cfg(not(test))]
    #[global_allocator]
    static GLOBAL: Counting = Counting;
}

#[cfg(not(feature = "count-allocs"))]
mod imp {
    pub(super) fn thread_allocs() -> Option<u64> {
        None
    }

    pub(super) fn thread_loan_allocs() -> Option<u64> {
        None
    }

    pub(super) fn add_loan_allocs(_: u64) {}
}
