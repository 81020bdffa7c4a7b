//! The futex floor: the least a cross-process wake-up costs on this kernel. Processes share
//! one page of POSIX shared memory; each waits with `FUTEX_WAIT` on its own word and is woken
//! with `FUTEX_WAKE` by the one before it — no socket, no pipe, no library in between.
//!
//! Layout of the page: `words[i]` is node i's sequence word (0: the driver), `stamps[i]` the
//! moment node i passed the token on (`CLOCK_MONOTONIC` ns). A token of round `seq` reaches
//! node i when `words[i]` becomes `seq`; a ring's last node sets `words[0]`, a star's nodes
//! each add one to `answers`.

use crate::floors::{Shape, Timing};
use nix::fcntl::OFlag;
use nix::sys::mman::{MapFlags, ProtFlags, mmap, shm_open, shm_unlink};
use nix::sys::stat::Mode;
use skillfab_proto::header::now_ns;
use skillfab_tests::TestDomain;
use std::num::NonZeroUsize;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Most participants (driver included).
const MAX: usize = 65;

#[repr(C)]
struct Page {
    words: [AtomicU32; MAX],
    stamps: [AtomicU64; MAX],
    /// A star's answers in the current round.
    answers: AtomicU32,
    /// Set by the driver when the nodes should exit.
    stop: AtomicU32,
}

/// The shared page, mapped.
struct Shared {
    page: NonNull<Page>,
}

// SAFETY: the page holds only atomics; every access goes through them.
unsafe impl Send for Shared {}

impl Shared {
    /// Creates (`create`) or opens the page called `name`.
    fn map(name: &str, create: bool) -> nix::Result<Shared> {
        let flags = if create {
            OFlag::O_CREAT | OFlag::O_EXCL | OFlag::O_RDWR
        } else {
            OFlag::O_RDWR
        };
        let fd = shm_open(name, flags, Mode::from_bits_truncate(0o600))?;
        let len = std::mem::size_of::<Page>();
        if create {
            nix::unistd::ftruncate(&fd, len as i64)?;
        }
        let len = NonZeroUsize::new(len).ok_or(nix::Error::EINVAL)?;
        // SAFETY: a fresh shared mapping of the whole object; the page outlives every use
        // (it is unmapped only when the process exits).
        let ptr = unsafe {
            mmap(
                None,
                len,
                ProtFlags::PROT_READ | ProtFlags::PROT_WRITE,
                MapFlags::MAP_SHARED,
                &fd,
                0,
            )?
        };
        Ok(Shared { page: ptr.cast() })
    }

    fn page(&self) -> &Page {
        // SAFETY: mapped for the life of the process, zero-initialised atomics.
        unsafe { self.page.as_ref() }
    }
}

/// Waits until `word` is no longer `seen` (or `timeout` passes); the futex is process-shared.
fn wait(word: &AtomicU32, seen: u32, timeout: Duration) {
    let ts = nix::libc::timespec {
        tv_sec: timeout.as_secs() as nix::libc::time_t,
        tv_nsec: timeout.subsec_nanos() as nix::libc::c_long,
    };
    // SAFETY: a futex wait on a live, aligned u32 of a shared mapping, with a valid timeout.
    unsafe {
        nix::libc::syscall(
            nix::libc::SYS_futex,
            word.as_ptr(),
            nix::libc::FUTEX_WAIT,
            seen,
            &ts as *const nix::libc::timespec,
            std::ptr::null::<u32>(),
            0,
        );
    }
}

/// Wakes every waiter on `word`.
fn wake(word: &AtomicU32) {
    // SAFETY: a futex wake on a live, aligned u32 of a shared mapping.
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

/// Passes the token of round `seq` to `to`: stamp, publish, wake.
fn pass(page: &Page, me: usize, to: usize, seq: u32) {
    page.stamps[me].store(now_ns(), Ordering::Release);
    page.words[to].store(seq, Ordering::Release);
    wake(&page.words[to]);
}

/// A running futex ring or star.
pub struct Futex {
    shape: Shape,
    shared: Shared,
    name: String,
    seq: u32,
    /// The nodes' indices in the fixture.
    nodes: Vec<usize>,
    // Last: kills the nodes and removes the domain's files.
    t: TestDomain,
}

impl Futex {
    /// Starts the nodes (`ring-node futex INDEX NEXT NAME ring|star`).
    pub fn start(shape: Shape) -> Futex {
        let mut t = TestDomain::new("futex");
        // In the domain's prefix, so the fixture removes it with the domain's files.
        let name = format!("/{}futex", t.domain.prefix());
        let shared = Shared::map(&name, true).expect("futex page");
        let n = match shape {
            Shape::Ring(d) | Shape::Star(d) => d,
        };
        assert!(n < MAX, "at most {} nodes", MAX - 1);
        let mut nodes = Vec::new();
        for i in 1..=n {
            let next = match shape {
                Shape::Ring(d) => (i + 1) % (d + 1),
                Shape::Star(_) => 0,
            };
            let mode = match shape {
                Shape::Ring(_) => "ring",
                Shape::Star(_) => "star",
            };
            nodes.push(t.spawn(
                "ring-node",
                &["futex", &i.to_string(), &next.to_string(), &name, mode],
            ));
        }
        Futex {
            shape,
            shared,
            name,
            seq: 0,
            nodes,
            t,
        }
    }

    fn round(&mut self) -> Timing {
        self.seq = self.seq.wrapping_add(1).max(1);
        let seq = self.seq;
        let page = self.shared.page();
        let start = now_ns();
        // The word the driver waits on, and the value that ends the round.
        let (word, target) = match self.shape {
            Shape::Ring(_) => {
                pass(page, 0, 1, seq);
                (&page.words[0], seq)
            }
            Shape::Star(n) => {
                page.answers.store(0, Ordering::Release);
                for i in 1..=n {
                    pass(page, 0, i, seq);
                }
                (&page.answers, n as u32)
            }
        };
        let deadline = Instant::now() + skillfab_tests::WAIT;
        loop {
            let v = word.load(Ordering::Acquire);
            if v == target {
                break;
            }
            assert!(Instant::now() < deadline, "futex nodes do not answer");
            wait(word, v, Duration::from_millis(100));
        }
        let last = match self.shape {
            Shape::Ring(d) => page.stamps[d].load(Ordering::Acquire),
            Shape::Star(n) => (1..=n)
                .map(|i| page.stamps[i].load(Ordering::Acquire))
                .max()
                .unwrap_or(0),
        };
        Timing::from_ns(start, last, now_ns())
    }

    /// `n` rounds.
    pub fn rounds(&mut self, n: usize, paced: bool) -> Vec<Timing> {
        crate::floors::rounds(n, paced, |_| self.round())
    }

    /// `n` rounds, one every `period` (`None`: back to back).
    pub fn rounds_every(&mut self, n: usize, period: Option<Duration>) -> Vec<Timing> {
        crate::floors::rounds_every(n, period, |_| self.round())
    }

    /// Process ids of the nodes (the driver is the calling thread).
    pub fn node_pids(&self) -> Vec<u32> {
        self.nodes.iter().map(|&i| self.t.pid(i)).collect()
    }
}

impl Drop for Futex {
    fn drop(&mut self) {
        let page = self.shared.page();
        page.stop.store(1, Ordering::Release);
        for w in &page.words {
            wake(w);
        }
        let _ = shm_unlink(self.name.as_str());
    }
}

/// Node `index` of a futex ring or star (the `ring-node futex` process): waits for its word
/// to change, then passes the token to `next` — a ring's last node (`next` 0) by setting the
/// driver's word, a star's node (`star`) by adding one to the answers — until the driver says
/// stop or the process is killed.
pub fn futex_node(index: usize, next: usize, name: &str, star: bool) -> nix::Result<()> {
    let shared = Shared::map(name, false)?;
    let page = shared.page();
    // Rounds start at 1 on a zeroed page: a token passed before this process got here is
    // still seen as new.
    let mut seen = 0;
    while page.stop.load(Ordering::Acquire) == 0 {
        let v = page.words[index].load(Ordering::Acquire);
        if v == seen {
            wait(&page.words[index], seen, Duration::from_millis(200));
            continue;
        }
        seen = v;
        if star {
            page.stamps[index].store(now_ns(), Ordering::Release);
            page.answers.fetch_add(1, Ordering::AcqRel);
            wake(&page.answers);
        } else {
            pass(page, index, next, v);
        }
    }
    Ok(())
}
