//! The hub's answers to what a viewer asks: subscriptions, parameters (`/<skill>/<param>`,
//! checked by the manager as `ctl set` is) and the services `/skillfab/activate` and
//! `/skillfab/deactivate`.

use super::{ACTIVATE, DEACTIVATE, Hub, Own, Source, ViewerId, plan_json, stamp};
use crate::protocol::{
    self, ClientMessage, Level, Parameter, ServerMessage, Service, ServiceCall, ServiceSchema,
};
use serde_json::{Value as Json, json};
use skillfab_client::ClientError;
use skillfab_proto::bridge::unix_now_ns;
use skillfab_proto::control::SkillInfo;
use skillfab_proto::param::{ParamKind, ParamValue};
use std::collections::HashSet;

fn skills_schema(title: &str) -> ServiceSchema {
    ServiceSchema {
        encoding: "json".into(),
        schema_name: title.into(),
        schema_encoding: "jsonschema".into(),
        schema: json!({"type": "object", "title": title,
                       "properties": {"skills": {"type": "array", "items": {"type": "string"}}},
                       "required": ["skills"]})
        .to_string(),
    }
}

pub(super) fn services() -> Vec<Service> {
    let reply = ServiceSchema {
        encoding: "json".into(),
        schema_name: "skillfab.Done".into(),
        schema_encoding: "jsonschema".into(),
        schema: json!({"type": "object", "title": "skillfab.Done",
                       "properties": {"ok": {"type": "boolean"},
                                      "skills": {"type": "array", "items": {"type": "string"}}}})
        .to_string(),
    };
    [
        (ACTIVATE, "/skillfab/activate", "skillfab.Activate"),
        (DEACTIVATE, "/skillfab/deactivate", "skillfab.Deactivate"),
    ]
    .into_iter()
    .map(|(id, name, ty)| {
        let request = skills_schema(ty);
        Service {
            id,
            name: name.into(),
            ty: ty.into(),
            request_schema: request.schema.clone(),
            response_schema: reply.schema.clone(),
            request,
            response: reply.clone(),
        }
    })
    .collect()
}

/// A parameter as the protocol sends it: `float64` marks a float, so a client keeps `2.0` one.
pub(super) fn parameter(name: String, v: ParamValue) -> Parameter {
    Parameter {
        name,
        value: skillfab_proto::json::param_json(&v),
        ty: matches!(v, ParamValue::Float(_)).then(|| "float64".to_string()),
    }
}

/// A parameter's JSON value as the declared kind, or why not.
fn param_value(j: &Json, kind: ParamKind) -> Result<ParamValue, String> {
    skillfab_proto::json::param_from_json(j)
        .and_then(|v| v.coerce(kind))
        .ok_or_else(|| format!("{j} is not a {kind}"))
}

fn split_param(name: &str) -> Option<(&str, &str)> {
    let (skill, param) = name.strip_prefix('/')?.split_once('/')?;
    (!skill.is_empty() && !param.is_empty() && !param.contains('/')).then_some((skill, param))
}

impl Hub {
    fn status(&self, id: ViewerId, level: Level, message: String, req: Option<String>) {
        if let Some(v) = self.viewers.get(&id) {
            v.outbox.text(&ServerMessage::status(level, message, req));
        }
    }

    pub(super) fn request(&mut self, id: ViewerId, m: ClientMessage) {
        match m {
            ClientMessage::Subscribe { subscriptions } => {
                let mut latched = Vec::new();
                for s in subscriptions {
                    let Some(v) = self.viewers.get_mut(&id) else {
                        return;
                    };
                    let problem = if !self.channels.contains_key(&s.channel_id) {
                        Some(format!("subscribe: no channel {}", s.channel_id))
                    } else if v.subs.contains_key(&s.id) {
                        Some(format!("subscribe: subscription id {} is in use", s.id))
                    } else if v.by_channel.contains_key(&s.channel_id) {
                        Some(format!(
                            "subscribe: channel {} is already subscribed to (one subscription per channel)",
                            s.channel_id
                        ))
                    } else {
                        None
                    };
                    if let Some(p) = problem {
                        self.status(id, Level::Error, p, None);
                        continue;
                    }
                    v.subs.insert(s.id, s.channel_id);
                    v.by_channel
                        .entry(s.channel_id)
                        .or_insert_with(|| (Vec::new(), None))
                        .0
                        .push(s.id);
                    latched.push(s);
                }
                // What does not change often is sent at once to the new subscriber.
                for s in latched {
                    let msg = match self.channels.get(&s.channel_id).map(|c| &c.source) {
                        Some(Source::Own(Own::Scene)) => self
                            .opts
                            .scene
                            .as_ref()
                            .map(|sc| sc.update(stamp(unix_now_ns()))),
                        Some(Source::Own(Own::Tf)) => Some(self.static_tf()),
                        Some(Source::Own(Own::Plan)) => {
                            self.plan.as_ref().map(|p| plan_json(p, self.plan_cycle))
                        }
                        _ => None,
                    };
                    if let (Some(msg), Some(v)) = (msg, self.viewers.get(&id)) {
                        v.outbox.data(protocol::message_data(
                            s.id,
                            unix_now_ns(),
                            msg.to_string().as_bytes(),
                        ));
                    }
                }
            }
            ClientMessage::Unsubscribe { subscription_ids } => {
                let mut unknown = Vec::new();
                if let Some(v) = self.viewers.get_mut(&id) {
                    for s in subscription_ids {
                        let Some(ch) = v.subs.remove(&s) else {
                            unknown.push(s);
                            continue;
                        };
                        if let Some((subs, _)) = v.by_channel.get_mut(&ch) {
                            subs.retain(|x| *x != s);
                            if subs.is_empty() {
                                v.by_channel.remove(&ch);
                            }
                        }
                    }
                }
                for s in unknown {
                    self.status(
                        id,
                        Level::Error,
                        format!("unsubscribe: no subscription {s}"),
                        None,
                    );
                }
            }
            ClientMessage::GetParameters {
                parameter_names,
                id: req,
            } => {
                let names: HashSet<String> = parameter_names.into_iter().collect();
                match self.parameters(&names) {
                    Ok((params, unknown)) => {
                        if !unknown.is_empty() {
                            self.status(
                                id,
                                Level::Error,
                                format!("getParameters: no parameter {}", unknown.join(", ")),
                                req.clone(),
                            );
                        }
                        if let Some(v) = self.viewers.get(&id) {
                            v.outbox.text(&ServerMessage::ParameterValues {
                                parameters: params,
                                id: req,
                            });
                        }
                    }
                    Err(e) => self.status(id, Level::Error, format!("getParameters: {e}"), req),
                }
            }
            ClientMessage::SetParameters {
                parameters,
                id: req,
            } => self.set_parameters(id, parameters, req),
            ClientMessage::SubscribeParameterUpdates { parameter_names } => {
                if let Some(v) = self.viewers.get_mut(&id) {
                    let s = v.params.get_or_insert_with(HashSet::new);
                    if parameter_names.is_empty() {
                        s.clear();
                    } else {
                        s.extend(parameter_names);
                    }
                }
            }
            ClientMessage::UnsubscribeParameterUpdates { parameter_names } => {
                if let Some(v) = self.viewers.get_mut(&id) {
                    match (&mut v.params, parameter_names.is_empty()) {
                        (_, true) => v.params = None,
                        (Some(s), false) => {
                            for n in &parameter_names {
                                s.remove(n);
                            }
                            if s.is_empty() {
                                v.params = None;
                            }
                        }
                        (None, false) => {}
                    }
                }
            }
        }
    }

    fn skills(&mut self) -> Result<Vec<SkillInfo>, String> {
        let Some(c) = &self.client else {
            return Err("no manager is running in this domain".into());
        };
        match c.list() {
            Ok(s) => Ok(s),
            Err(e) => {
                let why = e.to_string();
                self.lost_manager(&e);
                Err(why)
            }
        }
    }

    /// The named parameters' values (all when `names` is empty), and the names not found.
    fn parameters(
        &mut self,
        names: &HashSet<String>,
    ) -> Result<(Vec<Parameter>, Vec<String>), String> {
        let skills = self.skills()?;
        let mut found = HashSet::new();
        let mut out = Vec::new();
        for s in &skills {
            for (param, value) in &s.values {
                let name = format!("/{}/{param}", s.name);
                if names.is_empty() || names.contains(&name) {
                    out.push(parameter(name.clone(), *value));
                    found.insert(name);
                }
            }
        }
        let mut unknown: Vec<String> = names.difference(&found).cloned().collect();
        unknown.sort();
        Ok((out, unknown))
    }

    fn set_parameters(&mut self, id: ViewerId, parameters: Vec<Parameter>, req: Option<String>) {
        let skills = match self.skills() {
            Ok(s) => s,
            Err(e) => return self.status(id, Level::Error, format!("setParameters: {e}"), req),
        };
        let mut names = HashSet::new();
        for p in parameters {
            names.insert(p.name.clone());
            let spec = split_param(&p.name).and_then(|(skill, param)| {
                let s = skills.iter().find(|s| s.name == skill)?;
                Some((
                    skill,
                    param,
                    s.params.iter().find(|x| x.name == param)?.kind,
                ))
            });
            let Some((skill, param, kind)) = spec else {
                self.status(
                    id,
                    Level::Error,
                    format!(
                        "setParameters: no parameter {:?} (names are /<skill>/<param>)",
                        p.name
                    ),
                    req.clone(),
                );
                continue;
            };
            let value = match param_value(&p.value, kind) {
                Ok(v) => v,
                Err(why) => {
                    self.status(
                        id,
                        Level::Error,
                        format!("setParameters {}: {why}", p.name),
                        req.clone(),
                    );
                    continue;
                }
            };
            let Some(c) = &self.client else {
                return;
            };
            match c.set_param_value(skill, param, value) {
                Ok(()) => {}
                Err(ClientError::Refused(why)) => {
                    self.status(
                        id,
                        Level::Error,
                        format!("setParameters {}: {why}", p.name),
                        req.clone(),
                    );
                }
                Err(e) => {
                    self.status(
                        id,
                        Level::Error,
                        format!("setParameters {}: {e}", p.name),
                        req.clone(),
                    );
                    return self.lost_manager(&e);
                }
            }
        }
        // The spec: with an id, the values as they now are (refused ones unchanged).
        if req.is_some()
            && let Ok((params, _)) = self.parameters(&names)
            && let Some(v) = self.viewers.get(&id)
        {
            v.outbox.text(&ServerMessage::ParameterValues {
                parameters: params,
                id: req,
            });
        }
    }

    pub(super) fn call(&mut self, id: ViewerId, call: &ServiceCall) {
        let fail = |hub: &Hub, message: String| {
            if let Some(v) = hub.viewers.get(&id) {
                v.outbox.text(&ServerMessage::ServiceCallFailure {
                    service_id: call.service_id,
                    call_id: call.call_id,
                    message,
                });
            }
        };
        if call.service_id != ACTIVATE && call.service_id != DEACTIVATE {
            return fail(self, format!("no service {}", call.service_id));
        }
        if call.encoding != "json" {
            return fail(
                self,
                format!("encoding {:?}: only json is taken", call.encoding),
            );
        }
        let skills: Vec<String> = match serde_json::from_slice::<Json>(&call.payload) {
            Ok(j) => match j.get("skills").and_then(Json::as_array) {
                Some(a) if a.iter().all(Json::is_string) && !a.is_empty() => a
                    .iter()
                    .filter_map(Json::as_str)
                    .map(str::to_string)
                    .collect(),
                _ => return fail(self, r#"the request is {"skills": ["name", …]}"#.into()),
            },
            Err(e) => return fail(self, format!("the request is not JSON: {e}")),
        };
        let Some(c) = &self.client else {
            return fail(self, "no manager is running in this domain".into());
        };
        let names: Vec<&str> = skills.iter().map(String::as_str).collect();
        let done = if call.service_id == ACTIVATE {
            c.activate(&names)
        } else {
            c.deactivate(&names)
        };
        match done {
            Ok(()) => {
                let reply = json!({"ok": true, "skills": skills}).to_string();
                if let Some(v) = self.viewers.get(&id) {
                    v.outbox.binary(protocol::service_response(
                        call.service_id,
                        call.call_id,
                        "json",
                        reply.as_bytes(),
                    ));
                }
            }
            Err(e) => {
                fail(self, e.to_string());
                if !matches!(e, ClientError::Refused(_)) {
                    self.lost_manager(&e);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_values_are_taken_as_their_declared_kind_or_refused_with_why() {
        assert_eq!(
            param_value(&json!(2), ParamKind::Float),
            Ok(ParamValue::Float(2.0))
        );
        assert_eq!(
            param_value(&json!(true), ParamKind::Bool),
            Ok(ParamValue::Bool(true))
        );
        assert_eq!(
            param_value(&json!(-3), ParamKind::Int),
            Ok(ParamValue::Int(-3))
        );
        assert!(
            param_value(&json!(-3), ParamKind::UInt)
                .unwrap_err()
                .contains("unsigned")
        );
        assert!(param_value(&json!(2.5), ParamKind::Int).is_err());
        assert!(
            param_value(&json!("fast"), ParamKind::Float)
                .unwrap_err()
                .contains("float")
        );
        assert_eq!(split_param("/avoid/gain"), Some(("avoid", "gain")));
        assert_eq!(split_param("avoid/gain"), None);
        assert_eq!(split_param("/avoid/a/b"), None);
        assert_eq!(split_param("//gain"), None);
    }
}
