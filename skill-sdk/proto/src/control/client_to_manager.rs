//! Requests, from a client (sequencer, `ctl`, console) to the manager.

use super::{ControlError, PROTOCOL_VERSION};
use crate::param::ParamValue;
use serde::{Deserialize, Serialize};

/// A request as sent: version, who asks, what.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RequestEnvelope {
    /// [`PROTOCOL_VERSION`] of the client.
    pub version: u16,
    /// The client's id (`<pid>-<n>`); monitors belong to it.
    pub client: String,
    /// The client's number for this request: a client that got no answer sends the same
    /// request again under the same number, and the manager answers it once (it re-sends the
    /// answer it gave, or answers the repeat when the first is still being carried out).
    pub seq: u64,
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
    /// Start a full-rate recording into an MCAP file (replacing one in progress), or stop it
    /// (`file` `None`).
    Record {
        /// The `.mcap` file, as the manager sees it (an absolute path is best).
        file: Option<String>,
        /// Topics to record; empty: every topic.
        topics: Vec<String>,
    },
    /// A bridge's figures (sent by `skillfab bridge` about once a second; shown in stats
    /// while they are fresh).
    BridgeReport(crate::bridge::BridgeStats),
    /// The message schema of a topic, as the skills that declare it declare it (its
    /// producer's first).
    TopicSchema(String),
    /// Take over monitors installed by another client (a plan runner that was restarted
    /// takes over its predecessor's): each that is still installed is this client's from now
    /// on. Answered with each one's fate ([`crate::control::MonitorFate`]).
    AdoptMonitors(Vec<u64>),
    /// `skillfab up` stopped restarting one of its processes (it crashed too often in a
    /// row): the manager tells every client ([`crate::control::EventKind::ProcessGaveUp`]).
    ProcessGaveUp {
        /// The launch file's name of the process.
        process: String,
        /// Restarts in a row before `up` gave up.
        restarts: u32,
        /// How it last exited.
        status: String,
    },
    /// The processes `skillfab up` gave up restarting, and not back since (a plan runner
    /// started after the event asks: it would not have seen it).
    GaveUp,
    /// Hold the fabric at a cycle: no cycle after it starts until this client moves or
    /// releases (`None`) its hold; the manager says when it stopped there
    /// ([`crate::control::EventKind::Held`]). Holds of several clients add up, apart from
    /// `Run`/`Stop` and from the pause of a monitor's firing in lock-step; a hold goes with its
    /// client's process. Lock-step observers use it to act at cycles of their choosing.
    Hold(Option<u64>),
    /// A skill's declaration as it registered (ports with topics and message schemas,
    /// parameters); a skill that is away, its last one. `skillfab sequence --check` checks a
    /// plan's names against them.
    Declaration(String),
    /// A plan runner's report: its plan's shape when it starts, the status changes of each
    /// tick ([`crate::control::PlanReport`]). The manager stamps them with the cycle they
    /// arrived in, keeps the tree and publishes
    /// [`crate::control::EventKind::PlanChanged`].
    Plan(crate::control::PlanReport),
    /// The plan running now, with each node's status ([`crate::control::Reply::Plan`]).
    CurrentPlan,
    /// Want skills (all or none): each is activated with every skill it reads from, the
    /// producers of its data inputs, transitively (the ones not active yet are activated *on
    /// demand*). Refused, with nothing changed, when one reads a topic nobody produces or the
    /// producers loop.
    Want(Vec<String>),
    /// Release wanted skills (all or none): each is deactivated, and with it every skill
    /// activated on demand that no skill still wanted reads from.
    Release(Vec<String>),
}

/// Encodes a request.
pub fn encode_request(
    client: &str,
    seq: u64,
    request: &Request,
) -> Result<Vec<u8>, postcard::Error> {
    postcard::to_allocvec(&RequestEnvelope {
        version: PROTOCOL_VERSION,
        client: client.to_string(),
        seq,
        request: request.clone(),
    })
}

/// Decodes a request, checking the version first.
pub fn decode_request(bytes: &[u8]) -> Result<RequestEnvelope, ControlError> {
    // The version is the envelope's first field: read it alone so that a client of another
    // version gets a version error rather than a decoding error.
    let (version, _): (u16, _) =
        postcard::take_from_bytes(bytes).map_err(ControlError::Malformed)?;
    if version != PROTOCOL_VERSION {
        return Err(ControlError::Version {
            client: version,
            manager: PROTOCOL_VERSION,
        });
    }
    postcard::from_bytes(bytes).map_err(ControlError::Malformed)
}
