//! The requests of the control plane, carried out between cycles.
//!
//! [`Manager::handle`] dispatches each request to a handler that is handed only the parts of
//! the manager it reads or changes (the registry, the observers, the board) and returns its
//! answer and, for a change the rest of the fabric must see, typed [`Effects`]: events,
//! control changes (the recording and the fabric log keep them), a replan. [`Manager::apply`]
//! carries effects out in one place. One file per family: `list` (skills, stats, schemas),
//! `params` (activation, parameters, priorities), `query` (values), `monitors`, `logging` (the
//! fabric log's I/O log), `plan` (the running plan's tree and statuses).

mod list;
mod logging;
mod monitors;
mod params;
mod plan;
mod query;

pub(crate) use logging::set_io_log;
pub(crate) use monitors::add_monitor;

use super::Manager;
use crate::monitors::Monitor;
use skillfab_proto::control::{
    ChannelStat, ControlError, EventKind, GaveUpInfo, Reply, Request, Response, SkillStat, Stats,
};
use skillfab_proto::param::{ParamError, ParamValue};
use std::sync::atomic::Ordering;

/// How long a bridge's last report counts: it reports about once a second.
const BRIDGE_FRESH: std::time::Duration = std::time::Duration::from_secs(3);

/// Most cycle latencies one `Latencies` answer carries (a console's history).
const MAX_LATENCIES: usize = 1024;

/// What a request changed that others must hear of, in the order it happened.
#[derive(Debug, Default)]
#[must_use = "effects must be applied (Manager::apply)"]
pub(crate) struct Effects {
    /// Control changes, kept by the recording and the fabric log and announced as events.
    pub(crate) changes: Vec<Change>,
    /// Events with no control change behind them.
    pub(crate) events: Vec<EventKind>,
    /// The cycle plan must be made again before the next cycle (activation, priority).
    pub(crate) replan: bool,
    /// Plan trees that arrived whole: the recording keeps each as a `plan` record, so that
    /// a replay can rebuild the tree the `plan_changed` events change.
    pub(crate) plan_trees: Vec<skillfab_proto::control::PlanTree>,
}

/// A control change a client made, which takes effect from the next cycle to start.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Change {
    /// `skill` was activated or deactivated.
    Activation { skill: String, active: bool },
    /// Client `by` set `skill`'s parameter `param` from `old` to `new`.
    Param {
        skill: String,
        param: String,
        old: ParamValue,
        new: ParamValue,
        by: String,
    },
    /// Client `by` changed `skill`'s arbitration priority from `old` to `new`.
    Priority {
        skill: String,
        old: i32,
        new: i32,
        by: String,
    },
}

impl Effects {
    /// Adds a control change.
    fn change(&mut self, change: Change) {
        self.changes.push(change);
    }
}

/// The refusal of a request about a skill that is not registered.
fn unknown(skill: &str) -> ControlError {
    ControlError::UnknownSkill(skill.to_string())
}

fn param_err(skill: &str, e: ParamError) -> ControlError {
    ControlError::Param {
        skill: skill.to_string(),
        error: e,
    }
}

impl Manager {
    /// The cycle in progress, or the last one done.
    pub(crate) fn in_progress(&self) -> u64 {
        self.board
            .header()
            .cycle
            .load(Ordering::Acquire)
            .max(self.cycles.cycle)
    }

    /// Carries out one request of `client` (a `step` is answered by the control plane when
    /// its cycles are done).
    pub(crate) fn handle(&mut self, client: &str, request: Request) -> Response {
        // Most requests change nothing; the state file is rewritten only if its bytes differ.
        self.state.check = true;
        let cycle = self.cycles.cycle;
        let (response, effects) = match request {
            Request::List => (
                Ok(Reply::Skills(list::list(&self.skills, &self.board))),
                Effects::default(),
            ),
            Request::Activate(names) => split(params::set_active(&mut self.skills, &names, true)),
            Request::Deactivate(names) => {
                split(params::set_active(&mut self.skills, &names, false))
            }
            Request::Want(names) => split(params::want(&mut self.skills, &names)),
            Request::Release(names) => split(params::release(&mut self.skills, &names)),
            Request::SetParam {
                skill,
                param,
                value,
            } => split(params::set_param(
                &mut self.skills,
                &self.board,
                client,
                &skill,
                &param,
                value,
            )),
            Request::GetParam { skill, param } => (
                params::get_param(&self.skills, &skill, param),
                Effects::default(),
            ),
            Request::SetPriority { skill, priority } => split(params::set_priority(
                &mut self.skills,
                client,
                skill,
                priority,
            )),
            Request::Query(path) => (
                query::query(&mut self.observers, &self.skills, &self.node, &path),
                Effects::default(),
            ),
            Request::AddMonitor { expr, mode, hold } => {
                let from = self.in_progress() + 1;
                (
                    add_monitor(
                        &mut self.observers,
                        &self.skills,
                        &self.node,
                        client,
                        expr,
                        mode,
                        hold,
                        from,
                    ),
                    Effects::default(),
                )
            }
            Request::RemoveMonitor(id) => (
                if self.observers.monitors.remove(id) {
                    Ok(Reply::Done)
                } else {
                    Err(ControlError::UnknownMonitor(id))
                },
                Effects::default(),
            ),
            Request::AdoptMonitors(ids) => (
                Ok(Reply::Adopted(self.observers.monitors.adopt(client, &ids))),
                Effects::default(),
            ),
            Request::ListMonitors => (
                Ok(Reply::Monitors(
                    self.observers.monitors.iter().map(Monitor::info).collect(),
                )),
                Effects::default(),
            ),
            Request::ProcessGaveUp {
                process,
                restarts,
                status,
            } => {
                tracing::error!(%process, restarts, %status, "skillfab up gave up restarting it");
                let info = GaveUpInfo {
                    process: process.clone(),
                    restarts,
                    status: status.clone(),
                    cycle,
                };
                self.skills.gave_up.insert(process.clone(), info);
                let event = EventKind::ProcessGaveUp {
                    process,
                    restarts,
                    status,
                };
                (Ok(Reply::Done), events(vec![event]))
            }
            Request::GaveUp => (
                Ok(Reply::GaveUp(
                    self.skills.gave_up.values().cloned().collect(),
                )),
                Effects::default(),
            ),
            Request::Run => {
                self.cycles.stop_at = None;
                self.set_paused(false);
                (Ok(Reply::Done), Effects::default())
            }
            Request::Stop => {
                self.cycles.stop_at = None;
                self.set_paused(true);
                (Ok(Reply::Done), Effects::default())
            }
            // A positive step waits for its cycles ([`Manager::serve_requests`]).
            Request::Step(_) => (Ok(Reply::Stepped(cycle)), Effects::default()),
            Request::Hold(at) => {
                self.cycles.holds.set(client, at);
                (Ok(Reply::Done), Effects::default())
            }
            Request::Declaration(skill) => (
                self.skills
                    .decl(&skill)
                    .map(|d| Reply::Declaration(Box::new(d.clone())))
                    .ok_or(ControlError::UnknownSkill(skill)),
                Effects::default(),
            ),
            Request::Stats => (Ok(Reply::Stats(self.stats_info())), Effects::default()),
            Request::Plan(report) => {
                let at = self.in_progress();
                split(plan::report(&mut self.plans, client, report, at))
            }
            Request::CurrentPlan => (
                Ok(Reply::Plan(self.plans.current().cloned())),
                Effects::default(),
            ),
            Request::Latencies(n) => {
                let n = (n as usize).min(MAX_LATENCIES);
                let stats = &self.cycles.stats;
                let reply = Reply::Latencies {
                    cycle,
                    latency_us: stats.recent_us(n),
                    round_trip_us: stats.recent_round_trips_us(n),
                };
                (Ok(reply), Effects::default())
            }
            Request::TopicSchema(topic) => {
                (list::topic_schema(&self.skills, &topic), Effects::default())
            }
            Request::SetIoLog { skill, on } => (
                logging::set_io_log(
                    &mut self.observers,
                    &self.skills,
                    &self.node,
                    cycle,
                    client,
                    &skill,
                    on,
                ),
                Effects::default(),
            ),
            Request::Logging => (Ok(logging::logging(&self.observers)), Effects::default()),
            Request::Record { file, topics } => {
                let at = super::record::RecordStart::new(
                    &self.config.domain,
                    cycle,
                    &self.board,
                    &self.skills,
                    &self.node,
                );
                (
                    self.observers.record_request(file, topics, &at),
                    Effects::default(),
                )
            }
            Request::BridgeReport(report) => {
                let at = std::time::Instant::now();
                self.observers
                    .bridges
                    .insert(report.name.clone(), (report, at));
                (Ok(Reply::Done), Effects::default())
            }
        };
        self.apply(effects);
        response
    }

    /// Cycle statistics, per-skill figures and channel winners: a summary of every part.
    fn stats_info(&self) -> Stats {
        let l = self.cycles.stats.latency_us();
        Stats {
            cycles: self.cycles.cycle,
            running: !self.cycles.paused,
            overruns: self.cycles.stats.overruns,
            latency_us: l,
            skills: list::list(&self.skills, &self.board)
                .into_iter()
                .map(|s| SkillStat {
                    name: s.name,
                    figures: s.figures,
                })
                .collect(),
            deaths: self.skills.deaths,
            events: self.events.published(),
            channels: {
                let mut v: Vec<ChannelStat> = self
                    .observers
                    .channels
                    .iter()
                    .map(|(c, v)| {
                        let who = match (&v.winner, v.weights.is_empty()) {
                            (Some(w), _) => w.clone(),
                            (None, true) => "safe".to_string(),
                            (None, false) => "blend".to_string(),
                        };
                        ChannelStat {
                            channel: c.clone(),
                            winner: who,
                            cycle: v.cycle,
                        }
                    })
                    .collect();
                v.sort_by(|a, b| a.channel.cmp(&b.channel));
                v
            },
            // A bridge reports about once a second; one silent for longer is gone.
            bridges: self
                .observers
                .bridges
                .values()
                .filter(|(_, at)| at.elapsed() < BRIDGE_FRESH)
                .map(|(b, _)| b.clone())
                .collect(),
            late_starts: self.cycles.stats.late_starts,
        }
    }

    /// Carries out what a request changed: the recording and the fabric log keep each
    /// control change (from the next cycle to start), clients hear of it as an event, and a
    /// change of activation or priority makes the plan again before the next cycle.
    pub(crate) fn apply(&mut self, effects: Effects) {
        let from = self.in_progress() + 1;
        for change in effects.changes {
            let (what, fields, event) = match change {
                Change::Activation { skill, active } => (
                    if active { "activate" } else { "deactivate" },
                    serde_json::json!({"skill": skill}),
                    if active {
                        EventKind::SkillActivated { skill }
                    } else {
                        EventKind::SkillDeactivated { skill }
                    },
                ),
                Change::Param {
                    skill,
                    param,
                    old,
                    new,
                    by,
                } => {
                    tracing::info!(%skill, %param, %old, %new, %by, cycle = self.cycles.cycle, "parameter changed");
                    if let Some(log) = &self.observers.fabric_log {
                        log.param(from - 1, &skill, &param, old, new, &by);
                    }
                    (
                        "param",
                        serde_json::json!({"skill": skill, "param": param,
                            "value": skillfab_proto::json::param_json(&new), "by": by}),
                        EventKind::ParamChanged {
                            skill,
                            param,
                            old,
                            new,
                            by,
                        },
                    )
                }
                Change::Priority {
                    skill,
                    old,
                    new,
                    by,
                } => {
                    if let Some(log) = &self.observers.fabric_log {
                        log.line(
                            "priority",
                            Some(from - 1),
                            serde_json::json!({"skill": skill, "old": old, "new": new, "by": by}),
                        );
                    }
                    (
                        "priority",
                        serde_json::json!({"skill": skill, "value": new, "by": by}),
                        EventKind::PriorityChanged {
                            skill,
                            old,
                            new,
                            by,
                        },
                    )
                }
            };
            self.observers.record_control(from, what, fields);
            self.events.push(event);
        }
        for tree in &effects.plan_trees {
            self.observers.record_plan(from - 1, tree);
        }
        for event in effects.events {
            self.events.push(event);
        }
        self.cycles.dirty |= effects.replan;
    }
}

/// A handler's answer and effects as the dispatch carries them.
fn split(result: Result<Effects, ControlError>) -> (Response, Effects) {
    match result {
        Ok(effects) => (Ok(Reply::Done), effects),
        Err(e) => (Err(e), Effects::default()),
    }
}

/// Effects that are events only.
fn events(events: Vec<EventKind>) -> Effects {
    Effects {
        events,
        ..Effects::default()
    }
}
