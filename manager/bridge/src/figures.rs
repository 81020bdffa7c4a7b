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
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Arrival {
    /// Carried; `lost` samples were skipped before it.
    Taken {
        /// Samples missing before this one.
        lost: u64,
    },
    /// Its type is not the topic's here.
    Refused,
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

    /// A sample sent out.
    pub(crate) fn sent(&self) {
        self.with(|c| c.stats.samples += 1);
    }

    /// A sample that arrived with `meta`, checked against the type expected here.
    pub(crate) fn arrived(&self, meta: &SampleMeta, size: u32, align: u32) -> Arrival {
        self.with(|c| {
            if meta.type_name != c.stats.type_name || meta.size != size || meta.align != align {
                c.stats.refused += 1;
                return Arrival::Refused;
            }
            c.stats.samples += 1;
            let lost = if c.last_seq != 0 && meta.seq > c.last_seq + 1 {
                meta.seq - c.last_seq - 1
            } else {
                0
            };
            c.stats.lost += lost;
            c.last_seq = meta.seq;
            Arrival::Taken { lost }
        })
        .unwrap_or(Arrival::Refused)
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
        assert_eq!(
            f.arrived(&meta(1, "skillfab.Scalar"), 8, 8),
            Arrival::Taken { lost: 0 }
        );
        assert_eq!(
            f.arrived(&meta(4, "skillfab.Scalar"), 8, 8),
            Arrival::Taken { lost: 2 }
        );
        // The exporter restarted: it counts from 1 again.
        assert_eq!(
            f.arrived(&meta(1, "skillfab.Scalar"), 8, 8),
            Arrival::Taken { lost: 0 }
        );
        assert_eq!(f.arrived(&meta(2, "other.Type"), 8, 8), Arrival::Refused);
        assert_eq!(
            f.arrived(&meta(2, "skillfab.Scalar"), 8, 4),
            Arrival::Refused
        );
        let r = f.report();
        assert_eq!((r.samples, r.lost, r.refused), (3, 2, 2));
    }

    #[test]
    fn percentiles_of_latencies() {
        let p = percentiles((1..=100).map(f64::from).collect());
        assert_eq!((p.p50, p.p99, p.max), (51.0, 99.0, 100.0));
        assert_eq!(percentiles(Vec::new()), Percentiles::default());
    }
}
