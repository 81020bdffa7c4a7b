//! `iolog`, `logging`: which skills' samples go to the fabric log, and where it is.

use super::*;
use skillfab_proto::services::RawReader;
use skillfab_proto::value;

impl Manager {
    /// Starts or stops logging a skill's input and output samples to the fabric log.
    pub(crate) fn set_io_log(&mut self, client: &str, skill: &str, on: bool) -> Response {
        let s = self.slot_of(skill)?;
        let e = self
            .skills
            .get(s)
            .ok_or_else(|| ControlError::UnknownSkill(skill.to_string()))?;
        if !on {
            if self.io_log.remove(skill).is_some()
                && let Some(r) = &self.recorder
            {
                r.line(
                    "iolog",
                    Some(self.cycle),
                    serde_json::json!({"skill": skill, "on": false, "by": client}),
                );
            }
            return Ok(Reply::Done);
        }
        if self.recorder.is_none() {
            return Err(ControlError::NoFabricLog);
        }
        let mut ports = Vec::new();
        let sides = [("in", &e.decl.inputs), ("out", &e.decl.outputs)];
        for (dir, decls) in sides {
            for p in decls {
                let field =
                    value::resolve(&p.schema, "").map_err(|error| ControlError::BadPath {
                        path: format!("{skill}.{}", p.port),
                        error,
                    })?;
                let slot = (dir == "out" && p.kind == skillfab_proto::decl::PortKind::Proposal)
                    .then_some(s as u32);
                ports.push((
                    dir,
                    p.port.clone(),
                    p.topic.clone(),
                    p.schema.clone(),
                    field,
                    slot,
                ));
            }
        }
        let mut logged = Vec::new();
        for (dir, port, topic, schema, field, slot) in ports {
            if !self.readers.contains_key(&topic) {
                let reader = RawReader::open(&self.node, &topic, &schema)
                    .map_err(|e| super::cannot_read(&topic, &e))?;
                self.readers.insert(topic.clone(), reader);
            }
            logged.push(crate::engine::IoPort {
                dir,
                port,
                topic,
                type_name: schema.type_name.clone(),
                field: std::sync::Arc::new(field),
                slot,
                last: self.cycle,
            });
        }
        if let Some(r) = &self.recorder {
            r.line(
                "iolog",
                Some(self.cycle),
                serde_json::json!({"skill": skill, "on": true, "by": client}),
            );
        }
        self.io_log.insert(skill.to_string(), logged);
        Ok(Reply::Done)
    }

    /// Where the fabric log is, and whose samples it logs.
    pub(super) fn logging(&self) -> Reply {
        Reply::Logging {
            file: self
                .recorder
                .as_ref()
                .map(|r| r.path().display().to_string()),
            io_skills: {
                let mut v: Vec<String> = self.io_log.keys().cloned().collect();
                v.sort();
                v
            },
        }
    }
}
