//! The iceoryx2 user header that travels with every data sample.

use crate::schema::{FieldKind, FieldType, Prim};
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
    /// The producer's slot on the cycle board (tells proposers on a channel apart); on a
    /// device's command, the winning proposer's, or none when nobody proposed (the safe
    /// command) or the command was blended.
    pub slot: MaybeSlot,
    /// Reserved, zero.
    pub reserved: u32,
}

/// A board slot or none, as the four bytes of [`SampleHeader::slot`]: an `Option<u32>` with
/// the fixed layout other languages and plain iceoryx2 readers see — a `u32`, none being
/// `u32::MAX` (4294967295; no board has that many slots).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
#[repr(transparent)]
pub struct MaybeSlot(u32);

impl MaybeSlot {
    /// No slot.
    pub const NONE: MaybeSlot = MaybeSlot(u32::MAX);

    /// Slot `slot` (which is never `u32::MAX`: a board has [`MAX_SLOTS`](crate::board::MAX_SLOTS)).
    pub const fn some(slot: u32) -> MaybeSlot {
        MaybeSlot(slot)
    }

    /// The slot, if there is one.
    pub const fn get(self) -> Option<u32> {
        if self.0 == Self::NONE.0 {
            None
        } else {
            Some(self.0)
        }
    }
}

impl From<Option<u32>> for MaybeSlot {
    fn from(slot: Option<u32>) -> MaybeSlot {
        slot.map_or(MaybeSlot::NONE, MaybeSlot::some)
    }
}

/// None: a header says which slot sent it only once its sender sets it (iceoryx2 writes the
/// default into every loaned sample; the fabric's senders always overwrite it).
impl Default for MaybeSlot {
    fn default() -> MaybeSlot {
        MaybeSlot::NONE
    }
}

impl std::fmt::Debug for MaybeSlot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.get().fmt(f)
    }
}

/// The slot's number, or `none`.
impl std::fmt::Display for MaybeSlot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.get() {
            Some(s) => write!(f, "{s}"),
            None => f.write_str("none"),
        }
    }
}

// SAFETY: a transparent `u32`: plain old data, and all-zero bytes are slot 0, a valid value.
// Its schema is the `u32` it is on the wire, so the header's layout and schema are unchanged.
unsafe impl FieldType for MaybeSlot {
    fn field_type() -> FieldKind {
        FieldKind::Prim(Prim::U32)
    }
}

/// As decoded through the header's schema: the `u32` it is on the wire.
impl crate::value::FromValue for MaybeSlot {
    fn from_value(value: &crate::value::Value) -> Option<MaybeSlot> {
        u32::from_value(value).map(MaybeSlot)
    }
}

/// `CLOCK_MONOTONIC` in nanoseconds: comparable between processes on one host.
pub fn now_ns() -> u64 {
    match nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC) {
        Ok(t) => (t.tv_sec() as u64) * 1_000_000_000 + t.tv_nsec() as u64,
        // CLOCK_MONOTONIC exists on every Linux; 0 only marks "unknown" in stats.
        Err(_) => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Message;

    #[test]
    fn a_slot_or_none_is_the_u32_the_header_always_carried() {
        assert_eq!(MaybeSlot::some(3).get(), Some(3));
        assert_eq!(MaybeSlot::some(0).get(), Some(0));
        assert_eq!(MaybeSlot::NONE.get(), None);
        assert_eq!(MaybeSlot::from(None), MaybeSlot::NONE);
        assert_eq!(MaybeSlot::from(Some(7)), MaybeSlot::some(7));
        // On the wire: a u32, none being u32::MAX.
        assert_eq!(std::mem::size_of::<MaybeSlot>(), 4);
        // SAFETY: a transparent u32.
        let raw = unsafe { std::mem::transmute::<MaybeSlot, u32>(MaybeSlot::NONE) };
        assert_eq!(raw, u32::MAX);
        let h = SampleHeader::schema();
        assert_eq!((h.size, h.align), (24, 8));
        let slot = h.fields.iter().find(|f| f.name == "slot");
        assert_eq!(
            slot.map(|f| (f.offset, &f.ty)),
            Some((16, &FieldKind::Prim(Prim::U32)))
        );
    }
}
