//! Registration and liveness: skills claiming slots, admitted or refused, leaving or found
//! dead, and rejoining.

use super::requests::set_io_log;
use super::skills::Kept;
use super::{Entry, Manager, NODE_SWEEP};
use crate::graph;
use skillfab_proto::board::{MAX_SLOTS, SlotState, pid_alive};
use skillfab_proto::control::EventKind;
use skillfab_proto::decl::SkillDecl;
use skillfab_proto::names;
use skillfab_proto::param::ParamValue;
use skillfab_proto::param::check_bounds;
use skillfab_proto::registration::Refusal;
use std::sync::atomic::Ordering;
use std::time::Instant;

/// Most inputs, and most outputs, a skill declares (a slot's masks have a bit for each).
const MAX_PORTS: usize = 64;

/// Why a skill leaves the registry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DropReason {
    /// It said goodbye on the board (a clean exit).
    Left,
    /// Its process is gone without a goodbye (crash, `kill -9`).
    Died,
}

impl Manager {
    pub(super) fn service_registry(&mut self) {
        for i in 0..MAX_SLOTS {
            match self.board.slot(i).state() {
                SlotState::Pending => self.admit(i),
                SlotState::Ready => {
                    if let Some(e) = self.skills.get_mut(i).filter(|e| !e.ready) {
                        e.ready = true;
                        self.cycles.dirty = true;
                        tracing::info!(skill = %e.decl.name, "skill ready");
                        // Read its outputs from now on, so queries and monitors find the
                        // latest sample.
                        let outputs = e.decl.outputs.clone();
                        self.observers.read_outputs(&self.node, &outputs);
                    }
                }
                SlotState::Leaving => self.drop_slot(i, DropReason::Left),
                _ => {}
            }
        }
    }

    pub(super) fn refuse(&self, i: usize, name: Option<&str>, reason: Refusal) {
        tracing::warn!(skill = name.unwrap_or("?"), %reason, "registration refused");
        let slot = self.board.slot(i);
        slot.write_msg(&reason.encode());
        slot.set_state(SlotState::Refused);
        slot.bell.ring();
    }

    pub(super) fn admit(&mut self, i: usize) {
        let slot = self.board.slot(i);
        let mut decl: SkillDecl = match postcard::from_bytes(&slot.read_decl()) {
            Ok(d) => d,
            Err(e) => return self.refuse(i, None, Refusal::Malformed(e)),
        };
        let bad_name = |what: &str, name: &str| {
            names::check_name(what, name, what == "topic")
                .is_err()
                .then(|| Refusal::BadName {
                    what: what.into(),
                    name: name.into(),
                })
        };
        let bad = bad_name("skill", &decl.name).or_else(|| {
            decl.inputs
                .iter()
                .chain(&decl.outputs)
                .find_map(|p| bad_name("topic", &p.topic))
        });
        if let Some(refusal) = bad {
            return self.refuse(i, None, refusal);
        }
        if decl.inputs.len() > MAX_PORTS || decl.outputs.len() > MAX_PORTS {
            let refusal = Refusal::TooManyPorts {
                inputs: decl.inputs.len() as u32,
                outputs: decl.outputs.len() as u32,
                max: MAX_PORTS as u32,
            };
            return self.refuse(i, Some(&decl.name), refusal);
        }
        // A previous instance of the same name that died is replaced, not a duplicate.
        if let Some(j) = (0..MAX_SLOTS).find(|&j| {
            j != i
                && self
                    .skills
                    .get(j)
                    .is_some_and(|e| e.decl.name == decl.name && !pid_alive(e.decl.pid))
        }) {
            self.drop_slot(j, DropReason::Died);
        }
        let live = self.skills.all().map(|e| &e.decl);
        if let Err(e) = graph::check_join(live, &decl) {
            return self.refuse(i, Some(&decl.name), Refusal::Wiring(*e));
        }
        // What clients set for an earlier instance of this name comes back.
        let mut values = decl.param_values.clone();
        let restored = self
            .skills
            .kept(&decl.name)
            .map(|k| restore(k, &mut decl, &mut values));
        let active = restored.as_ref().map_or(decl.start_active, |r| r.active);
        let slot = self.board.slot(i);
        slot.reset_counters();
        slot.generation.fetch_add(1, Ordering::Relaxed);
        if values != decl.param_values {
            // Read by the skill before its first run (it was written while it waits for
            // the answer); the same snapshot a `set` writes.
            match postcard::to_allocvec(&values).map(|b| slot.write_params(&b)) {
                Ok(Ok(())) => {}
                Ok(Err(e)) => {
                    tracing::warn!(skill = %decl.name, error = %e, "parameters not restored")
                }
                Err(e) => tracing::warn!(skill = %decl.name, error = %e, "parameters not restored"),
            }
        }
        slot.active.store(
            self.skills.activation(&decl.name, active),
            Ordering::Release,
        );
        slot.set_state(SlotState::Accepted);
        slot.bell.ring();
        tracing::info!(
            skill = %decl.name, kind = %decl.kind, mode = %decl.mode, pid = decl.pid,
            active, "skill registered"
        );
        // Back (started by hand, or by a new `up`): no longer given up on.
        self.skills.gave_up.remove(&decl.name);
        let (name, pid, device) = (decl.name.clone(), decl.pid, is_device(&decl));
        let restarted = self.skills.insert(
            i,
            Entry {
                values,
                ready: false,
                active,
                decl,
            },
        );
        if restarted && device {
            self.events.push(EventKind::DeviceBack {
                device: name.clone(),
            });
        }
        self.state.check = true;
        self.events.push(EventKind::SkillRegistered {
            skill: name.clone(),
            pid,
            restarted,
        });
        if let Some(r) = restored {
            // Its samples go to the fabric log again (the ports are those of the new one).
            let io_log = self.observers.io_log.contains_key(&name)
                && match set_io_log(
                    &mut self.observers,
                    &self.skills,
                    &self.node,
                    self.cycles.cycle,
                    "restore",
                    &name,
                    true,
                ) {
                    Ok(_) => true,
                    Err(e) => {
                        tracing::warn!(skill = %name, error = %e, "I/O logging not restored");
                        false
                    }
                };
            tracing::info!(skill = %name, active = r.active, params = r.params.len(), priority = ?r.priority, io_log, "state restored");
            self.events.push(EventKind::StateRestored {
                skill: name,
                active: r.active,
                params: r.params,
                priority: r.priority,
                io_log,
                dropped: r.dropped,
            });
        }
        self.cycles.dirty = true;
    }

    /// Removes slot `i`: its skill left or died. Its pending run in this cycle (and whatever
    /// depended on it) is taken off the counter so the cycle does not wait for it.
    fn drop_slot(&mut self, i: usize, why: DropReason) {
        if let Some(mut run) = self.cycles.running.take() {
            let n = self.cancel_all(&mut run, vec![i]);
            if n > 0 {
                self.board.complete(run.k, n);
            }
            self.cycles.running = Some(run);
        }
        let slot = self.board.slot(i);
        if let Some(e) = self.skills.remove(i) {
            if why == DropReason::Died {
                self.skills.deaths += 1;
                tracing::warn!(skill = %e.decl.name, pid = e.decl.pid, "skill died");
                self.events.push(EventKind::SkillDied {
                    skill: e.decl.name.clone(),
                    pid: e.decl.pid,
                });
                if is_device(&e.decl) {
                    self.events.push(EventKind::DeviceLost {
                        device: e.decl.name.clone(),
                    });
                }
            } else {
                tracing::info!(skill = %e.decl.name, "skill left");
                self.events.push(EventKind::SkillLeft {
                    skill: e.decl.name.clone(),
                });
            }
            self.cycles.dirty = true;
            // Stop reading its outputs: the manager must not keep a dead producer's topics
            // alive. They are read again when a new producer is ready.
            self.observers.forget_outputs(&e.decl.outputs);
        }
        slot.active.store(0, Ordering::Release);
        slot.pid.store(0, Ordering::Release);
        slot.set_state(SlotState::Free);
    }

    pub(super) fn check_liveness(&mut self) {
        self.cycles.last_liveness = Instant::now();
        let mut died = false;
        for i in 0..MAX_SLOTS {
            let slot = self.board.slot(i);
            let state = slot.state();
            if state == SlotState::Free || state == SlotState::Refused {
                continue;
            }
            let pid = slot.pid.load(Ordering::Acquire);
            if pid != 0 && !pid_alive(pid) {
                self.drop_slot(i, DropReason::Died);
                died = true;
            }
        }
        // Frees the ports of dead processes (skills, or clients killed with Ctrl-C) so a
        // restarted instance can take their place and no shared memory is left behind.
        if died || self.cycles.last_node_sweep.elapsed() >= NODE_SWEEP {
            self.cycles.last_node_sweep = Instant::now();
            let _ = self.node.try_cleanup_dead_nodes();
        }
    }
}

/// What a new instance got back of what clients set for the name.
struct Restored {
    active: bool,
    params: Vec<(String, ParamValue)>,
    priority: Option<i32>,
    dropped: Vec<String>,
}

/// Applies `kept` to a new instance's declaration and parameter values: activation,
/// priority, and every parameter the new binary still declares with a type and bounds that
/// admit the kept value (the others are dropped, with the reason).
fn restore(kept: &Kept, decl: &mut SkillDecl, values: &mut Vec<(String, ParamValue)>) -> Restored {
    let mut r = Restored {
        active: kept.active.unwrap_or(decl.start_active),
        params: Vec::new(),
        priority: kept.priority,
        dropped: Vec::new(),
    };
    if let Some(p) = kept.priority {
        decl.priority = p;
    }
    for (name, value) in &kept.params {
        let Some(spec) = decl.params.iter().find(|p| p.name == *name) else {
            r.dropped.push(format!("{name}: no longer declared"));
            continue;
        };
        let checked = value
            .coerce(spec.kind)
            .ok_or_else(|| format!("{name}: now of type {}", spec.kind))
            .and_then(|v| {
                check_bounds(spec, v)
                    .map(|()| v)
                    .map_err(|e| format!("{name}: {e}"))
            });
        match checked {
            Ok(v) => {
                match values.iter_mut().find(|(n, _)| n == name) {
                    Some(slot) => slot.1 = v,
                    None => values.push((name.clone(), v)),
                }
                r.params.push((name.clone(), v));
            }
            Err(why) => r.dropped.push(why),
        }
    }
    r
}

/// Whether a registered unit is a device (it serves an actuator channel).
fn is_device(d: &SkillDecl) -> bool {
    d.inputs
        .iter()
        .any(|p| matches!(p.kind, skillfab_proto::decl::PortKind::Channel(_)))
}
