//! Monitors: conditions over live skill outputs, evaluated by the manager at the end of every
//! cycle, that push an event when they fire (the paper's "send an asynchronous event back when
//! the front sonar reads < 10 inches").

use skillfab_proto::control::{EventKind, MonitorFate, MonitorInfo, MonitorMode};
pub mod expr;

use expr::{Expr, PathRef};
use skillfab_proto::value::{FieldPath, Value};
use std::collections::{HashSet, VecDeque};

/// How many fired `Once` monitors [`Monitors`] remembers, for a restarted plan runner asking
/// what became of its monitors ([`Monitors::adopt`]).
pub const FIRED_KEPT: usize = 4096;

/// The installed monitors: their ids, their owners, and the `Once` monitors that fired and
/// were removed. Pure bookkeeping: what they read is handed to [`Monitors::evaluate`].
#[derive(Debug)]
pub struct Monitors {
    /// Installed, oldest first.
    list: Vec<Monitor>,
    /// The id the next one gets.
    next_id: u64,
    /// `Once` monitors that fired and were removed, with their cycle, newest last (at most
    /// [`FIRED_KEPT`]).
    fired_once: VecDeque<(u64, u64)>,
}

impl Default for Monitors {
    fn default() -> Self {
        Monitors {
            list: Vec::new(),
            next_id: 1,
            fired_once: VecDeque::new(),
        }
    }
}

impl Monitors {
    /// Installs a monitor of `client` on a parsed, resolved condition, evaluated from cycle
    /// `from` on (see [`Monitor::from_cycle`]); returns its id.
    #[allow(clippy::too_many_arguments)]
    pub fn install(
        &mut self,
        client: &str,
        text: String,
        expr: Expr,
        mode: MonitorMode,
        hold: u32,
        paths: Vec<Resolved>,
        from: u64,
    ) -> u64 {
        let id = self.next_id;
        self.next_id += 1;
        let mut m = Monitor::new(id, text, expr, mode, hold, client.to_string(), paths);
        m.from_cycle = from;
        self.list.push(m);
        id
    }

    /// The id the next monitor gets, and setting it (a manager taking over a predecessor's
    /// monitors installs them under their old ids).
    pub fn next_id(&self) -> u64 {
        self.next_id
    }

    /// See [`Monitors::next_id`].
    pub fn set_next_id(&mut self, id: u64) {
        self.next_id = id;
    }

    /// Hands monitors over to `client` (a restarted plan runner taking its predecessor's):
    /// what became of each.
    pub fn adopt(&mut self, client: &str, ids: &[u64]) -> Vec<MonitorFate> {
        ids.iter()
            .map(|id| {
                if let Some(m) = self.list.iter_mut().find(|m| m.id == *id) {
                    m.client = client.to_string();
                    MonitorFate::Live
                } else if let Some((_, cycle)) = self.fired_once.iter().find(|(i, _)| i == id) {
                    MonitorFate::Fired(*cycle)
                } else {
                    MonitorFate::Gone
                }
            })
            .collect()
    }

    /// Removes monitor `id`; whether it was installed.
    pub fn remove(&mut self, id: u64) -> bool {
        let before = self.list.len();
        self.list.retain(|m| m.id != id);
        self.list.len() != before
    }

    /// Removes the monitors of `clients`; how many.
    pub fn remove_clients(&mut self, clients: &HashSet<String>) -> usize {
        let before = self.list.len();
        self.list.retain(|m| !clients.contains(&m.client));
        before - self.list.len()
    }

    /// The installed monitors, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &Monitor> {
        self.list.iter()
    }

    /// Whether none is installed.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// How many are installed.
    pub fn len(&self) -> usize {
        self.list.len()
    }

    /// The topics the monitors read.
    pub fn topics(&self) -> HashSet<String> {
        self.list
            .iter()
            .flat_map(|m| m.paths.iter().map(|p| p.topic.clone()))
            .collect()
    }

    /// Evaluates every monitor on the newest samples at the end of `cycle` (`value` gives the
    /// value at a resolved path read from a sample of that cycle or later — none if the
    /// newest is older —, `stamp` the stamp of the sample it is read from): the events of
    /// those that fired. A monitor is not evaluated before its [`Monitor::from_cycle`].
    /// `Once` monitors that fired are removed and remembered.
    pub fn evaluate(
        &mut self,
        cycle: u64,
        value: &dyn Fn(&Resolved, u64) -> Option<Value>,
        stamp: &dyn Fn(&Resolved) -> Option<u64>,
    ) -> Vec<EventKind> {
        let mut events = Vec::new();
        for m in &mut self.list {
            if cycle < m.from_cycle {
                continue;
            }
            let from = m.from_cycle;
            if let Some(values) = m.step(&|r| value(r, from)) {
                events.push(EventKind::MonitorFired {
                    id: m.id,
                    client: m.client.clone(),
                    expr: m.text.clone(),
                    values,
                    stamp_ns: m.paths.iter().filter_map(stamp).max().unwrap_or(0),
                });
            }
        }
        let spent = &mut self.fired_once;
        self.list.retain(|m| {
            if m.spent() {
                spent.push_back((m.id, cycle));
            }
            !m.spent()
        });
        while spent.len() > FIRED_KEPT {
            spent.pop_front();
        }
        events
    }
}

/// A path of a monitor, resolved against its message schema.
#[derive(Debug, Clone)]
pub struct Resolved {
    /// The path as written, split.
    pub path: PathRef,
    /// The topic it reads.
    pub topic: String,
    /// Where in the message.
    pub field: FieldPath,
    /// On a proposal topic: the proposer's board slot (only its samples count).
    pub slot: Option<u32>,
}

/// One installed monitor.
#[derive(Debug)]
pub struct Monitor {
    /// Its id.
    pub id: u64,
    /// The condition as written.
    pub text: String,
    expr: Expr,
    /// When it fires.
    pub mode: MonitorMode,
    /// Consecutive true cycles needed.
    pub hold: u32,
    /// Owner.
    pub client: String,
    /// Resolved paths.
    pub paths: Vec<Resolved>,
    /// Times fired.
    pub fired: u64,
    /// The first cycle it is evaluated in, and the oldest cycle whose samples it reads: the
    /// first to start after it was installed, so every request its client sent before it
    /// (a parameter, an activation) has taken effect. A value a skill computed before (with
    /// its old parameter, or in an earlier activation) never fires it, however late the
    /// skill or the cycle ran.
    pub from_cycle: u64,
    streak: u32,
    was_true: bool,
}

impl Monitor {
    /// A monitor of a parsed condition.
    pub fn new(
        id: u64,
        text: String,
        expr: Expr,
        mode: MonitorMode,
        hold: u32,
        client: String,
        paths: Vec<Resolved>,
    ) -> Self {
        Monitor {
            id,
            text,
            expr,
            mode,
            hold,
            client,
            paths,
            fired: 0,
            from_cycle: 0,
            streak: 0,
            was_true: false,
        }
    }

    /// Feeds one cycle's values (`read` gives the value at a resolved path); returns the
    /// values to report if the monitor fires in this cycle.
    pub fn step(
        &mut self,
        read: &dyn Fn(&Resolved) -> Option<Value>,
    ) -> Option<Vec<(String, Value)>> {
        let values: Vec<(usize, Option<Value>)> = self
            .paths
            .iter()
            .enumerate()
            .map(|(i, r)| (i, read(r)))
            .collect();
        let lookup = |p: &PathRef| {
            let i = self.paths.iter().position(|r| &r.path == p)?;
            values[i].1.as_ref().map(Value::numbers)
        };
        let now = expr::eval(&self.expr, &lookup);
        self.streak = if now {
            self.streak.saturating_add(1)
        } else {
            0
        };
        let holds = now && self.streak >= self.hold.max(1);
        let fire = match self.mode {
            MonitorMode::Every => holds,
            MonitorMode::Once => holds && self.fired == 0,
            MonitorMode::Edge => holds && !self.was_true,
        };
        self.was_true = holds;
        if !fire {
            return None;
        }
        self.fired += 1;
        Some(
            self.paths
                .iter()
                .zip(values)
                .filter_map(|(r, (_, v))| v.map(|v| (r.path.text.clone(), v)))
                .collect(),
        )
    }

    /// Whether a `once` monitor is spent.
    pub fn spent(&self) -> bool {
        self.mode == MonitorMode::Once && self.fired > 0
    }

    /// As listed.
    pub fn info(&self) -> MonitorInfo {
        MonitorInfo {
            id: self.id,
            expr: self.text.clone(),
            mode: self.mode,
            hold: self.hold,
            client: self.client.clone(),
            fired: self.fired,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skillfab_proto::schema::{FieldKind, Prim};

    fn monitor(mode: MonitorMode, hold: u32) -> Monitor {
        let e = expr::parse("a.b.c > 2").unwrap();
        let p = expr::paths(&e)[0].clone();
        let r = Resolved {
            path: p,
            topic: "b".into(),
            slot: None,
            field: FieldPath {
                offset: 0,
                kind: FieldKind::Prim(Prim::F64),
                count: None,
            },
        };
        Monitor::new(1, "a.b.c > 2".into(), e, mode, hold, "c".into(), vec![r])
    }

    fn run(m: &mut Monitor, series: &[f64]) -> Vec<usize> {
        series
            .iter()
            .enumerate()
            .filter_map(|(i, &v)| m.step(&|_| Some(Value::Float(v))).map(|_| i))
            .collect()
    }

    #[test]
    fn modes_and_hold() {
        let s = [1.0, 3.0, 4.0, 1.0, 5.0, 6.0, 7.0];
        assert_eq!(
            run(&mut monitor(MonitorMode::Every, 0), &s),
            vec![1, 2, 4, 5, 6]
        );
        assert_eq!(run(&mut monitor(MonitorMode::Edge, 0), &s), vec![1, 4]);
        assert_eq!(run(&mut monitor(MonitorMode::Once, 0), &s), vec![1]);
        assert_eq!(run(&mut monitor(MonitorMode::Edge, 2), &s), vec![2, 5]);
        assert_eq!(run(&mut monitor(MonitorMode::Every, 3), &s), vec![6]);
    }

    #[test]
    fn a_monitor_starts_at_its_cycle_and_reads_no_older_sample() {
        let m = monitor(MonitorMode::Once, 0);
        let mut ms = Monitors::default();
        let id = ms.install(
            "c",
            m.text.clone(),
            expr::parse("a.b.c > 2").unwrap(),
            MonitorMode::Once,
            0,
            m.paths.clone(),
            10,
        );
        // The newest sample says 5, made in `made`: a value is read only from a sample of
        // the monitor's first cycle or later.
        let made = std::cell::Cell::new(9u64);
        let value = |_: &Resolved, from: u64| (made.get() >= from).then_some(Value::Float(5.0));
        let stamp = |_: &Resolved| Some(0);
        assert!(
            ms.evaluate(9, &value, &stamp).is_empty(),
            "before its cycle"
        );
        assert!(
            ms.evaluate(10, &value, &stamp).is_empty(),
            "a sample of cycle 9"
        );
        made.set(10);
        let fired = ms.evaluate(10, &value, &stamp);
        assert!(matches!(fired.as_slice(), [EventKind::MonitorFired { id: i, .. }] if *i == id));
    }

    #[test]
    fn a_missing_value_is_not_true() {
        let mut m = monitor(MonitorMode::Every, 0);
        assert_eq!(m.step(&|_| None), None);
    }
}
