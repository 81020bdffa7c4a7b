//! What the manager reads at the end of a cycle: the I/O log's samples, each channel's
//! arbitration, and the monitors.

use super::*;

impl Manager {
    /// Copies the new samples of the I/O-logged skills to the fabric log (decoded there).
    pub(super) fn log_io(&mut self) {
        let Some(rec) = self.recorder.as_ref() else {
            return;
        };
        let mut polled = HashSet::new();
        for (skill, ports) in &mut self.io_log {
            for p in ports.iter_mut() {
                let Some(reader) = self.readers.get_mut(&p.topic) else {
                    continue;
                };
                if polled.insert(p.topic.clone())
                    && let Err(e) = reader.poll()
                {
                    tracing::warn!(topic = %p.topic, error = %e, "I/O log read failed");
                }
                let Some((bytes, h)) = reader.latest_of(p.slot) else {
                    continue;
                };
                if h.cycle <= p.last {
                    continue;
                }
                p.last = h.cycle;
                rec.sample(IoSample {
                    cycle: h.cycle,
                    skill: skill.clone(),
                    dir: p.dir,
                    port: p.port.clone(),
                    topic: p.topic.clone(),
                    type_name: p.type_name.clone(),
                    stamp_ns: h.stamp_ns,
                    field: p.field.clone(),
                    bytes: bytes.to_vec(),
                    raw: false,
                });
            }
        }
    }

    /// Reads each channel's arbitration of cycle `k` from the board; a new winner is an event.
    pub(super) fn read_channels(&mut self, k: u64) {
        let name_of = |s: usize| self.skills.get(s).map(|e| e.decl.name.clone());
        let mut changes = Vec::new();
        for ch in &self.plan.channels {
            if ch.index >= skillfab_proto::board::MAX_CHANNELS {
                continue;
            }
            let slot = self.board.slot(ch.device);
            if slot.channel_cycle[ch.index].load(Ordering::Acquire) != k {
                continue;
            }
            let winner = slot.channel_winner[ch.index].load(Ordering::Acquire);
            let mask = slot.channel_mask[ch.index].load(Ordering::Acquire);
            let winner = (winner > 0).then(|| name_of(winner as usize - 1)).flatten();
            let contributors: Vec<usize> =
                (0..MAX_SLOTS).filter(|s| mask & (1 << s) != 0).collect();
            let weights: Vec<f64> = if ch.policy == skillfab_proto::decl::Policy::Priority {
                vec![1.0; contributors.len()]
            } else {
                let priorities: Vec<i32> = contributors
                    .iter()
                    .map(|&s| self.board.slot(s).priority.load(Ordering::Acquire))
                    .collect();
                skillfab_proto::decl::blend_weights(&priorities)
            };
            // By name: slots follow the order in which processes happened to register.
            let mut weights: Vec<(String, f64)> = contributors
                .iter()
                .zip(weights)
                .filter_map(|(&s, w)| name_of(s).map(|n| (n, w)))
                .collect();
            weights.sort_by(|a, b| a.0.cmp(&b.0));
            let view = ChannelView {
                device: name_of(ch.device).unwrap_or_default(),
                policy: ch.policy,
                cycle: k,
                winner,
                weights,
            };
            let changed = self.channels.get(&ch.channel).is_none_or(|old| {
                old.winner != view.winner
                    || old
                        .weights
                        .iter()
                        .map(|w| &w.0)
                        .ne(view.weights.iter().map(|w| &w.0))
            });
            if changed {
                changes.push(EventKind::ChannelWinner {
                    channel: ch.channel.clone(),
                    winner: view.winner.clone(),
                    weights: view.weights.clone(),
                });
            }
            self.channels.insert(ch.channel.clone(), view);
        }
        self.outbox.extend(changes);
    }

    /// Evaluates every monitor on the newest samples of the cycle that just finished. In
    /// lock-step a monitor that fires pauses cycling after this cycle (ending a `step` early):
    /// its owner reacts and resumes (`run`, `step`), so what a sequencer does in reaction
    /// lands in the same cycle every run.
    pub(super) fn evaluate_monitors(&mut self) {
        for t in &self.monitors.topics() {
            if let Some(r) = self.readers.get_mut(t)
                && let Err(e) = r.poll()
            {
                tracing::warn!(topic = %t, error = %e, "monitor read failed");
            }
        }
        let readers = &self.readers;
        let latest = |r: &crate::monitors::Resolved| readers.get(&r.topic)?.latest_of(r.slot);
        let value = |r: &crate::monitors::Resolved| r.field.read(latest(r)?.0);
        let stamp = |r: &crate::monitors::Resolved| latest(r).map(|(_, h)| h.stamp_ns);
        let before = self.monitors.len();
        let fired = self.monitors.evaluate(self.cycle, &value, &stamp);
        // A `Once` monitor that fired is gone from the state file.
        self.state_check |= self.monitors.len() != before;
        let any = !fired.is_empty();
        // The firings first, then the pause they cause.
        self.outbox.extend(fired);
        if any && matches!(self.config.pace, Pace::LockStep(_)) {
            self.set_paused(true);
            // A `step` in progress ends here too (its answer says at which cycle): its client
            // reacts to the firing first.
            self.stop_at = None;
        }
    }
}
