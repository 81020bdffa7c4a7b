//! `list`, `stats`: the registered skills and the cycle statistics.

use super::*;
use skillfab_proto::control::{ChannelStat, PortInfo, SkillInfo, SkillStat, SkillState, Stats};

/// How long a bridge's last report counts: it reports about once a second.
const BRIDGE_FRESH: std::time::Duration = std::time::Duration::from_secs(3);

impl Manager {
    /// Every registered skill, in registration order.
    pub(super) fn list(&self) -> Vec<SkillInfo> {
        let ports = |p: &[skillfab_proto::decl::PortDecl]| {
            p.iter()
                .map(|p| PortInfo {
                    port: p.port.clone(),
                    topic: p.topic.clone(),
                    type_name: p.schema.type_name.clone(),
                })
                .collect()
        };
        self.skills
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
                figures: self.figures(s),
            })
            .collect()
    }

    /// The schema of `topic` as its producer declares it, else as a consumer does.
    pub(super) fn topic_schema(&self, topic: &str) -> Result<Reply, ControlError> {
        let decls = || self.skills.in_order().map(|(_, e)| &e.decl);
        decls()
            .flat_map(|d| d.outputs.iter())
            .chain(decls().flat_map(|d| d.inputs.iter()))
            .find(|p| p.topic == topic)
            .map(|p| Reply::Schema(p.schema.clone()))
            .ok_or_else(|| ControlError::UnknownTopic(topic.to_string()))
    }

    /// Cycle statistics, per-skill figures and channel winners.
    pub(super) fn stats_info(&self) -> Stats {
        let l = self.stats.latency_us();
        Stats {
            cycles: self.cycle,
            running: !self.paused,
            overruns: self.stats.overruns,
            latency_us: l,
            skills: self
                .list()
                .into_iter()
                .map(|s| SkillStat {
                    name: s.name,
                    figures: s.figures,
                })
                .collect(),
            deaths: self.deaths,
            events: self.events_published,
            channels: {
                let mut v: Vec<ChannelStat> = self
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
                .bridges
                .values()
                .filter(|(_, at)| at.elapsed() < BRIDGE_FRESH)
                .map(|(b, _)| b.clone())
                .collect(),
        }
    }
}
