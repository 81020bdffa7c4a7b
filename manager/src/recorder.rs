//! The fabric log: every parameter and priority change, and — for the skills it is turned on
//! for (`ctl iolog S on`, `l` in the console) — every input and output sample, appended to
//! one JSON-lines file.
//!
//! The manager hands records to a writer thread over a channel, so a slow disk never holds up
//! a cycle; samples are copied out as bytes and decoded through their schema on that thread.
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
//! (what Foxglove and rosbag2 users open): one channel per logged port,
//! `/<skill>/<in|out>/<port>`, with a JSON Schema made from the message schema, and one per
//! other kind, `/skillfab/<kind>`; message encoding `json`, each message the record above;
//! `log_time` is the wall clock of the record, `publish_time` the sample's stamp, `sequence`
//! the cycle. The file is written unchunked and flushed with every batch, so a manager that is
//! killed leaves every record written so far readable (only the summary at the end is
//! missing).

use serde_json::{Value as Json, json};
use skillfab_proto::header::now_ns;
use skillfab_proto::json::param_json;
use skillfab_proto::param::ParamValue;
use skillfab_proto::value::FieldPath;
use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;

/// One sample copied out of a topic, decoded on the writer thread.
pub(crate) struct IoSample {
    pub(crate) cycle: u64,
    pub(crate) skill: String,
    /// `in` or `out`.
    pub(crate) dir: &'static str,
    pub(crate) port: String,
    pub(crate) topic: String,
    pub(crate) type_name: String,
    pub(crate) stamp_ns: u64,
    pub(crate) field: Arc<FieldPath>,
    pub(crate) bytes: Vec<u8>,
    /// Also keep the bytes themselves (`raw`, hex): a recording replays them exactly (NaN,
    /// infinities and padding included, which JSON numbers cannot carry).
    pub(crate) raw: bool,
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
    /// Starts the writer thread of `path` (creating its directory). The file itself is
    /// created with the first record other than `start`, which is kept until then: a manager
    /// whose parameters nobody touched leaves no file. A `.jsonl` file is appended to; an
    /// `.mcap` file is created anew.
    pub fn open(path: &Path) -> std::io::Result<Recorder> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)?;
        }
        let (tx, rx) = channel();
        let target = path.to_path_buf();
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || write_loop(&target, &rx))?;
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

fn sample_json(s: &IoSample) -> Json {
    let value = s
        .field
        .read(&s.bytes)
        .map_or(Json::Null, |v| skillfab_proto::json::value_json(&v));
    let mut j = json!({"kind": "sample", "cycle": s.cycle, "time_ns": now_ns(), "skill": s.skill,
           "dir": s.dir, "port": s.port, "topic": s.topic, "type": s.type_name,
           "stamp_ns": s.stamp_ns, "value": value});
    if s.raw {
        j["raw"] = json!(hex(&s.bytes));
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
                    Record::Sample(s) => sample_json(&s),
                };
                writeln!(out, "{j}")?;
            }
            Sink::Mcap(m) => m.put(r)?,
        }
        Ok(())
    }

    fn flush(&mut self) -> anyhow::Result<()> {
        match self {
            Sink::Lines(out) => out.flush()?,
            Sink::Mcap(m) => m.writer.flush()?,
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
    /// Channel of each topic.
    channels: HashMap<String, u16>,
    /// Wall clock minus monotonic clock (ns), to stamp records with the wall clock.
    wall_offset: i128,
}

impl McapSink {
    fn new(file: std::fs::File) -> anyhow::Result<McapSink> {
        let writer = mcap::WriteOptions::new()
            .compression(None)
            .use_chunks(false)
            .profile("")
            .library(concat!("skillfab ", env!("CARGO_PKG_VERSION")))
            .create(std::io::BufWriter::new(file))?;
        let wall = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        Ok(McapSink {
            writer,
            channels: HashMap::new(),
            wall_offset: wall - i128::from(now_ns()),
        })
    }

    fn wall(&self, mono_ns: u64) -> u64 {
        u64::try_from(i128::from(mono_ns) + self.wall_offset).unwrap_or(0)
    }

    /// The channel of `topic`, added with `schema` (a JSON Schema) the first time.
    fn channel(&mut self, topic: &str, schema: Option<(&str, Json)>) -> anyhow::Result<u16> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let schema_id = match schema {
            Some((name, s)) => {
                self.writer
                    .add_schema(name, "jsonschema", s.to_string().as_bytes())?
            }
            None => 0,
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, "json", &BTreeMap::new())?;
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    fn put(&mut self, r: Record) -> anyhow::Result<()> {
        let (topic, schema, j, stamp) = match r {
            Record::Line(j) => {
                let kind = j["kind"].as_str().unwrap_or("record").to_string();
                (format!("/skillfab/{kind}"), None, j, None)
            }
            Record::Sample(s) => {
                let schema = sample_schema(&s);
                let j = sample_json(&s);
                let topic = format!("/{}/{}/{}", s.skill, s.dir, s.port);
                (
                    topic,
                    Some((s.type_name.clone(), schema)),
                    j,
                    Some(s.stamp_ns),
                )
            }
        };
        let channel_id = self.channel(
            &topic,
            schema.as_ref().map(|(n, s)| (n.as_str(), s.clone())),
        )?;
        let time = j["time_ns"].as_u64().unwrap_or_else(now_ns);
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: j["cycle"].as_u64().map_or(0, |c| c as u32),
            log_time: self.wall(time),
            publish_time: self.wall(stamp.unwrap_or(time)),
        };
        self.writer
            .write_to_known_channel(&header, j.to_string().as_bytes())?;
        Ok(())
    }
}

/// JSON Schema of a sample record, its `value` described by the message schema.
fn sample_schema(s: &IoSample) -> Json {
    let value = kind_schema(&s.field.kind);
    json!({
        "title": s.type_name,
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

/// The records of a fabric log file (JSON lines or MCAP), as JSON-lines text. An MCAP file
/// whose writer was killed (no summary) gives the records written before.
pub fn read_records(path: &Path) -> anyhow::Result<String> {
    use anyhow::Context;
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    if !is_mcap(path) {
        return String::from_utf8(bytes).with_context(|| format!("{} is not text", path.display()));
    }
    let mut out = String::new();
    let stream =
        mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
            .with_context(|| format!("{} is not an MCAP file", path.display()))?;
    for m in stream {
        match m {
            Ok(m) => {
                let text = std::str::from_utf8(&m.data).with_context(|| {
                    format!(
                        "{}: a message on {} is not JSON text",
                        path.display(),
                        m.channel.topic
                    )
                })?;
                out.push_str(text);
                out.push('\n');
            }
            // A file cut short (the manager was killed): the records before are good.
            Err(e) if !out.is_empty() => {
                tracing::warn!(file = %path.display(), error = %e, "MCAP file ends early");
                break;
            }
            Err(e) => {
                return Err(e).with_context(|| format!("reading MCAP file {}", path.display()));
            }
        }
    }
    Ok(out)
}

impl Sink {
    fn create(path: &Path) -> anyhow::Result<Sink> {
        Ok(if is_mcap(path) {
            // An MCAP file has one header and one footer: a new file each time.
            Sink::Mcap(Box::new(McapSink::new(std::fs::File::create(path)?)?))
        } else {
            let file = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(path)?;
            Sink::Lines(std::io::BufWriter::new(file))
        })
    }
}

fn write_loop(path: &Path, rx: &Receiver<Record>) {
    let mut failed = false;
    let mut report = |e: anyhow::Error| {
        if !failed {
            failed = true;
            tracing::warn!(file = %path.display(), error = %e, "fabric log write failed");
        }
    };
    let mut sink: Option<Sink> = None;
    let mut start: Option<Json> = None;
    // Block for the first record, then take whatever else is queued, then flush once.
    while let Ok(first) = rx.recv() {
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
                match Sink::create(path) {
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
        if let Some(Err(e)) = sink.as_mut().map(Sink::flush) {
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

    fn scaled_sample(cycle: u64, value: f64) -> IoSample {
        use skillfab_proto::schema::{FieldKind, FieldSchema, MessageSchema, Prim};
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
        IoSample {
            cycle,
            skill: "scale".into(),
            dir: "out",
            port: "scaled".into(),
            topic: "scaled".into(),
            type_name: schema.type_name.clone(),
            stamp_ns: now_ns(),
            field: Arc::new(skillfab_proto::value::resolve(&schema, "").unwrap()),
            bytes: value.to_ne_bytes().to_vec(),
            raw: false,
        }
    }

    #[test]
    fn an_mcap_log_holds_the_same_records_on_channels_with_schemas() {
        let dir = Scratch::new("mcap");
        let path = dir.0.join("log.mcap");
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
            r.sample(scaled_sample(8, 6.0));
            r.sample(scaled_sample(9, 9.0));
        }
        let bytes = std::fs::read(&path).unwrap();
        let mut topics = Vec::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            assert_eq!(m.channel.message_encoding, "json");
            topics.push((m.channel.topic.clone(), m.sequence));
            if m.channel.topic == "/scale/out/scaled" {
                let schema = m
                    .channel
                    .schema
                    .as_ref()
                    .expect("a sample channel has a schema");
                assert_eq!(schema.encoding, "jsonschema");
                let s: Json = serde_json::from_slice(&schema.data).unwrap();
                assert_eq!(
                    s["properties"]["value"]["properties"]["value"]["type"],
                    "number"
                );
                // Wall-clock nanoseconds (after 2020), not the monotonic clock.
                assert!(m.log_time > 1_600_000_000_000_000_000, "{}", m.log_time);
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
        // The same records as the JSON-lines file would hold.
        let text = read_records(&path).unwrap();
        let lines: Vec<Json> = text
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(lines[0]["kind"], "param");
        assert_eq!(lines[0]["new"], 3.0);
        assert_eq!(lines[2]["kind"], "sample");
        assert_eq!(lines[2]["value"]["value"], 9.0);

        // Cut short as if the manager had been killed: the records before the cut are read.
        let cut = dir.0.join("cut.mcap");
        std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).unwrap();
        let text = read_records(&cut).unwrap();
        assert!(text.lines().count() >= 2, "{text}");
        std::fs::write(&cut, b"not an mcap file").unwrap();
        assert!(read_records(&cut).is_err());
    }
}
