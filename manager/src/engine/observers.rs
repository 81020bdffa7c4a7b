//! The observers of the fabric: everything that reads the skills' samples from outside the
//! cycle — the topic readers they share, the monitors, the fabric log and its I/O log, the
//! full-rate recording, each channel's last arbitration, and the bridges' reports. They read
//! at the end of a cycle ([`Observers::end_of_cycle`]) and when a client asks (the requests in
//! `requests/`); none of them is on a cycle's path.

use super::record::Recording;
use crate::graph::ChannelPlan;
use crate::monitors::Monitors;
use crate::recorder::{IoSample, Recorder, SampleSource};
use iceoryx2::node::Node;
use iceoryx2::prelude::*;
use skillfab_proto::board::{Board, MAX_CHANNELS, MAX_SLOTS};
use skillfab_proto::bridge::BridgeStats;
use skillfab_proto::control::{ControlError, EventKind};
use skillfab_proto::decl::{Policy, PortDecl};
use skillfab_proto::schema::MessageSchema;
use skillfab_proto::services::RawReader;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::skills::Skills;

/// The observers' state (see the module's documentation).
#[derive(Default)]
pub(crate) struct Observers {
    /// Untyped readers of the topics that monitors, queries, the I/O log and the recording
    /// read, by topic.
    pub(crate) readers: HashMap<String, RawReader>,
    /// Installed monitors, and the `Once` ones that fired.
    pub(crate) monitors: Monitors,
    /// Clients holding monitors whose process was first seen dead then.
    orphans: Orphans,
    /// The fabric log's writer (`None` if its file could not be opened).
    pub(crate) fabric_log: Option<Recorder>,
    /// Skills whose samples are logged to the fabric log, with their ports.
    pub(crate) io_log: HashMap<String, Vec<IoPort>>,
    /// The full-rate recording, when one runs.
    pub(crate) recording: Option<Recording>,
    /// Last arbitration seen per channel.
    pub(crate) channels: HashMap<String, ChannelView>,
    /// The last report of each bridge of the domain, and when it came.
    pub(crate) bridges: BTreeMap<String, (BridgeStats, Instant)>,
}

/// A port whose samples go to the fabric log.
pub(crate) struct IoPort {
    /// The skill, port and type of its samples (shared by each of them).
    pub(crate) source: Arc<SampleSource>,
    /// On a proposal topic, the proposer's slot.
    pub(crate) slot: Option<u32>,
    /// The cycle of the last sample logged (each sample once).
    pub(crate) last: u64,
}

/// The latest arbitration of a channel, as the manager last read it from the board.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ChannelView {
    pub(crate) device: String,
    pub(crate) policy: Policy,
    pub(crate) cycle: u64,
    pub(crate) winner: Option<String>,
    pub(crate) weights: Vec<(String, f64)>,
}

/// What the observers found at the end of a cycle.
#[derive(Debug, Default)]
pub(crate) struct Observed {
    /// New channel winners, then monitor firings, in that order.
    pub(crate) events: Vec<EventKind>,
    /// A monitor fired.
    pub(crate) fired: bool,
    /// A `Once` monitor that fired is gone (the state file changes).
    pub(crate) monitors_changed: bool,
}

/// The refusal of a request that needs a reader of `topic` iceoryx2 would not open or poll
/// (the cause goes to the manager's log).
pub(crate) fn cannot_read(topic: &str, error: &skillfab_proto::Error) -> ControlError {
    tracing::warn!(%topic, error = error as &dyn std::error::Error, "cannot read topic");
    ControlError::CannotRead {
        topic: topic.into(),
    }
}

impl Observers {
    /// Observers with nothing to observe yet, `fabric_log` the fabric log's writer.
    pub(crate) fn new(fabric_log: Option<Recorder>) -> Observers {
        Observers {
            fabric_log,
            ..Observers::default()
        }
    }

    /// An untyped reader of `topic` from now on (opened once).
    pub(crate) fn read(
        &mut self,
        node: &Node<ipc::Service>,
        topic: &str,
        schema: &MessageSchema,
    ) -> Result<(), skillfab_proto::Error> {
        if !self.readers.contains_key(topic) {
            let reader = RawReader::open(node, topic, schema)?;
            self.readers.insert(topic.to_string(), reader);
        }
        Ok(())
    }

    /// Reads a ready skill's outputs from now on, so queries and monitors find the latest
    /// sample (a late subscriber would only get it at the next send).
    pub(crate) fn read_outputs(&mut self, node: &Node<ipc::Service>, outputs: &[PortDecl]) {
        for p in outputs {
            if let Err(error) = self.read(node, &p.topic, &p.schema) {
                tracing::warn!(topic = %p.topic, %error, "cannot read topic");
            }
        }
    }

    /// Stops reading the outputs of a skill that left: the manager must not keep a dead
    /// producer's topics alive. They are read again when a new producer is ready.
    pub(crate) fn forget_outputs(&mut self, outputs: &[PortDecl]) {
        for p in outputs {
            self.readers.remove(&p.topic);
        }
    }

    /// The end of cycle `k`: the recording takes every new sample first (before monitors and
    /// queries poll), then the channels' arbitration, the monitors, the I/O log.
    pub(crate) fn end_of_cycle(
        &mut self,
        k: u64,
        board: &Board,
        channels: &[ChannelPlan],
        skills: &Skills,
    ) -> Observed {
        let mut seen = Observed::default();
        if let Some(rec) = self.recording.as_mut() {
            rec.record_cycle(k, &mut self.readers, board.header().clock());
        }
        if !channels.is_empty() {
            seen.events = self.read_channels(k, board, channels, skills);
        }
        if !self.monitors.is_empty() {
            let before = self.monitors.len();
            let fired = self.evaluate_monitors(k);
            seen.monitors_changed = self.monitors.len() != before;
            seen.fired = !fired.is_empty();
            seen.events.extend(fired);
        }
        if !self.io_log.is_empty() {
            self.log_io();
        }
        seen
    }

    /// Copies the new samples of the I/O-logged skills to the fabric log (decoded there).
    fn log_io(&mut self) {
        let Some(rec) = self.fabric_log.as_ref() else {
            return;
        };
        let mut polled = HashSet::new();
        for ports in self.io_log.values_mut() {
            for p in ports.iter_mut() {
                let topic = &p.source.topic;
                let Some(reader) = self.readers.get_mut(topic) else {
                    continue;
                };
                if polled.insert(topic.clone())
                    && let Err(e) = reader.poll()
                {
                    tracing::warn!(%topic, error = %e, "I/O log read failed");
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
                    stamp_ns: h.stamp_ns,
                    source: p.source.clone(),
                    bytes: bytes.to_vec(),
                });
            }
        }
    }

    /// Reads each channel's arbitration of cycle `k` from the board; a new winner is an event.
    fn read_channels(
        &mut self,
        k: u64,
        board: &Board,
        channels: &[ChannelPlan],
        skills: &Skills,
    ) -> Vec<EventKind> {
        let name_of = |s: usize| skills.get(s).map(|e| e.decl.name.clone());
        let mut changes = Vec::new();
        for ch in channels {
            if ch.index >= MAX_CHANNELS {
                continue;
            }
            let slot = board.slot(ch.device);
            if slot.channel_cycle[ch.index].load(Ordering::Acquire) != k {
                continue;
            }
            let winner = slot.channel_winner[ch.index].load(Ordering::Acquire);
            let mask = slot.channel_mask[ch.index].load(Ordering::Acquire);
            let winner = winner.and_then(|w| name_of(w as usize));
            let contributors: Vec<usize> =
                (0..MAX_SLOTS).filter(|s| mask & (1 << s) != 0).collect();
            let weights: Vec<f64> = if ch.policy == Policy::Priority {
                vec![1.0; contributors.len()]
            } else {
                let priorities: Vec<i32> = contributors
                    .iter()
                    .map(|&s| board.slot(s).priority.load(Ordering::Acquire))
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
        changes
    }

    /// Evaluates every monitor on the newest samples of `cycle`, which just finished: the
    /// firings.
    fn evaluate_monitors(&mut self, cycle: u64) -> Vec<EventKind> {
        for t in &self.monitors.topics() {
            if let Some(r) = self.readers.get_mut(t)
                && let Err(e) = r.poll()
            {
                tracing::warn!(topic = %t, error = %e, "monitor read failed");
            }
        }
        let readers = &self.readers;
        let latest = |r: &crate::monitors::Resolved| readers.get(&r.topic)?.latest_of(r.slot);
        let value = |r: &crate::monitors::Resolved, from: u64| {
            let (bytes, header) = latest(r)?;
            (header.cycle >= from).then(|| r.field.read(bytes))?
        };
        let stamp = |r: &crate::monitors::Resolved| latest(r).map(|(_, h)| h.stamp_ns);
        self.monitors.evaluate(cycle, &value, &stamp)
    }

    /// Drops the monitors of clients whose process has been gone for `grace` (`dead` tells
    /// whether a client's process is gone); how many went.
    pub(crate) fn drop_orphaned_monitors(
        &mut self,
        dead: impl Fn(&str) -> bool,
        grace: Duration,
    ) -> usize {
        let dead = self
            .monitors
            .iter()
            .filter(|mon| dead(&mon.client))
            .map(|mon| mon.client.clone())
            .collect();
        let expired = self.orphans.expired(dead, Instant::now(), grace);
        if expired.is_empty() {
            return 0;
        }
        self.monitors.remove_clients(&expired)
    }
}

/// The clients holding monitors whose process died, and since when.
#[derive(Debug, Default)]
struct Orphans(HashMap<String, Instant>);

impl Orphans {
    /// Takes note of the clients of `dead` (those holding monitors whose process is gone)
    /// at `now`; the clients among them dead for `grace` or longer, whose monitors go.
    fn expired(&mut self, dead: HashSet<String>, now: Instant, grace: Duration) -> HashSet<String> {
        // A client no longer listed had its monitors taken over or removed.
        self.0.retain(|c, _| dead.contains(c));
        for c in dead {
            self.0.entry(c).or_insert(now);
        }
        self.0
            .iter()
            .filter(|(_, since)| now.duration_since(**since) >= grace)
            .map(|(c, _)| c.clone())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(names: &[&str]) -> HashSet<String> {
        names.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_dead_clients_monitors_go_after_the_grace_and_not_if_taken_over() {
        let grace = Duration::from_secs(10);
        let t0 = Instant::now();
        let mut o = Orphans::default();
        assert!(o.expired(set(&["7-1", "8-1"]), t0, grace).is_empty());
        // 8-1's monitors were taken over (no longer listed); 7-1 stays dead.
        let t1 = t0 + Duration::from_secs(9);
        assert!(o.expired(set(&["7-1"]), t1, grace).is_empty());
        assert_eq!(o.expired(set(&["7-1"]), t0 + grace, grace), set(&["7-1"]));
        // 8-1 seen dead again later (say, a restarted runner that died too): a grace of
        // its own from then.
        let t2 = t0 + Duration::from_secs(12);
        assert!(o.expired(set(&["8-1"]), t2, grace).is_empty());
        assert_eq!(o.expired(set(&["8-1"]), t2 + grace, grace), set(&["8-1"]));
    }
}
