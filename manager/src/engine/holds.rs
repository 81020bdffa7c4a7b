//! Holds: clients that keep the fabric from running past a cycle of their choosing.
//!
//! In lock-step the fabric runs as fast as the host allows, so an observer that acts on what
//! it sees (the demo's judge reading the simulator's ground truth, a test, a viewer) would act
//! at whatever cycle the fabric had reached when it looked: a different cycle every run. A
//! hold makes that cycle the observer's own choice. A client that holds at cycle `c` is
//! promised that no cycle after `c` starts until it moves or releases its hold; the manager
//! says when it stopped there ([`EventKind::Held`]). Holds of several clients add up (the
//! fabric stops at the lowest), and they are apart from `run`/`stop` and from the pause a
//! monitor's firing causes: a plan runner that resumes after a firing does not run past a
//! demo's hold. A hold goes with its client's process.
//!
//! [`EventKind::Held`]: skillfab_proto::control::EventKind::Held

use std::collections::BTreeMap;

/// Every client's hold.
#[derive(Debug, Default, Clone, PartialEq)]
pub(crate) struct Holds {
    /// Client → the last cycle it lets run.
    by_client: BTreeMap<String, u64>,
    /// The hold the fabric stopped at and said so (said once).
    announced: Option<u64>,
}

/// The hold a fabric started `--held` has until a client holds (no client has this name).
const AT_START: &str = "(start)";

impl Holds {
    /// Held before its first cycle until a client sets a hold of its own (`--held`): an
    /// observer that connects after a plan runner has resumed the fabric still acts from the
    /// first cycle on.
    pub(crate) fn at_start() -> Holds {
        let mut h = Holds::default();
        h.by_client.insert(AT_START.into(), 0);
        h
    }

    /// Holds at `at` for `client` (replacing its hold), or releases it (`None`). The hold at
    /// start goes with the first client's.
    pub(crate) fn set(&mut self, client: &str, at: Option<u64>) {
        self.by_client.remove(AT_START);
        match at {
            Some(c) => self.by_client.insert(client.to_string(), c),
            None => self.by_client.remove(client),
        };
    }

    /// The lowest hold: no cycle after it may start.
    pub(crate) fn limit(&self) -> Option<u64> {
        self.by_client.values().copied().min()
    }

    /// Whether a hold keeps the cycle after `done` (cycles completed) from starting.
    pub(crate) fn blocks(&self, done: u64) -> bool {
        self.limit().is_some_and(|c| done >= c)
    }

    /// The fabric cannot start its next cycle (`done` completed) because of a hold: the cycle
    /// to announce as held, the first time for that hold. The hold at start is not announced:
    /// no client waits for it, and whether a plan runner resumed the fabric before the first
    /// client held it is a matter of the host's timing (a run's record is the seed's alone).
    pub(crate) fn reached(&mut self, done: u64) -> Option<u64> {
        if self.by_client.contains_key(AT_START) {
            return None;
        }
        let limit = self.limit().filter(|&c| done >= c)?;
        (self.announced != Some(limit)).then(|| {
            self.announced = Some(limit);
            done
        })
    }

    /// Releases the holds of clients `gone` says are gone (not the hold at start: nobody's
    /// process); returns them.
    pub(crate) fn release_gone(&mut self, gone: impl Fn(&str) -> bool) -> Vec<String> {
        let dead: Vec<String> = self
            .by_client
            .keys()
            .filter(|c| *c != AT_START && gone(c))
            .cloned()
            .collect();
        for c in &dead {
            self.by_client.remove(c);
        }
        dead
    }

    /// Every hold, by client (for the state file).
    pub(crate) fn all(&self) -> &BTreeMap<String, u64> {
        &self.by_client
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fabric_stops_at_the_lowest_hold_and_says_so_once_per_hold() {
        let mut h = Holds::default();
        assert!(!h.blocks(1_000_000));
        h.set("demo", Some(10));
        h.set("viewer", Some(30));
        assert_eq!(h.limit(), Some(10));
        assert!(!h.blocks(9));
        assert!(h.blocks(10));
        assert_eq!(h.reached(9), None, "not there yet");
        assert_eq!(h.reached(10), Some(10));
        assert_eq!(h.reached(10), None, "said once");
        // Moved on: the next stop is the viewer's, and it is said.
        h.set("demo", Some(40));
        assert!(!h.blocks(10));
        assert_eq!(h.reached(30), Some(30));
        // A hold set behind the fabric stops it where it is.
        h.set("late", Some(5));
        assert_eq!(h.reached(30), Some(30));
        h.set("late", None);
        h.set("viewer", None);
        assert_eq!(h.limit(), Some(40));
    }

    #[test]
    fn a_hold_goes_with_its_client() {
        let mut h = Holds::default();
        h.set("10-0", Some(3));
        h.set("11-0", Some(8));
        assert_eq!(h.release_gone(|c| c.starts_with("10-")), vec!["10-0"]);
        assert_eq!(h.limit(), Some(8));
        assert_eq!(h.release_gone(|_| false), Vec::<String>::new());
        h.set("11-0", None);
        assert_eq!(h.limit(), None);
    }

    #[test]
    fn a_fabric_started_held_waits_for_the_first_client_to_hold() {
        let mut h = Holds::at_start();
        assert!(h.blocks(0));
        assert_eq!(h.reached(0), None, "not announced: nobody waits for it");
        // A client that dies is gone; the hold at start is nobody's process.
        assert!(h.release_gone(|c| c != "5-0").is_empty());
        h.set("5-0", Some(10));
        assert!(!h.blocks(9));
        assert_eq!(h.reached(10), Some(10));
    }
}
