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
use skillfab_manager::recorder::{hex, read_records, unhex};
use skillfab_proto::control::SkillState;
use skillfab_proto::domain::Domain;
use skillfab_proto::schema::{FieldKind, Prim};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

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

/// A kill asked for: the skill, killed after its run of `cycle`.
#[derive(Debug, Clone, PartialEq)]
pub struct KillAt {
    /// Instance name.
    pub skill: String,
    /// The cycle after whose run it is killed.
    pub cycle: u64,
}

fn kill_at(text: &str) -> Result<KillAt, String> {
    let (skill, cycle) = text
        .rsplit_once('@')
        .ok_or_else(|| format!("'{text}' is not SKILL@CYCLE"))?;
    let cycle = cycle
        .parse()
        .map_err(|e| format!("'{text}': the cycle '{cycle}' is not a number ({e})"))?;
    if skill.is_empty() {
        return Err(format!("'{text}' names no skill"));
    }
    Ok(KillAt {
        skill: skill.to_string(),
        cycle,
    })
}

/// A kill done, and the process that took the skill's place.
#[derive(Debug, Clone, Serialize)]
pub struct Killed {
    /// Instance name.
    pub skill: String,
    /// The cycle after whose run it was killed.
    pub cycle: u64,
    /// The process killed.
    pub pid: u32,
    /// The process that replaced it.
    pub new_pid: u32,
    /// Whether its kept state was removed first (`--forget`).
    pub forgot: bool,
}

/// One recorded sample.
#[derive(Debug, Clone)]
struct Sample {
    skill: String,
    port: String,
    topic: String,
    type_name: String,
    bytes: Vec<u8>,
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
        let text = read_records(path)?;
        let mut r = Recording::default();
        for (n, line) in text.lines().enumerate() {
            let j: Json = serde_json::from_str(line)
                .with_context(|| format!("{}: record {} is not JSON", path.display(), n + 1))?;
            let cycle = j["cycle"].as_u64();
            match j["kind"].as_str() {
                Some("start") if j["recording"] == true => r.period_ns = j["period_ns"].as_u64(),
                Some("decl") => r.decls.push(j),
                Some("control") => r.controls.push(j),
                Some("cycle") => {
                    r.complete.extend(cycle);
                }
                Some("sample") => {
                    let (Some(cycle), Some(bytes)) = (cycle, j["raw"].as_str().and_then(unhex))
                    else {
                        continue;
                    };
                    let text = |k: &str| j[k].as_str().unwrap_or_default().to_string();
                    r.samples.entry(cycle).or_default().push(Sample {
                        skill: text("skill"),
                        port: text("port"),
                        topic: text("topic"),
                        type_name: text("type"),
                        bytes,
                        value: j["value"].clone(),
                    });
                }
                _ => {}
            }
        }
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
        manager: ManagerSection {
            period_ms: rec.period_ns.map(|ns| ns as f64 / 1e6),
            deadline_ms: None,
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

/// Kills replayed skills and waits for `up` to start them again.
struct Killer<'a> {
    domain: &'a Domain,
    forget: bool,
    log: PathBuf,
}

impl Killer<'_> {
    /// Kills `skill` (its kept state removed first with `forget`) and waits until a new
    /// process has it again, in the state (active or not) it was in.
    fn kill(&self, c: &Client, at: &KillAt) -> anyhow::Result<Killed> {
        let find = || -> anyhow::Result<Option<(u32, SkillState)>> {
            Ok(c.list()?
                .into_iter()
                .find(|s| s.name == at.skill)
                .map(|s| (s.pid, s.state)))
        };
        let (pid, was) = find()?.with_context(|| format!("{} is not registered", at.skill))?;
        if self.forget {
            let name = skillfab_proto::names::state(&self.domain.prefix(), &at.skill);
            // Removed while the process still runs (the fabric is stopped: it commits
            // nothing), so the next one finds no state whatever instant `up` restarts it.
            match nix::sys::mman::shm_unlink(name.as_str()) {
                Ok(()) | Err(nix::errno::Errno::ENOENT) => {}
                Err(e) => bail!("removing {name}: {e}"),
            }
        }
        nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(i32::try_from(pid)?),
            nix::sys::signal::Signal::SIGKILL,
        )
        .with_context(|| format!("SIGKILL to {} ({pid})", at.skill))?;
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Some((new_pid, state)) = find()?
                && new_pid != pid
                && state == was
            {
                return Ok(Killed {
                    skill: at.skill.clone(),
                    cycle: at.cycle,
                    pid,
                    new_pid,
                    forgot: self.forget,
                });
            }
            if Instant::now() > deadline {
                bail!(
                    "{} killed after cycle {} was not back within 30 s (see {})",
                    at.skill,
                    at.cycle,
                    self.log.display()
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
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

/// The outputs of the replayed skills, by cycle: (skill, port) → sample.
fn outputs<'a>(
    rec: &'a Recording,
    skills: &[String],
    from: u64,
    to: u64,
) -> BTreeMap<u64, BTreeMap<(String, String), &'a Sample>> {
    let mut m: BTreeMap<u64, BTreeMap<(String, String), &Sample>> = BTreeMap::new();
    for (cycle, samples) in rec.samples.range(from..=to) {
        for s in samples.iter().filter(|s| skills.contains(&s.skill)) {
            m.entry(*cycle)
                .or_default()
                .insert((s.skill.clone(), s.port.clone()), s);
        }
    }
    m
}

/// The first field (a dotted path) where two decoded values differ.
fn first_difference(a: &Json, b: &Json, path: &str) -> Option<(String, Json, Json)> {
    match (a, b) {
        (Json::Object(x), Json::Object(y)) => x.iter().find_map(|(k, v)| {
            let p = if path.is_empty() {
                k.clone()
            } else {
                format!("{path}.{k}")
            };
            first_difference(v, y.get(k).unwrap_or(&Json::Null), &p)
        }),
        (Json::Array(x), Json::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .find_map(|(i, (v, w))| first_difference(v, w, &format!("{path}[{i}]"))),
        _ if a == b => None,
        _ => Some((path.to_string(), a.clone(), b.clone())),
    }
}

/// A primitive field of a message: its path, byte range and kind.
struct Leaf {
    path: String,
    at: std::ops::Range<usize>,
    prim: Prim,
}

fn kind_size(k: &FieldKind) -> usize {
    match k {
        FieldKind::Prim(p) => p.size(),
        FieldKind::Array { elem, len } => kind_size(elem) * *len as usize,
        FieldKind::Struct(m) => m.size as usize,
    }
}

fn leaves_of(kind: &FieldKind, path: String, offset: usize, out: &mut Vec<Leaf>) {
    match kind {
        FieldKind::Prim(p) => out.push(Leaf {
            path,
            at: offset..offset + p.size(),
            prim: *p,
        }),
        FieldKind::Array { elem, len } => {
            for i in 0..*len as usize {
                leaves_of(
                    elem,
                    format!("{path}[{i}]"),
                    offset + i * kind_size(elem),
                    out,
                );
            }
        }
        FieldKind::Struct(m) => {
            for f in &m.fields {
                let p = if path.is_empty() {
                    f.name.clone()
                } else {
                    format!("{path}.{}", f.name)
                };
                leaves_of(&f.ty, p, offset + f.offset as usize, out);
            }
        }
    }
}

/// The fields of a message type of the shared catalog, in declaration order (`None`: a type
/// the catalog does not hold).
fn leaves(type_name: &str) -> Option<Vec<Leaf>> {
    let t = skillfab_msgs::registry()
        .iter()
        .find(|t| t.type_name == type_name)?;
    let mut out = Vec::new();
    leaves_of(&FieldKind::Struct((t.schema)()), String::new(), 0, &mut out);
    Some(out)
}

/// A primitive read from bytes, as JSON (non-finite floats as text).
fn prim_json(b: &[u8], p: Prim) -> Json {
    let float = |v: f64| {
        if v.is_finite() {
            Json::from(v)
        } else {
            Json::from(v.to_string())
        }
    };
    let mut w = [0u8; 8];
    w[..p.size()].copy_from_slice(&b[..p.size()]);
    let (w2, w4) = ([w[0], w[1]], [w[0], w[1], w[2], w[3]]);
    match p {
        Prim::Bool => Json::from(w[0] != 0),
        Prim::U8 => Json::from(w[0]),
        Prim::I8 => Json::from(i8::from_ne_bytes([w[0]])),
        Prim::U16 => Json::from(u16::from_ne_bytes(w2)),
        Prim::I16 => Json::from(i16::from_ne_bytes(w2)),
        Prim::U32 => Json::from(u32::from_ne_bytes(w4)),
        Prim::I32 => Json::from(i32::from_ne_bytes(w4)),
        Prim::F32 => float(f64::from(f32::from_ne_bytes(w4))),
        Prim::U64 => Json::from(u64::from_ne_bytes(w)),
        Prim::I64 => Json::from(i64::from_ne_bytes(w)),
        Prim::F64 => float(f64::from_ne_bytes(w)),
    }
}

/// Where two samples of one port differ: the first field (declaration order) whose bytes
/// differ, with both values. Padding between fields is not compared (it holds whatever the
/// publisher's memory held). A type outside the catalog is compared as bytes.
fn sample_difference(
    a: &Sample,
    b: &Sample,
    fields: Option<&[Leaf]>,
) -> Option<(String, Json, Json)> {
    let Some(fields) = fields else {
        return (a.bytes != b.bytes).then(|| {
            first_difference(&a.value, &b.value, "").unwrap_or_else(|| {
                (
                    "bytes".into(),
                    Json::from(hex(&a.bytes)),
                    Json::from(hex(&b.bytes)),
                )
            })
        });
    };
    fields.iter().find_map(|l| {
        let (x, y) = (a.bytes.get(l.at.clone())?, b.bytes.get(l.at.clone())?);
        (x != y).then(|| (l.path.clone(), prim_json(x, l.prim), prim_json(y, l.prim)))
    })
}

fn compare(rec: &Recording, replayed: &Recording, skills: &[String], from: u64, to: u64) -> Report {
    let want = outputs(rec, skills, from, to);
    let got = outputs(replayed, skills, from, to);
    let mut report = Report {
        skills: skills.to_vec(),
        from,
        to,
        cycles: to - from + 1,
        identical_cycles: 0,
        samples: 0,
        divergence: None,
        kills: Vec::new(),
        wall_s: 0.0,
    };
    let empty = BTreeMap::new();
    let mut layouts: std::collections::HashMap<String, Option<Vec<Leaf>>> =
        std::collections::HashMap::new();
    for cycle in from..=to {
        let (w, g) = (
            want.get(&cycle).unwrap_or(&empty),
            got.get(&cycle).unwrap_or(&empty),
        );
        let keys: BTreeSet<&(String, String)> = w.keys().chain(g.keys()).collect();
        let mut same = true;
        for key in keys {
            report.samples += 1;
            let diff = match (w.get(key), g.get(key)) {
                (Some(a), Some(b)) if a.bytes == b.bytes => None,
                (Some(a), Some(b)) => {
                    let fields = layouts
                        .entry(a.type_name.clone())
                        .or_insert_with(|| leaves(&a.type_name));
                    sample_difference(a, b, fields.as_deref())
                }
                (a, b) => Some((
                    "-".into(),
                    Json::from(if a.is_some() { "published" } else { "nothing" }),
                    Json::from(if b.is_some() { "published" } else { "nothing" }),
                )),
            };
            if let Some((field, recorded, replayed)) = diff {
                same = false;
                if report.divergence.is_none() {
                    report.divergence = Some(Divergence {
                        cycle,
                        skill: key.0.clone(),
                        port: key.1.clone(),
                        field,
                        recorded,
                        replayed,
                    });
                }
            }
        }
        report.identical_cycles += u64::from(same);
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn the_first_difference_is_named_by_its_field_path() {
        let a = json!({"translate": 0.3, "rotate": 0.0, "ranges": [1.0, 2.0]});
        let b = json!({"translate": 0.3, "rotate": 0.0, "ranges": [1.0, 2.5]});
        assert_eq!(
            first_difference(&a, &b, ""),
            Some(("ranges[1]".into(), json!(2.0), json!(2.5)))
        );
        assert_eq!(first_difference(&a, &a, ""), None);
    }

    fn sample(type_name: &str, bytes: Vec<u8>) -> Sample {
        Sample {
            skill: "s".into(),
            port: "p".into(),
            topic: "t".into(),
            type_name: type_name.into(),
            bytes,
            value: Json::Null,
        }
    }

    #[test]
    fn padding_is_not_compared_and_a_non_finite_value_is_named() {
        // skillfab.Door: found (bool) at 0, seven bytes of padding, then x, y, heading, width.
        let mut a = vec![0u8; 40];
        let mut b = a.clone();
        a[1..8].copy_from_slice(&[0x66, 0xc4, 0x33, 0xef, 0x55, 0, 0]);
        let fields = leaves("skillfab.Door").unwrap();
        assert!(
            sample_difference(
                &sample("skillfab.Door", a.clone()),
                &sample("skillfab.Door", b.clone()),
                Some(&fields)
            )
            .is_none()
        );
        b[16..24].copy_from_slice(&f64::NAN.to_ne_bytes());
        a[16..24].copy_from_slice(&f64::INFINITY.to_ne_bytes());
        assert_eq!(
            sample_difference(
                &sample("skillfab.Door", a),
                &sample("skillfab.Door", b),
                Some(&fields)
            ),
            Some(("y".into(), json!("inf"), json!("NaN")))
        );
    }
}
