//! `activate`/`deactivate`, `set`/`get` of parameters, `priority`.

use super::{Change, Effects, param_err, unknown};
use crate::engine::skills::Skills;
use crate::graph::DemandError;
use skillfab_proto::board::Board;
use skillfab_proto::control::{ControlError, EventKind, ParamArg, Reply, Response};
use skillfab_proto::param::ParamError;

/// Activates or deactivates every named skill, or none (an unknown name refuses all), as a
/// client asks. A skill activated on demand that a client activates is the client's from then
/// on (a release leaves it); one a client deactivates is neither wanted nor demanded any more,
/// and what it alone needed on demand is released with it.
pub(super) fn set_active(
    skills: &mut Skills,
    names: &[String],
    active: bool,
) -> Result<Effects, ControlError> {
    let mut effects = switch(skills, names, active)?;
    for n in names {
        let kept = skills.keep(n);
        kept.demanded = false;
        if !active {
            kept.wanted = false;
        }
    }
    if !active {
        release_unneeded(skills, &mut effects)?;
    }
    Ok(effects)
}

/// Wants every named skill, or none: each is activated with the producers of what it reads,
/// transitively; those not active yet are activated on demand. Refused, with nothing changed,
/// when a needed input has no producer or producers loop.
pub(super) fn want(skills: &mut Skills, names: &[String]) -> Result<Effects, ControlError> {
    if let Some(n) = names.iter().find(|n| skills.decl(n).is_none()) {
        return Err(unknown(n));
    }
    let needed = needed_by(skills, names)?;
    let off: Vec<String> = needed
        .into_iter()
        .filter(|n| !skills.is_active(n))
        .collect();
    for n in &off {
        skills.keep(n).demanded = !names.contains(n);
    }
    for n in names {
        skills.keep(n).wanted = true;
    }
    tracing::info!(wanted = ?names, activated = ?off, "skills wanted");
    switch(skills, &off, true)
}

/// Releases every named skill, or none: it is not wanted any more and is deactivated unless a
/// skill still wanted reads from it (then it stays, on demand); every skill activated on demand
/// that no wanted skill needs now is deactivated too.
pub(super) fn release(skills: &mut Skills, names: &[String]) -> Result<Effects, ControlError> {
    if let Some(n) = names.iter().find(|n| skills.decl(n).is_none()) {
        return Err(unknown(n));
    }
    for n in names {
        let kept = skills.keep(n);
        kept.wanted = false;
        kept.demanded = true;
    }
    let mut effects = Effects::default();
    release_unneeded(skills, &mut effects)?;
    Ok(effects)
}

/// What the wanted skills `names` need running: they and their producers, transitively, each
/// producer before the skills that read it.
fn needed_by(skills: &Skills, names: &[String]) -> Result<Vec<String>, ControlError> {
    let known = skills.known();
    match crate::graph::demand(&known, names) {
        Ok(needed) => Ok(needed.into_iter().map(str::to_string).collect()),
        Err(DemandError::NoProducer {
            skill,
            port,
            topic,
            wanted_by,
        }) => Err(ControlError::NoProducer {
            skill,
            port,
            topic,
            wanted_by,
        }),
        Err(DemandError::Loop(loop_)) => Err(ControlError::DemandLoop { loop_ }),
    }
}

/// Deactivates the skills activated on demand that no wanted skill needs any more.
fn release_unneeded(skills: &mut Skills, effects: &mut Effects) -> Result<(), ControlError> {
    let needed = needed_by(skills, &skills.marked(|k| k.wanted))?;
    let unneeded: Vec<String> = skills
        .marked(|k| k.demanded)
        .into_iter()
        .filter(|n| !needed.contains(n))
        .collect();
    for n in &unneeded {
        skills.keep(n).demanded = false;
    }
    if !unneeded.is_empty() {
        tracing::info!(released = ?unneeded, "skills no longer needed");
    }
    let more = switch(skills, &unneeded, false)?;
    effects.changes.extend(more.changes);
    effects.replan |= more.replan;
    Ok(())
}

/// Activates or deactivates every named skill, or none (an unknown name refuses all).
/// A skill that is away (its process died and may be restarted) gets it when it is back.
fn switch(skills: &mut Skills, names: &[String], active: bool) -> Result<Effects, ControlError> {
    let mut effects = Effects::default();
    let slots = names
        .iter()
        .map(|n| match skills.away(n) {
            Some(_) => Ok(Err(n.clone())),
            None => skills.slot_of(n).map(Ok).ok_or_else(|| unknown(n)),
        })
        .collect::<Result<Vec<_>, _>>()?;
    for s in slots {
        let s = match s {
            Ok(s) => s,
            Err(away) => {
                tracing::info!(skill = %away, active, "activation kept for its return");
                let kept = skills.keep(&away);
                if active && kept.active != Some(true) {
                    kept.activations += 1;
                }
                kept.active = Some(active);
                continue;
            }
        };
        let Some(e) = skills.get_mut(s) else {
            continue;
        };
        if e.active == active {
            continue;
        }
        // Takes effect at the next cycle start (the plan writes it to the board), so a
        // skill deactivated mid-cycle still finishes the run the cycle counts on.
        e.active = active;
        let skill = e.decl.name.clone();
        let kept = skills.keep(&skill);
        kept.active = Some(active);
        if active {
            kept.activations += 1;
        }
        effects.replan = true;
        tracing::info!(%skill, active, "activation changed");
        effects.change(Change::Activation { skill, active });
    }
    Ok(effects)
}

/// Sets a parameter after checking its type and bounds; logged and announced.
pub(super) fn set_param(
    skills: &mut Skills,
    board: &Board,
    client: &str,
    skill: &str,
    param: &str,
    arg: ParamArg,
) -> Result<Effects, ControlError> {
    // A skill that is away gets the value when it is back; it is checked against the
    // declaration it had.
    let live = skills.slot_of(skill);
    let decl = skills
        .decl(skill)
        .ok_or_else(|| ControlError::UnknownSkill(skill.to_string()))?;
    let (value, spec) =
        crate::checks::param_value(decl, param, arg).map_err(|err| param_err(skill, err))?;
    let default = spec.default;
    let old = match live.and_then(|s| skills.get(s)) {
        Some(e) => e.values.iter().find(|(n, _)| n == param).map(|(_, v)| *v),
        None => skills
            .kept(skill)
            .and_then(|k| k.params.iter().find(|(n, _)| n == param).map(|(_, v)| *v)),
    }
    .unwrap_or(default);
    if let Some(s) = live
        && let Some(e) = skills.get_mut(s)
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
        board
            .slot(s)
            .write_params(&bytes)
            .map_err(|err| cannot(&err))?;
    }
    let kept = &mut skills.keep(skill).params;
    match kept.iter_mut().find(|(n, _)| n == param) {
        Some(slot) => slot.1 = value,
        None => kept.push((param.to_string(), value)),
    }
    let mut effects = Effects::default();
    effects.change(Change::Param {
        skill: skill.to_string(),
        param: param.to_string(),
        old,
        new: value,
        by: client.to_string(),
    });
    Ok(effects)
}

/// A parameter's current value.
pub(super) fn get_param(skills: &Skills, skill: &str, param: String) -> Response {
    let value = match skills.away(skill) {
        // A skill that is away has the value it will be given when it is back: what a
        // client set, else what its last process started with (a plan that reads it
        // to restore it later, while the skill is being restarted, reads that).
        Some(decl) => skills
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
            let e = skills
                .slot_of(skill)
                .and_then(|s| skills.get(s))
                .ok_or_else(|| unknown(skill))?;
            e.values.iter().find(|(n, _)| *n == param).map(|(_, v)| *v)
        }
    };
    value
        .map(Reply::Param)
        .ok_or_else(|| param_err(skill, ParamError::Unknown { param }))
}

/// A skill's arbitration priority, from the next cycle start.
pub(super) fn set_priority(
    skills: &mut Skills,
    client: &str,
    skill: String,
    priority: i32,
) -> Result<Effects, ControlError> {
    let mut effects = Effects::default();
    if let Some(d) = skills.away(&skill) {
        // Applied when it is back.
        let old = skills
            .kept(&skill)
            .and_then(|k| k.priority)
            .unwrap_or(d.priority);
        skills.keep(&skill).priority = Some(priority);
        if old != priority {
            effects.events.push(EventKind::PriorityChanged {
                skill,
                old,
                new: priority,
                by: client.to_string(),
            });
        }
        return Ok(effects);
    }
    let s = skills.slot_of(&skill).ok_or_else(|| unknown(&skill))?;
    if let Some(e) = skills.get_mut(s) {
        let old = e.decl.priority;
        e.decl.priority = priority;
        skills.keep(&skill).priority = Some(priority);
        if old != priority {
            // Written to the board at the next cycle start: arbitration changes
            // from the next cycle.
            effects.replan = true;
            effects.change(Change::Priority {
                skill,
                old,
                new: priority,
                by: client.to_string(),
            });
        }
    }
    Ok(effects)
}
