//! `activate`/`deactivate`, `set`/`get` of parameters, `priority`.

use super::*;
use skillfab_proto::control::{EventKind, ParamArg};

impl Manager {
    /// Activates or deactivates every named skill, or none (an unknown name refuses all).
    /// A skill that is away (its process died and may be restarted) gets it when it is back.
    pub(super) fn set_active(&mut self, names: &[String], active: bool) -> Response {
        let slots = names
            .iter()
            .map(|n| match self.skills.away(n) {
                Some(_) => Ok(Err(n.clone())),
                None => self.slot_of(n).map(Ok),
            })
            .collect::<Result<Vec<_>, _>>()?;
        for s in slots {
            let s = match s {
                Ok(s) => s,
                Err(away) => {
                    tracing::info!(skill = %away, active, "activation kept for its return");
                    let kept = self.skills.keep(&away);
                    if active && kept.active != Some(true) {
                        kept.activations += 1;
                    }
                    kept.active = Some(active);
                    continue;
                }
            };
            let Some(e) = self.skills.get_mut(s) else {
                continue;
            };
            if e.active == active {
                continue;
            }
            // Takes effect at the next cycle start (the plan writes it to the board), so a
            // skill deactivated mid-cycle still finishes the run the cycle counts on.
            e.active = active;
            let skill = e.decl.name.clone();
            let kept = self.skills.keep(&skill);
            kept.active = Some(active);
            if active {
                kept.activations += 1;
            }
            self.dirty = true;
            tracing::info!(%skill, active, "activation changed");
            self.record_control(
                if active { "activate" } else { "deactivate" },
                serde_json::json!({"skill": skill}),
            );
            self.outbox.push(if active {
                EventKind::SkillActivated { skill }
            } else {
                EventKind::SkillDeactivated { skill }
            });
        }
        Ok(Reply::Done)
    }

    /// Sets a parameter after checking its type and bounds; logged and announced.
    pub(super) fn set_param(
        &mut self,
        client: &str,
        skill: &str,
        param: &str,
        arg: ParamArg,
    ) -> Response {
        // A skill that is away gets the value when it is back; it is checked against the
        // declaration it had.
        let live = self.skills.slot_of(skill);
        let decl = self
            .skills
            .decl(skill)
            .ok_or_else(|| ControlError::UnknownSkill(skill.to_string()))?;
        let (value, spec) =
            crate::checks::param_value(decl, param, arg).map_err(|err| param_err(skill, err))?;
        let default = spec.default;
        let old = match live.and_then(|s| self.skills.get(s)) {
            Some(e) => e.values.iter().find(|(n, _)| n == param).map(|(_, v)| *v),
            None => self
                .skills
                .kept(skill)
                .and_then(|k| k.params.iter().find(|(n, _)| n == param).map(|(_, v)| *v)),
        }
        .unwrap_or(default);
        if let Some(s) = live
            && let Some(e) = self.skills.get_mut(s)
        {
            match e.values.iter_mut().find(|(n, _)| n == param) {
                Some(slot) => slot.1 = value,
                None => e.values.push((param.to_string(), value)),
            }
            let cannot = |error: &(dyn std::error::Error + 'static)| {
                tracing::warn!(%skill, error, "cannot write parameters");
                ControlError::CannotWriteParams {
                    skill: skill.into(),
                }
            };
            let bytes = postcard::to_allocvec(&e.values).map_err(|err| cannot(&err))?;
            self.board
                .slot(s)
                .write_params(&bytes)
                .map_err(|err| cannot(&err))?;
        }
        let kept = &mut self.skills.keep(skill).params;
        match kept.iter_mut().find(|(n, _)| n == param) {
            Some(slot) => slot.1 = value,
            None => kept.push((param.to_string(), value)),
        }
        tracing::info!(skill, param, %old, new = %value, by = client, cycle = self.cycle, "parameter changed");
        if let Some(r) = &self.recorder {
            r.param(self.in_progress(), skill, param, old, value, client);
        }
        self.record_control(
            "param",
            serde_json::json!({"skill": skill, "param": param,
                               "value": skillfab_proto::json::param_json(&value), "by": client}),
        );
        self.outbox.push(EventKind::ParamChanged {
            skill: skill.to_string(),
            param: param.to_string(),
            old,
            new: value,
            by: client.to_string(),
        });
        Ok(Reply::Done)
    }

    /// A parameter's current value.
    pub(super) fn get_param(&self, skill: &str, param: String) -> Response {
        let value = match self.skills.away(skill) {
            // A skill that is away has the value it will be given when it is back: what a
            // client set, else what its last process started with (a plan that reads it
            // to restore it later, while the skill is being restarted, reads that).
            Some(decl) => self
                .skills
                .kept(skill)
                .and_then(|k| k.params.iter().find(|(n, _)| *n == param))
                .or_else(|| decl.param_values.iter().find(|(n, _)| *n == param))
                .map(|(_, v)| *v)
                .or_else(|| {
                    decl.params
                        .iter()
                        .find(|p| p.name == param)
                        .map(|p| p.default)
                }),
            None => {
                let s = self.slot_of(skill)?;
                let e = self
                    .skills
                    .get(s)
                    .ok_or_else(|| ControlError::UnknownSkill(skill.to_string()))?;
                e.values.iter().find(|(n, _)| *n == param).map(|(_, v)| *v)
            }
        };
        value
            .map(Reply::Param)
            .ok_or_else(|| param_err(skill, ParamError::Unknown { param }))
    }

    /// A skill's arbitration priority, from the next cycle start.
    pub(super) fn set_priority(&mut self, client: &str, skill: String, priority: i32) -> Response {
        if let Some(d) = self.skills.away(&skill) {
            // Applied when it is back.
            let old = self
                .skills
                .kept(&skill)
                .and_then(|k| k.priority)
                .unwrap_or(d.priority);
            self.skills.keep(&skill).priority = Some(priority);
            if old != priority {
                self.outbox.push(EventKind::PriorityChanged {
                    skill,
                    old,
                    new: priority,
                    by: client.to_string(),
                });
            }
            return Ok(Reply::Done);
        }
        let s = self.slot_of(&skill)?;
        if let Some(e) = self.skills.get_mut(s) {
            let old = e.decl.priority;
            e.decl.priority = priority;
            self.skills.keep(&skill).priority = Some(priority);
            if old != priority {
                // Written to the board at the next cycle start: arbitration changes
                // from the next cycle.
                self.dirty = true;
                if let Some(r) = &self.recorder {
                    r.line(
                            "priority",
                            Some(self.in_progress()),
                            serde_json::json!({"skill": skill, "old": old, "new": priority, "by": client}),
                        );
                }
                self.record_control(
                    "priority",
                    serde_json::json!({"skill": skill, "value": priority, "by": client}),
                );
                self.outbox.push(EventKind::PriorityChanged {
                    skill,
                    old,
                    new: priority,
                    by: client.to_string(),
                });
            }
        }
        Ok(Reply::Done)
    }
}
