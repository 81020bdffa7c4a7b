//! Where a skill's state lives between its runs and across its deaths: one shared-memory
//! object per instance, `/dev/shm/sf_<domain>_state_<name>` ([`crate::names::state`]).
//!
//! The object is a [`Head`] followed by data regions. The head names two slots, each a
//! region (offset, capacity) holding one encoded state (length, cycle). A commit writes the
//! slot the counter `seq` does not point at, then raises `seq` with release ordering: the slot
//! `seq` points at is always whole, whatever instant the process is killed at. A state larger
//! than its slot's region gets a new region at the end of the object (the object grows; the
//! old region is left unused, so the space is at most about twice the largest state per slot).
//! Only the instance of that name writes it; the next instance reads it before its first run.

use nix::fcntl::OFlag;
use nix::sys::mman::{MapFlags, ProtFlags, mmap, munmap, shm_open, shm_unlink};
use nix::sys::stat::Mode as FileMode;
use std::num::NonZeroUsize;
use std::os::fd::OwnedFd;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU64, Ordering};

const MAGIC: u64 = 0x5346_5354_4154_4501; // "SFSTATE" + layout version 1

/// One slot: where its bytes are and what they are.
#[repr(C)]
struct SlotHead {
    offset: AtomicU64,
    capacity: AtomicU64,
    len: AtomicU64,
    /// The cycle of the run whose state this is.
    cycle: AtomicU64,
}

#[repr(C)]
struct Head {
    magic: AtomicU64,
    /// The state type's fingerprint ([`crate::state::State::fingerprint`]).
    fingerprint: AtomicU64,
    /// Commits so far; slot `seq % 2` is the whole one (none while 0).
    seq: AtomicU64,
    slots: [SlotHead; 2],
}

const HEAD: usize = std::mem::size_of::<Head>().next_multiple_of(64);

/// What an earlier instance left.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Found {
    /// No state of this name (a first start, or the last instance left cleanly).
    Nothing,
    /// State of this type, as of the run of `cycle`.
    State { bytes: Vec<u8>, cycle: u64 },
    /// State of another type or version of the skill.
    OtherVersion { fingerprint: u64 },
    /// An object of this name that is not a whole state (bad magic, out-of-range slot).
    Unreadable,
}

/// Why the state object could not be used.
#[derive(Debug, thiserror::Error)]
#[error("state object {name}")]
pub(crate) struct KeptError {
    name: String,
    #[source]
    source: nix::Error,
}

/// The open state object of one instance.
pub(crate) struct Kept {
    name: String,
    fd: OwnedFd,
    ptr: NonNull<u8>,
    len: usize,
    fingerprint: u64,
}

impl Kept {
    /// Opens (or creates) the state object `name` (from [`crate::names::state`]) and reads
    /// what it holds; from here on this instance owns it, with the state type `fingerprint`.
    pub(crate) fn open(name: &str, fingerprint: u64) -> Result<(Kept, Found), KeptError> {
        let err = |source| KeptError {
            name: name.to_string(),
            source,
        };
        let fd = shm_open(
            name,
            OFlag::O_CREAT | OFlag::O_RDWR,
            FileMode::from_bits_truncate(0o600),
        )
        .map_err(err)?;
        let size = nix::sys::stat::fstat(&fd).map_err(err)?.st_size as usize;
        let fresh = size < HEAD;
        if fresh {
            nix::unistd::ftruncate(&fd, HEAD as i64).map_err(err)?;
        }
        let (ptr, len) = map(&fd, size.max(HEAD)).map_err(err)?;
        let mut kept = Kept {
            name: name.to_string(),
            fd,
            ptr,
            len,
            fingerprint,
        };
        let found = if fresh { Found::Nothing } else { kept.read() };
        if fresh || matches!(found, Found::OtherVersion { .. } | Found::Unreadable) {
            kept.reset();
        }
        Ok((kept, found))
    }

    fn head(&self) -> &Head {
        // SAFETY: the mapping is at least HEAD bytes, page-aligned, and Head is made of
        // atomics only (sound to share with another process).
        unsafe { self.ptr.cast::<Head>().as_ref() }
    }

    fn read(&self) -> Found {
        let h = self.head();
        if h.magic.load(Ordering::Acquire) != MAGIC {
            return Found::Unreadable;
        }
        let fingerprint = h.fingerprint.load(Ordering::Relaxed);
        if fingerprint != self.fingerprint {
            return Found::OtherVersion { fingerprint };
        }
        let seq = h.seq.load(Ordering::Acquire);
        if seq == 0 {
            return Found::Nothing;
        }
        let s = &h.slots[(seq % 2) as usize];
        let (offset, len) = (
            s.offset.load(Ordering::Relaxed) as usize,
            s.len.load(Ordering::Relaxed) as usize,
        );
        if offset < HEAD || len > s.capacity.load(Ordering::Relaxed) as usize {
            return Found::Unreadable;
        }
        match offset.checked_add(len) {
            Some(end) if end <= self.len => {}
            _ => return Found::Unreadable,
        }
        // SAFETY: offset..offset+len is inside the mapping (checked above); no one writes it
        // while this instance, its only writer, reads.
        let bytes = unsafe { std::slice::from_raw_parts(self.ptr.as_ptr().add(offset), len) };
        Found::State {
            bytes: bytes.to_vec(),
            cycle: s.cycle.load(Ordering::Relaxed),
        }
    }

    /// Empties the object for this instance's type (nothing committed).
    fn reset(&mut self) {
        let h = self.head();
        h.magic.store(0, Ordering::Release);
        h.seq.store(0, Ordering::Relaxed);
        for s in &h.slots {
            s.offset.store(0, Ordering::Relaxed);
            s.capacity.store(0, Ordering::Relaxed);
            s.len.store(0, Ordering::Relaxed);
            s.cycle.store(0, Ordering::Relaxed);
        }
        h.fingerprint.store(self.fingerprint, Ordering::Relaxed);
        h.magic.store(MAGIC, Ordering::Release);
    }

    /// Keeps `bytes` as the state of the run of `cycle`: written to the other slot, then
    /// made the whole one.
    pub(crate) fn commit(&mut self, bytes: &[u8], cycle: u64) -> Result<(), KeptError> {
        let seq = self.head().seq.load(Ordering::Relaxed);
        let i = ((seq + 1) % 2) as usize;
        let capacity = self.head().slots[i].capacity.load(Ordering::Relaxed) as usize;
        if bytes.len() > capacity {
            // A new region at the end, twice what is needed (a state that grows in steps
            // moves rarely).
            let capacity = (bytes.len() * 2).max(256).next_multiple_of(64);
            let offset = self.len;
            self.grow(offset + capacity)?;
            let s = &self.head().slots[i];
            s.offset.store(offset as u64, Ordering::Relaxed);
            s.capacity.store(capacity as u64, Ordering::Relaxed);
        }
        let h = self.head();
        let s = &h.slots[i];
        let offset = s.offset.load(Ordering::Relaxed) as usize;
        // SAFETY: offset..offset+capacity is inside the mapping (made so above or by an
        // earlier commit of this instance) and capacity >= bytes.len(); this instance is the
        // only writer, and slot i is not the one a reader would take.
        unsafe {
            std::ptr::copy_nonoverlapping(
                bytes.as_ptr(),
                self.ptr.as_ptr().add(offset),
                bytes.len(),
            );
        }
        s.len.store(bytes.len() as u64, Ordering::Relaxed);
        s.cycle.store(cycle, Ordering::Relaxed);
        h.seq.store(seq + 1, Ordering::Release);
        Ok(())
    }

    /// The state last committed, as a restarted instance would find it.
    pub(crate) fn last(&self) -> Option<Vec<u8>> {
        match self.read() {
            Found::State { bytes, .. } => Some(bytes),
            _ => None,
        }
    }

    fn grow(&mut self, len: usize) -> Result<(), KeptError> {
        let err = |source| KeptError {
            name: self.name.clone(),
            source,
        };
        nix::unistd::ftruncate(&self.fd, len as i64).map_err(err)?;
        let (ptr, len) = map(&self.fd, len).map_err(err)?;
        // SAFETY: unmapping the previous mapping, which nothing refers to any more (the head
        // is re-read through self.ptr after this).
        unsafe {
            let _ = munmap(self.ptr.cast(), self.len);
        }
        self.ptr = ptr;
        self.len = len;
        Ok(())
    }

    /// The instance leaves on purpose: the next one starts afresh.
    pub(crate) fn remove(self) {
        let _ = shm_unlink(self.name.as_str());
    }
}

impl Drop for Kept {
    fn drop(&mut self) {
        // SAFETY: unmapping what `map` mapped, once.
        unsafe {
            let _ = munmap(self.ptr.cast(), self.len);
        }
    }
}

fn map(fd: &OwnedFd, len: usize) -> Result<(NonNull<u8>, usize), nix::Error> {
    let size = NonZeroUsize::new(len).ok_or(nix::Error::EINVAL)?;
    // SAFETY: mapping a shared-memory object we opened, of at least `len` bytes, read-write.
    let p = unsafe {
        mmap(
            None,
            size,
            ProtFlags::PROT_READ | ProtFlags::PROT_WRITE,
            MapFlags::MAP_SHARED,
            fd,
            0,
        )?
    };
    Ok((p.cast(), len))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn name(test: &str) -> String {
        format!("/sf_kepttest{}{test}_state_x", std::process::id())
    }

    #[test]
    fn the_next_instance_finds_the_last_commit_even_after_the_object_grew() {
        let n = name("grow");
        let (mut k, found) = Kept::open(&n, 7).unwrap();
        assert_eq!(found, Found::Nothing);
        k.commit(&[1, 2, 3], 10).unwrap();
        let big: Vec<u8> = (0..5000u32).map(|i| i as u8).collect();
        k.commit(&big, 11).unwrap();
        k.commit(&[9; 40], 12).unwrap();
        k.commit(&big, 13).unwrap();
        drop(k);
        let (k, found) = Kept::open(&n, 7).unwrap();
        assert_eq!(
            found,
            Found::State {
                bytes: big.clone(),
                cycle: 13
            }
        );
        assert_eq!(k.last(), Some(big));
        k.remove();
    }

    #[test]
    fn another_fingerprint_is_told_apart_and_not_read() {
        let n = name("other");
        let (mut k, _) = Kept::open(&n, 1).unwrap();
        k.commit(&[1], 1).unwrap();
        drop(k);
        let (k, found) = Kept::open(&n, 2).unwrap();
        assert_eq!(found, Found::OtherVersion { fingerprint: 1 });
        // The object now belongs to the new type, empty.
        assert_eq!(k.last(), None);
        drop(k);
        let (k, found) = Kept::open(&n, 2).unwrap();
        assert_eq!(found, Found::Nothing);
        k.remove();
    }

    #[test]
    fn a_commit_cut_short_leaves_the_previous_state() {
        let n = name("torn");
        let (mut k, _) = Kept::open(&n, 3).unwrap();
        k.commit(&[1; 8], 1).unwrap();
        k.commit(&[2; 8], 2).unwrap();
        // A process killed while writing slot (seq + 1) % 2: its bytes are there, seq not yet
        // raised.
        let h = k.head();
        let seq = h.seq.load(Ordering::Relaxed);
        let s = &h.slots[((seq + 1) % 2) as usize];
        let off = s.offset.load(Ordering::Relaxed) as usize;
        // SAFETY: inside the slot's region of this test's own object.
        unsafe { std::ptr::write_bytes(k.ptr.as_ptr().add(off), 0xEE, 8) };
        s.len.store(3, Ordering::Relaxed);
        drop(k);
        let (k, found) = Kept::open(&n, 3).unwrap();
        assert_eq!(
            found,
            Found::State {
                bytes: vec![2; 8],
                cycle: 2
            }
        );
        k.remove();
    }

    #[test]
    fn garbage_under_the_name_is_unreadable_not_a_state() {
        let n = name("garbage");
        let fd = shm_open(
            n.as_str(),
            OFlag::O_CREAT | OFlag::O_RDWR,
            FileMode::from_bits_truncate(0o600),
        )
        .unwrap();
        nix::unistd::ftruncate(&fd, 4096).unwrap();
        let (p, len) = map(&fd, 4096).unwrap();
        // SAFETY: the test's own mapping of 4096 bytes.
        unsafe { std::ptr::write_bytes(p.as_ptr(), 0x5A, len) };
        // SAFETY: unmapping it once.
        unsafe { munmap(p.cast(), len).unwrap() };
        let (k, found) = Kept::open(&n, 3).unwrap();
        assert_eq!(found, Found::Unreadable);
        k.remove();
    }
}
