//! A device's arbitration: which proposers of the cycle have settled, and one command per
//! channel from their proposals (the policy itself is the channel's, in `actuation`).

use super::Io;
use crate::board::{Board, MAX_CHANNELS, MAX_SLOTS, Slot};
use crate::decl::SkillDecl;
use crate::ports::Candidate;
use std::collections::HashMap;
use std::sync::atomic::Ordering;

/// A proposer that settled in the cycle: its slot, priority and name.
pub(super) type Settled = (u32, i32, String);

/// The arbitration state a device keeps between cycles.
#[derive(Default)]
pub(super) struct Arbiter {
    /// Proposer names by slot, with the slot generation they belong to: a name is decoded
    /// from the board's declaration once per registration, not once per cycle.
    names: HashMap<u32, (u32, String)>,
}

impl Arbiter {
    /// The proposers of each channel in cycle `k`, once every one the manager expects has
    /// settled: its proposal for k is in, or it finished k without proposing (it then wakes
    /// the device), or it was cancelled. `None` while one may still propose.
    pub(super) fn settled(
        &mut self,
        board: &Board,
        me: &Slot,
        io: &mut Io,
        k: u64,
    ) -> Option<Vec<Vec<Settled>>> {
        let mut channels = Vec::new();
        for c in 0..io.inputs.len().min(MAX_CHANNELS) {
            let mask = me.channel_proposers[c].load(Ordering::Acquire);
            let mut settled = Vec::new();
            for s in (0..MAX_SLOTS).filter(|s| mask & (1 << s) != 0) {
                let p = board.slot(s);
                if p.expected_cycle.load(Ordering::Acquire) != k {
                    continue;
                }
                let proposed = io.inputs[c]
                    .as_channel()
                    .is_some_and(|ch| ch.has_proposal(s as u32, k));
                let done = proposed
                    || p.done_cycle.load(Ordering::Acquire) == k
                    || p.cancelled_cycle.load(Ordering::Acquire) == k;
                if !done {
                    return None;
                }
                let name = self.name_of(p, s as u32);
                settled.push((s as u32, p.priority.load(Ordering::Acquire), name));
            }
            channels.push(settled);
        }
        Some(channels)
    }

    /// The instance name of the skill in slot `s` (cached per registration).
    fn name_of(&mut self, p: &Slot, s: u32) -> String {
        let generation = p.generation.load(Ordering::Acquire);
        match self.names.get(&s) {
            Some((g, n)) if *g == generation => n.clone(),
            _ => {
                let n = postcard::from_bytes::<SkillDecl>(&p.read_decl())
                    .map(|d| d.name)
                    .unwrap_or_else(|_| format!("slot{s}"));
                self.names.insert(s, (generation, n.clone()));
                n
            }
        }
    }

    /// Picks each channel's command of cycle `k` among its settled proposers and records the
    /// winner and contributors on the board (the manager reports them).
    pub(super) fn arbitrate(me: &Slot, io: &mut Io, channels: &[Vec<Settled>], k: u64) {
        for (c, settled) in channels.iter().enumerate() {
            let Some(ch) = io.inputs[c].as_channel() else {
                continue;
            };
            let candidates: Vec<Candidate<'_>> = settled
                .iter()
                .map(|(slot, priority, name)| Candidate {
                    slot: *slot,
                    priority: *priority,
                    name,
                })
                .collect();
            let arb = ch.arbitrate(k, &candidates);
            me.channel_winner[c].store(arb.winner.map_or(0, |w| w + 1), Ordering::Relaxed);
            me.channel_mask[c].store(
                arb.weights.iter().fold(0u64, |m, (s, _)| m | (1 << s)),
                Ordering::Relaxed,
            );
            me.channel_cycle[c].store(k, Ordering::Release);
        }
    }
}
