//! What a skill tells the manager about itself when it registers.

use crate::param::{ParamSpec, ParamValue};
use crate::schema::MessageSchema;
use serde::{Deserialize, Serialize};
use std::fmt;

/// How a skill is scheduled (the paper's synchronous and asynchronous cskills).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Runs once per cycle when all its inputs for that cycle exist; the cycle waits for it.
    Sync,
    /// Free-running on the latest inputs; the cycle never waits for it.
    Async,
}

impl fmt::Display for Mode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Mode::Sync => "sync",
            Mode::Async => "async",
        })
    }
}

/// How an actuator channel turns the proposals of a cycle into one command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Policy {
    /// The highest-priority proposal wins; equal priorities: the skill name that sorts first.
    Priority,
    /// Priority-weighted average of the proposals (messages whose fields are all floats).
    Blend,
}

impl fmt::Display for Policy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Policy::Priority => "priority",
            Policy::Blend => "blend",
        })
    }
}

/// What a port is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum PortKind {
    /// Plain data: one producer per topic.
    Data,
    /// A proposal on an actuator channel (an output; many skills may propose on a channel).
    Proposal,
    /// An actuator channel a device serves (an input: the arbitrated command of each cycle).
    Channel(Policy),
}

/// One input or output port.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PortDecl {
    /// The port's name in the skill's code (the struct field).
    pub port: String,
    /// The topic it is wired to: the port name unless remapped (`--remap port=topic`); for
    /// proposals and channels `channel/<channel name>`.
    pub topic: String,
    /// Layout and type name of the message.
    pub schema: MessageSchema,
    /// Data, proposal or channel.
    pub kind: PortKind,
}

impl PortDecl {
    /// A port of message type `T`, wired to the topic of the same name.
    pub fn of<T: crate::Message>(port: &str) -> PortDecl {
        PortDecl {
            port: port.to_string(),
            topic: port.to_string(),
            schema: T::schema(),
            kind: PortKind::Data,
        }
    }

    /// A proposal or channel port of type `T` on channel `port`.
    pub fn channel<T: crate::Message>(port: &str, kind: PortKind) -> PortDecl {
        PortDecl {
            port: port.to_string(),
            topic: crate::names::channel_topic(port),
            schema: T::schema(),
            kind,
        }
    }

    /// The channel name of a proposal or channel port.
    pub fn channel_name(&self) -> Option<&str> {
        match self.kind {
            PortKind::Data => None,
            _ => self.topic.strip_prefix("channel/"),
        }
    }
}

/// A skill instance's whole declaration, sent to the manager at registration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkillDecl {
    /// Instance name, unique in the domain.
    pub name: String,
    /// What kind of skill this is (the Rust type or the program name).
    pub kind: String,
    /// Scheduling mode.
    pub mode: Mode,
    /// Priority for actuator arbitration (higher wins).
    pub priority: i32,
    /// Whether the instance starts active.
    pub start_active: bool,
    /// Process id of the skill process.
    pub pid: u32,
    /// Input ports in declaration order.
    pub inputs: Vec<PortDecl>,
    /// Output ports in declaration order.
    pub outputs: Vec<PortDecl>,
    /// Declared parameters.
    pub params: Vec<ParamSpec>,
    /// Their values at registration.
    pub param_values: Vec<(String, ParamValue)>,
}

/// The blend weights of proposers with these priorities, normalised to sum to 1: each
/// weight is `max(priority, 0)`; if all are 0, all are equal. The device and the manager's
/// report use this one rule.
pub fn blend_weights(priorities: &[i32]) -> Vec<f64> {
    let mut w: Vec<f64> = priorities.iter().map(|p| f64::from((*p).max(0))).collect();
    if w.iter().all(|x| *x == 0.0) {
        w.iter_mut().for_each(|x| *x = 1.0);
    }
    let total: f64 = w.iter().sum();
    w.iter().map(|x| x / total).collect()
}
