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
//! `skillfab ctl replay FILE` applies the `param` and `priority` lines of a file again, in order.

use crate::ctl::param_json;
use serde_json::{Value as Json, json};
use skill_sdk::header::now_ns;
use skill_sdk::params::ParamValue;
use skill_sdk::value::FieldPath;
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
    /// Opens `path` for appending (creating its directory) and starts the writer thread.
    pub fn open(path: &Path) -> std::io::Result<Recorder> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)?;
        }
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)?;
        let (tx, rx) = channel();
        let shown = path.display().to_string();
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || write_loop(file, &rx, &shown))?;
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

fn sample_json(s: IoSample) -> Json {
    let value = s
        .field
        .read(&s.bytes)
        .map_or(Json::Null, |v| crate::ctl::value_json(&v));
    json!({"kind": "sample", "cycle": s.cycle, "time_ns": now_ns(), "skill": s.skill,
           "dir": s.dir, "port": s.port, "topic": s.topic, "type": s.type_name,
           "stamp_ns": s.stamp_ns, "value": value})
}

fn write_loop(file: std::fs::File, rx: &Receiver<Record>, shown: &str) {
    let mut out = std::io::BufWriter::new(file);
    let mut failed = false;
    // Block for the first record, then take whatever else is queued, then flush once.
    while let Ok(first) = rx.recv() {
        let mut next = Some(first);
        while let Some(r) = next {
            let j = match r {
                Record::Line(j) => j,
                Record::Sample(s) => sample_json(s),
            };
            let res = writeln!(out, "{j}");
            if let Err(e) = res
                && !failed
            {
                failed = true;
                tracing::warn!(file = shown, error = %e, "fabric log write failed");
            }
            next = rx.try_recv().ok();
        }
        if let Err(e) = out.flush()
            && !failed
        {
            failed = true;
            tracing::warn!(file = shown, error = %e, "fabric log write failed");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_json_with_common_fields() {
        let dir = std::env::temp_dir().join(format!("sf-recorder-{}", std::process::id()));
        let path = dir.join("log.jsonl");
        let _ = std::fs::remove_file(&path);
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
        let _ = std::fs::remove_dir_all(&dir);
    }
}
