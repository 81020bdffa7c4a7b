//! `skillfab replay FILE.mcap --skills a,b [--from C] [--to C] [--json]`: runs the named skill
//! binaries again — as they are built now — against a recording (`skillfab up --record`), and
//! compares what they produce with what was recorded.
//!
//! The skills run in a private domain under a lock-step manager that numbers cycles as the
//! recording did. `skillfab-player` publishes, cycle by cycle, the recorded samples of every
//! topic they read and do not produce; their recorded activations and parameter changes are
//! applied at the cycles they took effect from (the manager is stepped to each). The replay
//! is itself recorded, and the two files are compared sample by sample: the report gives the
//! cycles with identical outputs and the first divergence (cycle, skill, port, field, both
//! values). Skills are compared on the bytes of each field they published (a NaN counts,
//! padding does not).
//!
//! `--kill SKILL@CYCLE` kills a replayed skill (SIGKILL) after its run of that cycle; `up`
//! starts it again and the replay goes on once it is back. Its outputs after the kill are
//! compared like the others: a skill that starts from the state of its last completed run
//! (`Skill::STATE`) replays identically; one that forgot what it knew diverges (`--forget`
//! removes the kept state before the restart, to show what that memory is worth).

use anyhow::{Context, bail};
use serde::Serialize;
use serde_json::Value as Json;
use skillfab_client::Client;
use skillfab_manager::launch::{LaunchFile, ManagerSection, ProcessEntry, find_program};
use skillfab_manager::recorder::{ReadRecord, hex, read_file, unhex};
use skillfab_proto::control::SkillState;
use skillfab_proto::domain::Domain;
use skillfab_proto::schema::MessageSchema;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod compare;
mod kill;

use compare::compare;
pub use kill::{KillAt, Killed};
use kill::{Killer, kill_at};

/// Options of `skillfab replay`.
#[derive(clap::Args, Debug, Clone)]
pub struct ReplayOptions {
    /// The recording (.mcap).
    pub file: PathBuf,
    /// Skills to replay (comma-separated instance names).
    #[arg(long, value_delimiter = ',', required = true)]
    pub skills: Vec<String>,
    /// First cycle (default: the recording's first).
    #[arg(long, value_name = "CYCLE")]
    pub from: Option<u64>,
    /// Last cycle (default: the recording's last complete cycle).
    #[arg(long, value_name = "CYCLE")]
    pub to: Option<u64>,
    /// Where the skill binaries are (default: next to skillfab).
    #[arg(long, value_name = "DIR")]
    pub bin_dir: Option<PathBuf>,
    /// Keep the replay's files (launch file, player script, its recording, log) here.
    #[arg(long, value_name = "DIR")]
    pub keep: Option<PathBuf>,
    /// Kill a replayed skill (SIGKILL) after its run of a cycle; it is started again before
    /// the next (comma-separated `SKILL@CYCLE`).
    #[arg(long, value_name = "SKILL@CYCLE", value_delimiter = ',', value_parser = kill_at)]
    pub kill: Vec<KillAt>,
    /// With --kill: remove the killed skill's kept state before it is started again, as if
    /// it kept none.
    #[arg(long, requires = "kill")]
    pub forget: bool,
}

/// One recorded sample.
#[derive(Debug, Clone)]
struct Sample {
    skill: String,
    port: String,
    topic: String,
    type_name: String,
    bytes: Vec<u8>,
    /// Its layout as the recording gives it (a CDR recording; a JSON one has the `value`).
    schema: Option<std::sync::Arc<MessageSchema>>,
    /// The decoded value of a JSON recording's sample (`Null` in a CDR recording).
    value: Json,
}

/// A recording, read back.
#[derive(Debug, Default)]
struct Recording {
    period_ns: Option<u64>,
    /// Declarations, in order.
    decls: Vec<Json>,
    /// Control changes, in order.
    controls: Vec<Json>,
    /// Samples by cycle.
    samples: BTreeMap<u64, Vec<Sample>>,
    /// Cycles whose end marker is in the file (complete).
    complete: BTreeSet<u64>,
}

impl Recording {
    fn read(path: &Path) -> anyhow::Result<Recording> {
        let mut r = Recording::default();
        // A CDR channel's schema, shared by its samples.
        let mut schemas: BTreeMap<String, std::sync::Arc<MessageSchema>> = BTreeMap::new();
        read_file(path, |record| {
            let j = match record {
                ReadRecord::Json(j) => j,
                ReadRecord::Sample(s) => {
                    let c = &s.channel;
                    let schema = schemas
                        .entry(c.topic.clone() + "/" + &c.schema.type_name)
                        .or_insert_with(|| std::sync::Arc::new(c.schema.clone()))
                        .clone();
                    r.samples.entry(s.cycle).or_default().push(Sample {
                        skill: c.skill.clone(),
                        port: c.port.clone(),
                        topic: c.topic.clone(),
                        type_name: c.schema.type_name.clone(),
                        bytes: s.bytes,
                        schema: Some(schema),
                        value: Json::Null,
                    });
                    return;
                }
            };
            let cycle = j["cycle"].as_u64();
            match j["kind"].as_str() {
                Some("start") if j["recording"] == true => r.period_ns = j["period_ns"].as_u64(),
                Some("decl") => r.decls.push(j),
                Some("control") => r.controls.push(j),
                Some("cycle") => {
                    r.complete.extend(cycle);
                }
                // A JSON recording's sample (recordings before CDR, `--record-encoding json`).
                Some("sample") => {
                    let (Some(cycle), Some(bytes)) = (cycle, j["raw"].as_str().and_then(unhex))
                    else {
                        return;
                    };
                    let text = |k: &str| j[k].as_str().unwrap_or_default().to_string();
                    r.samples.entry(cycle).or_default().push(Sample {
                        skill: text("skill"),
                        port: text("port"),
                        topic: text("topic"),
                        type_name: text("type"),
                        bytes,
                        schema: None,
                        value: j["value"].clone(),
                    });
                }
                _ => {}
            }
        })?;
        if r.complete.is_empty() {
            bail!(
                "{} holds no complete cycle: is it a recording (skillfab up --record)?",
                path.display()
            );
        }
        Ok(r)
    }

    /// The newest declaration of `skill`.
    fn decl(&self, skill: &str) -> Option<&Json> {
        self.decls.iter().rev().find(|d| d["skill"] == skill)
    }

    /// The topics (and types) of a declaration's ports of `side` (`inputs`/`outputs`) whose
    /// kind is `kind` (any, if `None`).
    fn ports(decl: &Json, side: &str, kind: Option<&str>) -> Vec<(String, String, String)> {
        decl[side]
            .as_array()
            .into_iter()
            .flatten()
            .filter(|p| kind.is_none_or(|k| p["kind"] == k))
            .map(|p| {
                let s = |k: &str| p[k].as_str().unwrap_or_default().to_string();
                (s("port"), s("topic"), s("type"))
            })
            .collect()
    }
}

/// The first difference between two samples' outputs.
#[derive(Debug, Clone, Serialize)]
pub struct Divergence {
    /// Cycle.
    pub cycle: u64,
    /// Skill.
    pub skill: String,
    /// Output port.
    pub port: String,
    /// Field path in the message (`-`: the sample itself is missing on one side; `bytes`:
    /// the values read the same but the bytes differ).
    pub field: String,
    /// Recorded value.
    pub recorded: Json,
    /// Replayed value.
    pub replayed: Json,
}

/// What `skillfab replay` reports.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// Skills replayed.
    pub skills: Vec<String>,
    /// First and last cycle.
    pub from: u64,
    /// Last cycle.
    pub to: u64,
    /// Cycles compared.
    pub cycles: u64,
    /// Cycles in which every output of the replayed skills was identical to the recording.
    pub identical_cycles: u64,
    /// Samples compared.
    pub samples: u64,
    /// The first divergence, if any.
    pub divergence: Option<Divergence>,
    /// The skills killed on the way (`--kill`).
    pub kills: Vec<Killed>,
    /// Host time the replay took (s).
    pub wall_s: f64,
}

fn param_text(v: &Json) -> String {
    match v {
        Json::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// Runs a replay; the report says whether it diverged.
pub fn replay(opts: &ReplayOptions) -> anyhow::Result<Report> {
    let started = Instant::now();
    let rec = Recording::read(&opts.file)?;
    if opts.skills.is_empty() {
        bail!("--skills: name at least one skill to replay");
    }
    let mut decls = Vec::new();
    for s in &opts.skills {
        let d = rec.decl(s).with_context(|| {
            let known: BTreeSet<&str> = rec
                .decls
                .iter()
                .filter_map(|d| d["skill"].as_str())
                .collect();
            format!(
                "no skill '{s}' in {} (recorded: {})",
                opts.file.display(),
                known.into_iter().collect::<Vec<_>>().join(", ")
            )
        })?;
        if d["mode"] != "Sync" {
            bail!("'{s}' is an async skill: only sync skills replay cycle by cycle");
        }
        decls.push(d);
    }
    let first = *rec.complete.first().unwrap_or(&1);
    let last = *rec.complete.last().unwrap_or(&1);
    let from = opts.from.unwrap_or(first).max(first);
    let to = opts.to.unwrap_or(last).min(last);
    if from > to {
        bail!("nothing to replay: cycles {from}..={to} (the recording has {first}..={last})");
    }
    for k in &opts.kill {
        if !opts.skills.contains(&k.skill) {
            bail!(
                "--kill {}@{}: '{}' is not among --skills",
                k.skill,
                k.cycle,
                k.skill
            );
        }
        if !(from..to).contains(&k.cycle) {
            bail!(
                "--kill {}@{}: a kill after cycle {} is outside the replay's cycles {from}..{to}",
                k.skill,
                k.cycle,
                k.cycle
            );
        }
    }
    // What the player publishes: every data topic the skills read and none of them produces.
    let produced: BTreeSet<String> = decls
        .iter()
        .flat_map(|d| Recording::ports(d, "outputs", None))
        .map(|(_, t, _)| t)
        .collect();
    let mut played: BTreeMap<String, String> = BTreeMap::new();
    for d in &decls {
        for (_, topic, ty) in Recording::ports(d, "inputs", Some("Data")) {
            if !produced.contains(&topic) {
                played.insert(topic, ty);
            }
        }
    }
    let work = match &opts.keep {
        Some(d) => d.clone(),
        None => std::env::temp_dir().join(format!("skillfab-replay-{}", std::process::id())),
    };
    std::fs::create_dir_all(&work).with_context(|| format!("creating {}", work.display()))?;
    let _cleanup = Cleanup(opts.keep.is_none().then(|| work.clone()));
    let script = work.join("player.txt");
    write_script(&script, &rec, &played, from, to)?;
    let launch = launch_file(opts, &rec, &decls, &script)?;
    let launch_path = work.join("replay.toml");
    std::fs::write(&launch_path, toml::to_string(&launch)?)?;
    let out = work.join("replay.mcap");
    let domain = Domain::new(&format!("replay-{}", std::process::id()))?;
    domain.remove_all_files();
    let mut up = Command::new(std::env::current_exe()?);
    up.arg("up")
        .arg(&launch_path)
        .args(["--domain", domain.name(), "--lockstep", "--paused"])
        .args(["--first-cycle", &from.to_string()])
        .arg("--record")
        .arg(&out)
        .args([
            "--topics",
            &produced.iter().cloned().collect::<Vec<_>>().join(","),
        ])
        .env_remove(skillfab_proto::domain::DOMAIN_ENV)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(work.join("up.log"))?);
    let child = up.spawn().context("starting skillfab up")?;
    let net = Net(child);
    let c = connect(&domain, opts.skills.len() + 1, &work)?;
    let killer = Killer {
        domain: &domain,
        forget: opts.forget,
        log: work.join("up.log"),
    };
    let kills = drive(
        &c,
        &rec,
        &opts.skills,
        &decls,
        (from, to),
        &opts.kill,
        &killer,
    )?;
    drop(c);
    // Stops the replay's network: its manager finishes the recording read next.
    drop(net);
    let replayed = Recording::read(&out).context("reading the replay's own recording")?;
    let mut report = compare(&rec, &replayed, &opts.skills, from, to);
    report.kills = kills;
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}

/// The player's script: the played topics, then their samples in `from..=to`.
fn write_script(
    path: &Path,
    rec: &Recording,
    played: &BTreeMap<String, String>,
    from: u64,
    to: u64,
) -> anyhow::Result<()> {
    use std::io::Write;
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(f, "# skillfab-player script")?;
    let index: BTreeMap<&str, usize> = played
        .keys()
        .enumerate()
        .map(|(i, t)| (t.as_str(), i))
        .collect();
    for (i, (topic, ty)) in played.iter().enumerate() {
        writeln!(f, "topic {i} {topic} {ty}")?;
    }
    for (cycle, samples) in rec.samples.range(from..=to) {
        for s in samples {
            if let Some(i) = index.get(s.topic.as_str())
                && played.get(&s.topic) == Some(&s.type_name)
            {
                writeln!(f, "sample {cycle} {i} {}", hex(&s.bytes))?;
            }
        }
    }
    f.flush()?;
    Ok(())
}

/// The replay's launch file: the player and the skills, inactive, with the parameters the
/// recording's run gave them on start-up (those that differ from the defaults it declared:
/// a default changed since is the replayed binary's own).
fn launch_file(
    opts: &ReplayOptions,
    rec: &Recording,
    decls: &[&Json],
    script: &Path,
) -> anyhow::Result<LaunchFile> {
    // The player is skillfab's own; the skills come from --bin-dir if given.
    let tool = |name: &str| {
        find_program(name, Path::new(".")).with_context(|| format!("program '{name}' not found"))
    };
    let program = |name: &str| match &opts.bin_dir {
        Some(dir) => Some(dir.join(name))
            .filter(|p| p.is_file())
            .with_context(|| format!("program '{name}' not found in {}", dir.display())),
        None => tool(name),
    };
    let text = |p: PathBuf| p.to_string_lossy().into_owned();
    let mut launch = LaunchFile {
        bridge: None,
        plan: None,
        realtime: None,
        manager: ManagerSection {
            period_ms: rec.period_ns.map(|ns| ns as f64 / 1e6),
            ..ManagerSection::default()
        },
        process: vec![ProcessEntry {
            name: "player".into(),
            bin: text(tool("skillfab-player")?),
            args: vec!["--script".into(), text(script.to_path_buf())],
            ..ProcessEntry::default()
        }],
    };
    for d in decls {
        let name = d["skill"].as_str().unwrap_or_default();
        let kind = d["kind_of"].as_str().unwrap_or(name);
        let params = d["params"]
            .as_object()
            .into_iter()
            .flatten()
            .filter(|(k, v)| d["defaults"].get(k.as_str()) != Some(v))
            .map(|(k, v)| (k.clone(), toml::Value::String(param_text(v))))
            .collect();
        // Wired as recorded (a launch file's remaps: the demo's `go_through/progress`).
        let remap = ["inputs", "outputs"]
            .iter()
            .flat_map(|side| Recording::ports(d, side, Some("Data")))
            .filter(|(port, topic, _)| port != topic)
            .map(|(port, topic, _)| (port, topic))
            .collect();
        launch.process.push(ProcessEntry {
            name: name.into(),
            bin: text(program(kind)?),
            active: Some(false),
            params,
            remap,
            // Started again at once when killed (`--kill`), however often.
            backoff_ms: Some(0),
            max_restarts: Some(u32::MAX),
            ..ProcessEntry::default()
        });
    }
    Ok(launch)
}

/// The replay's `skillfab up`, stopped (SIGTERM, then waited for) when dropped.
struct Net(std::process::Child);

impl Drop for Net {
    fn drop(&mut self) {
        if let Ok(pid) = i32::try_from(self.0.id()) {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(pid),
                nix::sys::signal::Signal::SIGTERM,
            );
        }
        let deadline = Instant::now() + Duration::from_secs(20);
        while Instant::now() < deadline {
            if matches!(self.0.try_wait(), Ok(Some(_))) {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Removes the replay's scratch directory.
struct Cleanup(Option<PathBuf>);

impl Drop for Cleanup {
    fn drop(&mut self) {
        if let Some(d) = &self.0 {
            let _ = std::fs::remove_dir_all(d);
        }
    }
}

fn connect(domain: &Domain, units: usize, work: &Path) -> anyhow::Result<Client> {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        if let Ok(mut c) = Client::connect(domain)
            && let Ok(list) = c.list()
            && list.len() == units
            && list.iter().all(|s| s.state != SkillState::Starting)
        {
            // A long stretch of cycles is one `step`.
            c.set_timeout(Duration::from_secs(3600));
            return Ok(c);
        }
        if Instant::now() > deadline {
            bail!(
                "the replay's skills did not all register within 30 s (see {})",
                work.join("up.log").display()
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Applies a control record to the replay.
fn apply(c: &Client, ctl: &Json) -> anyhow::Result<()> {
    let skill = ctl["skill"].as_str().unwrap_or_default();
    match ctl["what"].as_str() {
        Some("activate") => c.activate(&[skill])?,
        Some("deactivate") => c.deactivate(&[skill])?,
        Some("param") => {
            let param = ctl["param"].as_str().unwrap_or_default();
            c.set_param(skill, param, &param_text(&ctl["value"]))
                .with_context(|| format!("setting {skill}.{param} as recorded"))?;
        }
        // Priorities only matter to arbitration, which a replay does not do.
        _ => {}
    }
    Ok(())
}

/// What happens at a cycle boundary of the replay.
enum Action<'a> {
    /// A replayed skill killed (before the boundary's control changes).
    Kill(&'a KillAt),
    /// A recorded control change applied.
    Control(&'a Json),
}

/// Sets the skills up as they were when cycle `from` started, then steps the manager from
/// boundary to boundary up to `to`: at each, the kills asked for, then the recorded control
/// changes that took effect from the next cycle.
fn drive(
    c: &Client,
    rec: &Recording,
    skills: &[String],
    decls: &[&Json],
    (from, to): (u64, u64),
    kills: &[KillAt],
    killer: &Killer<'_>,
) -> anyhow::Result<Vec<Killed>> {
    let ours = |j: &Json| skills.iter().any(|s| j["skill"] == s.as_str());
    for d in decls {
        if d["active"] == true && d["from"].as_u64().unwrap_or(0) <= from {
            c.activate(&[d["skill"].as_str().unwrap_or_default()])?;
        }
    }
    // Keyed by the last cycle run before the action.
    let mut later: BTreeMap<u64, Vec<Action>> = BTreeMap::new();
    for k in kills {
        later.entry(k.cycle).or_default().push(Action::Kill(k));
    }
    for ctl in rec.controls.iter().filter(|j| ours(j)) {
        let at = ctl["from"].as_u64().unwrap_or(0);
        if at <= from {
            apply(c, ctl)?;
        } else if at <= to {
            later.entry(at - 1).or_default().push(Action::Control(ctl));
        }
    }
    let mut done = from - 1;
    let mut killed = Vec::new();
    for (at, actions) in later {
        if at > done {
            done = c.step(at - done)?;
        }
        for action in actions {
            match action {
                Action::Kill(k) => killed.push(killer.kill(c, k)?),
                Action::Control(ctl) => apply(c, ctl)?,
            }
        }
    }
    if to > done {
        c.step(to - done)?;
    }
    Ok(killed)
}
