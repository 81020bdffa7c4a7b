//! `[realtime]` of a launch file and a process's `realtime`: which real-time mode, if any,
//! each process and the manager get (docs/realtime.md).

use serde::{Deserialize, Serialize};
use skillfab_proto::realtime::{CpuList, Policy, Priority, RealTime};

/// `[realtime]` of a launch file: the fabric's real-time mode (docs/realtime.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RealTimeSection {
    /// Scheduling policy of the real-time threads (default `fifo`).
    #[serde(default)]
    pub policy: Policy,
    /// Priority of every registering process's serving thread.
    pub priority: Priority,
    /// Priority of the manager's cycle thread (default: `priority` + 1, at most 99): as
    /// ros2_control's controller manager above its hardware, the thread that starts cycles
    /// on time preempts the skills it wakes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub manager_priority: Option<Priority>,
    /// CPUs the real-time threads are pinned to (default: not pinned).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpus: Option<CpuList>,
    /// CPUs of the manager's cycle thread (default: `cpus`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub manager_cpus: Option<CpuList>,
    /// Lock the processes' memory (default true).
    #[serde(default = "yes")]
    pub lock_memory: bool,
}

fn yes() -> bool {
    true
}

impl RealTimeSection {
    /// What a registering process gets.
    fn process(&self) -> RealTime {
        RealTime {
            policy: self.policy,
            priority: self.priority,
            cpus: self.cpus.clone(),
            lock_memory: self.lock_memory,
        }
    }

    /// What the manager's cycle thread gets.
    pub(super) fn manager(&self) -> RealTime {
        RealTime {
            priority: self.manager_priority.unwrap_or(self.priority.above()),
            cpus: self.manager_cpus.clone().or_else(|| self.cpus.clone()),
            ..self.process()
        }
    }
}

/// A process's `realtime`: a switch, or settings that replace the section's.
#[derive(Debug, Clone, PartialEq)]
pub enum ProcessRealTime {
    /// `true`: the `[realtime]` section's settings; `false`: none.
    Switch(bool),
    /// A table: these settings over the section's.
    Settings(RealTimeOverride),
}

/// The settings of a process's `realtime` table; what it leaves out comes from `[realtime]`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RealTimeOverride {
    /// Scheduling policy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy: Option<Policy>,
    /// Priority.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub priority: Option<Priority>,
    /// CPUs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpus: Option<CpuList>,
    /// Lock memory.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lock_memory: Option<bool>,
}

impl Serialize for ProcessRealTime {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            ProcessRealTime::Switch(on) => s.serialize_bool(*on),
            ProcessRealTime::Settings(o) => o.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for ProcessRealTime {
    /// `true`, `false` or a table (whose unknown keys are errors, with the key named).
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = ProcessRealTime;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("true, false or a table of real-time settings")
            }
            fn visit_bool<E: serde::de::Error>(self, on: bool) -> Result<ProcessRealTime, E> {
                Ok(ProcessRealTime::Switch(on))
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                map: A,
            ) -> Result<ProcessRealTime, A::Error> {
                RealTimeOverride::deserialize(serde::de::value::MapAccessDeserializer::new(map))
                    .map(ProcessRealTime::Settings)
            }
        }
        d.deserialize_any(Visitor)
    }
}

/// The real-time mode of a process of `[[process]]`: its `realtime` over the section.
pub(super) fn process_realtime(
    section: Option<&RealTimeSection>,
    entry: Option<&ProcessRealTime>,
    registers: bool,
) -> Result<Option<RealTime>, String> {
    if !registers {
        return match entry {
            None | Some(ProcessRealTime::Switch(false)) => Ok(None),
            Some(_) => Err(
                "it does not register (registers = false): real-time mode is for \
                            the fabric's skills and devices, a program of its own sets its own"
                    .into(),
            ),
        };
    }
    match entry {
        None => Ok(section.map(RealTimeSection::process)),
        Some(ProcessRealTime::Switch(false)) => Ok(None),
        Some(ProcessRealTime::Switch(true)) => {
            section.map(|s| Some(s.process())).ok_or_else(|| {
                "realtime = true needs a [realtime] section (or settings of its own: \
                 realtime = { priority = 10 })"
                    .to_string()
            })
        }
        Some(ProcessRealTime::Settings(o)) => {
            let base = section.map(RealTimeSection::process);
            let priority = o
                .priority
                .or(base.as_ref().map(|b| b.priority))
                .ok_or_else(|| {
                    "realtime needs a priority (1..=99) here: there is no [realtime] section"
                        .to_string()
                })?;
            Ok(Some(RealTime {
                policy: o
                    .policy
                    .or(base.as_ref().map(|b| b.policy))
                    .unwrap_or_default(),
                priority,
                cpus: o
                    .cpus
                    .clone()
                    .or(base.as_ref().and_then(|b| b.cpus.clone())),
                lock_memory: o
                    .lock_memory
                    .or(base.as_ref().map(|b| b.lock_memory))
                    .unwrap_or(true),
            }))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::launch::{Launch, LaunchError, LaunchFile, ProcessEntry, ProcessSpec};
    use std::path::Path;

    fn parse(text: &str) -> Result<Launch, LaunchError> {
        Launch::parse(text, Path::new("t.toml"), Path::new("/"))
    }

    const TWO_SKILLS: &str = "[[process]]\nname = \"a\"\nbin = \"/bin/sh\"\n\
                              [[process]]\nname = \"b\"\nbin = \"/bin/sh\"\n";

    /// The real-time flags among a process's arguments.
    fn rt_flags(p: &ProcessSpec) -> Vec<&str> {
        let at = p.args.iter().position(|a| a == "--realtime");
        at.map_or(Vec::new(), |i| {
            p.args[i..]
                .iter()
                .map(String::as_str)
                .take_while(|a| {
                    !a.starts_with("--") || ["--realtime", "--cpus", "--lock-memory"].contains(a)
                })
                .collect()
        })
    }

    #[test]
    fn a_realtime_section_reaches_every_registering_process_and_the_manager() {
        let l = parse(&format!(
            "[realtime]\npriority = 10\ncpus = [1, 0]\n{TWO_SKILLS}\
             [[process]]\nname = \"sim\"\nbin = \"/bin/sh\"\nregisters = false\n"
        ))
        .unwrap();
        for p in &l.processes[..2] {
            assert_eq!(
                rt_flags(p),
                ["--realtime", "fifo:10", "--cpus", "0-1", "--lock-memory"],
                "{}",
                p.name
            );
        }
        assert!(
            rt_flags(&l.processes[2]).is_empty(),
            "a simulator gets none"
        );
        let m = l.manager_realtime.unwrap();
        assert_eq!(m.to_string(), "fifo:11@0-1+mlock", "one above the skills");
        let l = parse(
            "[realtime]\npolicy = \"rr\"\npriority = 99\nmanager_cpus = [0]\nlock_memory = false\n",
        )
        .unwrap();
        assert_eq!(
            l.manager_realtime.unwrap().to_string(),
            "rr:99@0",
            "99 at most"
        );
        assert_eq!(
            parse(TWO_SKILLS).unwrap().manager_realtime,
            None,
            "off unless asked"
        );
    }

    #[test]
    fn a_process_opts_out_in_or_replaces_settings() {
        let l = parse(
            "[realtime]\npriority = 20\nmanager_priority = 30\n\
             [[process]]\nname = \"off\"\nbin = \"/bin/sh\"\nrealtime = false\n\
             [[process]]\nname = \"on\"\nbin = \"/bin/sh\"\nrealtime = true\n\
             [[process]]\nname = \"own\"\nbin = \"/bin/sh\"\nargs = [\"--x\"]\n\
             realtime = { priority = 5, cpus = [1], lock_memory = false }\n",
        )
        .unwrap();
        assert!(rt_flags(&l.processes[0]).is_empty());
        assert_eq!(
            rt_flags(&l.processes[1]),
            ["--realtime", "fifo:20", "--lock-memory"]
        );
        assert_eq!(
            rt_flags(&l.processes[2]),
            ["--realtime", "fifo:5", "--cpus", "1"]
        );
        assert_eq!(
            l.processes[2].args.last().map(String::as_str),
            Some("--x"),
            "its own arguments last"
        );
        assert_eq!(l.manager_realtime.unwrap().to_string(), "fifo:30+mlock");
        // One process alone, no section: its table is all there is (the manager gets none).
        let l = parse("[[process]]\nname = \"a\"\nbin = \"/bin/sh\"\nrealtime = { policy = \"rr\", priority = 3 }\n").unwrap();
        assert_eq!(
            rt_flags(&l.processes[0]),
            ["--realtime", "rr:3", "--lock-memory"]
        );
        assert_eq!(l.manager_realtime, None);
    }

    #[test]
    fn bad_realtime_settings_are_refused_with_the_reason() {
        let err = |text: &str| parse(text).unwrap_err().to_string();
        for (text, want) in [
            ("[realtime]\npriority = 0\n", "1..=99"),
            ("[realtime]\npriority = 100\n", "1..=99"),
            (
                "[realtime]\npriority = 10\ncpus = []\n",
                "CPU list is empty",
            ),
            (
                "[realtime]\npriority = 10\ncpus = [1, 5000]\n",
                "CPU 5000 is past",
            ),
            (
                "[realtime]\npriority = 10\nmanager_priority = 0\n",
                "1..=99",
            ),
            (
                "[realtime]\npolicy = \"deadline\"\npriority = 10\n",
                "deadline",
            ),
            ("[realtime]\npriority = 10\nnice = -5\n", "nice"),
            ("[realtime]\ncpus = [0]\n", "priority"),
            (
                "[[process]]\nname = \"a\"\nbin = \"/bin/sh\"\nrealtime = { priority = 10, cpu = [1] }\n",
                "cpu",
            ),
            (
                "[[process]]\nname = \"a\"\nbin = \"/bin/sh\"\nrealtime = \"yes\"\n",
                "true, false or a table",
            ),
            (
                "[[process]]\nname = \"a\"\nbin = \"/bin/sh\"\nrealtime = true\n",
                "needs a [realtime] section",
            ),
            (
                "[[process]]\nname = \"a\"\nbin = \"/bin/sh\"\nrealtime = { cpus = [1] }\n",
                "needs a priority",
            ),
            (
                "[realtime]\npriority = 10\n[[process]]\nname = \"sim\"\nbin = \"/bin/sh\"\n\
                 registers = false\nrealtime = true\n",
                "does not register",
            ),
        ] {
            let e = err(text);
            assert!(e.contains(want), "{text:?}: {e}");
        }
    }

    #[test]
    fn a_written_realtime_section_reads_back() {
        let file = LaunchFile {
            realtime: Some(RealTimeSection {
                policy: Policy::RoundRobin,
                priority: Priority::new(40).unwrap(),
                manager_priority: None,
                cpus: Some("1".parse().unwrap()),
                manager_cpus: None,
                lock_memory: false,
            }),
            process: vec![ProcessEntry {
                name: "a".into(),
                bin: "/bin/sh".into(),
                realtime: Some(ProcessRealTime::Settings(RealTimeOverride {
                    priority: Some(Priority::new(30).unwrap()),
                    ..RealTimeOverride::default()
                })),
                ..ProcessEntry::default()
            }],
            ..LaunchFile::default()
        };
        let text = toml::to_string(&file).unwrap();
        assert_eq!(toml::from_str::<LaunchFile>(&text).unwrap(), file, "{text}");
        let l = parse(&text).unwrap();
        assert_eq!(
            rt_flags(&l.processes[0]),
            ["--realtime", "rr:30", "--cpus", "1"]
        );
    }
}
