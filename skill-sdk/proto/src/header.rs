//! The iceoryx2 user header that travels with every data sample.

use skill_sdk_macros::Message;

/// Cycle bookkeeping of a sample; the payload itself is the plain message type, so any
/// iceoryx2 client can read it.
#[derive(Message, Debug, Default, Clone, Copy, PartialEq, Eq)]
#[message(type_name = "skillfab.SampleHeader", crate = "crate")]
#[repr(C)]
pub struct SampleHeader {
    /// The cycle in which the sample was produced.
    pub cycle: u64,
    /// Monotonic clock (ns, `CLOCK_MONOTONIC`) when it was sent.
    pub stamp_ns: u64,
    /// The producer's slot on the cycle board (tells proposers on a channel apart).
    pub slot: u32,
    /// Reserved, zero.
    pub reserved: u32,
}

/// `CLOCK_MONOTONIC` in nanoseconds: comparable between processes on one host.
pub fn now_ns() -> u64 {
    match nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC) {
        Ok(t) => (t.tv_sec() as u64) * 1_000_000_000 + t.tv_nsec() as u64,
        // CLOCK_MONOTONIC exists on every Linux; 0 only marks "unknown" in stats.
        Err(_) => 0,
    }
}
