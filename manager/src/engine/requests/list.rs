//! `list`, `stats`, `schema`: the registered skills, the cycle statistics, the topics' types.

use crate::engine::figures;
use crate::engine::skills::Skills;
use skillfab_proto::board::Board;
use skillfab_proto::control::{ControlError, PortInfo, Reply, SkillInfo, SkillState};

/// Every registered skill, in registration order.
pub(super) fn list(skills: &Skills, board: &Board) -> Vec<SkillInfo> {
    let ports = |p: &[skillfab_proto::decl::PortDecl]| {
        p.iter()
            .map(|p| PortInfo {
                port: p.port.clone(),
                topic: p.topic.clone(),
                type_name: p.schema.type_name.clone(),
            })
            .collect()
    };
    skills
        .in_order()
        .map(|(s, e)| SkillInfo {
            name: e.decl.name.clone(),
            kind: e.decl.kind.clone(),
            mode: e.decl.mode,
            state: if !e.ready {
                SkillState::Starting
            } else if e.active {
                SkillState::Active
            } else {
                SkillState::Inactive
            },
            priority: e.decl.priority,
            pid: e.decl.pid,
            params: e.decl.params.clone(),
            values: e.values.clone(),
            inputs: ports(&e.decl.inputs),
            outputs: ports(&e.decl.outputs),
            figures: figures(board, s),
        })
        .collect()
}

/// The schema of `topic` as its producer declares it, else as a consumer does.
pub(super) fn topic_schema(skills: &Skills, topic: &str) -> Result<Reply, ControlError> {
    let decls = || skills.in_order().map(|(_, e)| &e.decl);
    decls()
        .flat_map(|d| d.outputs.iter())
        .chain(decls().flat_map(|d| d.inputs.iter()))
        .find(|p| p.topic == topic)
        .map(|p| Reply::Schema(p.schema.clone()))
        .ok_or_else(|| ControlError::UnknownTopic(topic.to_string()))
}
