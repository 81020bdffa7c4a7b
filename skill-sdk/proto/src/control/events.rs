//! The event stream, from the manager to every subscribed client, in order.

use crate::param::ParamValue;
use crate::value::Value;
use serde::{Deserialize, Serialize};

/// What happened.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum EventKind {
    /// A monitor's condition held.
    MonitorFired {
        /// Monitor id.
        id: u64,
        /// Its owner.
        client: String,
        /// The condition.
        expr: String,
        /// Each path it read and its value in that cycle.
        values: Vec<(String, Value)>,
        /// Monotonic clock (ns) when the newest sample it read was sent: the moment the
        /// condition became true in a skill's output.
        stamp_ns: u64,
    },
    /// A skill registered.
    SkillRegistered {
        /// Instance name.
        skill: String,
        /// Process id.
        pid: u32,
        /// Whether a previous instance of that name existed (a restart).
        restarted: bool,
    },
    /// A restarted skill got back what the sequencer had set for its previous instance
    /// (right after its `SkillRegistered`).
    StateRestored {
        /// Instance name.
        skill: String,
        /// Its activation.
        active: bool,
        /// Parameters set by clients, re-applied.
        params: Vec<(String, ParamValue)>,
        /// Priority set by a client, re-applied.
        priority: Option<i32>,
        /// Whether its samples are logged to the fabric log again.
        io_log: bool,
        /// What could not be re-applied, and why (a parameter the new binary no longer
        /// declares, or declares with another type or bounds).
        dropped: Vec<String>,
    },
    /// A skill was activated.
    SkillActivated {
        /// Instance name.
        skill: String,
    },
    /// A skill was deactivated.
    SkillDeactivated {
        /// Instance name.
        skill: String,
    },
    /// A skill's process died.
    SkillDied {
        /// Instance name.
        skill: String,
        /// Process id.
        pid: u32,
    },
    /// A device process died: its hardware is out of the fabric until it is back.
    DeviceLost {
        /// Instance name.
        device: String,
    },
    /// A device process registered again after it was lost.
    DeviceBack {
        /// Instance name.
        device: String,
    },
    /// A skill left cleanly.
    SkillLeft {
        /// Instance name.
        skill: String,
    },
    /// A parameter changed.
    ParamChanged {
        /// Skill instance.
        skill: String,
        /// Parameter.
        param: String,
        /// Previous value.
        old: ParamValue,
        /// New value.
        new: ParamValue,
        /// The client that changed it.
        by: String,
    },
    /// A skill's priority changed.
    PriorityChanged {
        /// Skill instance.
        skill: String,
        /// Previous priority.
        old: i32,
        /// New priority.
        new: i32,
        /// The client that changed it.
        by: String,
    },
    /// A cycle passed its deadline.
    CycleOverrun {
        /// Expected runs that had not finished.
        unfinished: u32,
    },
    /// The command of an actuator channel now comes from another skill (or blend).
    ChannelWinner {
        /// Channel.
        channel: String,
        /// The winning skill (priority policy); `None`: blend, or nobody proposed (safe command).
        winner: Option<String>,
        /// Contributors and their weights.
        weights: Vec<(String, f64)>,
    },
    /// The manager started or stopped cycling.
    Cycling {
        /// Whether it runs now.
        running: bool,
    },
    /// `skillfab up` gave up restarting a process of the fabric that kept crashing (a plan
    /// reacts with `WaitGaveUp`).
    ProcessGaveUp {
        /// The launch file's name of the process.
        process: String,
        /// Restarts in a row before `up` gave up.
        restarts: u32,
        /// How it last exited.
        status: String,
    },
    /// The fabric stopped at a client's hold (`Request::Hold`): no cycle after `cycle` starts
    /// until the hold is moved or released.
    Held {
        /// The last cycle run.
        cycle: u64,
    },
    /// Nodes of the running plan changed status (a tick of its runner). A tick that changed
    /// more nodes than one event carries comes as several, in order.
    PlanChanged {
        /// The plan ([`crate::control::PlanTree::plan`]).
        plan: String,
        /// The cycle the changes arrived in (each node has its status since then).
        cycle: u64,
        /// The nodes and their new statuses.
        changes: Vec<crate::control::PlanNodeChange>,
    },
    /// A plan's tree arrived: a plan started, or a new runner took it over (its statuses
    /// are the tree's now; `Request::CurrentPlan` gives the tree).
    PlanStarted {
        /// The plan.
        plan: String,
        /// The runner (client id).
        client: String,
        /// Nodes in its tree.
        nodes: u32,
        /// The plan it replaced (another runner's, or this plan's previous runner's).
        replaced: Option<String>,
    },
    /// The running plan ended (succeeded, failed, or was halted): no plan runs now.
    PlanEnded {
        /// The plan.
        plan: String,
        /// Its root's last status (`Idle`: halted).
        status: crate::control::NodeStatus,
    },
}

/// One event of the stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    /// Sequence number, from 1, without gaps: a subscriber sees a gap if it lost events.
    pub seq: u64,
    /// Cycle it happened in (the current or last cycle).
    pub cycle: u64,
    /// Monotonic clock (ns).
    pub time_ns: u64,
    /// What happened.
    pub kind: EventKind,
}

/// Encodes an event.
pub fn encode_event(event: &Event) -> Result<Vec<u8>, postcard::Error> {
    postcard::to_allocvec(event)
}

/// Encodes an event in at most `max` bytes. A monitor firing that read large arrays is cut
/// to fit: the longest array value is halved until it fits (each cut array ends with
/// `Value::Text("… N more")`), then whole values are replaced by that marker; the monitor's
/// id, cycle and stamp always arrive. `None` if even that does not fit (an expression text
/// longer than `max`).
pub fn encode_event_within(event: &Event, max: usize) -> Option<Vec<u8>> {
    let bytes = encode_event(event).ok()?;
    if bytes.len() <= max {
        return Some(bytes);
    }
    let EventKind::MonitorFired { values, .. } = &event.kind else {
        return None;
    };
    let mut cut = event.clone();
    // Per value: the elements kept of each array (None: not an array).
    let mut keep: Vec<Option<usize>> = values
        .iter()
        .map(|(_, v)| match v {
            Value::Array(a) => Some(a.len()),
            _ => None,
        })
        .collect();
    loop {
        let shown = values
            .iter()
            .zip(&keep)
            .map(|((path, v), k)| {
                let v = match (v, k) {
                    (Value::Array(a), Some(k)) if *k < a.len() => {
                        let mut kept = a[..*k].to_vec();
                        kept.push(Value::Text(format!("… {} more", a.len() - k)));
                        Value::Array(kept)
                    }
                    (_, Some(0)) => Value::Text("… cut".into()),
                    _ => v.clone(),
                };
                (path.clone(), v)
            })
            .collect();
        if let EventKind::MonitorFired { values: out, .. } = &mut cut.kind {
            *out = shown;
        }
        let bytes = encode_event(&cut).ok()?;
        if bytes.len() <= max {
            return Some(bytes);
        }
        // Halve the longest array still kept; then drop whole values, last first.
        let longest = keep
            .iter()
            .enumerate()
            .filter_map(|(i, k)| k.filter(|&k| k > 0).map(|k| (k, i)))
            .max();
        match longest {
            Some((k, i)) => keep[i] = Some(k / 2),
            None => {
                let i = keep.iter().rposition(|k| *k != Some(0))?;
                keep[i] = Some(0);
            }
        }
    }
}

/// Decodes an event.
pub fn decode_event(bytes: &[u8]) -> Result<Event, postcard::Error> {
    postcard::from_bytes(bytes)
}
