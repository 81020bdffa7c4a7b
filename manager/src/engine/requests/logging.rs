//! `iolog`, `logging`: which skills' samples go to the fabric log, and where it is.

use super::unknown;
use crate::engine::observers::{IoPort, Observers, cannot_read};
use crate::engine::skills::Skills;
use crate::recorder::SampleSource;
use iceoryx2::node::Node;
use iceoryx2::prelude::*;
use skillfab_proto::control::{ControlError, Reply, Response};

/// Starts or stops logging a skill's input and output samples to the fabric log, at `cycle`.
pub(crate) fn set_io_log(
    observers: &mut Observers,
    skills: &Skills,
    node: &Node<ipc::Service>,
    cycle: u64,
    client: &str,
    skill: &str,
    on: bool,
) -> Response {
    let s = skills.slot_of(skill).ok_or_else(|| unknown(skill))?;
    let e = skills.get(s).ok_or_else(|| unknown(skill))?;
    if !on {
        if observers.io_log.remove(skill).is_some()
            && let Some(r) = &observers.fabric_log
        {
            r.line(
                "iolog",
                Some(cycle),
                serde_json::json!({"skill": skill, "on": false, "by": client}),
            );
        }
        return Ok(Reply::Done);
    }
    if observers.fabric_log.is_none() {
        return Err(ControlError::NoFabricLog);
    }
    let mut ports = Vec::new();
    let sides = [("in", &e.decl.inputs), ("out", &e.decl.outputs)];
    for (dir, decls) in sides {
        for p in decls {
            let source = SampleSource::new(skill, dir, &p.port, &p.topic, &p.schema, false)
                .map_err(|error| ControlError::BadPath {
                    path: format!("{skill}.{}", p.port),
                    error,
                })?;
            let slot = (dir == "out" && p.kind == skillfab_proto::decl::PortKind::Proposal)
                .then_some(s as u32);
            ports.push((p.schema.clone(), source, slot));
        }
    }
    let mut logged = Vec::new();
    for (schema, source, slot) in ports {
        observers
            .read(node, &source.topic, &schema)
            .map_err(|e| cannot_read(&source.topic, &e))?;
        logged.push(IoPort {
            source: std::sync::Arc::new(source),
            slot,
            last: cycle,
        });
    }
    if let Some(r) = &observers.fabric_log {
        r.line(
            "iolog",
            Some(cycle),
            serde_json::json!({"skill": skill, "on": true, "by": client}),
        );
    }
    observers.io_log.insert(skill.to_string(), logged);
    Ok(Reply::Done)
}

/// Where the fabric log is, and whose samples it logs.
pub(super) fn logging(observers: &Observers) -> Reply {
    Reply::Logging {
        file: observers
            .fabric_log
            .as_ref()
            .map(|r| r.path().display().to_string()),
        io_skills: {
            let mut v: Vec<String> = observers.io_log.keys().cloned().collect();
            v.sort();
            v
        },
    }
}
