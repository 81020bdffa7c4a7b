//! Monitors: conditions over live skill outputs, evaluated by the manager at the end of every
//! cycle, that push an event when they fire (the paper's "send an asynchronous event back when
//! the front sonar reads < 10 inches").

use skillfab_proto::control::{MonitorInfo, MonitorMode};
pub mod expr;

use expr::{Expr, PathRef};
use skillfab_proto::value::{FieldPath, Value};

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
    fn a_missing_value_is_not_true() {
        let mut m = monitor(MonitorMode::Every, 0);
        assert_eq!(m.step(&|_| None), None);
    }
}
