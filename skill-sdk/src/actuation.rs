//! Actuator channels: the command type's contract, the arbitration among the proposals of a
//! cycle, the device-side port that does it, and the `Command<'a, T>` a device's body receives.
//!
//! Skills propose through [`Proposal`](crate::ports::Proposal) outputs; a device declares the
//! channels it serves as `Command<'a, T>` fields of a `#[derive(Channels)]` struct.
//! Proposals travel straight from proposer to device (one topic per channel, many
//! publishers): arbitration adds no process hop.

use crate::Message;
use crate::decl::{Policy, PortDecl, PortKind};
use crate::header::{MaybeSlot, SampleHeader};
use crate::ports::PortMaker;
use crate::schema::{FieldKind, MessageSchema, Prim};
use crate::value::kind_size;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use std::any::Any;
use std::collections::HashMap;
use std::ops::Deref;
use std::sync::Arc;

/// A message that commands an actuator.
pub trait Actuation: Message {
    /// The command that makes the actuator safe (e.g. stop), used when nobody proposes.
    fn safe() -> Self;
}

/// Byte offsets and kinds of every number in a layout, or `None` if something is not a float
/// (then the type cannot be blended).
pub fn float_leaves(schema: &MessageSchema) -> Option<Vec<(usize, Prim)>> {
    fn walk(kind: &FieldKind, base: usize, out: &mut Vec<(usize, Prim)>) -> bool {
        match kind {
            FieldKind::Prim(p @ (Prim::F32 | Prim::F64)) => {
                out.push((base, *p));
                true
            }
            FieldKind::Prim(_) => false,
            FieldKind::Array { elem, len } => {
                let step = kind_size(elem);
                (0..*len as usize).all(|i| walk(elem, base + i * step, out))
            }
            FieldKind::Struct(s) => s
                .fields
                .iter()
                .all(|f| walk(&f.ty, base + f.offset as usize, out)),
        }
    }
    let mut out = Vec::new();
    walk(&FieldKind::Struct(schema.clone()), 0, &mut out).then_some(out)
}

fn bytes_of<T>(v: &T) -> &[u8] {
    // SAFETY: a Message is plain old data; reading its bytes is sound.
    unsafe { std::slice::from_raw_parts((v as *const T).cast::<u8>(), std::mem::size_of::<T>()) }
}

/// The weighted average of `items`, field by field (`leaves` from [`float_leaves`]).
pub fn blend<T: Message>(leaves: &[(usize, Prim)], items: &[(f64, &T)]) -> T {
    blend_by(leaves, items.iter().map(|(w, v)| (*w, *v)))
}

/// [`blend`] of the items an iterator yields (walked once per leaf): a device's cycle blends
/// without collecting them.
fn blend_by<'t, T: Message>(
    leaves: &[(usize, Prim)],
    items: impl Iterator<Item = (f64, &'t T)> + Clone,
) -> T {
    let total: f64 = items.clone().map(|(w, _)| w).sum();
    // SAFETY: every Message is valid when all bytes are zero.
    let mut out: T = unsafe { std::mem::zeroed() };
    let dst = (&mut out as *mut T).cast::<u8>();
    for &(off, prim) in leaves {
        let mut acc = 0.0f64;
        for (w, v) in items.clone() {
            let b = bytes_of(v);
            let x = match prim {
                Prim::F32 => f64::from(f32::from_ne_bytes(
                    b[off..off + 4].try_into().unwrap_or([0; 4]),
                )),
                _ => f64::from_ne_bytes(b[off..off + 8].try_into().unwrap_or([0; 8])),
            };
            acc += w * x;
        }
        let mean = if total > 0.0 { acc / total } else { 0.0 };
        // SAFETY: `off` is the offset of a float field of T (from its schema), in bounds.
        unsafe {
            match prim {
                Prim::F32 => std::ptr::copy_nonoverlapping(
                    (mean as f32).to_ne_bytes().as_ptr(),
                    dst.add(off),
                    4,
                ),
                _ => std::ptr::copy_nonoverlapping(mean.to_ne_bytes().as_ptr(), dst.add(off), 8),
            }
        }
    }
    out
}

pub use skillfab_proto::decl::blend_weights;

/// One proposer of a cycle that settled, as the device's runtime finds it on the board.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// Board slot.
    pub slot: u32,
    /// Current priority.
    pub priority: i32,
    /// Instance name (breaks ties: the name that sorts first wins). Shared with the device's
    /// name cache: a cycle's candidates copy no name.
    pub name: Arc<str>,
}

/// The outcome of arbitrating one channel in one cycle.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Arbitration {
    /// The winner's slot (priority policy); `None` under blend or when nobody proposed.
    pub winner: Option<u32>,
    /// Slots whose proposals made the command, with their weights (1.0 for a priority win);
    /// empty when nobody proposed (the command is the safe one).
    pub weights: Vec<(u32, f64)>,
}

/// Picks the command of a cycle from `proposals` (slot → value) of `candidates`.
pub fn arbitrate<T: Message + Actuation>(
    policy: Policy,
    leaves: Option<&[(usize, Prim)]>,
    candidates: &[Candidate],
    proposal: &dyn Fn(u32) -> Option<T>,
) -> (T, Arbitration) {
    let mut arb = Arbitration::default();
    let cmd = arbitrate_into(policy, leaves, candidates, proposal, &mut arb);
    (cmd, arb)
}

/// [`arbitrate`] into `arb`, whose weights' room is reused: a device's cycle arbitrates
/// without allocating.
pub fn arbitrate_into<T: Message + Actuation>(
    policy: Policy,
    leaves: Option<&[(usize, Prim)]>,
    candidates: &[Candidate],
    proposal: &dyn Fn(u32) -> Option<T>,
    arb: &mut Arbitration,
) -> T {
    arb.winner = None;
    arb.weights.clear();
    match (policy, leaves) {
        (Policy::Blend, Some(leaves)) => {
            // Priority-weighted (negative priorities weigh nothing; all nothing: equal).
            for c in candidates.iter().filter(|c| proposal(c.slot).is_some()) {
                arb.weights.push((c.slot, f64::from(c.priority.max(0))));
            }
            if arb.weights.is_empty() {
                return T::safe();
            }
            if arb.weights.iter().all(|(_, w)| *w == 0.0) {
                arb.weights.iter_mut().for_each(|(_, w)| *w = 1.0);
            }
            let total: f64 = arb.weights.iter().map(|(_, w)| w).sum();
            arb.weights.iter_mut().for_each(|(_, w)| *w /= total);
            // Each proposal once, in the weights' order.
            let mut values = [None::<T>; crate::board::MAX_SLOTS];
            for (i, (slot, _)) in arb.weights.iter().enumerate().take(values.len()) {
                values[i] = proposal(*slot);
            }
            let items = arb
                .weights
                .iter()
                .zip(values.iter())
                .filter_map(|((_, w), v)| v.as_ref().map(|v| (*w, v)));
            blend_by(leaves, items)
        }
        _ => {
            // Highest priority; among equals the name that sorts first (stable across runs,
            // unlike slots or pids).
            let best = candidates
                .iter()
                .filter_map(|c| proposal(c.slot).map(|v| (c, v)))
                .min_by(|(a, _), (b, _)| {
                    b.priority
                        .cmp(&a.priority)
                        .then_with(|| a.name.cmp(&b.name))
                });
            let Some((best, cmd)) = best else {
                return T::safe();
            };
            arb.winner = Some(best.slot);
            arb.weights.push((best.slot, 1.0));
            cmd
        }
    }
}

/// What a channel's last arbitration decided, besides the command itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decision {
    /// The cycle it was made for.
    pub cycle: u64,
    /// The winner's slot (priority policy); `None` under blend or when nobody proposed.
    pub winner: Option<u32>,
    /// Nobody proposed: the command is the channel's safe one.
    pub safe: bool,
}

/// A device's runtime port of one channel, type-erased: the runtime keeps these apart from
/// inputs (a channel is not read, it is arbitrated) and drives them through a cycle.
pub trait ErasedChannel {
    /// Receives every proposal that arrived, keeping each proposer's newest.
    fn poll(&mut self) -> Result<(), crate::SdkError>;
    /// Whether the proposer in `slot` has proposed for `cycle`.
    fn has_proposal(&self, slot: u32, cycle: u64) -> bool;
    /// Turns the proposals of `cycle` from `candidates` into the cycle's command; the
    /// arbitration is the port's until the next cycle.
    fn arbitrate(&mut self, cycle: u64, candidates: &[Candidate]) -> &Arbitration;
    /// The command of the last arbitration (a `&T` of the channel's type) and its decision.
    fn command(&self) -> (&dyn Any, Decision);
    /// Publishes the cycle's command on the channel's command topic.
    fn publish(&mut self, header: SampleHeader) -> Result<(), crate::SdkError>;
}

/// The device-side port of a channel: receives every proposer's proposals, arbitrates, holds
/// the cycle's command, and publishes it on the channel's command topic.
pub struct ChannelPort<T: Actuation> {
    subscriber: Subscriber<ipc::Service, T, SampleHeader>,
    publisher: Publisher<ipc::Service, T, SampleHeader>,
    policy: Policy,
    leaves: Option<Vec<(usize, Prim)>>,
    /// Newest proposal of each proposer slot, copied out: a held sample would count against
    /// the subscriber's few borrowed samples and block receiving the next proposals.
    latest: HashMap<u32, (SampleHeader, T)>,
    command: T,
    decision: Decision,
    /// The last arbitration (its weights' room reused from cycle to cycle).
    arbitration: Arbitration,
}

impl<T: Actuation> ErasedChannel for ChannelPort<T> {
    fn poll(&mut self) -> Result<(), crate::SdkError> {
        loop {
            match self.subscriber.receive() {
                Ok(Some(s)) => {
                    let h = *s.user_header();
                    // A proposal always names its proposer.
                    if let Some(slot) = h.slot.get() {
                        self.latest.insert(slot, (h, *s.payload()));
                    }
                }
                Ok(None) => return Ok(()),
                Err(e) => {
                    return Err(crate::SdkError::transport(
                        &format!("receive proposals of {}", T::TYPE_NAME),
                        e,
                    ));
                }
            }
        }
    }
    fn has_proposal(&self, slot: u32, cycle: u64) -> bool {
        self.latest
            .get(&slot)
            .is_some_and(|(h, _)| h.cycle == cycle)
    }
    fn arbitrate(&mut self, cycle: u64, candidates: &[Candidate]) -> &Arbitration {
        let latest = &self.latest;
        let proposal = |slot: u32| {
            latest
                .get(&slot)
                .filter(|(h, _)| h.cycle == cycle)
                .map(|(_, p)| *p)
        };
        let arb = &mut self.arbitration;
        self.command = arbitrate_into(
            self.policy,
            self.leaves.as_deref(),
            candidates,
            &proposal,
            arb,
        );
        self.decision = Decision {
            cycle,
            winner: arb.winner,
            safe: arb.weights.is_empty(),
        };
        // Forget proposers that left the candidates (dead, deactivated, gone).
        self.latest
            .retain(|slot, _| candidates.iter().any(|c| c.slot == *slot));
        &self.arbitration
    }
    fn command(&self) -> (&dyn Any, Decision) {
        (&self.command, self.decision)
    }
    fn publish(&mut self, header: SampleHeader) -> Result<(), crate::SdkError> {
        let mut s = crate::allocs::in_loan(|| self.publisher.loan_uninit())
            .map_err(|e| crate::SdkError::transport("loan command", e))?
            .write_payload(self.command);
        // A command's header names the winning proposer, not the device.
        *s.user_header_mut() = SampleHeader {
            slot: MaybeSlot::from(self.decision.winner),
            ..header
        };
        s.send()
            .map_err(|e| crate::SdkError::transport("send command", e))?;
        Ok(())
    }
}

/// The command of one channel for this cycle, as a device's body receives it.
#[derive(Debug)]
pub struct Command<'a, T> {
    value: &'a T,
    decision: Decision,
}

impl<T> Command<'_, T> {
    /// True when nobody proposed: the value is the safe command.
    pub fn is_safe(&self) -> bool {
        self.decision.safe
    }
    /// Board slot of the winning proposer (priority policy; `None` under blend).
    pub fn winner_slot(&self) -> Option<u32> {
        self.decision.winner
    }
    /// The cycle it belongs to.
    pub fn cycle(&self) -> u64 {
        self.decision.cycle
    }
}

impl<T> Deref for Command<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.value
    }
}

/// A field type of a `Channels` struct (generated code uses it).
pub trait ChannelField<'a>: Sized {
    /// The channel's declaration (the field name is the channel).
    fn decl(port: &str) -> PortDecl;
    /// The cycle's command of channel `idx`; `None` if it is missing.
    fn fetch(channels: &'a [Box<dyn ErasedChannel>], idx: usize) -> Option<Self>;
    /// The runtime port of channel `idx`.
    fn make(maker: &PortMaker<'_>, idx: usize) -> Result<Box<dyn ErasedChannel>, crate::SdkError>;
}

impl<'a, T: Actuation> ChannelField<'a> for Command<'a, T> {
    fn decl(port: &str) -> PortDecl {
        PortDecl::channel::<T>(port, PortKind::Channel(Policy::Priority))
    }
    fn fetch(channels: &'a [Box<dyn ErasedChannel>], idx: usize) -> Option<Self> {
        let (any, decision) = channels.get(idx)?.command();
        Some(Command {
            value: any.downcast_ref::<T>()?,
            decision,
        })
    }
    fn make(maker: &PortMaker<'_>, idx: usize) -> Result<Box<dyn ErasedChannel>, crate::SdkError> {
        let node = maker.node.ok_or(crate::SdkError::NoNode)?;
        let decl = maker.ports.get(idx).ok_or(crate::SdkError::NoNode)?;
        let policy = match decl.kind {
            PortKind::Channel(p) => p,
            _ => Policy::Priority,
        };
        let leaves = float_leaves(&T::schema());
        if policy == Policy::Blend && leaves.is_none() {
            return Err(crate::SdkError::NotBlendable {
                channel: decl.port.clone(),
                type_name: T::TYPE_NAME.to_string(),
            });
        }
        let channel = decl.channel_name().unwrap_or(&decl.port).to_string();
        Ok(Box::new(ChannelPort::<T> {
            subscriber: crate::services::proposal_subscriber::<T>(node, &decl.topic)?,
            publisher: crate::services::publisher::<T>(
                node,
                &crate::names::command_topic(&channel),
            )?,
            policy,
            leaves,
            latest: HashMap::new(),
            command: T::safe(),
            decision: Decision {
                cycle: 0,
                winner: None,
                safe: true,
            },
            arbitration: Arbitration::default(),
        }))
    }
}

/// The channels a device serves. Derive it with `#[derive(Channels)]` over `Command<'a, T>`
/// fields; `()` is "no channels". A device's declaration lists its channels as its inputs,
/// in field order (the manager numbers a device's channels by that position).
pub trait ChannelSet<'a>: Sized {
    /// Declarations in field order.
    fn ports() -> Vec<PortDecl>;
    /// Every channel's command of the cycle, or `None` if one is missing.
    fn fetch(channels: &'a [Box<dyn ErasedChannel>]) -> Option<Self>;
    /// One runtime port per field, in order.
    fn make(maker: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedChannel>>, crate::SdkError>;
}

impl<'a> ChannelSet<'a> for () {
    fn ports() -> Vec<PortDecl> {
        Vec::new()
    }
    fn fetch(_: &'a [Box<dyn ErasedChannel>]) -> Option<Self> {
        Some(())
    }
    fn make(_: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedChannel>>, crate::SdkError> {
        Ok(Vec::new())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prelude::Message;

    #[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
    #[repr(C)]
    struct Drive {
        translate: f64,
        rotate: f64,
    }
    impl Actuation for Drive {
        fn safe() -> Self {
            Drive::default()
        }
    }
    #[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
    #[repr(C)]
    struct Tick {
        value: u64,
    }

    fn cands() -> Vec<Candidate> {
        [(1, 1, "wander"), (2, 3, "avoid"), (3, 3, "home")]
            .map(|(slot, priority, name)| Candidate {
                slot,
                priority,
                name: name.into(),
            })
            .to_vec()
    }

    #[test]
    fn highest_priority_wins_and_ties_go_to_the_first_name() {
        let p = |slot: u32| {
            Some(Drive {
                translate: f64::from(slot),
                rotate: 0.0,
            })
        };
        let (cmd, arb) = arbitrate(Policy::Priority, None, &cands(), &p);
        assert_eq!(
            arb.winner,
            Some(2),
            "avoid and home tie at 3; 'avoid' sorts first"
        );
        assert_eq!(cmd.translate, 2.0);
        let only_wander = |slot: u32| {
            (slot == 1).then_some(Drive {
                translate: 7.0,
                rotate: 0.5,
            })
        };
        let (cmd, arb) = arbitrate(Policy::Priority, None, &cands(), &only_wander);
        assert_eq!(
            (arb.winner, cmd),
            (
                Some(1),
                Drive {
                    translate: 7.0,
                    rotate: 0.5
                }
            )
        );
    }

    #[test]
    fn blend_is_the_priority_weighted_mean() {
        let leaves = float_leaves(&Drive::schema()).unwrap();
        let p = |slot: u32| match slot {
            1 => Some(Drive {
                translate: 1.0,
                rotate: -1.0,
            }),
            2 => Some(Drive {
                translate: 5.0,
                rotate: 3.0,
            }),
            _ => None,
        };
        let (cmd, arb) = arbitrate(Policy::Blend, Some(&leaves), &cands(), &p);
        // weights 1 and 3: (1·1 + 3·5)/4 = 4, (1·-1 + 3·3)/4 = 2
        assert_eq!(
            cmd,
            Drive {
                translate: 4.0,
                rotate: 2.0
            }
        );
        assert_eq!(arb.weights, vec![(1, 0.25), (2, 0.75)]);
    }

    #[test]
    fn nobody_proposing_gives_the_safe_command() {
        let (cmd, arb) = arbitrate::<Drive>(Policy::Priority, None, &cands(), &|_| None);
        assert_eq!(cmd, Drive::safe());
        assert_eq!(arb, Arbitration::default());
    }

    #[test]
    fn non_float_types_are_not_blendable() {
        assert!(float_leaves(&Tick::schema()).is_none());
        assert_eq!(float_leaves(&Drive::schema()).unwrap().len(), 2);
    }
}
