//! Answers, from the manager to a client: replies and the errors that refuse a request.

use crate::decl::Mode;
use crate::param::{ParamError, ParamSpec, ParamValue};
use crate::value::Value;
use serde::{Deserialize, Serialize};

use super::MonitorMode;

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

/// A syntax or type error in a monitor expression, with the byte position it was found at.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize, Deserialize)]
#[error("at {position}: {message}")]
pub struct ExprError {
    /// Byte offset into the expression.
    pub position: usize,
    /// What is wrong.
    pub message: String,
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
