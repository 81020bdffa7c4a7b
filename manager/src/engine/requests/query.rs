//! `query`: the latest value of an output (or a channel's arbitration) through its schema.

use super::unknown;
use crate::engine::observers::{Observers, cannot_read};
use crate::engine::skills::Skills;
use iceoryx2::node::Node;
use iceoryx2::prelude::*;
use skillfab_proto::control::{ControlError, Reply, Response};
use skillfab_proto::services::RawReader;
use skillfab_proto::value::{self, FieldPath, OutputPath, PathError, Value};

/// Topic, field and (on a proposal topic) producer slot of `skill.output[.field]`.
pub(super) fn resolve_path(
    skills: &Skills,
    skill: &str,
    output: &str,
    field: &str,
    text: &str,
) -> Result<(String, FieldPath, Option<u32>), ControlError> {
    let bad = |error: PathError| ControlError::BadPath {
        path: text.to_string(),
        error,
    };
    // A skill that is away (restarting) is resolved against its last declaration.
    let live = skills.slot_of(skill);
    let decl = skills.decl(skill).ok_or_else(|| unknown(skill))?;
    let (port, f) = crate::checks::output_field(decl, output, field).map_err(bad)?;
    // Every proposer publishes on its channel's topic: read this skill's own proposals.
    let slot = match (port.kind == skillfab_proto::decl::PortKind::Proposal, live) {
        (false, _) => None,
        (true, Some(s)) => Some(s as u32),
        (true, None) => {
            return Err(ControlError::SkillAway {
                skill: skill.into(),
            });
        }
    };
    Ok((port.topic.clone(), f, slot))
}

/// Opens (once) an untyped reader of the output's topic.
/// Nothing to open while the skill is away: its readers open when it is ready again.
pub(super) fn open_reader(
    observers: &mut Observers,
    skills: &Skills,
    node: &Node<ipc::Service>,
    skill: &str,
    output: &str,
) -> Result<(), ControlError> {
    if skills.away(skill).is_some() {
        return Ok(());
    }
    let Some(port) = skills
        .slot_of(skill)
        .and_then(|s| skills.get(s))
        .and_then(|e| e.decl.outputs.iter().find(|p| p.port == output))
    else {
        return Err(unknown(skill));
    };
    observers
        .read(node, &port.topic, &port.schema)
        .map_err(|e| cannot_read(&port.topic, &e))
}

/// `channel.<name>[.command[.field]]`: the channel's last arbitration and command.
fn query_channel(
    observers: &mut Observers,
    skills: &Skills,
    node: &Node<ipc::Service>,
    text: &str,
    rest: &str,
) -> Response {
    let (name, sub) = match rest.split_once('.') {
        Some((n, s)) => (n, Some(s)),
        None => (rest, None),
    };
    let view = observers
        .channels
        .get(name)
        .cloned()
        .ok_or_else(|| ControlError::BadPath {
            path: text.into(),
            error: PathError::NoChannel {
                channel: name.into(),
                channels: {
                    let mut c: Vec<String> = observers.channels.keys().cloned().collect();
                    c.sort();
                    c
                },
            },
        })?;
    let schema = skills
        .in_order()
        .flat_map(|(_, e)| e.decl.inputs.iter())
        .find(|p| {
            p.channel_name() == Some(name)
                && matches!(p.kind, skillfab_proto::decl::PortKind::Channel(_))
        })
        .map(|p| p.schema.clone())
        .ok_or_else(|| ControlError::NoValue(text.into()))?;
    let topic = skillfab_proto::names::command_topic(name);
    observers
        .read(node, &topic, &schema)
        .map_err(|e| cannot_read(&topic, &e))?;
    let field = match sub {
        None => "",
        Some(s) => s
            .strip_prefix("command")
            .ok_or_else(|| ControlError::BadPath {
                path: text.into(),
                error: PathError::NotACommand,
            })?,
    };
    let f = value::resolve(&schema, field).map_err(|error| ControlError::BadPath {
        path: text.into(),
        error,
    })?;
    let reader = polled_reader(observers, &topic, text)?;
    let command = reader
        .latest()
        .and_then(|(b, h)| Some((f.read(b)?, h.cycle)));
    if sub.is_some() {
        let (value, cycle) = command.ok_or_else(|| ControlError::NoValue(text.into()))?;
        return Ok(Reply::Value { value, cycle });
    }
    let value = Value::Struct(vec![
        ("channel".into(), Value::Text(name.into())),
        ("device".into(), Value::Text(view.device.clone())),
        ("policy".into(), Value::Text(view.policy.to_string())),
        (
            "winner".into(),
            view.winner.clone().map_or(Value::Null, Value::Text),
        ),
        (
            "weights".into(),
            Value::Struct(
                view.weights
                    .iter()
                    .map(|(n, w)| (n.clone(), Value::Float(*w)))
                    .collect(),
            ),
        ),
        // The latest command may be from a later cycle than the arbitration record.
        (
            "command_cycle".into(),
            command.as_ref().map_or(Value::Null, |c| Value::UInt(c.1)),
        ),
        ("command".into(), command.map_or(Value::Null, |c| c.0)),
    ]);
    Ok(Reply::Value {
        value,
        cycle: view.cycle,
    })
}

/// The open reader of `topic`, with what arrived since its last poll taken in.
fn polled_reader<'a>(
    observers: &'a mut Observers,
    topic: &str,
    text: &str,
) -> Result<&'a mut RawReader, ControlError> {
    let reader = observers
        .readers
        .get_mut(topic)
        .ok_or_else(|| ControlError::NoValue(text.into()))?;
    reader.poll().map_err(|e| cannot_read(topic, &e))?;
    Ok(reader)
}

/// The latest value at `skill.output[.field][index]` (or `channel.…`), with its cycle.
pub(super) fn query(
    observers: &mut Observers,
    skills: &Skills,
    node: &Node<ipc::Service>,
    path: &str,
) -> Response {
    let text = path.trim();
    if let Some(rest) = text.strip_prefix("channel.") {
        return query_channel(observers, skills, node, text, rest);
    }
    let path = OutputPath::parse(text).map_err(|error| ControlError::BadPath {
        path: text.into(),
        error,
    })?;
    let (topic, f, slot) = resolve_path(skills, &path.skill, &path.output, &path.field, text)?;
    open_reader(observers, skills, node, &path.skill, &path.output)?;
    let reader = polled_reader(observers, &topic, text)?;
    let (bytes, header) = reader
        .latest_of(slot)
        .ok_or_else(|| ControlError::NoValue(text.into()))?;
    let value = f
        .read(bytes)
        .ok_or_else(|| ControlError::NoValue(text.into()))?;
    Ok(Reply::Value {
        value,
        cycle: header.cycle,
    })
}
