//! A device's arbitration: which proposers of the cycle have settled, and one command per
//! channel from their proposals (the policy itself is the channel's, in `actuation`).

use super::Io;
use crate::actuation::Candidate;
use crate::board::{Board, MAX_CHANNELS, MAX_SLOTS, Slot};
use crate::decl::SkillDecl;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// The arbitration state a device keeps between cycles.
#[derive(Default)]
pub(super) struct Arbiter {
    /// Proposer names by slot, with the slot generation they belong to: a name is decoded
    /// from the board's declaration once per registration, not once per cycle.
    names: HashMap<u32, (u32, Arc<str>)>,
    /// The settled candidates of each channel, refilled every cycle (their room is kept: a
    /// cycle allocates nothing).
    channels: Vec<Vec<Candidate>>,
}

impl Arbiter {
    /// The candidates of each channel in cycle `k`, once every proposer the manager expects
    /// has settled: its proposal for k is in, or it finished k without proposing (it then
    /// wakes the device), or it was cancelled. `None` while one may still propose.
    pub(super) fn settled(
        &mut self,
        board: &Board,
        me: &Slot,
        io: &Io,
        k: u64,
    ) -> Option<&[Vec<Candidate>]> {
        let n = io.channels.len().min(MAX_CHANNELS);
        self.channels.resize_with(n, Vec::new);
        for (c, channel) in io.channels.iter().enumerate().take(n) {
            let mask = me.channel_proposers[c].load(Ordering::Acquire);
            let mut settled = std::mem::take(&mut self.channels[c]);
            settled.clear();
            for s in (0..MAX_SLOTS).filter(|s| mask & (1 << s) != 0) {
                let p = board.slot(s);
                if p.expected_cycle.load(Ordering::Acquire) != k {
                    continue;
                }
                let done = channel.has_proposal(s as u32, k)
                    || p.done_cycle.load(Ordering::Acquire) == k
                    || p.cancelled_cycle.load(Ordering::Acquire) == k;
                if !done {
                    self.channels[c] = settled;
                    return None;
                }
                settled.push(Candidate {
                    slot: s as u32,
                    priority: p.priority.load(Ordering::Acquire),
                    name: self.name_of(p, s as u32),
                });
            }
            self.channels[c] = settled;
        }
        Some(&self.channels)
    }

    /// The instance name of the skill in slot `s` (cached per registration).
    fn name_of(&mut self, p: &Slot, s: u32) -> Arc<str> {
        let generation = p.generation.load(Ordering::Acquire);
        match self.names.get(&s) {
            Some((g, n)) if *g == generation => n.clone(),
            _ => {
                let n: Arc<str> = postcard::from_bytes::<SkillDecl>(&p.read_decl())
                    .map(|d| d.name)
                    .unwrap_or_else(|_| format!("slot{s}"))
                    .into();
                self.names.insert(s, (generation, n.clone()));
                n
            }
        }
    }

    /// Picks each channel's command of cycle `k` among its settled candidates and records the
    /// winner and contributors on the board (the manager reports them).
    pub(super) fn arbitrate(me: &Slot, io: &mut Io, channels: &[Vec<Candidate>], k: u64) {
        for (c, (candidates, ch)) in channels.iter().zip(io.channels.iter_mut()).enumerate() {
            let arb = ch.arbitrate(k, candidates);
            me.channel_winner[c].store(arb.winner, Ordering::Relaxed);
            me.channel_mask[c].store(
                arb.weights.iter().fold(0u64, |m, (s, _)| m | (1 << s)),
                Ordering::Relaxed,
            );
            me.channel_cycle[c].store(k, Ordering::Release);
        }
    }
}
