//! The fabric's values and events as JSON: what `skillfab ctl --json`, the fabric log and the
//! C and Python clients print and parse.

use crate::control::{Event, EventKind, PlanTree, PortInfo, SkillInfo, Stats};
use crate::param::ParamValue;
use crate::value::Value;
use serde_json::{Value as Json, json};

/// A parameter value as a plain JSON number or bool.
pub fn param_json(v: &ParamValue) -> Json {
    match *v {
        ParamValue::Bool(b) => json!(b),
        ParamValue::Int(i) => json!(i),
        ParamValue::UInt(u) => json!(u),
        ParamValue::Float(f) => json!(f),
    }
}

/// A parameter value back from [`param_json`]'s JSON: a bool, else an unsigned, a signed or
/// a float number (the declared kind then decides, [`ParamValue::coerce`]); `None` for
/// anything else.
pub fn param_from_json(j: &Json) -> Option<ParamValue> {
    if let Some(b) = j.as_bool() {
        Some(ParamValue::Bool(b))
    } else if let Some(u) = j.as_u64() {
        Some(ParamValue::UInt(u))
    } else if let Some(i) = j.as_i64() {
        Some(ParamValue::Int(i))
    } else {
        j.as_f64().map(ParamValue::Float)
    }
}

/// A decoded value as JSON.
pub fn value_json(v: &Value) -> Json {
    // Built directly (it was a round trip through text: the recorder calls this for every
    // sample of every recorded topic).
    match v {
        Value::Bool(b) => Json::Bool(*b),
        Value::Int(i) => json!(i),
        Value::UInt(u) => json!(u),
        Value::Float(x) if x.is_finite() => json!(x),
        Value::Float(_) | Value::Null => Json::Null,
        Value::Text(t) => Json::String(t.clone()),
        Value::Array(a) => Json::Array(a.iter().map(value_json).collect()),
        Value::Struct(fields) => Json::Object(
            fields
                .iter()
                .map(|(k, x)| (k.clone(), value_json(x)))
                .collect(),
        ),
    }
}

/// An event as one JSON object: `{"seq", "cycle", "time_ns", "event": "<kind>", ...fields}`.
pub fn event_json(e: &Event) -> Json {
    let mut obj = json!({"seq": e.seq, "cycle": e.cycle, "time_ns": e.time_ns});
    let (name, fields) = match &e.kind {
        EventKind::MonitorFired {
            id,
            client,
            expr,
            values,
            stamp_ns,
        } => {
            let vals: serde_json::Map<String, Json> = values
                .iter()
                .map(|(p, v)| (p.clone(), value_json(v)))
                .collect();
            (
                "monitor_fired",
                json!({"monitor": id, "client": client, "expr": expr, "values": vals, "stamp_ns": stamp_ns}),
            )
        }
        EventKind::SkillRegistered {
            skill,
            pid,
            restarted,
        } => (
            "skill_registered",
            json!({"skill": skill, "pid": pid, "restarted": restarted}),
        ),
        EventKind::StateRestored {
            skill,
            active,
            params,
            priority,
            io_log,
            dropped,
        } => {
            let p: serde_json::Map<String, Json> = params
                .iter()
                .map(|(n, v)| (n.clone(), param_json(v)))
                .collect();
            (
                "state_restored",
                json!({"skill": skill, "active": active, "params": p, "priority": priority,
                       "io_log": io_log, "dropped": dropped}),
            )
        }
        EventKind::SkillActivated { skill } => ("skill_activated", json!({"skill": skill})),
        EventKind::SkillDeactivated { skill } => ("skill_deactivated", json!({"skill": skill})),
        EventKind::SkillDied { skill, pid } => ("skill_died", json!({"skill": skill, "pid": pid})),
        EventKind::SkillLeft { skill } => ("skill_left", json!({"skill": skill})),
        EventKind::DeviceLost { device } => ("device_lost", json!({"device": device})),
        EventKind::DeviceBack { device } => ("device_back", json!({"device": device})),
        EventKind::ParamChanged {
            skill,
            param,
            old,
            new,
            by,
        } => (
            "param_changed",
            json!({"skill": skill, "param": param, "old": param_json(old), "new": param_json(new), "by": by}),
        ),
        EventKind::PriorityChanged {
            skill,
            old,
            new,
            by,
        } => (
            "priority_changed",
            json!({"skill": skill, "old": old, "new": new, "by": by}),
        ),
        EventKind::CycleOverrun { unfinished } => {
            ("cycle_overrun", json!({"unfinished": unfinished}))
        }
        EventKind::Cycling { running } => ("cycling", json!({"running": running})),
        EventKind::Held { cycle } => ("held", json!({"at": cycle})),
        EventKind::ProcessGaveUp {
            process,
            restarts,
            status,
        } => (
            "process_gave_up",
            json!({"process": process, "restarts": restarts, "status": status}),
        ),
        EventKind::PlanChanged {
            plan,
            cycle,
            changes,
        } => (
            "plan_changed",
            json!({"plan": plan, "at": cycle,
                   "changes": changes.iter().map(|c| json!({"id": c.id, "status": c.status.as_str()}))
                       .collect::<Vec<_>>()}),
        ),
        EventKind::PlanStarted {
            plan,
            client,
            nodes,
            replaced,
        } => (
            "plan_started",
            json!({"plan": plan, "client": client, "nodes": nodes, "replaced": replaced}),
        ),
        EventKind::PlanEnded { plan, status } => (
            "plan_ended",
            json!({"plan": plan, "status": status.as_str()}),
        ),
        EventKind::ChannelWinner {
            channel,
            winner,
            weights,
        } => {
            let w: serde_json::Map<String, Json> =
                weights.iter().map(|(n, x)| (n.clone(), json!(x))).collect();
            (
                "channel_winner",
                json!({"channel": channel, "winner": winner, "weights": w}),
            )
        }
    };
    obj["event"] = json!(name);
    if let (Some(o), Json::Object(f)) = (obj.as_object_mut(), fields) {
        o.extend(f);
    }
    obj
}

/// A plan's tree as JSON (what `skillfab ctl --json plan` prints, and a recording's `plan`
/// record): `{"plan", "nodes": [{"id", "parent", "name", "kind", "detail", "status", "since"}]}`.
pub fn plan_json(t: &PlanTree) -> Json {
    let nodes: Vec<Json> = t
        .nodes
        .iter()
        .map(|n| {
            let (status, since) = t.status.get(n.id as usize).copied().unwrap_or_default();
            json!({"id": n.id, "parent": n.parent, "name": n.name, "kind": n.kind,
                   "detail": n.detail, "status": status.as_str(), "since": since})
        })
        .collect();
    json!({"plan": t.plan, "nodes": nodes})
}

/// A registered skill as JSON (what `skillfab ctl --json ls` prints per skill).
pub fn skill_json(s: &SkillInfo) -> Json {
    let params: Vec<Json> = s
        .params
        .iter()
        .map(|p| {
            let value = s
                .values
                .iter()
                .find(|(n, _)| *n == p.name)
                .map(|(_, v)| param_json(v));
            json!({"name": p.name, "type": p.kind.to_string(), "value": value,
                   "default": param_json(&p.default), "min": p.min.as_ref().map(param_json),
                   "max": p.max.as_ref().map(param_json), "doc": p.doc})
        })
        .collect();
    let ports = |p: &[PortInfo]| -> Vec<Json> {
        p.iter()
            .map(|p| json!({"port": p.port, "topic": p.topic, "type": p.type_name}))
            .collect()
    };
    let f = &s.figures;
    json!({"name": s.name, "kind": s.kind, "mode": s.mode.to_string(), "state": s.state.as_str(),
           "priority": s.priority, "pid": s.pid, "params": params, "inputs": ports(&s.inputs),
           "outputs": ports(&s.outputs), "runs": f.runs, "skips": f.skips, "failures": f.failures,
           "last_cycle": f.last_cycle, "compute_us_last": f.compute_us_last,
           "compute_us_mean": f.compute_us_mean, "deadline_misses": f.deadline_misses,
           "cycle_allocs": f.cycle_allocs})
}

/// Cycle statistics as JSON (what `skillfab ctl --json stats` prints).
pub fn stats_json(s: &Stats) -> Json {
    let l = &s.latency_us;
    json!({"cycles": s.cycles, "running": s.running, "overruns": s.overruns,
           "late_starts": s.late_starts,
           "latency_us": {"p50": l.p50, "p99": l.p99, "max": l.max},
           "skills": s.skills.iter().map(|k| json!({"name": k.name, "runs": k.figures.runs,
               "skips": k.figures.skips, "failures": k.figures.failures,
               "compute_us_mean": k.figures.compute_us_mean,
               "deadline_misses": k.figures.deadline_misses,
               "cycle_allocs": k.figures.cycle_allocs})).collect::<Vec<_>>(),
           "deaths": s.deaths, "events": s.events,
           "channels": s.channels.iter().map(|c| json!({"channel": c.channel, "winner": c.winner,
               "cycle": c.cycle})).collect::<Vec<_>>(),
           "bridges": serde_json::to_value(&s.bridges).unwrap_or_default()})
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_become_json_as_their_text_reads() {
        let v = Value::Struct(vec![
            ("x".into(), Value::Float(0.1 + 0.2)),
            (
                "r".into(),
                Value::Array(vec![
                    Value::Float(f64::NAN),
                    Value::Float(f64::INFINITY),
                    Value::Float(-0.0),
                    Value::Float(1e300),
                ]),
            ),
            ("n".into(), Value::Int(-3)),
            ("u".into(), Value::UInt(u64::MAX)),
            ("b".into(), Value::Bool(true)),
            ("t".into(), Value::Text("… 3 more".into())),
        ]);
        let through_text: Json = serde_json::from_str(&v.to_string()).unwrap();
        assert_eq!(value_json(&v), through_text);
        assert_eq!(value_json(&v)["r"][0], Json::Null, "non-finite: null");
    }
}
