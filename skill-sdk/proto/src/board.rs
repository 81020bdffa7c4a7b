//! The cycle board: one shared-memory segment per domain, created by the manager.
//!
//! It carries what must not cost a wake-up: the current cycle number, which skills are active,
//! which of a skill's inputs must come from the same cycle, and the completion stamps and
//! counters that skills write when they finish, and every unit's [`Doorbell`]. Skills wake each
//! other directly (a producer rings the doorbells of its output's consumers, listed here by the
//! manager); the manager reads the board and is woken once, by the skill that finishes a
//! cycle's last expected run (or by one whose run produced nothing to pass on).
//!
//! Every field is an atomic, so plain shared references are sound across processes. Byte areas
//! (a skill's declaration, the manager's refusal text) are owned by one side at a time; the
//! slot's `state` atomic hands them over with release/acquire ordering.

use crate::Error;
use crate::doorbell::Doorbell;
use nix::fcntl::OFlag;
use nix::sys::mman::{MapFlags, ProtFlags, mmap, munmap, shm_open, shm_unlink};
use nix::sys::stat::Mode as FileMode;
use std::cell::UnsafeCell;
use std::num::NonZeroUsize;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicI32, AtomicU32, AtomicU64, Ordering};

/// Most skill instances in one domain.
pub const MAX_SLOTS: usize = 64;
/// Room for one skill's encoded declaration.
pub const DECL_BYTES: usize = 16 * 1024;
/// Room for the manager's answer text.
pub const MSG_BYTES: usize = 1024;
/// Most actuator channels one device serves.
pub const MAX_CHANNELS: usize = 4;
/// Room for a skill's encoded parameter values.
pub const PARAM_BYTES: usize = 4096;
/// Most outputs of one skill (the published mask is a `u64`).
pub const MAX_OUTPUTS: usize = 64;
// "SFBOARD" + layout version 6 (5: a refusal is encoded; 6: a unit's spin budget, deadline
// misses and cycle-path allocations per slot)
const MAGIC: u64 = 0x5346_424f_4152_4406;

/// Life of a slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum SlotState {
    /// Unused.
    Free = 0,
    /// A skill took it and is writing its declaration.
    Claimed = 1,
    /// Declaration written; the manager has not answered yet.
    Pending = 2,
    /// Registered; the skill is opening its data ports.
    Accepted = 3,
    /// Refused; the reason is in the message area (`registration::Refusal`).
    Refused = 4,
    /// The skill is leaving cleanly.
    Leaving = 5,
    /// Ports open: taking part in cycles. Only now can a cycle count on it, since a
    /// subscriber that connects after a sample was sent would miss that sample.
    Ready = 6,
}

impl SlotState {
    fn from_u32(v: u32) -> SlotState {
        match v {
            1 => SlotState::Claimed,
            2 => SlotState::Pending,
            3 => SlotState::Accepted,
            4 => SlotState::Refused,
            5 => SlotState::Leaving,
            6 => SlotState::Ready,
            _ => SlotState::Free,
        }
    }
}

/// Outcome of a skill's last run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RunStatus {
    /// Not run yet.
    None = 0,
    /// The body returned `Ok`; its written outputs were published.
    Ok = 1,
    /// Not run: an input it needs was missing (e.g. an async producer has not produced yet).
    Skipped = 2,
    /// The body returned an error or panicked; nothing was published.
    Failed = 3,
}

impl RunStatus {
    /// Decodes the stored value.
    pub fn from_u32(v: u32) -> RunStatus {
        match v {
            1 => RunStatus::Ok,
            2 => RunStatus::Skipped,
            3 => RunStatus::Failed,
            _ => RunStatus::None,
        }
    }
}

/// The time a run belongs to, as the manager set it for the cycle: what a skill reads instead
/// of the wall clock, so that a run can be replayed (see docs/replay.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Clock {
    /// The cycle's time since the fabric's time origin: cycle × period when the manager has a
    /// period (lock-step included), the cycle's start stamp when it free-runs.
    pub time: std::time::Duration,
    /// The manager's nominal period, in this clock's time (a manager with a time factor
    /// paces cycles that many times faster on the host); `None` when it free-runs.
    pub period: Option<std::time::Duration>,
    /// Whether the manager runs in lock-step: cycles follow each other as fast as the units
    /// finish them and a simulator advances one period per cycle.
    pub lockstep: bool,
}

impl Header {
    /// The current cycle's clock.
    pub fn clock(&self) -> Clock {
        let period = self.period_ns.load(Ordering::Acquire);
        Clock {
            time: std::time::Duration::from_nanos(self.cycle_time_ns.load(Ordering::Acquire)),
            period: (period > 0).then(|| std::time::Duration::from_nanos(period)),
            lockstep: self.lockstep.load(Ordering::Acquire) == 1,
        }
    }
}

/// Board-wide fields.
#[repr(C)]
pub struct Header {
    magic: AtomicU64,
    /// Process id of the manager that created the board.
    pub manager_pid: AtomicU32,
    /// 1 while the manager runs; 0 once it has shut down.
    pub open: AtomicU32,
    /// The cycle in progress (or last finished), starting at 1.
    pub cycle: AtomicU64,
    /// Expected sync runs left in the current cycle: `(cycle as u32) << 32 | count`.
    pub remaining: AtomicU64,
    /// Monotonic clock (ns) when the current cycle started.
    pub cycle_start_ns: AtomicU64,
    /// The current cycle's time (ns), the clock skills read ([`Clock`]): cycle × period when
    /// the manager has a period, its start stamp when it free-runs.
    pub cycle_time_ns: AtomicU64,
    /// The manager's nominal period (ns); 0: free-running.
    pub period_ns: AtomicU64,
    /// 1 when the manager runs in lock-step (cycles back to back, simulated time).
    pub lockstep: AtomicU32,
    /// The manager's doorbell.
    pub bell: Doorbell,
}

/// One skill instance.
#[repr(C)]
pub struct Slot {
    /// A [`SlotState`].
    pub state: AtomicU32,
    /// The unit's doorbell: the manager rings it at cycle start and for registration, and
    /// producers ring it when they publish one of its inputs.
    pub bell: Doorbell,
    /// Per output: the slots with an input on that output's topic (written by the manager
    /// when it plans), whose doorbells a run rings after it publishes.
    pub consumers: [AtomicU64; MAX_OUTPUTS],
    /// Process id of the skill.
    pub pid: AtomicU32,
    /// Bumped by the manager each time the slot is (re)accepted, so stats can tell instances apart.
    pub generation: AtomicU32,
    /// 0 when inactive; when active, which activation of the skill's name this is (written by
    /// the manager: raised each time a client activates the name, the same for a restarted
    /// process of it, so a skill tells a new activation from a restart, `Ctx::activation`).
    pub active: AtomicU32,
    /// The cycle in which the manager expects this (sync) skill to run; a skill only runs
    /// for cycle k when this says k, so an unexpected run never counts toward completion.
    pub expected_cycle: AtomicU64,
    /// Bit i set: input i comes from a sync producer and must be from the running cycle
    /// (written by the manager). Inputs with the bit clear use the latest sample.
    pub fresh_mask: AtomicU64,
    /// Last cycle this skill finished a run (or skip) for.
    pub done_cycle: AtomicU64,
    /// [`RunStatus`] of that run.
    pub status: AtomicU32,
    /// Bit i set: output i was published by that run.
    pub published_mask: AtomicU64,
    /// Number of completed runs (status Ok).
    pub runs: AtomicU64,
    /// Number of failed runs.
    pub failures: AtomicU64,
    /// Number of skipped cycles.
    pub skips: AtomicU64,
    /// Sum of body compute times (ns).
    pub compute_ns_total: AtomicU64,
    /// Compute time of the last run (ns).
    pub last_compute_ns: AtomicU64,
    /// Monotonic clock (ns) when the last run started.
    pub last_start_ns: AtomicU64,
    /// Monotonic clock (ns) when the last run finished and its outputs were sent.
    pub last_end_ns: AtomicU64,
    /// Arbitration priority (written by the manager at cycle start).
    pub priority: AtomicI32,
    /// The cycle in which the manager found this skill unable to run (an upstream run
    /// failed): a device waiting for its proposal stops waiting.
    pub cancelled_cycle: AtomicU64,
    /// For a device: per channel, the slots that propose on it (written by the manager).
    pub channel_proposers: [AtomicU64; MAX_CHANNELS],
    /// For a device: per channel, the cycle of the last arbitration.
    pub channel_cycle: [AtomicU64; MAX_CHANNELS],
    /// For a device: per channel, the winner's slot (none: nobody proposed, the safe
    /// command, or the command was blended).
    pub channel_winner: [AtomicMaybeSlot; MAX_CHANNELS],
    /// For a device: per channel, the slots whose proposals made the command.
    pub channel_mask: [AtomicU64; MAX_CHANNELS],
    /// The unit's spin budget (ns, written by the unit before it is ready): 0, it sleeps on
    /// its doorbell until rung (the default); else the manager rings it at cycle start as it
    /// does a source, and it polls its doorbell instead of sleeping until its run is done or
    /// this long after the cycle's start, so the producers' rings reach it as a cache-line
    /// transfer rather than a kernel wake-up.
    pub spin_ns: AtomicU64,
    /// Parameter snapshot generation (a seqlock: odd while the manager writes).
    pub param_gen: AtomicU64,
    param_len: AtomicU32,
    params: [AtomicU64; PARAM_BYTES / 8],
    decl_len: AtomicU32,
    msg_len: AtomicU32,
    decl: UnsafeCell<[u8; DECL_BYTES]>,
    msg: UnsafeCell<[u8; MSG_BYTES]>,
    /// Runs of this skill that missed their cycle's deadline (written by the manager when it
    /// finishes a cycle: a run that ended after the deadline, or one still in progress when
    /// an overrun closed the cycle).
    pub deadline_misses: AtomicU64,
    /// Allocations the unit's thread made on the cycle's path after its warm-up (written by
    /// the unit; none: its runtime does not count them).
    pub cycle_allocs: AtomicMaybeCount,
}

#[repr(C)]
struct Layout {
    header: Header,
    slots: [Slot; MAX_SLOTS],
}

/// A mapping of a domain's board.
pub struct Board {
    ptr: NonNull<Layout>,
    name: String,
    owner: bool,
}

// SAFETY: the mapping is shared memory made only of atomics and byte areas whose ownership is
// handed over through atomics; it may be used from any thread.
unsafe impl Send for Board {}
// SAFETY: as above.
unsafe impl Sync for Board {}

fn map(fd: &std::os::fd::OwnedFd) -> Result<NonNull<Layout>, nix::Error> {
    let len = NonZeroUsize::new(std::mem::size_of::<Layout>()).ok_or(nix::Error::EINVAL)?;
    // SAFETY: mapping a shared-memory object we opened, of at least `len` bytes, read-write.
    let p = unsafe {
        mmap(
            None,
            len,
            ProtFlags::PROT_READ | ProtFlags::PROT_WRITE,
            MapFlags::MAP_SHARED,
            fd,
            0,
        )?
    };
    Ok(p.cast())
}

impl Board {
    /// Creates the board of a domain (the manager does this). An existing board of a manager
    /// that is still alive is an error; a stale one is replaced.
    pub fn create(prefix: &str) -> Result<Board, Error> {
        let name = crate::names::board(prefix);
        let io = |e: nix::Error| Error::Board {
            name: name.clone(),
            source: std::io::Error::from(e),
        };
        let fd = match shm_open(
            name.as_str(),
            OFlag::O_CREAT | OFlag::O_EXCL | OFlag::O_RDWR,
            FileMode::from_bits_truncate(0o600),
        ) {
            Ok(fd) => fd,
            Err(nix::Error::EEXIST) => {
                if let Ok(old) = Board::open(prefix)
                    && old.manager_alive()
                {
                    return Err(Error::ManagerRunning {
                        pid: old.header().manager_pid.load(Ordering::Acquire),
                    });
                }
                let _ = shm_unlink(name.as_str());
                shm_open(
                    name.as_str(),
                    OFlag::O_CREAT | OFlag::O_EXCL | OFlag::O_RDWR,
                    FileMode::from_bits_truncate(0o600),
                )
                .map_err(io)?
            }
            Err(e) => return Err(io(e)),
        };
        nix::unistd::ftruncate(&fd, std::mem::size_of::<Layout>() as i64).map_err(io)?;
        let ptr = map(&fd).map_err(io)?;
        let board = Board {
            ptr,
            name: name.clone(),
            owner: true,
        };
        let h = board.header();
        h.manager_pid.store(std::process::id(), Ordering::Relaxed);
        h.open.store(1, Ordering::Relaxed);
        h.magic.store(MAGIC, Ordering::Release);
        Ok(board)
    }

    /// Retires the board a manager that died left behind, before a new manager creates its
    /// own: marks it closed and rings every slot, so its skills notice at once (not at their
    /// next liveness tick) and register with the new board. Returns the last cycle it ran, so
    /// the new manager numbers on from there; `None` if there is no such board (none, or its
    /// manager is alive).
    pub fn retire_dead(prefix: &str) -> Option<u64> {
        let old = Board::open(prefix).ok()?;
        let h = old.header();
        if pid_alive(h.manager_pid.load(Ordering::Acquire)) {
            return None;
        }
        let cycle = h.cycle.load(Ordering::Acquire);
        old.close();
        old.ring(u64::MAX);
        Some(cycle)
    }

    /// Whether the board is still open (one atomic load: cheap enough for every wake-up; a
    /// closed board means its manager left or was replaced).
    pub fn is_open(&self) -> bool {
        self.header().open.load(Ordering::Acquire) == 1
    }

    /// Opens the board of a domain; fails while no manager has created it.
    pub fn open(prefix: &str) -> Result<Board, Error> {
        let name = crate::names::board(prefix);
        let io = |e: nix::Error| Error::Board {
            name: name.clone(),
            source: std::io::Error::from(e),
        };
        let fd = shm_open(name.as_str(), OFlag::O_RDWR, FileMode::empty()).map_err(io)?;
        let st = nix::sys::stat::fstat(&fd).map_err(io)?;
        if (st.st_size as usize) < std::mem::size_of::<Layout>() {
            return Err(Error::BoardNotReady);
        }
        let ptr = map(&fd).map_err(io)?;
        let board = Board {
            ptr,
            name,
            owner: false,
        };
        if board.header().magic.load(Ordering::Acquire) != MAGIC {
            return Err(Error::BoardNotReady);
        }
        Ok(board)
    }

    /// Board-wide fields.
    pub fn header(&self) -> &Header {
        // SAFETY: the mapping lives as long as `self` and holds a `Layout`.
        unsafe { &self.ptr.as_ref().header }
    }

    /// Slot `i` (< [`MAX_SLOTS`]).
    pub fn slot(&self, i: usize) -> &Slot {
        // SAFETY: as in `header`; indexing panics past MAX_SLOTS.
        unsafe { &self.ptr.as_ref().slots[i] }
    }

    /// Whether the manager that created this board is still running.
    pub fn manager_alive(&self) -> bool {
        let h = self.header();
        h.open.load(Ordering::Acquire) == 1 && pid_alive(h.manager_pid.load(Ordering::Acquire))
    }

    /// Marks the board closed (the manager, on shutdown).
    pub fn close(&self) {
        self.header().open.store(0, Ordering::Release);
    }

    /// Rings the doorbell of every slot in `mask` (bit i: slot i).
    pub fn ring(&self, mut mask: u64) {
        while mask != 0 {
            self.slot(mask.trailing_zeros() as usize).bell.ring();
            mask &= mask - 1;
        }
    }

    /// Rings the manager's doorbell.
    pub fn ring_manager(&self) {
        self.header().bell.ring();
    }

    /// Arms the completion counter for `cycle` with `count` expected runs.
    pub fn arm(&self, cycle: u64, count: u32) {
        self.header().remaining.store(
            ((cycle as u32 as u64) << 32) | u64::from(count),
            Ordering::Release,
        );
    }

    /// Takes `n` expected runs of `cycle` off the counter; true if that finished the cycle.
    /// A stale call (another cycle armed meanwhile) changes nothing and returns false.
    pub fn complete(&self, cycle: u64, n: u32) -> bool {
        let r = &self.header().remaining;
        let mut cur = r.load(Ordering::Acquire);
        loop {
            let (c, left) = ((cur >> 32) as u32, cur as u32);
            if c != cycle as u32 || left == 0 {
                return false;
            }
            let next = ((c as u64) << 32) | u64::from(left.saturating_sub(n));
            match r.compare_exchange_weak(cur, next, Ordering::AcqRel, Ordering::Acquire) {
                Ok(_) => return left <= n,
                Err(now) => cur = now,
            }
        }
    }

    /// Expected runs left in `cycle` (0 if another cycle is armed).
    pub fn remaining(&self, cycle: u64) -> u32 {
        let cur = self.header().remaining.load(Ordering::Acquire);
        if (cur >> 32) as u32 == cycle as u32 {
            cur as u32
        } else {
            0
        }
    }
}

impl Drop for Board {
    fn drop(&mut self) {
        // SAFETY: unmapping what `map` mapped, once.
        unsafe {
            let _ = munmap(self.ptr.cast(), std::mem::size_of::<Layout>());
        }
        if self.owner {
            let _ = shm_unlink(self.name.as_str());
        }
    }
}

impl Slot {
    /// Current state.
    pub fn state(&self) -> SlotState {
        SlotState::from_u32(self.state.load(Ordering::Acquire))
    }

    /// Moves the slot from `from` to `to`; false if it was not in `from`.
    pub fn transition(&self, from: SlotState, to: SlotState) -> bool {
        self.state
            .compare_exchange(from as u32, to as u32, Ordering::AcqRel, Ordering::Acquire)
            .is_ok()
    }

    /// Sets the state unconditionally (by the side that owns the slot now).
    pub fn set_state(&self, to: SlotState) {
        self.state.store(to as u32, Ordering::Release);
    }

    /// Writes the declaration bytes (the skill, in state `Claimed`).
    pub fn write_decl(&self, bytes: &[u8]) -> Result<(), Error> {
        if bytes.len() > DECL_BYTES {
            return Err(Error::DeclTooLarge {
                len: bytes.len(),
                max: DECL_BYTES,
            });
        }
        // SAFETY: in state `Claimed` only the claiming skill touches the area; the later
        // release store of `Pending` publishes it.
        unsafe {
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), self.decl.get().cast::<u8>(), bytes.len())
        };
        self.decl_len.store(bytes.len() as u32, Ordering::Relaxed);
        Ok(())
    }

    /// Reads the declaration bytes (the manager, in state `Pending` or later).
    pub fn read_decl(&self) -> Vec<u8> {
        let len = (self.decl_len.load(Ordering::Relaxed) as usize).min(DECL_BYTES);
        // SAFETY: after the acquire load of `Pending` the skill no longer writes the area.
        unsafe { std::slice::from_raw_parts(self.decl.get().cast::<u8>(), len).to_vec() }
    }

    /// Writes the answer (the manager, before setting `Refused`): an encoded
    /// [`crate::registration::Refusal`], cut at [`MSG_BYTES`].
    pub fn write_msg(&self, bytes: &[u8]) {
        let n = bytes.len().min(MSG_BYTES);
        // SAFETY: in state `Pending` only the manager writes the area; the release store of
        // `Refused` publishes it.
        unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), self.msg.get().cast::<u8>(), n) };
        self.msg_len.store(n as u32, Ordering::Relaxed);
    }

    /// Reads the answer (the skill, after seeing `Refused`).
    pub fn read_msg(&self) -> Vec<u8> {
        let n = (self.msg_len.load(Ordering::Relaxed) as usize).min(MSG_BYTES);
        // SAFETY: after the acquire load of `Refused` the manager no longer writes the area.
        unsafe { std::slice::from_raw_parts(self.msg.get().cast::<u8>(), n).to_vec() }
    }

    /// Publishes a new parameter snapshot (the manager). Readers that overlap the write see
    /// an odd or changed generation and retry.
    pub fn write_params(&self, bytes: &[u8]) -> Result<(), Error> {
        if bytes.len() > PARAM_BYTES {
            return Err(Error::DeclTooLarge {
                len: bytes.len(),
                max: PARAM_BYTES,
            });
        }
        self.param_gen.fetch_add(1, Ordering::AcqRel);
        for (i, chunk) in bytes.chunks(8).enumerate() {
            let mut w = [0u8; 8];
            w[..chunk.len()].copy_from_slice(chunk);
            self.params[i].store(u64::from_ne_bytes(w), Ordering::Relaxed);
        }
        self.param_len.store(bytes.len() as u32, Ordering::Relaxed);
        self.param_gen.fetch_add(1, Ordering::Release);
        Ok(())
    }

    /// The parameter snapshot if its generation differs from `seen` (the skill).
    pub fn read_params(&self, seen: u64) -> Option<(u64, Vec<u8>)> {
        for _ in 0..1000 {
            let g1 = self.param_gen.load(Ordering::Acquire);
            if g1 == seen {
                return None;
            }
            if g1 % 2 == 1 {
                std::hint::spin_loop();
                continue;
            }
            let len = (self.param_len.load(Ordering::Relaxed) as usize).min(PARAM_BYTES);
            let mut out = Vec::with_capacity(len + 8);
            for w in &self.params[..len.div_ceil(8)] {
                out.extend_from_slice(&w.load(Ordering::Relaxed).to_ne_bytes());
            }
            out.truncate(len);
            std::sync::atomic::fence(Ordering::Acquire);
            if self.param_gen.load(Ordering::Relaxed) == g1 {
                return Some((g1, out));
            }
        }
        None
    }

    /// Resets the run counters (the manager, when it accepts a new instance).
    pub fn reset_counters(&self) {
        for a in [
            &self.done_cycle,
            &self.published_mask,
            &self.runs,
            &self.failures,
            &self.skips,
            &self.compute_ns_total,
            &self.last_compute_ns,
            &self.last_start_ns,
            &self.last_end_ns,
            &self.fresh_mask,
            &self.expected_cycle,
            &self.param_gen,
            &self.cancelled_cycle,
            &self.deadline_misses,
        ] {
            a.store(0, Ordering::Relaxed);
        }
        self.status.store(RunStatus::None as u32, Ordering::Relaxed);
        for c in 0..MAX_CHANNELS {
            self.channel_proposers[c].store(0, Ordering::Relaxed);
            self.channel_cycle[c].store(0, Ordering::Relaxed);
            self.channel_winner[c].store(None, Ordering::Relaxed);
            self.channel_mask[c].store(0, Ordering::Relaxed);
        }
        self.cycle_allocs.clear(Ordering::Relaxed);
    }
}

/// A count that may not be kept, in one atomic word of the board: a zeroed board (a new one, a
/// reset slot) reads as "not counted"; the counter stores `n + 1`.
#[repr(transparent)]
#[derive(Default)]
pub struct AtomicMaybeCount(AtomicU64);

impl AtomicMaybeCount {
    /// The count, if it is kept.
    pub fn load(&self, order: Ordering) -> Option<u64> {
        self.0.load(order).checked_sub(1)
    }

    /// Starts counting from 0.
    pub fn start(&self, order: Ordering) {
        self.0.store(1, order);
    }

    /// Adds `n` to a count that is kept (the writer started it).
    pub fn add(&self, n: u64, order: Ordering) {
        self.0.fetch_add(n, order);
    }

    /// Back to "not counted".
    pub fn clear(&self, order: Ordering) {
        self.0.store(0, order);
    }
}

/// A board slot or none in one atomic word, for the board's own fields: slot `s` is stored
/// as `s + 1` and none as 0, so a zeroed board (a new one, a reset slot) reads as none.
/// (A [`SampleHeader`](crate::header::SampleHeader) carries its slot as a
/// [`MaybeSlot`](crate::header::MaybeSlot), readable outside the fabric; this encoding stays
/// inside the board.)
#[repr(transparent)]
#[derive(Default)]
pub struct AtomicMaybeSlot(AtomicU32);

impl AtomicMaybeSlot {
    /// The slot, if there is one.
    pub fn load(&self, order: Ordering) -> Option<u32> {
        self.0.load(order).checked_sub(1)
    }

    /// Sets the slot (`slot` is below [`MAX_SLOTS`], so `slot + 1` cannot wrap).
    pub fn store(&self, slot: Option<u32>, order: Ordering) {
        self.0.store(slot.map_or(0, |s| s + 1), order);
    }
}

/// Whether a process exists and is not a zombie.
pub fn pid_alive(pid: u32) -> bool {
    if pid == 0 {
        return false;
    }
    let Ok(p) = i32::try_from(pid) else {
        return false;
    };
    if nix::sys::signal::kill(nix::unistd::Pid::from_raw(p), None)
        .is_err_and(|e| e == nix::Error::ESRCH)
    {
        return false;
    }
    // A killed child stays a zombie until its parent reaps it: that is dead too.
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(stat) => stat
            .rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().next())
            .is_none_or(|s| s != "Z" && s != "X"),
        Err(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_zeroed_winner_is_none_and_slot_zero_is_a_slot() {
        let w = AtomicMaybeSlot::default();
        assert_eq!(w.load(Ordering::Relaxed), None);
        w.store(Some(0), Ordering::Relaxed);
        assert_eq!(w.load(Ordering::Relaxed), Some(0));
        w.store(Some(63), Ordering::Relaxed);
        assert_eq!(w.load(Ordering::Relaxed), Some(63));
        w.store(None, Ordering::Relaxed);
        assert_eq!(w.load(Ordering::Relaxed), None);
    }

    #[test]
    fn a_zeroed_count_is_not_kept_and_a_started_one_counts_from_zero() {
        let c = AtomicMaybeCount::default();
        assert_eq!(c.load(Ordering::Relaxed), None);
        c.start(Ordering::Relaxed);
        assert_eq!(c.load(Ordering::Relaxed), Some(0));
        c.add(3, Ordering::Relaxed);
        assert_eq!(c.load(Ordering::Relaxed), Some(3));
        c.clear(Ordering::Relaxed);
        assert_eq!(c.load(Ordering::Relaxed), None);
    }

    #[test]
    fn completion_counter_is_cycle_tagged() {
        let prefix = format!("sf_unit-board-{}_", std::process::id());
        let b = Board::create(&prefix).unwrap();
        b.arm(7, 2);
        assert!(!b.complete(6, 1), "a stale cycle changes nothing");
        assert_eq!(b.remaining(7), 2);
        assert!(!b.complete(7, 1));
        assert!(b.complete(7, 1));
        assert!(!b.complete(7, 1), "already finished");
        b.arm(8, 3);
        assert!(
            b.complete(8, 5),
            "cancelling more than is left finishes the cycle"
        );
        let other = Board::open(&prefix).unwrap();
        assert!(other.manager_alive());
        drop(other);
        drop(b);
        assert!(Board::open(&prefix).is_err(), "the owner unlinks the board");
    }

    #[test]
    fn parameter_snapshots_pass_through_the_seqlock() {
        let prefix = format!("sf_unit-board3-{}_", std::process::id());
        let b = Board::create(&prefix).unwrap();
        let s = b.slot(3);
        assert_eq!(s.read_params(0), None, "nothing written yet");
        s.write_params(b"gain=3 and some more bytes").unwrap();
        let (g, bytes) = s.read_params(0).unwrap();
        assert_eq!(bytes, b"gain=3 and some more bytes");
        assert_eq!(s.read_params(g), None, "nothing new");
        assert!(s.write_params(&[0; PARAM_BYTES + 1]).is_err());
    }

    #[test]
    fn a_second_live_manager_is_refused() {
        let prefix = format!("sf_unit-board2-{}_", std::process::id());
        let b = Board::create(&prefix).unwrap();
        assert!(matches!(
            Board::create(&prefix),
            Err(Error::ManagerRunning { .. })
        ));
        drop(b);
    }

    #[test]
    fn own_pid_is_alive_and_pid_zero_is_not() {
        assert!(pid_alive(std::process::id()));
        assert!(!pid_alive(0));
    }
}
