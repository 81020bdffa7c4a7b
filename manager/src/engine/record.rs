//! The full-rate recording (`skillfab up --record FILE.mcap`, `ctl record start|stop`): every
//! sample of the chosen topics (default: all) with its cycle, producer and stamp, the skills'
//! declarations, the control changes (activations, parameters, priorities) with the cycle they
//! take effect from, the events, and a marker after each cycle's samples. `skillfab replay`
//! reads it back (docs/replay.md).
//!
//! Samples are read from shared memory at the end of each cycle, before anything else reads
//! them, copied out (a sample must be released to its publisher) and handed to the recorder's
//! writer thread, which encodes (CDR, or JSON if asked for) and writes them: the cycle's own
//! path only pays the copy, and a sample's names travel with it as one shared reference. A sample the writer thread has not taken yet waits in its queue, so nothing is dropped
//! for a slow disk; what a subscriber's buffer could not hold (more than
//! `SUBSCRIBER_BUFFER` samples of one topic in one cycle) is counted in the cycle markers.

use super::observers::Observers;
use super::skills::Skills;
use crate::recorder::{IoSample, Recorder, SampleEncoding, SampleSource};
use iceoryx2::node::Node;
use iceoryx2::prelude::*;
use serde_json::json;
use skillfab_proto::board::{Board, Clock};
use skillfab_proto::control::{ControlError, Event, Reply, Response};
use skillfab_proto::domain::Domain;
use skillfab_proto::header::MaybeSlot;
use skillfab_proto::names;
use skillfab_proto::schema::MessageSchema;
use skillfab_proto::services::RawReader;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;

/// What and where to record.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordSpec {
    /// The MCAP file.
    pub path: PathBuf,
    /// Topics to record; empty: every topic.
    pub topics: Vec<String>,
    /// How samples are written.
    pub encoding: SampleEncoding,
}

/// A recording in progress.
pub(crate) struct Recording {
    rec: Recorder,
    spec: RecordSpec,
    /// Per recorded topic (in order: a cycle's samples are written in the same order every
    /// run): how to decode it and who produces it.
    topics: BTreeMap<String, RecTopic>,
    /// Skill instances whose declaration is in the file: (name, pid).
    declared: HashSet<(String, u32)>,
    /// Samples recorded so far.
    pub(crate) samples: u64,
    /// Samples seen out of order or twice (a publisher's cycle that went backwards).
    pub(crate) out_of_order: u64,
}

struct RecTopic {
    schema: MessageSchema,
    /// Producers by board slot (a device's command: `cmd`, else `out`).
    producers: HashMap<u32, Arc<SampleSource>>,
    /// Samples of a slot no declaration names (`slot<N>`), made once per slot.
    strangers: HashMap<MaybeSlot, Arc<SampleSource>>,
    /// Newest cycle recorded, per producer.
    last: HashMap<String, u64>,
}

/// Why a recording cannot start.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordError {
    /// The file is not named `*.mcap`.
    #[error("a recording is an MCAP file: {} does not end in .mcap", path.display())]
    NotMcap {
        /// The file asked for.
        path: PathBuf,
    },
    /// The file cannot be created or written.
    #[error("cannot record to {}", path.display())]
    Io {
        /// The file asked for.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}

impl From<RecordError> for ControlError {
    fn from(e: RecordError) -> ControlError {
        match e {
            RecordError::NotMcap { path } => ControlError::NotMcap {
                file: path.display().to_string(),
            },
            RecordError::Io { path, source } => ControlError::CannotRecord {
                file: path.display().to_string(),
                os_error: source.raw_os_error(),
            },
        }
    }
}

impl Recording {
    /// Starts writing `spec.path` (which must name an `.mcap` file) for the fabric of
    /// `domain`, at `cycle` and `clock`.
    pub(crate) fn start(
        spec: RecordSpec,
        domain: &str,
        cycle: u64,
        clock: Clock,
    ) -> Result<Recording, RecordError> {
        if !crate::recorder::is_mcap(&spec.path) {
            return Err(RecordError::NotMcap { path: spec.path });
        }
        let cannot = |source: std::io::Error| RecordError::Io {
            path: spec.path.clone(),
            source,
        };
        if let Some(dir) = spec.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(cannot)?;
        }
        std::fs::File::create(&spec.path).map_err(cannot)?;
        let rec = Recorder::open_with(&spec.path, spec.encoding).map_err(cannot)?;
        rec.line(
            "start",
            Some(cycle),
            json!({
                "domain": domain, "pid": std::process::id(),
                "recording": true, "topics": spec.topics,
                "encoding": format!("{:?}", spec.encoding).to_lowercase(),
                "period_ns": clock.period.map(|p| p.as_nanos() as u64),
                "lockstep": clock.lockstep,
            }),
        );
        Ok(Recording {
            rec,
            spec,
            topics: BTreeMap::new(),
            declared: HashSet::new(),
            samples: 0,
            out_of_order: 0,
        })
    }

    /// Where it goes.
    pub(crate) fn path(&self) -> &std::path::Path {
        &self.spec.path
    }

    fn wanted(&self, topic: &str) -> bool {
        self.spec.topics.is_empty() || self.spec.topics.iter().any(|t| t == topic)
    }

    /// A control change that takes effect from cycle `from`.
    pub(crate) fn control(&self, from: u64, what: &str, fields: serde_json::Value) {
        let mut j = json!({"what": what, "from": from});
        if let (Some(o), serde_json::Value::Object(f)) = (j.as_object_mut(), fields) {
            o.extend(f);
        }
        self.rec.line("control", Some(from.saturating_sub(1)), j);
    }

    /// End of cycle `k`: every new sample of the recorded topics (read through `readers`),
    /// then the cycle's marker.
    pub(crate) fn record_cycle(
        &mut self,
        k: u64,
        readers: &mut HashMap<String, RawReader>,
        clock: Clock,
    ) {
        let mut n = 0u64;
        for (topic, t) in &mut self.topics {
            let Some(reader) = readers.get_mut(topic) else {
                continue;
            };
            let mut taken = Vec::new();
            let drained = reader.drain(&mut |bytes, h| taken.push((bytes.to_vec(), h)));
            if let Err(e) = drained {
                tracing::warn!(%topic, error = %e, "recording read failed");
            }
            let mut samples = Vec::with_capacity(taken.len());
            for (bytes, h) in taken {
                // A command's header names the proposal that won, not the device.
                let source = match h
                    .slot
                    .get()
                    .and_then(|s| t.producers.get(&s))
                    .or_else(|| t.producers.values().find(|p| p.dir == "cmd"))
                {
                    Some(s) => s.clone(),
                    None => match t.strangers.get(&h.slot) {
                        Some(s) => s.clone(),
                        None => {
                            let name = format!("slot{}", h.slot);
                            let Ok(s) =
                                SampleSource::new(&name, "out", topic, topic, &t.schema, true)
                            else {
                                continue;
                            };
                            let s = Arc::new(s);
                            t.strangers.insert(h.slot, s.clone());
                            s
                        }
                    },
                };
                let last = match t.last.get_mut(&source.skill) {
                    Some(l) => l,
                    None => t.last.entry(source.skill.clone()).or_insert(0),
                };
                if h.cycle <= *last && *last > 0 {
                    self.out_of_order += 1;
                }
                *last = h.cycle;
                samples.push(IoSample {
                    cycle: h.cycle,
                    stamp_ns: h.stamp_ns,
                    source,
                    bytes,
                });
            }
            // A topic with several producers (a channel's proposals) delivers their samples
            // in the order its publishers connected, which is the host's: recorded by cycle,
            // then producer's name, so one run's recording is the same on any host.
            samples.sort_by(|a, b| (a.cycle, &a.source.skill).cmp(&(b.cycle, &b.source.skill)));
            n += samples.len() as u64;
            for sample in samples {
                self.rec.sample(sample);
            }
        }
        self.samples += n;
        self.rec.line(
            "cycle",
            Some(k),
            json!({"clock_ns": clock.time.as_nanos() as u64, "samples": n,
                   "out_of_order": self.out_of_order}),
        );
    }
}

/// Where the fabric stands when a recording starts.
pub(crate) struct RecordStart<'a> {
    pub(crate) domain: &'a str,
    pub(crate) cycle: u64,
    pub(crate) clock: Clock,
    pub(crate) skills: &'a Skills,
    pub(crate) node: &'a Node<ipc::Service>,
}

impl<'a> RecordStart<'a> {
    /// The fabric of `domain` at `cycle`, its clock as `board` gives it.
    pub(crate) fn new(
        domain: &'a Domain,
        cycle: u64,
        board: &Board,
        skills: &'a Skills,
        node: &'a Node<ipc::Service>,
    ) -> RecordStart<'a> {
        RecordStart {
            domain: domain.name(),
            cycle,
            clock: board.header().clock(),
            skills,
            node,
        }
    }
}

impl Observers {
    /// Starts recording (replacing a recording in progress).
    pub(crate) fn start_recording(
        &mut self,
        spec: RecordSpec,
        at: &RecordStart<'_>,
    ) -> Result<(), RecordError> {
        self.recording = None;
        let r = Recording::start(spec, at.domain, at.cycle, at.clock)?;
        tracing::info!(file = %r.path().display(), "recording");
        self.recording = Some(r);
        self.update_recording(at.skills, at.node, at.cycle);
        Ok(())
    }

    /// `ctl record start|stop`.
    pub(crate) fn record_request(
        &mut self,
        file: Option<String>,
        topics: Vec<String>,
        at: &RecordStart<'_>,
    ) -> Response {
        match file {
            None if self.recording.is_none() => Err(ControlError::NotRecording),
            None => {
                if let Some(r) = self.recording.take() {
                    tracing::info!(file = %r.path().display(), samples = r.samples, "recording stopped");
                }
                Ok(Reply::Done)
            }
            Some(f) => self
                .start_recording(
                    RecordSpec {
                        path: PathBuf::from(f),
                        topics,
                        encoding: SampleEncoding::default(),
                    },
                    at,
                )
                .map(|()| Reply::Done)
                .map_err(ControlError::from),
        }
    }

    /// Records a control change that takes effect from cycle `from`.
    pub(crate) fn record_control(&self, from: u64, what: &str, fields: serde_json::Value) {
        if let Some(r) = &self.recording {
            r.control(from, what, fields);
        }
    }

    /// After a (re)plan, at `cycle`: declarations of new skill instances, and the topics to
    /// read.
    pub(crate) fn update_recording(
        &mut self,
        skills: &Skills,
        node: &Node<ipc::Service>,
        cycle: u64,
    ) {
        let Some(rec) = self.recording.as_mut() else {
            return;
        };
        let mut wanted: Vec<(String, MessageSchema, u32, String, String, &'static str)> =
            Vec::new();
        for (s, e) in skills.in_order() {
            if !e.ready {
                continue;
            }
            let d = &e.decl;
            if rec.declared.insert((d.name.clone(), d.pid)) {
                let port = |p: &skillfab_proto::decl::PortDecl| {
                    json!({"port": p.port, "topic": p.topic, "type": p.schema.type_name,
                           "kind": format!("{:?}", p.kind)})
                };
                let params: serde_json::Map<String, serde_json::Value> = d
                    .param_values
                    .iter()
                    .map(|(n, v)| (n.clone(), skillfab_proto::json::param_json(v)))
                    .collect();
                let defaults: serde_json::Map<String, serde_json::Value> = d
                    .params
                    .iter()
                    .map(|p| (p.name.clone(), skillfab_proto::json::param_json(&p.default)))
                    .collect();
                rec.rec.line(
                    "decl",
                    Some(cycle),
                    json!({"skill": d.name, "kind_of": d.kind, "mode": format!("{:?}", d.mode),
                           "priority": d.priority, "active": e.active, "pid": d.pid,
                           "from": cycle + 1,
                           "inputs": d.inputs.iter().map(port).collect::<Vec<_>>(),
                           "outputs": d.outputs.iter().map(port).collect::<Vec<_>>(),
                           "params": params, "defaults": defaults}),
                );
            }
            for p in &d.outputs {
                wanted.push((
                    p.topic.clone(),
                    p.schema.clone(),
                    s as u32,
                    d.name.clone(),
                    p.port.clone(),
                    "out",
                ));
            }
            for p in &d.inputs {
                if matches!(p.kind, skillfab_proto::decl::PortKind::Channel(_)) {
                    wanted.push((
                        names::command_topic(p.topic.strip_prefix("channel/").unwrap_or(&p.topic)),
                        p.schema.clone(),
                        s as u32,
                        d.name.clone(),
                        p.port.clone(),
                        "cmd",
                    ));
                }
            }
        }
        for (topic, schema, slot, skill, port, dir) in wanted {
            if !rec.wanted(&topic) {
                continue;
            }
            if !self.readers.contains_key(&topic) {
                match RawReader::open(node, &topic, &schema) {
                    Ok(r) => {
                        self.readers.insert(topic.clone(), r);
                    }
                    Err(e) => {
                        tracing::warn!(%topic, error = %e, "cannot record topic");
                        continue;
                    }
                }
            }
            let Ok(source) = SampleSource::new(&skill, dir, &port, &topic, &schema, true) else {
                continue;
            };
            let t = rec.topics.entry(topic).or_insert_with(|| RecTopic {
                schema,
                producers: HashMap::new(),
                strangers: HashMap::new(),
                last: HashMap::new(),
            });
            // The same source as before (the writer's channel cache is keyed by it) unless it
            // changed.
            let same = t.producers.get(&slot).is_some_and(|s| {
                (s.skill.as_str(), s.port.as_str(), s.dir) == (skill.as_str(), port.as_str(), dir)
                    && s.schema == source.schema
            });
            if !same {
                t.producers.insert(slot, Arc::new(source));
            }
        }
    }

    /// A plan's whole tree, as it arrived in `cycle` (its changes follow as events).
    pub(crate) fn record_plan(&self, cycle: u64, tree: &skillfab_proto::control::PlanTree) {
        if let Some(r) = &self.recording {
            r.rec
                .line("plan", Some(cycle), skillfab_proto::json::plan_json(tree));
        }
    }

    /// Events go into the recording as they are published.
    pub(crate) fn record_events(&self, events: &[Event]) {
        if let Some(r) = &self.recording {
            for e in events {
                r.rec
                    .line("event", Some(e.cycle), skillfab_proto::json::event_json(e));
            }
        }
    }
}
