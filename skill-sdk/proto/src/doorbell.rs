//! Doorbells: how fabric processes wake each other. A doorbell is a pair of words on the cycle
//! board: a ring counter that waiters block on with `FUTEX_WAIT` (a process-shared futex, the
//! least a cross-process wake-up costs on Linux) and a count of sleepers, so a ring costs a
//! system call only when somebody is actually asleep.
//!
//! Every unit has one in its slot (rung by the manager at cycle start and by the producers of
//! its inputs), the manager one in the header (rung by the run that ends a cycle, by
//! registrations and by its control thread). iceoryx2's event services stay beside them for
//! readers outside the fabric: a producer still notifies its topic's event service, which costs
//! nothing when no outside listener is attached.
//!
//! Protocol: a waiter reads [`Doorbell::seen`] *before* it looks for work, and sleeps with
//! [`Doorbell::wait`] on that value only when it found none; a ring after the read makes the
//! wait return at once. The sleeper count and the counter are both sequentially consistent,
//! so either the ringer sees the sleeper (and wakes it) or the sleeper sees the ring (and does
//! not sleep).

use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

/// A process-shared wake-up word with its sleeper count. Lives in shared memory (all zeros is
/// a valid, unrung doorbell).
#[repr(C)]
#[derive(Debug, Default)]
pub struct Doorbell {
    rings: AtomicU32,
    sleepers: AtomicU32,
}

/// How a [`Doorbell::wait`] ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// Rung (or a spurious wake-up: look for work again either way).
    Rung,
    /// The timeout passed without a ring.
    TimedOut,
    /// A signal handler ran (SIGTERM/SIGINT, or one to ignore).
    Interrupted,
}

impl Doorbell {
    /// The ring count now; pass it to [`Doorbell::wait`] after looking for work.
    pub fn seen(&self) -> u32 {
        self.rings.load(Ordering::SeqCst)
    }

    /// Rings: the waiter's next (or current) wait returns.
    pub fn ring(&self) {
        self.rings.fetch_add(1, Ordering::SeqCst);
        if self.sleepers.load(Ordering::SeqCst) != 0 {
            futex_wake(&self.rings);
        }
    }

    /// Sleeps until the doorbell was rung after `seen` was read, `timeout` passes, or a
    /// signal arrives.
    pub fn wait(&self, seen: u32, timeout: Duration) -> Wake {
        self.sleepers.fetch_add(1, Ordering::SeqCst);
        let wake = if self.rings.load(Ordering::SeqCst) != seen {
            Wake::Rung
        } else {
            futex_wait(&self.rings, seen, timeout)
        };
        self.sleepers.fetch_sub(1, Ordering::SeqCst);
        wake
    }
}

/// `FUTEX_WAIT` on a shared word (not `FUTEX_PRIVATE_FLAG`: the word is in a mapping other
/// processes share).
fn futex_wait(word: &AtomicU32, seen: u32, timeout: Duration) -> Wake {
    let ts = nix::libc::timespec {
        tv_sec: timeout.as_secs().min(i32::MAX as u64) as nix::libc::time_t,
        tv_nsec: timeout.subsec_nanos() as nix::libc::c_long,
    };
    // SAFETY: a futex wait on a live, aligned u32 with a valid relative timeout; the kernel
    // only reads the word.
    let r = unsafe {
        nix::libc::syscall(
            nix::libc::SYS_futex,
            word.as_ptr(),
            nix::libc::FUTEX_WAIT,
            seen,
            &ts as *const nix::libc::timespec,
            std::ptr::null::<u32>(),
            0,
        )
    };
    if r == 0 {
        return Wake::Rung;
    }
    match nix::errno::Errno::last() {
        nix::errno::Errno::ETIMEDOUT => Wake::TimedOut,
        nix::errno::Errno::EINTR => Wake::Interrupted,
        // EAGAIN: the word had changed already.
        _ => Wake::Rung,
    }
}

/// `FUTEX_WAKE` of every waiter on a shared word.
fn futex_wake(word: &AtomicU32) {
    // SAFETY: a futex wake on a live, aligned u32; the kernel does not touch the word.
    unsafe {
        nix::libc::syscall(
            nix::libc::SYS_futex,
            word.as_ptr(),
            nix::libc::FUTEX_WAKE,
            i32::MAX,
            std::ptr::null::<nix::libc::timespec>(),
            std::ptr::null::<u32>(),
            0,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::time::Instant;

    #[test]
    fn a_ring_before_the_wait_is_not_lost() {
        let bell = Doorbell::default();
        let seen = bell.seen();
        bell.ring();
        assert_eq!(bell.wait(seen, Duration::from_secs(5)), Wake::Rung);
    }

    #[test]
    fn an_unrung_bell_times_out() {
        let bell = Doorbell::default();
        let t = Instant::now();
        assert_eq!(
            bell.wait(bell.seen(), Duration::from_millis(20)),
            Wake::TimedOut
        );
        assert!(t.elapsed() >= Duration::from_millis(20));
    }

    #[test]
    fn a_ring_wakes_a_sleeper_in_another_thread() {
        let bell = Arc::new(Doorbell::default());
        let seen = bell.seen();
        let b = bell.clone();
        let waiter = std::thread::spawn(move || {
            // Loop as a unit does: a spurious wake-up looks again.
            while b.seen() == seen {
                if b.wait(seen, Duration::from_secs(10)) == Wake::TimedOut {
                    return false;
                }
            }
            true
        });
        while bell.sleepers.load(Ordering::SeqCst) == 0 && !waiter.is_finished() {
            std::thread::yield_now();
        }
        bell.ring();
        assert!(waiter.join().is_ok_and(|woken| woken));
    }
}
