//! Actuator channels: the command type's contract, the device-side port that arbitrates among
//! the proposals of a cycle, and the `Command<'a, T>` a device's body receives.
//!
//! Skills propose through [`Proposal`](crate::ports::Proposal) outputs; a device declares the
//! channels it serves as `Command<'a, T>` fields. Proposals travel straight from proposer to
//! device (one topic per channel, many publishers): arbitration adds no process hop.

use crate::Message;
use crate::decl::{Policy, PortDecl, PortKind};
use crate::header::SampleHeader;
use crate::ports::{
    Arbitration, Candidate, ErasedChannel, ErasedInput, InputField, InputMeta, InputSource,
    PortMaker,
};
use crate::schema::{FieldKind, MessageSchema, Prim};
use crate::value::kind_size;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use std::any::Any;
use std::collections::HashMap;
use std::ops::Deref;

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
    let total: f64 = items.iter().map(|(w, _)| *w).sum();
    // SAFETY: every Message is valid when all bytes are zero.
    let mut out: T = unsafe { std::mem::zeroed() };
    let dst = (&mut out as *mut T).cast::<u8>();
    for &(off, prim) in leaves {
        let mut acc = 0.0f64;
        for (w, v) in items {
            let b = bytes_of(*v);
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

/// Picks the command of a cycle from `proposals` (slot → value) of `candidates`.
pub fn arbitrate<T: Message + Actuation>(
    policy: Policy,
    leaves: Option<&[(usize, Prim)]>,
    candidates: &[Candidate<'_>],
    proposal: &dyn Fn(u32) -> Option<T>,
) -> (T, Arbitration) {
    let live: Vec<(&Candidate<'_>, T)> = candidates
        .iter()
        .filter_map(|c| proposal(c.slot).map(|v| (c, v)))
        .collect();
    if live.is_empty() {
        return (T::safe(), Arbitration::default());
    }
    match (policy, leaves) {
        (Policy::Blend, Some(leaves)) => {
            let priorities: Vec<i32> = live.iter().map(|(c, _)| c.priority).collect();
            let w = blend_weights(&priorities);
            let items: Vec<(f64, &T)> =
                w.iter().copied().zip(live.iter().map(|(_, v)| v)).collect();
            let cmd = blend(leaves, &items);
            let weights = live
                .iter()
                .zip(&w)
                .map(|((c, _), x)| (c.slot, *x))
                .collect();
            (
                cmd,
                Arbitration {
                    winner: None,
                    weights,
                },
            )
        }
        _ => {
            // Highest priority; among equals the name that sorts first (stable across runs,
            // unlike slots or pids).
            let (best, cmd) = live
                .iter()
                .min_by(|(a, _), (b, _)| {
                    b.priority.cmp(&a.priority).then_with(|| a.name.cmp(b.name))
                })
                .map(|(c, v)| (*c, *v))
                .unwrap_or((live[0].0, live[0].1));
            (
                cmd,
                Arbitration {
                    winner: Some(best.slot),
                    weights: vec![(best.slot, 1.0)],
                },
            )
        }
    }
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
    header: SampleHeader,
    winner: Option<u32>,
}

impl<T: Actuation> ErasedInput for ChannelPort<T> {
    fn poll(&mut self) -> Result<(), crate::SdkError> {
        loop {
            match self.subscriber.receive() {
                Ok(Some(s)) => {
                    self.latest
                        .insert(s.user_header().slot, (*s.user_header(), *s.payload()));
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
    fn latest_header(&self) -> Option<SampleHeader> {
        Some(self.header)
    }
    fn latest_any(&self) -> Option<&dyn Any> {
        Some(&self.command)
    }
    fn is_fresh(&self) -> bool {
        false
    }
    fn consume(&mut self) {}
    fn as_channel(&mut self) -> Option<&mut dyn ErasedChannel> {
        Some(self)
    }
}

impl<T: Actuation> ErasedChannel for ChannelPort<T> {
    fn arbitrate(&mut self, cycle: u64, candidates: &[Candidate<'_>]) -> Arbitration {
        let latest = &self.latest;
        let proposal = |slot: u32| {
            latest
                .get(&slot)
                .filter(|(h, _)| h.cycle == cycle)
                .map(|(_, p)| *p)
        };
        let (cmd, arb) = arbitrate(self.policy, self.leaves.as_deref(), candidates, &proposal);
        self.command = cmd;
        self.winner = arb.winner;
        self.header = SampleHeader {
            cycle,
            stamp_ns: crate::header::now_ns(),
            slot: arb.winner.unwrap_or(u32::MAX),
            reserved: 0,
        };
        // Forget proposers that left the candidates (dead, deactivated, gone).
        self.latest
            .retain(|slot, _| candidates.iter().any(|c| c.slot == *slot));
        arb
    }
    fn has_proposal(&self, slot: u32, cycle: u64) -> bool {
        self.latest
            .get(&slot)
            .is_some_and(|(h, _)| h.cycle == cycle)
    }
    fn publish(&mut self, header: SampleHeader) -> Result<(), crate::SdkError> {
        let mut s = self
            .publisher
            .loan_uninit()
            .map_err(|e| crate::SdkError::transport("loan command", e))?
            .write_payload(self.command);
        *s.user_header_mut() = SampleHeader {
            slot: self.header.slot,
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
    meta: InputMeta,
}

impl<T> Command<'_, T> {
    /// True when nobody proposed: the value is the safe command.
    pub fn is_safe(&self) -> bool {
        self.meta.source.is_none()
    }
    /// Board slot of the winning proposer (priority policy).
    pub fn winner_slot(&self) -> Option<u32> {
        self.meta.source
    }
    /// The cycle it belongs to.
    pub fn cycle(&self) -> u64 {
        self.meta.cycle
    }
}

impl<T> Deref for Command<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.value
    }
}

impl<'a, T: Actuation> InputField<'a> for Command<'a, T> {
    fn decl(port: &str) -> PortDecl {
        PortDecl::channel::<T>(port, PortKind::Channel(Policy::Priority))
    }
    fn fetch(src: &'a dyn InputSource, idx: usize) -> Option<Self> {
        let (any, meta) = src.get(idx)?;
        Some(Command {
            value: any.downcast_ref::<T>()?,
            meta,
        })
    }
    fn make(maker: &PortMaker<'_>, idx: usize) -> Result<Box<dyn ErasedInput>, crate::SdkError> {
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
            header: SampleHeader::default(),
            winner: None,
        }))
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

    fn cands() -> Vec<Candidate<'static>> {
        vec![
            Candidate {
                slot: 1,
                priority: 1,
                name: "wander",
            },
            Candidate {
                slot: 2,
                priority: 3,
                name: "avoid",
            },
            Candidate {
                slot: 3,
                priority: 3,
                name: "home",
            },
        ]
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
