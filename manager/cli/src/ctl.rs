//! `skillfab ctl`: a thin command line over the control client.
//!
//! Human output by default, `--json` for scripts; every refused request prints one line on
//! stderr and exits non-zero.

use anyhow::{Context, bail};
use clap::Subcommand;
use serde_json::{Value as Json, json};
use skillfab_client::{Address, Client};
use skillfab_proto::control::{EventKind, MonitorMode};
use skillfab_proto::domain::Domain;
pub use skillfab_proto::json::{event_json, param_json, skill_json, stats_json, value_json};
use skillfab_proto::log::{Level, LogReader};
use skillfab_proto::param::ParamValue;
use std::time::Duration;

/// `skillfab ctl` commands.
#[derive(Subcommand, Debug, Clone)]
pub enum CtlCmd {
    /// List skills: mode, state, priority, runs, compute time, parameters.
    Ls,
    /// Activate skills (all or none).
    Activate {
        /// Skill names.
        #[arg(required = true)]
        skills: Vec<String>,
    },
    /// Deactivate skills (all or none).
    Deactivate {
        /// Skill names.
        #[arg(required = true)]
        skills: Vec<String>,
    },
    /// Want skills (all or none): each runs with every skill it reads from, activated on
    /// demand; refused when one reads a topic nobody produces.
    Want {
        /// Skill names.
        #[arg(required = true)]
        skills: Vec<String>,
    },
    /// Release wanted skills (all or none), and what was activated only for them.
    Release {
        /// Skill names.
        #[arg(required = true)]
        skills: Vec<String>,
    },
    /// Set a parameter: SKILL.PARAM=VALUE (applied from the next cycle).
    Set {
        /// SKILL.PARAM=VALUE
        assignment: String,
    },
    /// Print a parameter: SKILL.PARAM.
    Get {
        /// SKILL.PARAM
        name: String,
    },
    /// Print a value: SKILL.OUTPUT[.FIELD][INDEX].
    Query {
        /// The path.
        path: String,
    },
    /// Install a monitor and print one JSON line per firing.
    Monitor {
        /// The condition, e.g. 'ticker.tick.value > 50'.
        expr: String,
        /// Fire the first time only, then exit.
        #[arg(long, conflicts_with_all = ["edge", "every"])]
        once: bool,
        /// Fire each time the condition becomes true (the default).
        #[arg(long, conflicts_with = "every")]
        edge: bool,
        /// Fire every cycle the condition holds.
        #[arg(long)]
        every: bool,
        /// Cycles the condition must hold first.
        #[arg(long, default_value_t = 0)]
        hold: u32,
    },
    /// List monitors.
    Monitors,
    /// The processes `skillfab up` gave up restarting (and not back since).
    GaveUp,
    /// The running plan as a tree: each node's status and the cycle it has had it since.
    Plan,
    /// Remove a monitor.
    Unmonitor {
        /// Its id.
        id: u64,
    },
    /// Stream every event as JSON lines.
    Events,
    /// Cycle and skill statistics.
    Stats,
    /// Start cycling.
    Run,
    /// Stop cycling.
    Stop,
    /// Run N cycles (default 1), then stop; returns when they are done.
    Step {
        /// Number of cycles.
        #[arg(default_value_t = 1)]
        n: u64,
    },
    /// Print skills' log lines as they come (the domain's log stream); Ctrl-C ends.
    Logs {
        /// Only this skill's lines.
        skill: Option<String>,
        /// Least severe level shown: error, warn, info, debug, trace.
        #[arg(long, default_value = "trace")]
        level: String,
    },
    /// Log a skill's input and output samples to the fabric log (on), or stop (off).
    Iolog {
        /// Skill name.
        skill: String,
        /// on or off.
        #[arg(value_parser = ["on", "off"])]
        state: String,
    },
    /// Where the manager's fabric log is, and whose samples it logs.
    Logging,
    /// Record every sample of the topics at full rate, with control changes and events, into
    /// an MCAP file (`start FILE [--topics a,b]`), or stop (`stop`); see `skillfab replay`.
    Record {
        /// start or stop.
        #[arg(value_parser = ["start", "stop"])]
        action: String,
        /// The .mcap file (start).
        file: Option<std::path::PathBuf>,
        /// Topics to record (comma-separated; default: all).
        #[arg(long, value_delimiter = ',')]
        topics: Vec<String>,
    },
    /// Apply the parameter and priority changes of a fabric log file again, in order (not
    /// `skillfab replay`, which runs skills again against a recording).
    Reapply {
        /// The JSON-lines file (`skillfab up/manager --param-log`).
        file: std::path::PathBuf,
        /// Only this skill's changes.
        #[arg(long)]
        skill: Option<String>,
    },
    /// Change a skill's arbitration priority.
    Priority {
        /// Skill name.
        skill: String,
        /// New priority (higher wins).
        #[arg(allow_negative_numbers = true)]
        priority: i32,
    },
}

fn split_dot(s: &str) -> anyhow::Result<(&str, &str)> {
    s.split_once('.')
        .filter(|(a, b)| !a.is_empty() && !b.is_empty())
        .with_context(|| format!("expected SKILL.PARAM, got '{s}'"))
}

fn parse_level(text: &str) -> anyhow::Result<Level> {
    Ok(match text.to_ascii_lowercase().as_str() {
        "error" => Level::Error,
        "warn" | "warning" => Level::Warn,
        "info" => Level::Info,
        "debug" => Level::Debug,
        "trace" => Level::Trace,
        other => bail!("unknown level '{other}': use error, warn, info, debug or trace"),
    })
}

/// `ctl logs`: needs no manager (the stream is there while skills run).
fn logs(domain: &Domain, json_out: bool, skill: Option<&str>, level: &str) -> anyhow::Result<()> {
    let level = parse_level(level)?;
    let reader = LogReader::open(domain, &format!("ctl-logs-{}", std::process::id()))?;
    loop {
        print_lines(reader.poll()?, json_out, skill, level);
        if !reader.wait(Duration::from_millis(50)) {
            return Ok(());
        }
    }
}

/// `ctl --remote … logs`: the lines the domain's bridge forwards, until interrupted.
fn remote_logs(
    mut client: Client,
    json_out: bool,
    skill: Option<&str>,
    level: &str,
) -> anyhow::Result<()> {
    let level = parse_level(level)?;
    loop {
        print_lines(client.log_lines()?, json_out, skill, level);
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn print_lines(
    lines: Vec<skillfab_proto::log::LogLine>,
    json_out: bool,
    skill: Option<&str>,
    level: skillfab_proto::log::Level,
) {
    for l in lines {
        if l.level > level || skill.is_some_and(|s| s != l.skill) {
            continue;
        }
        if json_out {
            println!(
                "{}",
                json!({"skill": l.skill, "pid": l.pid, "level": l.level.to_string(),
                       "target": l.target, "message": l.message, "time_ns": l.time_ns,
                       "dropped": l.dropped})
            );
        } else {
            println!("{l}");
        }
    }
}

/// A bridge's lines in `ctl stats`.
fn bridge_lines(b: &skillfab_proto::bridge::BridgeStats) -> String {
    let mut out = format!(
        "\n  bridge {}: {} link(s), {} reconnect(s), {} remote request(s)",
        b.name, b.links, b.reconnects, b.requests
    );
    for t in &b.exports {
        out.push_str(&format!(
            "\n    export {:<16} {} samples",
            t.topic, t.samples
        ));
    }
    for t in &b.imports {
        out.push_str(&format!(
            "\n    import {:<16} from {}: {} samples, {} lost, {} refused, one-way p50 {:.0} µs p99 {:.0} µs",
            t.topic, t.remote, t.samples, t.lost, t.refused, t.latency_us.p50, t.latency_us.p99
        ));
    }
    for e in &b.errors {
        out.push_str(&format!("\n    refused: {e}"));
    }
    out
}

/// One change read back from a fabric log.
#[derive(Debug, PartialEq)]
enum Change {
    Param(String, String, ParamValue),
    Priority(String, i32),
}

/// The `param` and `priority` lines of a fabric log, in order (other kinds are skipped).
fn changes(text: &str, only: Option<&str>) -> anyhow::Result<Vec<Change>> {
    let mut out = Vec::new();
    for (n, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let j: Json = serde_json::from_str(line).with_context(|| format!("line {}", n + 1))?;
        let skill = j["skill"].as_str().unwrap_or_default().to_string();
        if only.is_some_and(|s| s != skill) {
            continue;
        }
        let bad = || anyhow::anyhow!("line {}: malformed {} record", n + 1, j["kind"]);
        match j["kind"].as_str() {
            Some("param") => {
                let v = skillfab_proto::json::param_from_json(&j["new"]).ok_or_else(bad)?;
                let param = j["param"].as_str().ok_or_else(bad)?.to_string();
                out.push(Change::Param(skill, param, v));
            }
            Some("priority") => {
                let p = j["new"].as_i64().and_then(|p| i32::try_from(p).ok());
                out.push(Change::Priority(skill, p.ok_or_else(bad)?));
            }
            _ => {}
        }
    }
    Ok(out)
}

/// Carries out one `ctl` command on the manager at `address`: on this host, or through the
/// domain's bridge.
pub fn run(address: Address, json_out: bool, cmd: CtlCmd) -> anyhow::Result<()> {
    if let CtlCmd::Logs { skill, level } = &cmd {
        return match &address {
            Address::Remote { .. } => {
                remote_logs(address.connect()?, json_out, skill.as_deref(), level)
            }
            Address::Local(domain) => logs(domain, json_out, skill.as_deref(), level),
        };
    }
    let mut c = address.connect()?;
    let print = |human: String, j: Json| {
        if json_out {
            println!("{j}");
        } else if !human.is_empty() {
            println!("{human}");
        }
    };
    match cmd {
        CtlCmd::Ls => {
            let skills = c.list()?;
            let mut human = format!(
                "{:<16} {:<12} {:<6} {:<9} {:>4} {:>8} {:>10}  params",
                "skill", "kind", "mode", "state", "prio", "runs", "compute µs"
            );
            for s in &skills {
                let params: Vec<String> =
                    s.values.iter().map(|(n, v)| format!("{n}={v}")).collect();
                human.push_str(&format!(
                    "\n{:<16} {:<12} {:<6} {:<9} {:>4} {:>8} {:>10.1}  {}",
                    s.name,
                    s.kind,
                    s.mode,
                    s.state,
                    s.priority,
                    s.figures.runs,
                    s.figures.compute_us_mean,
                    params.join(" ")
                ));
            }
            print(human, Json::Array(skills.iter().map(skill_json).collect()));
        }
        CtlCmd::Activate { skills } => {
            let names: Vec<&str> = skills.iter().map(String::as_str).collect();
            c.activate(&names)?;
            print(String::new(), json!({"ok": true}));
        }
        CtlCmd::Deactivate { skills } => {
            let names: Vec<&str> = skills.iter().map(String::as_str).collect();
            c.deactivate(&names)?;
            print(String::new(), json!({"ok": true}));
        }
        CtlCmd::Want { skills } => {
            let names: Vec<&str> = skills.iter().map(String::as_str).collect();
            c.want(&names)?;
            print(String::new(), json!({"ok": true}));
        }
        CtlCmd::Release { skills } => {
            let names: Vec<&str> = skills.iter().map(String::as_str).collect();
            c.release(&names)?;
            print(String::new(), json!({"ok": true}));
        }
        CtlCmd::Set { assignment } => {
            let (name, value) = assignment
                .split_once('=')
                .with_context(|| format!("expected SKILL.PARAM=VALUE, got '{assignment}'"))?;
            let (skill, param) = split_dot(name)?;
            c.set_param(skill, param, value)?;
            print(String::new(), json!({"ok": true}));
        }
        CtlCmd::Get { name } => {
            let (skill, param) = split_dot(&name)?;
            let v = c.get_param(skill, param)?;
            print(v.to_string(), param_json(&v));
        }
        CtlCmd::Query { path } => {
            let (v, cycle) = c.query(&path)?;
            print(
                v.to_string(),
                json!({"path": path, "cycle": cycle, "value": value_json(&v)}),
            );
        }
        CtlCmd::Monitor {
            expr,
            once,
            edge: _,
            every,
            hold,
        } => {
            let mode = if once {
                MonitorMode::Once
            } else if every {
                MonitorMode::Every
            } else {
                MonitorMode::Edge
            };
            c.subscribe()?;
            let id = c.add_monitor(&expr, mode, hold)?;
            eprintln!("monitor {id} installed");
            loop {
                let Some(ev) = c.next_event(Duration::from_secs(1))? else {
                    continue;
                };
                if let EventKind::MonitorFired { id: fired, .. } = &ev.kind
                    && *fired == id
                {
                    println!("{}", event_json(&ev));
                    if once {
                        return Ok(());
                    }
                }
            }
        }
        CtlCmd::Plan => match c.plan()? {
            None => print("no plan is running".to_string(), Json::Null),
            Some(t) => print(plan_text(&t), skillfab_proto::json::plan_json(&t)),
        },
        CtlCmd::GaveUp => {
            let list = c.gave_up()?;
            let human = list
                .iter()
                .map(|g| {
                    format!(
                        "{}: given up at cycle {} after {} restarts ({})",
                        g.process, g.cycle, g.restarts, g.status
                    )
                })
                .collect::<Vec<_>>()
                .join("\n");
            let j = list
                .iter()
                .map(|g| json!({"process": g.process, "restarts": g.restarts, "status": g.status, "cycle": g.cycle}))
                .collect();
            print(human, Json::Array(j));
        }
        CtlCmd::Monitors => {
            let ms = c.monitors()?;
            let human = ms
                .iter()
                .map(|m| {
                    format!(
                        "{:>4} {:?} hold {} fired {} by {}: {}",
                        m.id, m.mode, m.hold, m.fired, m.client, m.expr
                    )
                })
                .collect::<Vec<_>>()
                .join("\n");
            let j = ms
                .iter()
                .map(|m| json!({"id": m.id, "expr": m.expr, "mode": format!("{:?}", m.mode).to_lowercase(),
                                "hold": m.hold, "client": m.client, "fired": m.fired}))
                .collect();
            print(human, Json::Array(j));
        }
        CtlCmd::Unmonitor { id } => {
            c.remove_monitor(id)?;
            print(String::new(), json!({"ok": true}));
        }
        CtlCmd::Events => loop {
            c.subscribe()?;
            if let Some(ev) = c.next_event(Duration::from_secs(1))? {
                println!("{}", event_json(&ev));
            }
        },
        CtlCmd::Stats => {
            let s = c.stats()?;
            let mut human = format!(
                "cycles {} ({}), overruns {}, late starts {}, latency p50 {:.1} µs p99 {:.1} µs max {:.1} µs, deaths {}, events {}",
                s.cycles,
                if s.running { "running" } else { "stopped" },
                s.overruns,
                s.late_starts,
                s.latency_us.p50,
                s.latency_us.p99,
                s.latency_us.max,
                s.deaths,
                s.events
            );
            for ch in &s.channels {
                human.push_str(&format!(
                    "\n  channel {:<10} {} (cycle {})",
                    ch.channel, ch.winner, ch.cycle
                ));
            }
            for k in &s.skills {
                let f = &k.figures;
                human.push_str(&format!(
                    "\n  {:<16} runs {:>8} skips {:>6} failures {:>6} compute {:.1} µs, deadline misses {}, cycle allocs {}",
                    k.name,
                    f.runs,
                    f.skips,
                    f.failures,
                    f.compute_us_mean,
                    f.deadline_misses,
                    f.cycle_allocs
                        .map_or_else(|| "not counted".to_string(), |n| n.to_string())
                ));
            }
            for b in &s.bridges {
                human.push_str(&bridge_lines(b));
            }
            print(human, stats_json(&s));
        }
        CtlCmd::Run => {
            c.run()?;
            print(String::new(), json!({"ok": true}));
        }
        CtlCmd::Stop => {
            c.stop()?;
            print(String::new(), json!({"ok": true}));
        }
        CtlCmd::Step { n } => {
            if n == 0 {
                bail!("step needs N >= 1");
            }
            let cycle = c.step(n)?;
            print(format!("cycle {cycle}"), json!({"cycle": cycle}));
        }
        CtlCmd::Logs { .. } => {}
        CtlCmd::Iolog { skill, state } => {
            c.set_io_log(&skill, state == "on")?;
            print(String::new(), json!({"ok": true}));
        }
        CtlCmd::Record {
            action,
            file,
            topics,
        } => {
            if action == "stop" {
                c.record_stop()?;
            } else {
                let file = file.context("ctl record start FILE.mcap: the file is missing")?;
                // The manager may run elsewhere: give it an absolute path.
                let file = std::path::absolute(&file)?;
                let topics: Vec<&str> = topics.iter().map(String::as_str).collect();
                c.record_start(&file.to_string_lossy(), &topics)?;
            }
            print(String::new(), json!({"ok": true}));
        }
        CtlCmd::Logging => {
            let (file, io) = c.logging()?;
            print(
                format!(
                    "fabric log: {}
samples logged of: {}",
                    file.as_deref().unwrap_or("(none)"),
                    if io.is_empty() {
                        "-".into()
                    } else {
                        io.join(" ")
                    }
                ),
                json!({"file": file, "io_skills": io}),
            );
        }
        CtlCmd::Reapply { file, skill } => {
            let text = skillfab_manager::recorder::read_records(&file)?;
            let todo = changes(&text, skill.as_deref())?;
            for ch in &todo {
                match ch {
                    Change::Param(s, p, v) => c
                        .set_param_value(s, p, *v)
                        .with_context(|| format!("{s}.{p} = {v}"))?,
                    Change::Priority(s, p) => c
                        .set_priority(s, *p)
                        .with_context(|| format!("priority of {s} = {p}"))?,
                }
            }
            print(
                format!("{} changes applied", todo.len()),
                json!({"applied": todo.len()}),
            );
        }
        CtlCmd::Priority { skill, priority } => {
            c.set_priority(&skill, priority)?;
            print(String::new(), json!({"ok": true}));
        }
    }
    Ok(())
}

/// A plan's tree as text: a line per node, indented by depth — its status letter (`·` idle,
/// `R` running, `S` success, `F` failure), name, kind and detail, the cycle since when; `▶`
/// marks the branch that runs.
fn plan_text(t: &skillfab_proto::control::PlanTree) -> String {
    use skillfab_proto::control::NodeStatus;
    let depths = t.depths();
    let branch = t.running_branch();
    let mut out = format!("plan {} ({} nodes)", t.plan, t.nodes.len());
    for n in &t.nodes {
        let i = n.id as usize;
        let (status, since) = t.status[i];
        let mut line = format!(
            "\n{}{}{} {}",
            if branch[i] { "▶" } else { " " },
            "  ".repeat(depths[i] + 1),
            status.letter(),
            n.name
        );
        if n.kind != n.name {
            line.push_str(&format!(" [{}]", n.kind));
        }
        if !n.detail.is_empty() {
            line.push_str(&format!(" {}", n.detail));
        }
        if status != NodeStatus::Idle {
            line.push_str(&format!(" ({status} since cycle {since})"));
        }
        out.push_str(&line);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replay_reads_param_and_priority_lines() {
        let log = r#"{"kind":"start","domain":"d","pid":1,"time_ns":1,"unix_ms":2}
{"kind":"param","cycle":5,"time_ns":1,"unix_ms":2,"skill":"scale","param":"gain","old":2.0,"new":3.5,"by":"1-0"}
{"kind":"sample","cycle":6,"skill":"scale","dir":"out","port":"scaled","value":{"value":1.0}}
{"kind":"param","cycle":7,"time_ns":1,"unix_ms":2,"skill":"wander","param":"seed","old":1,"new":9,"by":"1-0"}
{"kind":"priority","cycle":8,"time_ns":1,"unix_ms":2,"skill":"avoid","old":8,"new":-2,"by":"1-0"}
"#;
        assert_eq!(
            changes(log, None).unwrap(),
            vec![
                Change::Param("scale".into(), "gain".into(), ParamValue::Float(3.5)),
                Change::Param("wander".into(), "seed".into(), ParamValue::UInt(9)),
                Change::Priority("avoid".into(), -2),
            ]
        );
        assert_eq!(changes(log, Some("avoid")).unwrap().len(), 1);
        assert!(changes("{\"kind\":\"param\"}", None).is_err());
        assert!(changes("not json", None).is_err());
    }

    #[test]
    fn a_plan_prints_as_an_indented_tree_with_its_running_branch_marked() {
        use skillfab_proto::control::{NodeStatus, PlanNode, PlanTree};
        let node = |id, parent, name: &str, kind: &str, detail: &str| PlanNode {
            id,
            parent,
            name: name.into(),
            kind: kind.into(),
            detail: detail.into(),
        };
        let t = PlanTree {
            plan: "p.xml".into(),
            nodes: vec![
                node(0, None, "main", "Sequence", ""),
                node(1, Some(0), "Activate", "Activate", "a, b"),
                node(2, Some(0), "wait", "WaitFor", "x.y.z > 1"),
                node(3, Some(0), "Log", "Log", "done"),
            ],
            status: vec![
                (NodeStatus::Running, 3),
                (NodeStatus::Success, 3),
                (NodeStatus::Running, 4),
                (NodeStatus::Idle, 0),
            ],
        };
        assert_eq!(
            plan_text(&t),
            "plan p.xml (4 nodes)\n\
             ▶  R main [Sequence] (running since cycle 3)\n\
             \x20    S Activate a, b (success since cycle 3)\n\
             ▶    R wait [WaitFor] x.y.z > 1 (running since cycle 4)\n\
             \x20    · Log done"
        );
    }
}
