//! The control plane's protocol: what a sequencer asks the manager and what it gets back, and
//! the events the manager pushes. Encoded with postcard, one entry point each way, with a
//! version check (a client of another protocol version gets a precise error, not garbage).
//!
//! Transport (see [`crate::names`]): requests and responses travel over the iceoryx2
//! request-response service `skillfab/control` as byte slices; a client wakes the manager
//! through `skillfab/manager/wake` and is woken through `skillfab/client/<id>`. Events are
//! published on `skillfab/events` (byte slices, paired event service of the same name).

use crate::decl::Mode;
use crate::expr::ExprError;
use crate::params::{ParamError, ParamSpec, ParamValue};
use crate::schema::MessageSchema;
use crate::value::Value;
use serde::{Deserialize, Serialize};

/// Version of this protocol; bumped on any incompatible change.
pub const PROTOCOL_VERSION: u16 = 1;

/// A request as sent: version, who asks, what.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RequestEnvelope {
    /// [`PROTOCOL_VERSION`] of the client.
    pub version: u16,
    /// The client's id (`<pid>-<n>`); monitors belong to it.
    pub client: String,
    /// The request.
    pub request: Request,
}

/// A parameter value as the client gives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ParamArg {
    /// Text, parsed by the parameter's declared type (`ctl set s.p=3`).
    Text(String),
    /// A typed value.
    Value(ParamValue),
}

/// When a monitor fires.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MonitorMode {
    /// The first cycle the condition holds; then the monitor is removed.
    Once,
    /// Each cycle the condition becomes true (rising edge).
    Edge,
    /// Every cycle the condition holds.
    Every,
}

/// What a client can ask.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Request {
    /// Every registered skill.
    List,
    /// Activate skills (all or none).
    Activate(Vec<String>),
    /// Deactivate skills (all or none).
    Deactivate(Vec<String>),
    /// Set a parameter; applied from the next cycle.
    SetParam {
        /// Skill instance.
        skill: String,
        /// Parameter name.
        param: String,
        /// New value.
        value: ParamArg,
    },
    /// Read a parameter.
    GetParam {
        /// Skill instance.
        skill: String,
        /// Parameter name.
        param: String,
    },
    /// Read a value: `skill.output[.field][index]`.
    Query(String),
    /// Install a monitor.
    AddMonitor {
        /// The condition.
        expr: String,
        /// When it fires.
        mode: MonitorMode,
        /// Cycles the condition must hold before it counts as true (0 or 1: at once).
        hold: u32,
    },
    /// Remove a monitor.
    RemoveMonitor(u64),
    /// Every monitor.
    ListMonitors,
    /// Start cycling.
    Run,
    /// Stop cycling (the current cycle finishes).
    Stop,
    /// Run N cycles, then stop; answered when they are done.
    Step(u64),
    /// Cycle and skill statistics.
    Stats,
    /// Change a skill's arbitration priority.
    SetPriority {
        /// Skill instance.
        skill: String,
        /// New priority (higher wins).
        priority: i32,
    },
    // Variants below were added after version 1 shipped; appending keeps the encoding of
    // every earlier request unchanged (an older manager answers them `Malformed`).
    /// The latencies of the most recent cycles (at most this many, capped by the manager).
    Latencies(u32),
    /// Turn the logging of a skill's input and output samples on or off.
    SetIoLog {
        /// Skill instance.
        skill: String,
        /// Log every sample from the next cycle on.
        on: bool,
    },
    /// Where the manager logs, and whose samples.
    Logging,
}

/// A skill as listed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkillInfo {
    /// Instance name.
    pub name: String,
    /// Kind (program).
    pub kind: String,
    /// Scheduling mode.
    pub mode: Mode,
    /// `active`, `inactive` or `starting` (registered, ports not open yet).
    pub state: String,
    /// Arbitration priority.
    pub priority: i32,
    /// Process id.
    pub pid: u32,
    /// Declared parameters.
    pub params: Vec<ParamSpec>,
    /// Their current values.
    pub values: Vec<(String, ParamValue)>,
    /// Input ports: (port, topic, type name).
    pub inputs: Vec<(String, String, String)>,
    /// Output ports: (port, topic, type name).
    pub outputs: Vec<(String, String, String)>,
    /// Completed runs.
    pub runs: u64,
    /// Skipped cycles.
    pub skips: u64,
    /// Failed runs.
    pub failures: u64,
    /// Cycle of the last run (0: none).
    pub last_cycle: u64,
    /// Compute time of the last run (µs).
    pub compute_us_last: f64,
    /// Mean compute time (µs).
    pub compute_us_mean: f64,
}

/// An installed monitor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MonitorInfo {
    /// Its id.
    pub id: u64,
    /// The condition.
    pub expr: String,
    /// Mode.
    pub mode: MonitorMode,
    /// Hold cycles.
    pub hold: u32,
    /// The client that owns it.
    pub client: String,
    /// Times it fired.
    pub fired: u64,
}

/// Cycle statistics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    /// Cycles completed.
    pub cycles: u64,
    /// Whether the manager is cycling.
    pub running: bool,
    /// Overruns.
    pub overruns: u64,
    /// Latency percentiles (µs): p50, p99, max.
    pub latency_us: (f64, f64, f64),
    /// Per skill: (name, runs, skips, failures, mean compute µs).
    pub skills: Vec<(String, u64, u64, u64, f64)>,
    /// Skills that died.
    pub deaths: u64,
    /// Events published so far.
    pub events: u64,
    /// Per actuator channel: (channel, winner or `blend`/`safe`, cycle of the last command).
    pub channels: Vec<(String, String, u64)>,
}

/// What the manager answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Reply {
    /// The request was carried out.
    Done,
    /// Skills.
    Skills(Vec<SkillInfo>),
    /// A parameter's value.
    Param(ParamValue),
    /// A queried value and the cycle it was produced in.
    Value {
        /// The value.
        value: Value,
        /// Its cycle.
        cycle: u64,
    },
    /// The new monitor's id.
    MonitorAdded(u64),
    /// Monitors.
    Monitors(Vec<MonitorInfo>),
    /// Statistics.
    Stats(Stats),
    /// Stepping finished at this cycle.
    Stepped(u64),
    /// Recent cycle latencies, oldest first, in µs.
    Latencies {
        /// The last cycle completed.
        cycle: u64,
        /// One per cycle, ending with `cycle`'s.
        latency_us: Vec<f32>,
    },
    /// The fabric log.
    Logging {
        /// Its file (`None`: the manager could not open one).
        file: Option<String>,
        /// Skills whose input and output samples are logged.
        io_skills: Vec<String>,
    },
}

/// Why a request was refused. Every variant names what was wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize, Deserialize)]
#[non_exhaustive]
pub enum ControlError {
    /// No such skill.
    #[error("unknown skill '{0}'")]
    UnknownSkill(String),
    /// A parameter was refused.
    #[error("{skill}: {error}")]
    Param {
        /// Skill instance.
        skill: String,
        /// Why.
        error: ParamErrorText,
    },
    /// A value path that does not resolve.
    #[error("bad path '{path}': {reason}")]
    BadPath {
        /// As given.
        path: String,
        /// Why.
        reason: String,
    },
    /// Nothing has been published at that path yet.
    #[error("no value yet at '{0}'")]
    NoValue(String),
    /// A monitor expression that does not parse or type-check.
    #[error("bad expression '{expr}' {error}")]
    BadExpression {
        /// As given.
        expr: String,
        /// Where and why.
        error: ExprError,
    },
    /// No monitor with that id.
    #[error("unknown monitor {0}")]
    UnknownMonitor(u64),
    /// The client speaks another protocol version.
    #[error("protocol version mismatch: client {client}, manager {manager}")]
    Version {
        /// Client's version.
        client: u16,
        /// Manager's version.
        manager: u16,
    },
    /// The request bytes do not decode.
    #[error("malformed request: {0}")]
    Malformed(String),
    /// Something the request needs is not possible now.
    #[error("{0}")]
    Refused(String),
}

/// A parameter error as text that survives encoding.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize, Deserialize)]
#[error("{0}")]
pub struct ParamErrorText(pub String);

impl From<ParamError> for ParamErrorText {
    fn from(e: ParamError) -> Self {
        ParamErrorText(e.to_string())
    }
}

/// The manager's answer.
pub type Response = Result<Reply, ControlError>;

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

/// The declared type names of a skill's schema, for lists.
pub fn type_name(schema: &MessageSchema) -> String {
    schema.type_name.clone()
}

/// Encodes a request.
pub fn encode_request(client: &str, request: &Request) -> Result<Vec<u8>, postcard::Error> {
    postcard::to_allocvec(&RequestEnvelope {
        version: PROTOCOL_VERSION,
        client: client.to_string(),
        request: request.clone(),
    })
}

/// Decodes a request, checking the version first.
pub fn decode_request(bytes: &[u8]) -> Result<RequestEnvelope, ControlError> {
    // The version is the envelope's first field: read it alone so that a client of another
    // version gets a version error rather than a decoding error.
    let (version, _): (u16, _) =
        postcard::take_from_bytes(bytes).map_err(|e| ControlError::Malformed(e.to_string()))?;
    if version != PROTOCOL_VERSION {
        return Err(ControlError::Version {
            client: version,
            manager: PROTOCOL_VERSION,
        });
    }
    postcard::from_bytes(bytes).map_err(|e| ControlError::Malformed(e.to_string()))
}

/// Encodes a response.
pub fn encode_response(response: &Response) -> Vec<u8> {
    // Encoding into a Vec of plain data cannot fail; fall back to an error reply anyway.
    postcard::to_allocvec(response).unwrap_or_else(|e| {
        postcard::to_allocvec(&Response::Err(ControlError::Refused(format!(
            "encoding reply: {e}"
        ))))
        .unwrap_or_default()
    })
}

/// Decodes a response.
pub fn decode_response(bytes: &[u8]) -> Result<Response, postcard::Error> {
    postcard::from_bytes(bytes)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_large_monitor_firing_is_cut_to_fit_and_small_events_are_untouched() {
        let fired = |values: Vec<(String, Value)>| Event {
            seq: 7,
            cycle: 9,
            time_ns: 11,
            kind: EventKind::MonitorFired {
                id: 3,
                client: "1-0".into(),
                expr: "max(cam.image.data) > 250 and denning.link.fresh".into(),
                values,
                stamp_ns: 5,
            },
        };
        let small = fired(vec![("denning.link.fresh".into(), Value::Bool(true))]);
        assert_eq!(
            encode_event_within(&small, 2048),
            Some(encode_event(&small).unwrap())
        );
        let image = Value::Array((0..100_000).map(|i| Value::UInt(i % 256)).collect());
        let big = fired(vec![
            ("cam.image.data".into(), image),
            ("denning.link.fresh".into(), Value::Bool(true)),
        ]);
        let b = encode_event_within(&big, 2048).unwrap();
        assert!(b.len() <= 2048, "{}", b.len());
        let e = decode_event(&b).unwrap();
        assert_eq!((e.seq, e.cycle), (7, 9));
        let EventKind::MonitorFired { id, values, .. } = e.kind else {
            panic!("{e:?}")
        };
        assert_eq!(id, 3);
        assert_eq!(values[1], ("denning.link.fresh".into(), Value::Bool(true)));
        let Value::Array(kept) = &values[0].1 else {
            panic!("{values:?}")
        };
        assert!(kept.len() > 10, "as much as fits is kept: {}", kept.len());
        assert_eq!(kept[0], Value::UInt(0));
        let Some(Value::Text(more)) = kept.last() else {
            panic!("{kept:?}")
        };
        assert_eq!(*more, format!("… {} more", 100_000 - (kept.len() - 1)));
        // Nothing fits a tiny budget but the id: no event rather than a broken one.
        assert_eq!(encode_event_within(&big, 16), None);
    }

    #[test]
    fn requests_round_trip_and_versions_are_checked() {
        let r = Request::SetParam {
            skill: "scale".into(),
            param: "gain".into(),
            value: ParamArg::Text("3".into()),
        };
        let b = encode_request("12-1", &r).unwrap();
        assert_eq!(decode_request(&b).unwrap().request, r);
        let mut other = b.clone();
        other[0] = 9; // a varint 9: another protocol version
        assert!(matches!(
            decode_request(&other),
            Err(ControlError::Version { client: 9, .. })
        ));
        assert!(matches!(
            decode_request(&b[..3]),
            Err(ControlError::Malformed(_))
        ));
        assert!(matches!(
            decode_request(&[]),
            Err(ControlError::Malformed(_))
        ));
    }

    proptest::proptest! {
        #[test]
        fn any_bytes_decode_or_error_without_panicking(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..256)) {
            let _ = decode_request(&bytes);
            let _ = decode_response(&bytes);
            let _ = decode_event(&bytes);
        }

        #[test]
        fn set_param_requests_round_trip(skill in "[a-z]{1,12}", param in "[a-z_]{1,12}", text in ".{0,32}", client in "[0-9]{1,6}-[0-9]{1,3}") {
            let r = Request::SetParam { skill, param, value: ParamArg::Text(text) };
            let env = decode_request(&encode_request(&client, &r).unwrap()).unwrap();
            proptest::prop_assert_eq!(env.request, r);
            proptest::prop_assert_eq!(env.client, client);
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic_the_decoder() {
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        for len in 0..2000usize {
            let bytes: Vec<u8> = (0..len % 64)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    x as u8
                })
                .collect();
            let mut versioned = vec![PROTOCOL_VERSION as u8];
            versioned.extend_from_slice(&bytes);
            let _ = decode_request(&bytes);
            let _ = decode_request(&versioned);
            let _ = decode_response(&bytes);
            let _ = decode_event(&bytes);
        }
    }
}
