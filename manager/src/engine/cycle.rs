//! The cycle state machine: plan, start, resolve what can no longer run, finish (the
//! paper's do-periodic-step, do-next-skill and cleanup).

use super::{IDLE_FREE_RUN, Manager, ManagerError, Pace, Running};
use crate::graph::{self, PlanNode};
use skillfab_proto::board::{MAX_OUTPUTS, MAX_SLOTS, RunStatus};
use skillfab_proto::control::EventKind;
use skillfab_proto::header::now_ns;
use skillfab_proto::names;
use std::sync::atomic::Ordering;
use std::time::Instant;

impl Manager {
    /// Drives the cycle state machine as far as it can go now.
    pub(super) fn advance(&mut self) -> Result<(), ManagerError> {
        loop {
            if let Some(k) = self.cycles.running.as_ref().map(|r| r.k) {
                self.resolve();
                if self.board.remaining(k) == 0 {
                    self.finish(false);
                } else if self
                    .cycles
                    .running
                    .as_ref()
                    .is_some_and(|r| Instant::now() >= r.deadline)
                {
                    self.check_liveness();
                    if self.board.remaining(k) == 0 {
                        self.finish(false);
                    } else {
                        let unfinished = self.board.remaining(k);
                        tracing::warn!(cycle = k, unfinished, "cycle overrun");
                        self.events.push(EventKind::CycleOverrun { unfinished });
                        self.finish(true);
                    }
                } else {
                    return Ok(());
                }
            }
            if self.cycles.stop_at.is_some_and(|t| self.cycles.cycle >= t) {
                self.cycles.stop_at = None;
                self.set_paused(true);
            }
            if self.cycles.paused
                || self
                    .config
                    .max_cycles
                    .is_some_and(|m| self.cycles.cycle >= m)
            {
                self.cycles.on_schedule = false;
                return Ok(());
            }
            if self.cycles.holds.blocks(self.cycles.cycle) {
                self.cycles.on_schedule = false;
                if let Some(cycle) = self.cycles.holds.reached(self.cycles.cycle) {
                    self.events.push(EventKind::Held { cycle });
                }
                return Ok(());
            }
            if !self.cycles.started {
                let missing: Vec<String> = self
                    .config
                    .wait_for
                    .iter()
                    .filter(|n| !self.skills.all().any(|e| e.ready && &e.decl.name == *n))
                    .cloned()
                    .collect();
                if !missing.is_empty() {
                    if self.cycles.created.elapsed() > self.config.wait_timeout {
                        return Err(ManagerError::MissingSkills {
                            missing,
                            waited: self.config.wait_timeout,
                        });
                    }
                    return Ok(());
                }
                self.cycles.started = true;
                self.cycles.next_start = Instant::now();
            }
            let now = Instant::now();
            match self.config.pace {
                Pace::Period(p) => {
                    if now < self.cycles.next_start {
                        return Ok(());
                    }
                    self.cycles.next_start += p;
                    if self.cycles.next_start < now {
                        // More than a period after its scheduled start: a late start, unless
                        // cycling was paused or held (its schedule starts again now).
                        if self.cycles.on_schedule {
                            self.cycles.stats.late_starts += 1;
                        }
                        self.cycles.next_start = now;
                    }
                    self.cycles.on_schedule = true;
                }
                Pace::FreeRun | Pace::LockStep(_) => {
                    if self.cycles.plan.expected.is_empty() && !self.cycles.dirty {
                        if now < self.cycles.next_start {
                            return Ok(());
                        }
                        self.cycles.next_start = now + IDLE_FREE_RUN;
                    }
                }
            }
            self.start_cycle();
        }
    }

    pub(super) fn replan(&mut self) {
        let nodes: Vec<PlanNode<'_>> = self
            .skills
            .in_order()
            .filter_map(|(s, e)| {
                Some(e).filter(|e| e.ready).map(|e| PlanNode {
                    slot: s,
                    decl: &e.decl,
                    active: e.active,
                })
            })
            .collect();
        self.cycles.plan = graph::plan(&nodes);
        let plan = &self.cycles.plan;
        self.cycles.spinners = plan
            .expected
            .iter()
            .copied()
            .filter(|&s| {
                self.board.slot(s).spin_ns.load(Ordering::Acquire) != 0
                    && !plan.sources.contains(&s)
            })
            .collect();
        for &(slot, mask) in &self.cycles.plan.fresh_masks {
            self.board
                .slot(slot)
                .fresh_mask
                .store(mask, Ordering::Release);
        }
        for (s, e) in self.skills.in_order() {
            let slot = self.board.slot(s);
            slot.active.store(
                self.skills.activation(&e.decl.name, e.active),
                Ordering::Release,
            );
            slot.priority.store(e.decl.priority, Ordering::Release);
            // Whom each of its outputs wakes: every registered unit reading that topic.
            for (o, out) in e.decl.outputs.iter().enumerate().take(MAX_OUTPUTS) {
                let readers = self
                    .skills
                    .in_order()
                    .filter(|(_, c)| c.decl.inputs.iter().any(|i| i.topic == out.topic))
                    .fold(0u64, |m, (c, _)| m | 1 << c);
                slot.consumers[o].store(readers, Ordering::Release);
            }
        }
        for ch in &self.cycles.plan.channels {
            if ch.index < skillfab_proto::board::MAX_CHANNELS {
                self.board.slot(ch.device).channel_proposers[ch.index]
                    .store(ch.proposers, Ordering::Release);
            }
            // Read the commands from now on (queries find the latest one).
            let topic = names::command_topic(&ch.channel);
            let schema = self
                .skills
                .get(ch.device)
                .and_then(|e| e.decl.inputs.get(ch.index))
                .map(|p| p.schema.clone());
            if let Some(schema) = schema
                && let Err(e) = self.observers.read(&self.node, &topic, &schema)
            {
                tracing::warn!(%topic, error = %e, "cannot read commands");
            }
        }
        self.cycles.dirty = false;
        self.observers
            .update_recording(&self.skills, &self.node, self.cycles.cycle);
    }

    pub(super) fn start_cycle(&mut self) {
        self.stamp_events();
        if self.cycles.dirty {
            self.replan();
        }
        let k = self.cycles.cycle + 1;
        for &s in &self.cycles.plan.expected {
            self.board
                .slot(s)
                .expected_cycle
                .store(k, Ordering::Release);
        }
        self.board.arm(k, self.cycles.plan.expected.len() as u32);
        let mut run = Running {
            k,
            start_ns: 0,
            deadline: Instant::now() + self.config.deadline(),
            expected: self.cycles.plan.expected.iter().fold(0, |m, &s| m | 1 << s),
            processed: [false; MAX_SLOTS],
            cancelled: [false; MAX_SLOTS],
        };
        // The cycle starts when it is published and its sources woken: the book-keeping
        // above comes first, as the floors' driver stamps right before its wake-up. (Stamped
        // before the cycle number is published: a unit that is awake may run at once.)
        let h = self.board.header();
        run.start_ns = now_ns();
        h.cycle_start_ns.store(run.start_ns, Ordering::Release);
        let time = match self.config.clock_period() {
            Some(p) => (p.as_nanos() as u64).saturating_mul(k),
            None => run.start_ns,
        };
        h.cycle_time_ns.store(time, Ordering::Release);
        h.cycle.store(k, Ordering::Release);
        for &s in &self.cycles.plan.sources {
            self.board.slot(s).bell.ring();
        }
        // Units in spin mode are woken now too, after the sources: their wake-up overlaps
        // their producers' runs, and the rings that carry their inputs find them polling.
        for &s in &self.cycles.spinners {
            self.board.slot(s).bell.ring();
        }
        self.cycles.running = Some(run);
    }

    /// Looks at runs of the current cycle that finished without passing everything on, and
    /// takes the consumers that can no longer run off the completion counter.
    pub(super) fn resolve(&mut self) {
        let Some(mut run) = self.cycles.running.take() else {
            return;
        };
        let mut cancel = Vec::new();
        for &s in &self.cycles.plan.expected {
            let slot = self.board.slot(s);
            if run.processed[s] || slot.done_cycle.load(Ordering::Acquire) != run.k {
                continue;
            }
            run.processed[s] = true;
            let status = RunStatus::from_u32(slot.status.load(Ordering::Acquire));
            let mask = slot.published_mask.load(Ordering::Acquire);
            if let Some(per_output) = self.cycles.plan.consumers.get(&s) {
                for (o, consumers) in per_output.iter().enumerate() {
                    if status != RunStatus::Ok || mask & (1 << o) == 0 {
                        cancel.extend_from_slice(consumers);
                    }
                }
            }
        }
        let n = self.cancel_all(&mut run, cancel);
        if n > 0 {
            self.board.complete(run.k, n);
        }
        self.cycles.running = Some(run);
    }

    /// Marks `start` and everything downstream of it as unable to run in this cycle; returns
    /// how many expected runs that removed.
    pub(super) fn cancel_all(&self, run: &mut Running, mut todo: Vec<usize>) -> u32 {
        let mut n = 0;
        while let Some(s) = todo.pop() {
            if run.cancelled[s]
                || run.expected & 1 << s == 0
                || self.board.slot(s).done_cycle.load(Ordering::Acquire) == run.k
            {
                continue;
            }
            run.cancelled[s] = true;
            n += 1;
            self.board
                .slot(s)
                .cancelled_cycle
                .store(run.k, Ordering::Release);
            // A device waiting for this skill's proposal must look again.
            for ch in self
                .cycles
                .plan
                .channels
                .iter()
                .filter(|c| c.proposers & (1 << s) != 0)
            {
                self.board.slot(ch.device).bell.ring();
            }
            if let Some(per_output) = self.cycles.plan.consumers.get(&s) {
                todo.extend(per_output.iter().flatten());
            }
        }
        n
    }

    pub(super) fn finish(&mut self, overrun: bool) {
        let Some(run) = self.cycles.running.take() else {
            return;
        };
        let end = self
            .cycles
            .plan
            .expected
            .iter()
            .map(|&s| self.board.slot(s))
            .filter(|slot| slot.done_cycle.load(Ordering::Acquire) == run.k)
            .map(|slot| slot.last_end_ns.load(Ordering::Acquire))
            .max();
        // Handled now: the manager was woken by the run that completed the cycle (or by its
        // deadline), so this is the round trip back to the driver.
        let round_trip = now_ns().saturating_sub(run.start_ns);
        let latency = if overrun {
            round_trip
        } else {
            end.map_or(0, |e| e.saturating_sub(run.start_ns))
        };
        self.cycles.stats.record(latency, round_trip, overrun);
        self.count_deadline_misses(&run);
        self.cycles.cycle = run.k;
        let seen = self.observers.end_of_cycle(
            run.k,
            &self.board,
            &self.cycles.plan.channels,
            &self.skills,
        );
        self.state.check |= seen.monitors_changed;
        // The firings first, then the pause they cause.
        for event in seen.events {
            self.events.push(event);
        }
        // In lock-step a monitor that fires pauses cycling after this cycle (ending a `step`
        // early): its owner reacts and resumes (`run`, `step`), so what a sequencer does in
        // reaction lands in the same cycle every run.
        if seen.fired && self.config.pace.is_lockstep() {
            self.set_paused(true);
            self.cycles.stop_at = None;
        }
        self.stamp_events();
    }

    /// Counts the deadline misses of the finished cycle `run` on the board, per unit. An
    /// expected unit missed the cycle's deadline (cycle start + the configured deadline) when
    /// - its run for the cycle ended after the deadline (even if the cycle was not closed as
    ///   an overrun: the manager closes a cycle when it next looks), or
    /// - it had not finished when the deadline closed the cycle, though it was running (its run
    ///   started in the cycle) or could have run: every unit it waits for (the producers of its
    ///   same-cycle inputs, a device's proposers) had finished.
    ///
    /// A unit cancelled because an upstream run failed did not miss (it could not run), nor one
    /// that waited for a late upstream unit: the miss is that unit's.
    fn count_deadline_misses(&self, run: &Running) {
        let deadline_ns = run
            .start_ns
            .saturating_add(self.config.deadline().as_nanos() as u64);
        let done = |s: usize| self.board.slot(s).done_cycle.load(Ordering::Acquire) == run.k;
        for &s in &self.cycles.plan.expected {
            let slot = self.board.slot(s);
            let missed = if done(s) {
                slot.last_end_ns.load(Ordering::Acquire) > deadline_ns
            } else if run.cancelled[s] {
                false
            } else {
                let running = slot.last_start_ns.load(Ordering::Acquire) >= run.start_ns;
                running || !self.waits_for_unfinished(run, s, &done)
            };
            if missed {
                slot.deadline_misses.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Whether unit `s` waits, in cycle `run`, for an expected unit that has not finished: a
    /// producer of one of its same-cycle inputs, or, for a device, a proposer on its channels.
    fn waits_for_unfinished(&self, run: &Running, s: usize, done: &dyn Fn(usize) -> bool) -> bool {
        let plan = &self.cycles.plan;
        let producer_late = plan.consumers.iter().any(|(&p, per_output)| {
            p != s && per_output.iter().any(|c| c.contains(&s)) && !done(p) && !run.cancelled[p]
        });
        let proposer_late = plan.channels.iter().filter(|c| c.device == s).any(|c| {
            plan.expected
                .iter()
                .any(|&p| c.proposers & (1 << p) != 0 && !done(p) && !run.cancelled[p])
        });
        producer_late || proposer_late
    }

    /// Numbers the events queued so far, stamps them with the cycle they belong to (the last
    /// one completed) and puts them in the recording; the control plane publishes them. Done
    /// between cycles (when one ends, before the next starts, and when the control plane
    /// publishes), so an event's cycle and its place among the recorded samples are the
    /// run's, not the host's timing of the manager's loop.
    pub(crate) fn stamp_events(&mut self) {
        let stamped = self.events.stamp(self.cycles.cycle);
        self.observers.record_events(stamped);
    }

    /// Starts or stops cycling.
    pub(crate) fn set_paused(&mut self, paused: bool) {
        if self.cycles.paused != paused {
            self.cycles.paused = paused;
            self.events.push(EventKind::Cycling { running: !paused });
            if !paused {
                self.cycles.next_start = Instant::now();
            }
        }
    }
}
