//! Launch files: which processes `skillfab up` starts and supervises.
//!
//! ```toml
//! [manager]
//! period_ms = 10          # 0: free-running
//! deadline_ms = 50        # default: the period
//! spin_us = 0             # every process's spin budget (µs) unless it sets its own
//!
//! [[process]]
//! name = "scale"          # instance name (unique in the domain)
//! bin = "scale"           # next to `skillfab`, on PATH, or a path relative to this file
//! params = { gain = 2.0 } # --param gain=2
//! active = true           # false: --inactive
//! priority = 5            # --priority 5
//! remap = { tick = "t2" } # --remap tick=t2
//! args = []               # extra arguments
//! restart = "on-failure"  # never | on-failure | always
//! max_restarts = 5
//! backoff_ms = 200
//! registers = true        # false for processes that are not skills (e.g. a simulator)
//! spin_us = 300           # poll for its inputs up to 300 µs after cycle start, not sleep
//!                         # (default: [manager] spin_us, else 0; docs/realtime.md)
//! realtime = { priority = 70 }    # or `false`: this process opts out of [realtime]
//!
//! [realtime]              # real-time mode of the fabric (docs/realtime.md)
//! policy = "fifo"         # fifo | rr
//! priority = 80           # every registering process's serving thread (1..=99)
//! manager_priority = 81   # the manager's cycle thread (default: priority + 1, at most 99)
//! cpus = [1]              # pin those threads to these CPUs (default: not pinned)
//! manager_cpus = [1]      # the manager's (default: cpus)
//! lock_memory = true      # mlockall, stack pre-faulted (default true)
//!
//! [bridge]                # `skillfab bridge` (docs/bridge.md), supervised like a process
//! listen = ["tcp/0.0.0.0:7447"]   # and/or connect = ["tcp/HOST:PORT"]
//! export = ["sonar"]
//! import = ["nearest"]
//! from = "far-domain"     # the domain the imports come from (default: this one's name)
//! zenoh_config = "zenoh.json5"    # TLS, user/password (relative to this file)
//! ```
//! The raw file is parsed first (unknown keys are errors), then resolved into a validated
//! [`Launch`] with program paths found and parameters rendered.
//!
//! Real-time mode reaches the processes that register (skills and devices) as their
//! `--realtime/--cpus/--lock-memory` flags, and the manager as its own; a process's
//! `realtime` opts it out (`false`), in with the section's settings (`true`), or in with some
//! of them replaced (a table: `policy`, `priority`, `cpus`, `lock_memory`; without a
//! `[realtime]` section the table needs a `priority`). Processes that do not register (a
//! simulator, the bridge, the plan) get none: they are not the fabric's cycle.

mod realtime;

use realtime::process_realtime;
pub use realtime::{ProcessRealTime, RealTimeOverride, RealTimeSection};
use serde::{Deserialize, Serialize};
use skillfab_proto::realtime::RealTime;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// What is wrong with a launch file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LaunchError {
    /// The file could not be read.
    #[error("cannot read launch file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The file is not valid TOML of the expected shape.
    #[error("launch file {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message (with line and column).
        message: String,
    },
    /// A process entry is invalid.
    #[error("launch file {path}: process '{name}': {message}")]
    Process {
        /// The file.
        path: PathBuf,
        /// The entry's name.
        name: String,
        /// What is wrong.
        message: String,
    },
}

/// A launch file as written: the TOML format, before validation. Build one to write a launch
/// file from a program (`toml::to_string`); [`Launch::parse`] validates one.
#[derive(Debug, Default, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaunchFile {
    /// `[manager]`.
    #[serde(default)]
    pub manager: ManagerSection,
    /// `[[process]]`, in start order.
    #[serde(default)]
    pub process: Vec<ProcessEntry>,
    /// `[bridge]`: the domain's bridge to other hosts, started after the processes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bridge: Option<BridgeSection>,
    /// `[plan]`: the domain's sequencer, a plan run by `skillfab sequence` and supervised
    /// like a process (restarted after a crash, it resumes where it was).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<PlanSection>,
    /// `[realtime]`: real-time mode for the manager and every registering process.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub realtime: Option<RealTimeSection>,
}

/// `[plan]` of a launch file.
#[derive(Debug, Default, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanSection {
    /// The plan file (relative to the launch file).
    pub file: String,
    /// Its tree to run (default: its main one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tree: Option<String>,
    /// Most restarts in a row before giving up (default 5).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_restarts: Option<u32>,
    /// First restart delay (ms, default 200; doubles each time).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backoff_ms: Option<u64>,
    /// The plan is the planner's route: its runner plans again when a step fails
    /// (`skillfab sequence --replan`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub replan: Option<ReplanSection>,
}

/// `[plan.replan]` of a launch file: the route the plan was planned from (docs/maps.md).
#[derive(Debug, Default, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplanSection {
    /// The route map (relative to the launch file).
    pub map: String,
    /// The room (default: the map's office).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub to: Option<u32>,
    /// The route goes back to the lab too.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub and_back: bool,
    /// The subtrees the plans are built from (relative to the launch file).
    pub library: String,
}

/// `[bridge]` of a launch file: the options of `skillfab bridge`.
#[derive(Debug, Default, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BridgeSection {
    /// Its name in the domain (default `bridge`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Zenoh endpoints to connect to.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub connect: Vec<String>,
    /// Zenoh endpoints to listen on.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub listen: Vec<String>,
    /// A Zenoh configuration file, relative to the launch file.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zenoh_config: Option<String>,
    /// Join through a Zenoh router (client mode).
    #[serde(default)]
    pub client_mode: bool,
    /// Topics sent out.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub export: Vec<String>,
    /// Topics brought in.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub import: Vec<String>,
    /// The remote domain of the imports.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub from: Option<String>,
    /// Serve the control plane, events and logs to remote clients (default true).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub control: Option<bool>,
}

impl BridgeSection {
    /// The `skillfab bridge` arguments (the domain is added at spawn).
    fn args(&self, base: &Path) -> Vec<String> {
        let mut args = vec!["bridge".to_string()];
        let mut opt = |flag: &str, value: &str| {
            args.push(flag.to_string());
            args.push(value.to_string());
        };
        opt("--name", self.name.as_deref().unwrap_or("bridge"));
        self.connect.iter().for_each(|e| opt("--connect", e));
        self.listen.iter().for_each(|e| opt("--listen", e));
        if let Some(f) = &self.zenoh_config {
            opt("--zenoh-config", &base.join(f).display().to_string());
        }
        self.export.iter().for_each(|t| opt("--export", t));
        self.import.iter().for_each(|t| opt("--import", t));
        if let Some(d) = &self.from {
            opt("--from", d);
        }
        if self.client_mode {
            args.push("--client-mode".into());
        }
        if self.control == Some(false) {
            args.push("--no-control".into());
        }
        args
    }
}

/// `[manager]` of a launch file.
#[derive(Debug, Default, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ManagerSection {
    /// Cycle period (ms); 0: free-running.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub period_ms: Option<f64>,
    /// Cycle deadline (ms).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub deadline_ms: Option<f64>,
    /// The fabric's clock runs this many times faster than the host's (a simulator sped up
    /// as much): each cycle stands for `period_ms × time_factor` of the clock skills and
    /// plans time things in. Default 1; ignored in lock-step and free-running.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_factor: Option<f64>,
    /// Spin budget (µs) of every registering process that does not set its own (`--spin-us`;
    /// default 0: they sleep between rings).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spin_us: Option<u64>,
}

/// One `[[process]]` of a launch file.
#[derive(Debug, Default, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProcessEntry {
    /// Instance name.
    pub name: String,
    /// Program: a bare name (next to skillfab, then `PATH`) or a path relative to the file.
    pub bin: String,
    /// Parameter values (`--param k=v`).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub params: BTreeMap<String, toml::Value>,
    /// Start active (default) or inactive.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub active: Option<bool>,
    /// Arbitration priority.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub priority: Option<i32>,
    /// Port → topic rewiring (`--remap`).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub remap: BTreeMap<String, String>,
    /// Further arguments, as given.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub args: Vec<String>,
    /// Restart policy.
    #[serde(default)]
    pub restart: Restart,
    /// Most restarts before giving up (default 5).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_restarts: Option<u32>,
    /// First restart delay (ms, default 200; doubles each time).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backoff_ms: Option<u64>,
    /// Whether it registers as a skill (default true; false: e.g. a simulator).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub registers: Option<bool>,
    /// Spin budget after each cycle's start (µs; `--spin-us`): polls its doorbell instead of
    /// sleeping on it until it has run (default: `[manager] spin_us`, else 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spin_us: Option<u64>,
    /// Real-time mode: `false` opts out of `[realtime]`, `true` opts in, a table replaces
    /// some of its settings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub realtime: Option<ProcessRealTime>,
}

/// When a process that exited is started again.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Restart {
    /// Never.
    Never,
    /// When it exited with an error or was killed by a signal.
    #[default]
    OnFailure,
    /// Whenever it exits.
    Always,
}

/// One process to start.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcessSpec {
    /// Instance name.
    pub name: String,
    /// Resolved program path.
    pub program: PathBuf,
    /// Arguments after the program (domain excluded; added at spawn).
    pub args: Vec<String>,
    /// Restart policy.
    pub restart: Restart,
    /// Most restarts before giving up.
    pub max_restarts: u32,
    /// First restart delay (doubles each time, at most 5 s).
    pub backoff: Duration,
    /// Whether it registers with the manager as a skill.
    pub registers: bool,
    /// A plan runner: exit status 1 is the plan failing, an end like success (not restarted);
    /// killed, or exit 3 (the fabric could not be asked), it is restarted and resumes.
    pub plan: bool,
}

/// A validated launch file.
#[derive(Debug, Clone, PartialEq)]
pub struct Launch {
    /// Cycle period (`Some(0)`: free-running) if the file sets it.
    pub period: Option<Duration>,
    /// Cycle deadline if the file sets it.
    pub deadline: Option<Duration>,
    /// The clock's time factor if the file sets it.
    pub time_factor: Option<f64>,
    /// Processes in file order.
    pub processes: Vec<ProcessSpec>,
    /// Real-time mode of the manager's cycle thread (from `[realtime]`).
    pub manager_realtime: Option<RealTime>,
}

/// The largest spin budget a launch file may give (µs).
const MAX_SPIN_US: u64 = 1_000_000;

fn toml_value_text(v: &toml::Value) -> Option<String> {
    match v {
        toml::Value::String(s) => Some(s.clone()),
        toml::Value::Integer(i) => Some(i.to_string()),
        toml::Value::Float(f) => Some(f.to_string()),
        toml::Value::Boolean(b) => Some(b.to_string()),
        _ => None,
    }
}

/// Finds a program: a path with `/` is relative to `base`; a bare name is looked up next to
/// the running executable, then on `PATH`.
pub fn find_program(bin: &str, base: &Path) -> Option<PathBuf> {
    if bin.contains('/') {
        let p = base.join(bin);
        return p.is_file().then_some(p);
    }
    let beside = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(|d| d.join(bin)));
    let on_path = std::env::var_os("PATH")
        .map(|p| {
            std::env::split_paths(&p)
                .map(|d| d.join(bin))
                .collect::<Vec<_>>()
        })
        .unwrap_or_default();
    beside.into_iter().chain(on_path).find(|p| p.is_file())
}

impl Launch {
    /// Reads and validates a launch file.
    pub fn load(path: &Path) -> Result<Launch, LaunchError> {
        let text = std::fs::read_to_string(path).map_err(|source| LaunchError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let base = path.parent().unwrap_or(Path::new("."));
        Launch::parse(&text, path, base)
    }

    /// Validates launch-file text; `base` is where relative program paths start.
    pub fn parse(text: &str, path: &Path, base: &Path) -> Result<Launch, LaunchError> {
        let raw: LaunchFile = toml::from_str(text).map_err(|e| LaunchError::Parse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let ms = |v: Option<f64>, what: &str| -> Result<Option<Duration>, LaunchError> {
            match v {
                None => Ok(None),
                Some(v) if v.is_finite() && v >= 0.0 => {
                    Ok(Some(Duration::from_secs_f64(v / 1000.0)))
                }
                Some(v) => Err(LaunchError::Parse {
                    path: path.to_path_buf(),
                    message: format!("manager.{what} must be a non-negative number of ms, got {v}"),
                }),
            }
        };
        let mut processes = Vec::new();
        for p in raw.process {
            let bad = |message: String| LaunchError::Process {
                path: path.to_path_buf(),
                name: p.name.clone(),
                message,
            };
            skillfab_proto::names::check_name("process", &p.name, false)
                .map_err(|e| bad(e.to_string()))?;
            if processes.iter().any(|q: &ProcessSpec| q.name == p.name) {
                return Err(bad("the name is used twice".into()));
            }
            let program = find_program(&p.bin, base).ok_or_else(|| {
                bad(format!(
                    "program '{}' not found (next to skillfab, on PATH, or relative to the launch file)",
                    p.bin
                ))
            })?;
            // Skills and devices get their instance name; other programs (a simulator) only
            // their own arguments.
            let mut args = if p.registers.unwrap_or(true) {
                vec!["--name".to_string(), p.name.clone()]
            } else {
                Vec::new()
            };
            for (k, v) in &p.params {
                let v = toml_value_text(v)
                    .ok_or_else(|| bad(format!("param '{k}' must be a string, number or bool")))?;
                args.push("--param".into());
                args.push(format!("{k}={v}"));
            }
            if p.active == Some(false) {
                args.push("--inactive".into());
            }
            if let Some(pr) = p.priority {
                args.push("--priority".into());
                args.push(pr.to_string());
            }
            for (port, topic) in &p.remap {
                args.push("--remap".into());
                args.push(format!("{port}={topic}"));
            }
            match (
                p.spin_us.or(raw.manager.spin_us),
                p.registers.unwrap_or(true),
            ) {
                (Some(us), _) if us > MAX_SPIN_US => {
                    return Err(bad(format!(
                        "spin_us = {us}: at most {MAX_SPIN_US} (1 s); a budget is meant to cover a cycle's chain, not to hold a core"
                    )));
                }
                (Some(us), true) if us > 0 => {
                    args.push("--spin-us".into());
                    args.push(us.to_string());
                }
                (Some(us), false) if us > 0 && p.spin_us.is_some() => {
                    return Err(bad(
                        "spin_us is for processes that register (skills, devices)".into(),
                    ));
                }
                _ => {}
            }
            let registers = p.registers.unwrap_or(true);
            if let Some(rt) =
                process_realtime(raw.realtime.as_ref(), p.realtime.as_ref(), registers)
                    .map_err(bad)?
            {
                args.extend(rt.flags());
            }
            args.extend(p.args.iter().cloned());
            processes.push(ProcessSpec {
                name: p.name.clone(),
                program,
                args,
                restart: p.restart,
                max_restarts: p.max_restarts.unwrap_or(5),
                backoff: Duration::from_millis(p.backoff_ms.unwrap_or(200)),
                registers: p.registers.unwrap_or(true),
                plan: false,
            });
        }
        if let Some(b) = &raw.bridge {
            let name = b.name.clone().unwrap_or_else(|| "bridge".into());
            let bad = |message: String| LaunchError::Process {
                path: path.to_path_buf(),
                name: name.clone(),
                message,
            };
            if processes.iter().any(|q: &ProcessSpec| q.name == name) {
                return Err(bad("the bridge's name is a process's too".into()));
            }
            let program = find_program("skillfab", base).ok_or_else(|| {
                bad("program 'skillfab' not found (next to skillfab-manager, on PATH)".into())
            })?;
            processes.push(ProcessSpec {
                name,
                program,
                args: b.args(base),
                restart: Restart::OnFailure,
                max_restarts: 5,
                backoff: Duration::from_millis(200),
                // Its skill (the imports' producer) registers; a bridge that only exports
                // does not.
                registers: !b.import.is_empty(),
                plan: false,
            });
        }
        if let Some(plan) = &raw.plan {
            let bad = |message: String| LaunchError::Process {
                path: path.to_path_buf(),
                name: "plan".into(),
                message,
            };
            if processes.iter().any(|q: &ProcessSpec| q.name == "plan") {
                return Err(bad("a process is named 'plan' too".into()));
            }
            let program = find_program("skillfab", base).ok_or_else(|| {
                bad("program 'skillfab' not found (next to skillfab-manager, on PATH)".into())
            })?;
            let file = base.join(&plan.file);
            if !file.is_file() {
                return Err(bad(format!("plan file {} not found", file.display())));
            }
            let mut args = vec!["sequence".to_string(), file.to_string_lossy().into_owned()];
            if let Some(t) = &plan.tree {
                args.extend(["--tree".into(), t.clone()]);
            }
            if let Some(r) = &plan.replan {
                let path = |f: &str| base.join(f).to_string_lossy().into_owned();
                args.extend(["--replan".into(), path(&r.map)]);
                args.extend(["--library".into(), path(&r.library)]);
                if let Some(room) = r.to {
                    args.extend(["--to".into(), room.to_string()]);
                }
                if r.and_back {
                    args.push("--and-back".into());
                }
            }
            // It starts once the skills it drives have registered.
            let skills: Vec<&str> = processes
                .iter()
                .filter(|p| p.registers)
                .map(|p| p.name.as_str())
                .collect();
            if !skills.is_empty() {
                args.extend(["--wait-for".into(), skills.join(",")]);
            }
            processes.push(ProcessSpec {
                name: "plan".into(),
                program,
                args,
                restart: Restart::OnFailure,
                max_restarts: plan.max_restarts.unwrap_or(5),
                backoff: Duration::from_millis(plan.backoff_ms.unwrap_or(200)),
                registers: false,
                plan: true,
            });
        }
        Ok(Launch {
            period: ms(raw.manager.period_ms, "period_ms")?,
            deadline: ms(raw.manager.deadline_ms, "deadline_ms")?,
            time_factor: match raw.manager.time_factor {
                Some(f) if !(f.is_finite() && f > 0.0) => {
                    return Err(LaunchError::Parse {
                        path: path.to_path_buf(),
                        message: format!("manager.time_factor must be a positive number, got {f}"),
                    });
                }
                f => f,
            },
            processes,
            manager_realtime: raw.realtime.as_ref().map(RealTimeSection::manager),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Launch, LaunchError> {
        Launch::parse(text, Path::new("t.toml"), Path::new("/"))
    }

    #[test]
    fn a_bridge_section_becomes_the_arguments_of_skillfab_bridge() {
        let raw: LaunchFile = toml::from_str(
            "[bridge]\nlisten = [\"tcp/0.0.0.0:7447\"]\nexport = [\"sonar\"]\n\
             import = [\"nearest\"]\nfrom = \"far\"\nzenoh_config = \"z.json5\"\ncontrol = false\n",
        )
        .unwrap();
        let args = raw.bridge.unwrap().args(Path::new("/robot"));
        assert_eq!(
            args.join(" "),
            "bridge --name bridge --listen tcp/0.0.0.0:7447 --zenoh-config /robot/z.json5 \
             --export sonar --import nearest --from far --no-control"
        );
        let e = toml::from_str::<LaunchFile>("[bridge]\nlisten = \"tcp/x\"\nspeed = 1\n");
        assert!(e.is_err(), "unknown keys and wrong shapes are errors");
    }

    #[test]
    fn a_full_entry_becomes_arguments() {
        let l = parse(
            r#"
            [manager]
            period_ms = 5
            [[process]]
            name = "s1"
            bin = "/bin/sh"
            params = { gain = 2.5, on = true }
            active = false
            priority = -3
            remap = { tick = "t2" }
            restart = "always"
            "#,
        )
        .unwrap();
        assert_eq!(l.period, Some(Duration::from_millis(5)));
        let p = &l.processes[0];
        assert_eq!(
            p.args,
            [
                "--name",
                "s1",
                "--param",
                "gain=2.5",
                "--param",
                "on=true",
                "--inactive",
                "--priority",
                "-3",
                "--remap",
                "tick=t2"
            ]
        );
        assert_eq!(p.restart, Restart::Always);
        assert_eq!(p.program, PathBuf::from("/bin/sh"));
    }

    #[test]
    fn a_spin_budget_is_the_processs_own_else_the_managers_default() {
        let l = parse(
            "[manager]\nspin_us = 200\n\
             [[process]]\nname = \"a\"\nbin = \"/bin/sh\"\n\
             [[process]]\nname = \"b\"\nbin = \"/bin/sh\"\nspin_us = 50\n\
             [[process]]\nname = \"c\"\nbin = \"/bin/sh\"\nspin_us = 0\n\
             [[process]]\nname = \"sim\"\nbin = \"/bin/sh\"\nregisters = false\n",
        )
        .unwrap();
        let spin = |i: usize| {
            let a = &l.processes[i].args;
            a.iter()
                .position(|x| x == "--spin-us")
                .map(|j| a[j + 1].clone())
        };
        assert_eq!(spin(0).as_deref(), Some("200"));
        assert_eq!(spin(1).as_deref(), Some("50"));
        assert_eq!(spin(2), None, "0 is sleeping, the default");
        assert_eq!(spin(3), None, "a simulator does not take the default");
        let e =
            parse("[[process]]\nname = \"a\"\nbin = \"/bin/sh\"\nspin_us = 5000000\n").unwrap_err();
        assert!(e.to_string().contains("at most 1000000"), "{e}");
        let e = parse(
            "[[process]]\nname = \"sim\"\nbin = \"/bin/sh\"\nregisters = false\nspin_us = 10\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("register"), "{e}");
    }

    #[test]
    fn programs_that_do_not_register_get_only_their_own_arguments() {
        let l = parse("[[process]]\nname = \"sim\"\nbin = \"/bin/sh\"\nregisters = false\nargs = [\"--world\", \"w.toml\"]\n").unwrap();
        assert_eq!(l.processes[0].args, ["--world", "w.toml"]);
        assert!(!l.processes[0].registers);
    }

    #[test]
    fn mistakes_are_named() {
        let e = parse("[[process]]\nname = \"a\"\nbin = \"/bin/sh\"\nrestrat = \"never\"\n")
            .unwrap_err();
        assert!(e.to_string().contains("restrat"), "{e}");
        let e = parse("[[process]]\nname = \"a\"\nbin = \"no-such-program-xyz\"\n").unwrap_err();
        assert!(e.to_string().contains("no-such-program-xyz"), "{e}");
        let e = parse("[[process]]\nname = \"a b\"\nbin = \"/bin/sh\"\n").unwrap_err();
        assert!(e.to_string().contains("a b"), "{e}");
        let e = parse("[manager]\nperiod_ms = -1\n").unwrap_err();
        assert!(e.to_string().contains("period_ms"), "{e}");
        let e = parse("[manager]\ntime_factor = 0\n").unwrap_err();
        assert!(e.to_string().contains("time_factor"), "{e}");
        assert_eq!(
            parse("[manager]\ntime_factor = 4.0\n").unwrap().time_factor,
            Some(4.0)
        );
        let e = parse("[[process]]\nname = \"a\"\nbin = \"/bin/sh\"\n[[process]]\nname = \"a\"\nbin = \"/bin/sh\"\n")
            .unwrap_err();
        assert!(e.to_string().contains("twice"), "{e}");
    }

    mod properties {
        use super::*;
        use proptest::prelude::*;

        /// A launch file that LaunchFile's own serializer writes from arbitrary entries.
        fn entry() -> impl Strategy<Value = ProcessEntry> {
            (
                "[a-z][a-z0-9_]{0,12}",
                proptest::collection::btree_map("[a-z]{1,6}", -1000i64..1000, 0..3),
                proptest::option::of(any::<bool>()),
                proptest::option::of(-20i32..20),
                prop_oneof![
                    Just(Restart::Never),
                    Just(Restart::OnFailure),
                    Just(Restart::Always)
                ],
                proptest::collection::vec("[a-z0-9=./-]{0,10}", 0..3),
            )
                .prop_map(|(name, params, active, priority, restart, args)| {
                    ProcessEntry {
                        name,
                        bin: "/bin/sh".into(),
                        params: params
                            .into_iter()
                            .map(|(k, v)| (k, toml::Value::Integer(v)))
                            .collect(),
                        active,
                        priority,
                        restart,
                        args,
                        ..ProcessEntry::default()
                    }
                })
        }

        proptest! {
            /// Any text: an error or a launch, never a panic; an error names the file.
            #[test]
            fn any_text_parses_or_is_refused_with_the_file_named(text in "\\PC{0,400}") {
                if let Err(e) = parse(&text) {
                    prop_assert!(e.to_string().contains("t.toml"), "{}", e);
                }
            }

            /// Text that is almost a launch file (fragments of its keys and values, shuffled).
            #[test]
            fn launch_like_fragments_never_panic(parts in proptest::collection::vec(
                prop_oneof![
                    Just("[manager]\n"), Just("[[process]]\n"), Just("name = \"a\"\n"),
                    Just("bin = \"/bin/sh\"\n"), Just("period_ms = 5\n"), Just("period_ms = -1\n"),
                    Just("params = { g = 1.5 }\n"), Just("restart = \"sometimes\"\n"),
                    Just("priority = 99999999999\n"), Just("active = \"yes\"\n"), Just("= =\n"),
                    Just("registers = false\n"), Just("args = [1, 2]\n"), Just("deadline_ms = nan\n"),
                ],
                0..12,
            )) {
                let _ = parse(&parts.concat());
            }

            /// Entries written by the serializer come back with the arguments they ask for.
            #[test]
            fn written_entries_become_their_arguments(entries in proptest::collection::vec(entry(), 1..5)) {
                let mut seen = std::collections::HashSet::new();
                let entries: Vec<ProcessEntry> =
                    entries.into_iter().filter(|e| seen.insert(e.name.clone())).collect();
                let file = LaunchFile { manager: ManagerSection::default(), process: entries.clone(), bridge: None, plan: None, realtime: None };
                let text = toml::to_string(&file).unwrap();
                let launch = parse(&text).unwrap();
                prop_assert_eq!(launch.processes.len(), entries.len());
                for (e, p) in entries.iter().zip(&launch.processes) {
                    prop_assert_eq!(&p.name, &e.name);
                    prop_assert_eq!(p.restart, e.restart);
                    prop_assert_eq!(&p.args[..2], &["--name".to_string(), e.name.clone()][..]);
                    prop_assert_eq!(p.args.contains(&"--inactive".to_string()), e.active == Some(false));
                    for (k, v) in &e.params {
                        let arg = format!("{k}={}", v.as_integer().unwrap());
                        prop_assert!(p.args.contains(&arg), "{} missing in {:?}", arg, p.args);
                    }
                    prop_assert!(p.args.ends_with(&e.args));
                }
            }
        }
    }
}
