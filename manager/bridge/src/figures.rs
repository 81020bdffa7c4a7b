//! What a bridge counts per topic (samples, losses, refusals, one-way latency) and reports
//! to its manager.

use skillfab_proto::bridge::{SampleMeta, TopicStats};
use skillfab_proto::control::Percentiles;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

/// Latencies kept for the percentiles (the most recent ones).
const RECENT: usize = 1000;

/// One topic's counters, shared between the thread that carries its samples and the one
/// that reports.
#[derive(Clone)]
pub(crate) struct TopicFigures(Arc<Mutex<Counters>>);

struct Counters {
    stats: TopicStats,
    /// The last sequence number seen (imports): a jump is a loss, a step back a restarted
    /// exporter.
    last_seq: u64,
    recent_us: VecDeque<f64>,
}

/// What became of an imported sample.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Arrival {
    /// Carried; `lost` samples were skipped before it.
    Taken {
        /// Samples missing before this one.
        lost: u64,
    },
    /// Dropped, and counted as refused.
    Refused(Refusal),
}

/// Why an imported sample was dropped.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum Refusal {
    /// No readable [`SampleMeta`] attachment (not sent by a skillfab bridge of this version).
    #[error("a sample without a readable type attachment")]
    NoMeta,
    /// Another type than the one the topic has here.
    #[error("a sample of {got}, the topic here is {expected}")]
    Type {
        /// The sample's type, size and alignment.
        got: String,
        /// The topic's here.
        expected: String,
    },
    /// The right type, but not as many payload bytes as its size.
    #[error("a {type_name} sample of {got} B, its size is {size} B")]
    Length {
        /// The type.
        type_name: String,
        /// Payload bytes that came.
        got: usize,
        /// The type's size.
        size: u32,
    },
}

impl TopicFigures {
    pub(crate) fn new(topic: &str, remote: &str, type_name: &str) -> TopicFigures {
        TopicFigures(Arc::new(Mutex::new(Counters {
            stats: TopicStats {
                topic: topic.to_string(),
                remote: remote.to_string(),
                type_name: type_name.to_string(),
                ..TopicStats::default()
            },
            last_seq: 0,
            recent_us: VecDeque::with_capacity(RECENT),
        })))
    }

    fn with<R>(&self, f: impl FnOnce(&mut Counters) -> R) -> Option<R> {
        self.0.lock().ok().map(|mut c| f(&mut c))
    }

    /// The topic's type, once known (exports learn it when a local skill declares it).
    pub(crate) fn set_type(&self, type_name: &str) {
        self.with(|c| c.stats.type_name = type_name.to_string());
    }

    /// A sample sent out.
    pub(crate) fn sent(&self) {
        self.with(|c| c.stats.samples += 1);
    }

    /// A sample that arrived with `meta` (its attachment, if readable) and `len` payload
    /// bytes, checked against the type expected here (`size`, `align`).
    pub(crate) fn arrived(
        &self,
        meta: Option<&SampleMeta>,
        len: usize,
        size: u32,
        align: u32,
    ) -> Arrival {
        let checked = self.with(|c| {
            let refusal = match meta {
                None => Some(Refusal::NoMeta),
                Some(m)
                    if m.type_name != c.stats.type_name || m.size != size || m.align != align =>
                {
                    Some(Refusal::Type {
                        got: format!("{} ({} B, align {})", m.type_name, m.size, m.align),
                        expected: format!("{} ({size} B, align {align})", c.stats.type_name),
                    })
                }
                Some(m) if len != size as usize => Some(Refusal::Length {
                    type_name: m.type_name.clone(),
                    got: len,
                    size,
                }),
                Some(_) => None,
            };
            if let Some(r) = refusal {
                c.stats.refused += 1;
                return Arrival::Refused(r);
            }
            let seq = meta.map_or(0, |m| m.seq);
            c.stats.samples += 1;
            let lost = if c.last_seq != 0 && seq > c.last_seq + 1 {
                seq - c.last_seq - 1
            } else {
                0
            };
            c.stats.lost += lost;
            c.last_seq = seq;
            Arrival::Taken { lost }
        });
        // A poisoned lock: another thread panicked while counting; carry the sample uncounted.
        checked.unwrap_or(Arrival::Taken { lost: 0 })
    }

    /// A sample republished here `latency_us` after its exporter sent it.
    pub(crate) fn delivered(&self, latency_us: f64) {
        self.with(|c| {
            if c.recent_us.len() == RECENT {
                c.recent_us.pop_front();
            }
            c.recent_us.push_back(latency_us);
        });
    }

    /// The figures now.
    pub(crate) fn report(&self) -> TopicStats {
        self.with(|c| {
            let mut stats = c.stats.clone();
            stats.latency_us = percentiles(c.recent_us.iter().copied().collect());
            stats
        })
        .unwrap_or_default()
    }
}

/// Median, 99th percentile and largest of `v` (zeros when empty).
pub(crate) fn percentiles(mut v: Vec<f64>) -> Percentiles {
    if v.is_empty() {
        return Percentiles::default();
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    Percentiles {
        p50: at(0.5),
        p99: at(0.99),
        max: v[v.len() - 1],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta(seq: u64, type_name: &str) -> SampleMeta {
        SampleMeta {
            type_name: type_name.into(),
            size: 8,
            align: 8,
            seq,
            cycle: seq,
            sent_unix_ns: 0,
        }
    }

    #[test]
    fn gaps_in_the_sequence_count_as_losses_and_a_restarted_exporter_does_not() {
        let f = TopicFigures::new("tick", "a", "skillfab.Scalar");
        let scalar = |seq| f.arrived(Some(&meta(seq, "skillfab.Scalar")), 8, 8, 8);
        assert_eq!(scalar(1), Arrival::Taken { lost: 0 });
        assert_eq!(scalar(4), Arrival::Taken { lost: 2 });
        // The exporter restarted: it counts from 1 again.
        assert_eq!(scalar(1), Arrival::Taken { lost: 0 });
        let r = f.report();
        assert_eq!((r.samples, r.lost, r.refused), (3, 2, 0));
    }

    #[test]
    fn a_sample_of_another_type_or_length_or_without_its_type_is_refused_and_not_carried() {
        let f = TopicFigures::new("tick", "a", "skillfab.Scalar");
        assert_eq!(
            f.arrived(Some(&meta(1, "other.Type")), 8, 8, 8),
            Arrival::Refused(Refusal::Type {
                got: "other.Type (8 B, align 8)".into(),
                expected: "skillfab.Scalar (8 B, align 8)".into(),
            })
        );
        assert!(matches!(
            f.arrived(Some(&meta(2, "skillfab.Scalar")), 8, 8, 4),
            Arrival::Refused(Refusal::Type { .. })
        ));
        assert_eq!(
            f.arrived(Some(&meta(3, "skillfab.Scalar")), 5, 8, 8),
            Arrival::Refused(Refusal::Length {
                type_name: "skillfab.Scalar".into(),
                got: 5,
                size: 8
            })
        );
        assert_eq!(f.arrived(None, 8, 8, 8), Arrival::Refused(Refusal::NoMeta));
        let r = f.report();
        assert_eq!((r.samples, r.lost, r.refused), (0, 0, 4));
        // Refusals do not move the sequence: the next good sample counts no loss.
        assert_eq!(
            f.arrived(Some(&meta(4, "skillfab.Scalar")), 8, 8, 8),
            Arrival::Taken { lost: 0 }
        );
    }

    #[test]
    fn percentiles_of_latencies() {
        let p = percentiles((1..=100).map(f64::from).collect());
        assert_eq!((p.p50, p.p99, p.max), (51.0, 99.0, 100.0));
        assert_eq!(percentiles(Vec::new()), Percentiles::default());
    }
}
