//! The fabric log: every parameter and priority change, and — for the skills it is turned on
//! for (`ctl iolog S on`, `l` in the console) — every input and output sample, appended to
//! one JSON-lines file.
//!
//! The manager hands records to a writer thread over a channel, so a slow disk never holds up
//! a cycle; samples are copied out as bytes, each with a shared reference to where it comes
//! from (`SampleSource`), and encoded on that thread. The full-rate recording
//! (`crate::engine::record`) is written by the same writer. [`read_file`] reads either format
//! back, CDR samples decoded to their bytes.
//!
//! Format: one JSON object per line (keys in alphabetical order), told apart by `kind`;
//! `time_ns` is the host's monotonic clock — the clock of sample stamps and events — and
//! `unix_ms` the wall clock; `by` is the control client (`<pid>-<n>`) that made the change:
//!
//! ```text
//! {"kind":"start","domain":"default","pid":4242,"time_ns":…,"unix_ms":…}
//! {"kind":"param","cycle":1234,"time_ns":…,"unix_ms":…,"skill":"scale","param":"gain","old":2.0,"new":3.0,"by":"4711-0"}
//! {"kind":"priority","cycle":1300,"time_ns":…,"unix_ms":…,"skill":"avoid","old":8,"new":9,"by":"4711-0"}
//! {"kind":"iolog","cycle":1400,"time_ns":…,"unix_ms":…,"skill":"scale","on":true,"by":"4711-0"}
//! {"kind":"sample","cycle":1401,"time_ns":…,"skill":"scale","dir":"out","port":"scaled","topic":"scaled","type":"skillfab.Scaled","stamp_ns":…,"value":{"value":2802.0}}
//! ```
//!
//! `skillfab ctl reapply FILE` applies the `param` and `priority` lines of a file again, in order.
//!
//! A file named `*.mcap` gets the same records in an [MCAP](https://mcap.dev) container instead
//! (what Foxglove and rosbag2 users open), chunked, indexed and LZ4-compressed: one channel
//! per logged port, `/<skill>/<in|out|cmd>/<port>`, and one per other kind,
//! `/skillfab/<kind>` (message encoding `json`, each message the record above). Samples are
//! CDR (message encoding `cdr`, schema encoding `ros2msg`: [`skillfab_proto::cdr`],
//! [`skillfab_proto::ros2msg`]) unless [`SampleEncoding::Json`] is asked for; what a JSON
//! sample record says beside its value is in the channel's metadata (`skill`, `dir`, `port`,
//! `topic`, `type`, the message schema as JSON in `schema`) and the message header: `sequence`
//! is the cycle, `publish_time` the sample's stamp plus the channel's `clock_offset_ns` (wall
//! clock minus monotonic clock), `log_time` the wall clock when it was written.
//!
//! A chunk is closed and flushed every [`CHUNK_CYCLES`] cycle markers, every
//! [`CHUNK_BYTES`] of records or after [`CHUNK_AGE`], whichever comes first: a manager that is
//! killed leaves every closed chunk readable (what it loses is the open chunk, and the summary
//! at the end).

mod read;

pub use read::{ReadRecord, ReadSample, SampleChannel, read_file, read_records};

use serde_json::{Value as Json, json};
use skillfab_proto::header::now_ns;
use skillfab_proto::json::param_json;
use skillfab_proto::param::ParamValue;
use skillfab_proto::schema::MessageSchema;
use skillfab_proto::value::{FieldPath, PathError};
use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Cycle markers after which an MCAP file's chunk is closed and flushed (1 s at 100 Hz; the
/// exit-lab network's 100 cycles are about 60 KB of CDR).
pub const CHUNK_CYCLES: u32 = 100;
/// Bytes of records (before compression) after which a chunk is closed.
pub const CHUNK_BYTES: usize = 256 * 1024;
/// Age after which an open chunk is closed, even when nothing more comes (a paused fabric).
pub const CHUNK_AGE: Duration = Duration::from_secs(1);

/// How an MCAP file's samples are written.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum SampleEncoding {
    /// CDR with ros2msg schemas: the ROS tools decode them; the bytes come back exactly
    /// (padding zeroed).
    #[default]
    Cdr,
    /// One JSON record per sample: the decoded `value` and (in a recording) the bytes as hex.
    Json,
}

/// Where a sample comes from and what it is: the same for every sample of one producer's
/// port, so the manager hands a shared one with each sample instead of copying its names.
#[derive(Debug)]
pub(crate) struct SampleSource {
    pub(crate) skill: String,
    /// `in`, `out` or `cmd` (a device's arbitrated command).
    pub(crate) dir: &'static str,
    pub(crate) port: String,
    pub(crate) topic: String,
    pub(crate) schema: MessageSchema,
    /// The whole message (decoding it for JSON).
    field: FieldPath,
    /// In JSON, also keep the bytes themselves (`raw`, hex): a recording replays them exactly
    /// (NaN, infinities and padding included, which JSON numbers cannot carry).
    raw: bool,
}

impl SampleSource {
    /// The samples `skill` reads or writes (`dir`) on `port`, wired to `topic`.
    pub(crate) fn new(
        skill: &str,
        dir: &'static str,
        port: &str,
        topic: &str,
        schema: &MessageSchema,
        raw: bool,
    ) -> Result<SampleSource, PathError> {
        Ok(SampleSource {
            skill: skill.to_string(),
            dir,
            port: port.to_string(),
            topic: topic.to_string(),
            schema: schema.clone(),
            field: skillfab_proto::value::resolve(schema, "")?,
            raw,
        })
    }

    /// The MCAP channel of its samples.
    fn channel(&self) -> String {
        format!("/{}/{}/{}", self.skill, self.dir, self.port)
    }
}

/// One sample copied out of a topic, encoded on the writer thread.
pub(crate) struct IoSample {
    pub(crate) cycle: u64,
    pub(crate) stamp_ns: u64,
    pub(crate) source: Arc<SampleSource>,
    pub(crate) bytes: Vec<u8>,
}

enum Record {
    Line(Json),
    Sample(IoSample),
}

/// The writer of a fabric log file.
pub struct Recorder {
    tx: Option<Sender<Record>>,
    path: PathBuf,
    thread: Option<JoinHandle<()>>,
}

fn unix_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

impl Recorder {
    /// Starts the writer thread of `path` (creating its directory), its samples in CDR if it
    /// is an MCAP file. The file itself is created with the first record other than `start`,
    /// which is kept until then: a manager whose parameters nobody touched leaves no file. A
    /// `.jsonl` file is appended to; an `.mcap` file is created anew.
    pub fn open(path: &Path) -> std::io::Result<Recorder> {
        Recorder::open_with(path, SampleEncoding::Cdr)
    }

    /// [`Recorder::open`], an MCAP file's samples in `encoding` (a `.jsonl` file's are JSON).
    pub fn open_with(path: &Path, encoding: SampleEncoding) -> std::io::Result<Recorder> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)?;
        }
        let (tx, rx) = channel();
        let target = path.to_path_buf();
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || write_loop(&target, encoding, &rx))?;
        Ok(Recorder {
            tx: Some(tx),
            path: path.to_path_buf(),
            thread: Some(thread),
        })
    }

    /// The file written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn send(&self, r: Record) {
        if let Some(tx) = &self.tx {
            let _ = tx.send(r);
        }
    }

    /// Appends a line of `kind` with the common fields (`cycle`, `time_ns`, `unix_ms`).
    pub(crate) fn line(&self, kind: &str, cycle: Option<u64>, fields: Json) {
        let mut obj = json!({"kind": kind});
        if let Some(c) = cycle {
            obj["cycle"] = json!(c);
        }
        obj["time_ns"] = json!(now_ns());
        obj["unix_ms"] = json!(unix_ms());
        if let (Some(o), Json::Object(f)) = (obj.as_object_mut(), fields) {
            o.extend(f);
        }
        self.send(Record::Line(obj));
    }

    /// Records a parameter change.
    pub(crate) fn param(
        &self,
        cycle: u64,
        skill: &str,
        param: &str,
        old: ParamValue,
        new: ParamValue,
        by: &str,
    ) {
        self.line(
            "param",
            Some(cycle),
            json!({"skill": skill, "param": param, "old": param_json(&old),
                   "new": param_json(&new), "by": by}),
        );
    }

    /// Records a sample.
    pub(crate) fn sample(&self, s: IoSample) {
        self.send(Record::Sample(s));
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        // Closing the channel ends the writer once it wrote everything queued.
        drop(self.tx.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A sample as a JSON record: its decoded `value`, and in a recording its bytes as `raw`.
fn sample_json(
    cycle: u64,
    time_ns: u64,
    stamp_ns: u64,
    source: &SampleSource,
    bytes: &[u8],
) -> Json {
    let value = source
        .field
        .read(bytes)
        .map_or(Json::Null, |v| skillfab_proto::json::value_json(&v));
    let mut j = json!({"kind": "sample", "cycle": cycle, "time_ns": time_ns,
           "skill": source.skill, "dir": source.dir, "port": source.port, "topic": source.topic,
           "type": source.schema.type_name, "stamp_ns": stamp_ns, "value": value});
    if source.raw {
        j["raw"] = json!(hex(bytes));
    }
    j
}

/// Lower-case hex of `bytes`.
pub fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    bytes
        .iter()
        .fold(String::with_capacity(bytes.len() * 2), |mut s, b| {
            let _ = write!(s, "{b:02x}");
            s
        })
}

/// The bytes of lower-case or upper-case hex text; `None` if it is not hex.
pub fn unhex(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) {
        return None;
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(text.get(i..i + 2)?, 16).ok())
        .collect()
}

/// Whether `path` names an MCAP file (by its extension).
pub fn is_mcap(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
}

/// Where the records go.
enum Sink {
    Lines(std::io::BufWriter<std::fs::File>),
    Mcap(Box<McapSink>),
}

impl Sink {
    fn put(&mut self, r: Record) -> anyhow::Result<()> {
        match self {
            Sink::Lines(out) => {
                let j = match r {
                    Record::Line(j) => j,
                    Record::Sample(s) => {
                        sample_json(s.cycle, now_ns(), s.stamp_ns, &s.source, &s.bytes)
                    }
                };
                writeln!(out, "{j}")?;
            }
            Sink::Mcap(m) => m.put(r)?,
        }
        Ok(())
    }

    /// After a batch of records: a JSON-lines file is flushed, an MCAP file's chunk closed and
    /// flushed when it is due (or `now`).
    fn flush(&mut self, now: bool) -> anyhow::Result<()> {
        match self {
            Sink::Lines(out) => out.flush()?,
            Sink::Mcap(m) => m.flush(now)?,
        }
        Ok(())
    }

    fn finish(self) -> anyhow::Result<()> {
        match self {
            Sink::Lines(mut out) => out.flush()?,
            Sink::Mcap(mut m) => {
                m.writer.finish()?;
            }
        }
        Ok(())
    }
}

/// The MCAP container of the fabric log.
struct McapSink {
    writer: mcap::Writer<std::io::BufWriter<std::fs::File>>,
    encoding: SampleEncoding,
    /// Channel of each topic.
    channels: HashMap<String, u16>,
    /// Channel of each sample source seen; the source is kept so its address names it.
    sources: HashMap<*const SampleSource, (Arc<SampleSource>, u16)>,
    /// Wall clock minus monotonic clock (ns), to stamp records with the wall clock.
    wall_offset: i128,
    /// A sample's encoding (reused).
    buf: Vec<u8>,
    /// Since the open chunk started: cycle markers, bytes of records, and when.
    chunk_cycles: u32,
    chunk_bytes: usize,
    chunk_start: Option<Instant>,
}

impl McapSink {
    fn new(file: std::fs::File, encoding: SampleEncoding) -> anyhow::Result<McapSink> {
        let writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Lz4))
            .use_chunks(true)
            // Closed by `flush` (CHUNK_CYCLES, CHUNK_BYTES, CHUNK_AGE), which also flushes the
            // file: a chunk the writer closed by itself could wait in the buffer.
            .chunk_size(None)
            .profile("")
            .library(concat!("skillfab ", env!("CARGO_PKG_VERSION")))
            .create(std::io::BufWriter::new(file))?;
        let wall = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        Ok(McapSink {
            writer,
            encoding,
            channels: HashMap::new(),
            sources: HashMap::new(),
            wall_offset: wall - i128::from(now_ns()),
            buf: Vec::new(),
            chunk_cycles: 0,
            chunk_bytes: 0,
            chunk_start: None,
        })
    }

    fn wall(&self, mono_ns: u64) -> u64 {
        u64::try_from(i128::from(mono_ns) + self.wall_offset).unwrap_or(0)
    }

    /// The channel of a JSON record's `topic`.
    fn json_channel(&mut self, topic: &str) -> anyhow::Result<u16> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let id = self
            .writer
            .add_channel(0, topic, "json", &BTreeMap::new())?;
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    /// The channel of a sample's source, added with its schema the first time.
    fn sample_channel(&mut self, source: &Arc<SampleSource>) -> anyhow::Result<u16> {
        if let Some((_, id)) = self.sources.get(&Arc::as_ptr(source)) {
            return Ok(*id);
        }
        let topic = source.channel();
        let id = match self.channels.get(&topic) {
            Some(&id) => id,
            None => {
                let m = &source.schema;
                let id = match self.encoding {
                    SampleEncoding::Cdr => {
                        let schema_id = self.writer.add_schema(
                            &skillfab_proto::ros2msg::schema_name(&m.type_name),
                            "ros2msg",
                            skillfab_proto::ros2msg::schema_text(m).as_bytes(),
                        )?;
                        let metadata = BTreeMap::from([
                            ("skill".to_string(), source.skill.clone()),
                            ("dir".to_string(), source.dir.to_string()),
                            ("port".to_string(), source.port.clone()),
                            ("topic".to_string(), source.topic.clone()),
                            ("type".to_string(), m.type_name.clone()),
                            ("schema".to_string(), serde_json::to_string(m)?),
                            ("clock_offset_ns".to_string(), self.wall_offset.to_string()),
                        ]);
                        self.writer
                            .add_channel(schema_id, &topic, "cdr", &metadata)?
                    }
                    SampleEncoding::Json => {
                        let schema = sample_schema(&source.schema);
                        let schema_id = self.writer.add_schema(
                            &m.type_name,
                            "jsonschema",
                            schema.to_string().as_bytes(),
                        )?;
                        self.writer
                            .add_channel(schema_id, &topic, "json", &BTreeMap::new())?
                    }
                };
                self.channels.insert(topic, id);
                id
            }
        };
        self.sources
            .insert(Arc::as_ptr(source), (source.clone(), id));
        Ok(id)
    }

    fn put(&mut self, r: Record) -> anyhow::Result<()> {
        let now = now_ns();
        let (channel_id, sequence, stamp) = match &r {
            Record::Line(j) => {
                let kind = j["kind"].as_str().unwrap_or("record");
                if kind == "cycle" {
                    self.chunk_cycles += 1;
                }
                let id = self.json_channel(&format!("/skillfab/{kind}"))?;
                (id, j["cycle"].as_u64().unwrap_or(0), None)
            }
            Record::Sample(s) => (self.sample_channel(&s.source)?, s.cycle, Some(s.stamp_ns)),
        };
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        match r {
            Record::Line(j) => serde_json::to_writer(&mut buf, &j)?,
            Record::Sample(s) => match self.encoding {
                SampleEncoding::Cdr => {
                    skillfab_proto::cdr::encode(&s.source.schema, &s.bytes, &mut buf)
                }
                SampleEncoding::Json => serde_json::to_writer(
                    &mut buf,
                    &sample_json(s.cycle, now, s.stamp_ns, &s.source, &s.bytes),
                )?,
            },
        }
        let header = mcap::records::MessageHeader {
            channel_id,
            // (As a JSON record's `cycle`: u32 lasts 497 days at 100 Hz.)
            sequence: sequence as u32,
            log_time: self.wall(now),
            publish_time: self.wall(stamp.unwrap_or(now)),
        };
        self.chunk_start.get_or_insert_with(Instant::now);
        self.chunk_bytes += buf.len();
        let written = self.writer.write_to_known_channel(&header, &buf);
        self.buf = buf;
        written?;
        Ok(())
    }

    /// Closes the open chunk and flushes the file if the chunk is due (or `now`).
    fn flush(&mut self, now: bool) -> anyhow::Result<()> {
        let Some(start) = self.chunk_start else {
            return Ok(());
        };
        if now
            || self.chunk_cycles >= CHUNK_CYCLES
            || self.chunk_bytes >= CHUNK_BYTES
            || start.elapsed() >= CHUNK_AGE
        {
            self.writer.flush()?;
            self.chunk_cycles = 0;
            self.chunk_bytes = 0;
            self.chunk_start = None;
        }
        Ok(())
    }
}

/// JSON Schema of a sample record, its `value` described by the message schema.
fn sample_schema(m: &MessageSchema) -> Json {
    let value = kind_schema(&skillfab_proto::schema::FieldKind::Struct(m.clone()));
    json!({
        "title": m.type_name,
        "type": "object",
        "properties": {
            "kind": {"type": "string"}, "cycle": {"type": "integer"},
            "time_ns": {"type": "integer"}, "stamp_ns": {"type": "integer"},
            "skill": {"type": "string"}, "dir": {"type": "string"},
            "port": {"type": "string"}, "topic": {"type": "string"},
            "type": {"type": "string"}, "value": value,
            "raw": {"type": "string", "description": "the sample's bytes, hex"},
        }
    })
}

fn kind_schema(kind: &skillfab_proto::schema::FieldKind) -> Json {
    use skillfab_proto::schema::{FieldKind, Prim};
    match kind {
        FieldKind::Prim(Prim::Bool) => json!({"type": "boolean"}),
        FieldKind::Prim(Prim::F32 | Prim::F64) => json!({"type": "number"}),
        FieldKind::Prim(_) => json!({"type": "integer"}),
        FieldKind::Array { elem, len } => json!({
            "type": "array", "items": kind_schema(elem), "minItems": len, "maxItems": len,
        }),
        FieldKind::Struct(m) => {
            let props: serde_json::Map<String, Json> = m
                .fields
                .iter()
                .map(|f| (f.name.clone(), kind_schema(&f.ty)))
                .collect();
            json!({"type": "object", "title": m.type_name, "description": m.doc,
                   "properties": props})
        }
    }
}

impl Sink {
    fn create(path: &Path, encoding: SampleEncoding) -> anyhow::Result<Sink> {
        Ok(if is_mcap(path) {
            // An MCAP file has one header and one footer: a new file each time.
            Sink::Mcap(Box::new(McapSink::new(
                std::fs::File::create(path)?,
                encoding,
            )?))
        } else {
            let file = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(path)?;
            Sink::Lines(std::io::BufWriter::new(file))
        })
    }
}

fn write_loop(path: &Path, encoding: SampleEncoding, rx: &Receiver<Record>) {
    let mut failed = false;
    let mut report = |e: anyhow::Error| {
        if !failed {
            failed = true;
            tracing::warn!(file = %path.display(), error = %e, "fabric log write failed");
        }
    };
    let mut sink: Option<Sink> = None;
    let mut start: Option<Json> = None;
    // Block for the first record (an open chunk is closed once it is old enough), then take
    // whatever else is queued, then flush.
    loop {
        let first = match rx.recv_timeout(CHUNK_AGE) {
            Ok(r) => r,
            Err(RecvTimeoutError::Timeout) => {
                if let Some(Err(e)) = sink.as_mut().map(|s| s.flush(true)) {
                    report(e);
                }
                continue;
            }
            Err(RecvTimeoutError::Disconnected) => break,
        };
        let mut next = Some(first);
        while let Some(r) = next {
            next = rx.try_recv().ok();
            if sink.is_none() {
                if let Record::Line(j) = &r
                    && j["kind"] == "start"
                {
                    start = Some(j.clone());
                    continue;
                }
                match Sink::create(path, encoding) {
                    Ok(s) => sink = Some(s),
                    Err(e) => {
                        report(e);
                        continue;
                    }
                }
            }
            let Some(s) = sink.as_mut() else { continue };
            if let Some(j) = start.take()
                && let Err(e) = s.put(Record::Line(j))
            {
                report(e);
            }
            if let Err(e) = s.put(r) {
                report(e);
            }
        }
        if let Some(Err(e)) = sink.as_mut().map(|s| s.flush(false)) {
            report(e);
        }
    }
    if let Some(Err(e)) = sink.map(Sink::finish) {
        report(e);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh scratch directory of this test process, removed when dropped (even on failure).
    struct Scratch(PathBuf);

    impl Scratch {
        fn new(tag: &str) -> Scratch {
            let dir =
                std::env::temp_dir().join(format!("sf-recorder-{tag}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            Scratch(dir)
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn a_log_with_nothing_but_its_start_leaves_no_file() {
        let dir = Scratch::new("empty");
        let path = dir.0.join("log.jsonl");
        {
            let r = Recorder::open(&path).unwrap();
            r.line("start", None, json!({"domain": "d"}));
        }
        assert!(!path.exists());
        {
            let r = Recorder::open(&path).unwrap();
            r.line("start", None, json!({"domain": "d"}));
            r.line(
                "priority",
                Some(3),
                json!({"skill": "a", "old": 0, "new": 1}),
            );
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let kinds: Vec<String> = text
            .lines()
            .map(|l| serde_json::from_str::<Json>(l).unwrap()["kind"].to_string())
            .collect();
        assert_eq!(kinds, ["\"start\"", "\"priority\""]);
    }

    #[test]
    fn lines_are_json_with_common_fields() {
        let dir = Scratch::new("lines");
        let path = dir.0.join("log.jsonl");
        {
            let r = Recorder::open(&path).unwrap();
            r.param(
                7,
                "scale",
                "gain",
                ParamValue::Float(2.0),
                ParamValue::Float(3.0),
                "1-0",
            );
            r.line(
                "priority",
                Some(8),
                json!({"skill": "avoid", "old": 1, "new": 2}),
            );
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<Json> = text
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(lines.len(), 2);
        assert_eq!(lines[0]["kind"], "param");
        assert_eq!(lines[0]["cycle"], 7);
        assert_eq!(lines[0]["old"], 2.0);
        assert_eq!(lines[0]["new"], 3.0);
        assert_eq!(lines[0]["by"], "1-0");
        assert!(lines[0]["unix_ms"].as_u64().unwrap() > 0);
        assert_eq!(lines[1]["kind"], "priority");
    }

    fn scaled_source(raw: bool) -> Arc<SampleSource> {
        use skillfab_proto::schema::{FieldKind, FieldSchema, Prim};
        let schema = MessageSchema {
            type_name: "skillfab.Scaled".into(),
            doc: "a scaled tick".into(),
            size: 8,
            align: 8,
            fields: vec![FieldSchema {
                name: "value".into(),
                offset: 0,
                ty: FieldKind::Prim(Prim::F64),
            }],
        };
        Arc::new(SampleSource::new("scale", "out", "scaled", "scaled", &schema, raw).unwrap())
    }

    fn scaled_sample(source: &Arc<SampleSource>, cycle: u64, value: f64) -> IoSample {
        IoSample {
            cycle,
            stamp_ns: now_ns(),
            source: source.clone(),
            bytes: value.to_ne_bytes().to_vec(),
        }
    }

    /// Writes a parameter change and two samples (one a NaN) to `path`.
    fn write_some(path: &Path, encoding: SampleEncoding) -> u64 {
        let r = Recorder::open_with(path, encoding).unwrap();
        r.param(
            7,
            "scale",
            "gain",
            ParamValue::Float(2.0),
            ParamValue::Float(3.0),
            "1-0",
        );
        let source = scaled_source(encoding == SampleEncoding::Json);
        let s = scaled_sample(&source, 8, 6.0);
        let stamp = s.stamp_ns;
        r.sample(s);
        r.sample(scaled_sample(&source, 9, f64::NAN));
        stamp
    }

    #[test]
    fn an_mcap_log_holds_cdr_samples_on_channels_with_ros_schemas_and_reads_back() {
        let dir = Scratch::new("mcap");
        let path = dir.0.join("log.mcap");
        let stamp = write_some(&path, SampleEncoding::Cdr);
        let bytes = std::fs::read(&path).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert!(!summary.chunk_indexes.is_empty(), "chunked and indexed");
        assert!(
            summary.chunk_indexes.iter().all(|c| c.compression == "lz4"),
            "compressed"
        );
        let mut topics = Vec::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            topics.push((m.channel.topic.clone(), m.sequence));
            if m.channel.topic == "/scale/out/scaled" {
                assert_eq!(m.channel.message_encoding, "cdr");
                let schema = m
                    .channel
                    .schema
                    .as_ref()
                    .expect("a sample channel has a schema");
                assert_eq!(schema.encoding, "ros2msg");
                assert_eq!(schema.name, "skillfab/msg/Scaled");
                assert_eq!(&schema.data[..], b"float64 value\n");
                assert_eq!(m.channel.metadata["skill"], "scale");
                assert_eq!(m.data.len(), 4 + 8);
                // Wall-clock nanoseconds (after 2020), not the monotonic clock.
                assert!(m.log_time > 1_600_000_000_000_000_000, "{}", m.log_time);
            } else {
                assert_eq!(m.channel.message_encoding, "json");
            }
        }
        assert_eq!(
            topics,
            vec![
                ("/skillfab/param".to_string(), 7),
                ("/scale/out/scaled".to_string(), 8),
                ("/scale/out/scaled".to_string(), 9),
            ]
        );
        let mut samples = Vec::new();
        read_file(&path, |r| {
            if let ReadRecord::Sample(s) = r {
                samples.push(s);
            }
        })
        .unwrap();
        assert_eq!(samples.len(), 2);
        assert_eq!((samples[0].cycle, samples[0].stamp_ns), (8, stamp));
        assert_eq!(samples[0].bytes, 6.0f64.to_ne_bytes());
        assert_eq!(samples[1].bytes, f64::NAN.to_ne_bytes(), "NaN's bits");
        assert_eq!(samples[1].channel.port, "scaled");
        // The same records as the JSON-lines file would hold.
        let text = read_records(&path).unwrap();
        let lines: Vec<Json> = text
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(lines[0]["kind"], "param");
        assert_eq!(lines[0]["new"], 3.0);
        assert_eq!(lines[1]["kind"], "sample");
        assert_eq!(lines[1]["value"]["value"], 6.0);
        assert_eq!(lines[1]["raw"], hex(&6.0f64.to_ne_bytes()));

        // Cut short as if the manager had been killed: the records before the cut are read.
        let cut = dir.0.join("cut.mcap");
        std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).unwrap();
        assert!(read_records(&cut).is_ok());
        std::fs::write(&cut, b"not an mcap file").unwrap();
        assert!(read_records(&cut).is_err());
    }

    #[test]
    fn the_json_option_writes_samples_as_json_records() {
        let dir = Scratch::new("mcapjson");
        let path = dir.0.join("log.mcap");
        write_some(&path, SampleEncoding::Json);
        let bytes = std::fs::read(&path).unwrap();
        let mut n = 0;
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            assert_eq!(m.channel.message_encoding, "json");
            if m.channel.topic == "/scale/out/scaled" {
                let schema = m.channel.schema.as_ref().unwrap();
                assert_eq!(schema.encoding, "jsonschema");
                let j: Json = serde_json::from_slice(&m.data).unwrap();
                assert_eq!(j["cycle"], m.sequence);
                assert!(j["raw"].is_string(), "{j}");
                n += 1;
            }
        }
        assert_eq!(n, 2);
    }

    #[test]
    fn closed_chunks_are_on_disk_while_the_recorder_writes() {
        let dir = Scratch::new("chunks");
        let path = dir.0.join("run.mcap");
        let r = Recorder::open(&path).unwrap();
        let source = scaled_source(false);
        for k in 1..=u64::from(CHUNK_CYCLES) * 2 + 10 {
            r.sample(scaled_sample(&source, k, k as f64));
            r.line("cycle", Some(k), json!({}));
        }
        // Two chunks closed; what a reader of the file as it is sees, while the recorder
        // still runs (no summary yet).
        let deadline = Instant::now() + Duration::from_secs(30);
        let complete = || {
            let mut last = 0;
            let _ = read_file(&path, |rec| {
                if let ReadRecord::Json(j) = rec
                    && j["kind"] == "cycle"
                {
                    last = j["cycle"].as_u64().unwrap_or(0);
                }
            });
            last
        };
        while complete() < u64::from(CHUNK_CYCLES) * 2 {
            assert!(Instant::now() < deadline, "two chunks on disk");
            std::thread::yield_now();
        }
        drop(r);
        assert_eq!(complete(), u64::from(CHUNK_CYCLES) * 2 + 10);
    }
}
