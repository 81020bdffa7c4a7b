//! Reading a fabric log or a recording back: JSON lines, or MCAP with JSON records and CDR
//! samples (decoded to their bytes through the schema in their channel's metadata).

use super::{hex, is_mcap};
use serde_json::{Value as Json, json};
use skillfab_proto::schema::MessageSchema;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::Arc;

/// A CDR sample channel of an MCAP file, as its metadata describes it.
#[derive(Debug)]
pub struct SampleChannel {
    /// The skill that published (`out`, `cmd`) or read (`in`) it.
    pub skill: String,
    /// `in`, `out` or `cmd`.
    pub dir: String,
    /// The skill's port.
    pub port: String,
    /// The topic it travelled on.
    pub topic: String,
    /// The message layout the samples had.
    pub schema: MessageSchema,
    /// Wall clock minus monotonic clock when the file was written (ns): a sample's stamp is
    /// its `publish_time` minus this.
    pub clock_offset_ns: i128,
}

impl SampleChannel {
    fn from_metadata(topic: &str, meta: &BTreeMap<String, String>) -> anyhow::Result<Self> {
        use anyhow::Context;
        let get = |k: &str| {
            meta.get(k).cloned().with_context(|| {
                format!(
                    "CDR channel {topic} has no '{k}' in its metadata: not a skillfab recording"
                )
            })
        };
        Ok(SampleChannel {
            skill: get("skill")?,
            dir: get("dir")?,
            port: get("port")?,
            topic: get("topic")?,
            schema: serde_json::from_str(&get("schema")?).with_context(|| {
                format!("CDR channel {topic}: its 'schema' is not a message schema")
            })?,
            clock_offset_ns: get("clock_offset_ns")?
                .parse()
                .with_context(|| format!("CDR channel {topic}: a bad 'clock_offset_ns'"))?,
        })
    }
}

/// A sample of an MCAP file's CDR channel, its bytes decoded back through its schema.
#[derive(Debug)]
pub struct ReadSample {
    /// The cycle (the message's `sequence`).
    pub cycle: u64,
    /// The producer's stamp (monotonic clock, ns).
    pub stamp_ns: u64,
    /// Its channel.
    pub channel: Arc<SampleChannel>,
    /// The repr(C) bytes, padding zeroed.
    pub bytes: Vec<u8>,
}

/// One record of a fabric log or recording.
#[derive(Debug)]
pub enum ReadRecord {
    /// A JSON record (a JSON-lines file's lines; an MCAP file's `json` messages, a JSON
    /// sample among them).
    Json(Json),
    /// A CDR sample.
    Sample(ReadSample),
}

impl ReadSample {
    /// As the JSON record a JSON-encoded recording holds (`value`, `raw`).
    pub fn to_json(&self) -> Json {
        let c = &self.channel;
        let value = skillfab_proto::value::resolve(&c.schema, "")
            .ok()
            .and_then(|f| f.read(&self.bytes))
            .map_or(Json::Null, |v| skillfab_proto::json::value_json(&v));
        json!({"kind": "sample", "cycle": self.cycle, "skill": c.skill, "dir": c.dir,
               "port": c.port, "topic": c.topic, "type": c.schema.type_name,
               "stamp_ns": self.stamp_ns, "value": value, "raw": hex(&self.bytes)})
    }
}

/// Reads every record of a fabric log or recording (JSON lines or MCAP, its samples in CDR or
/// JSON) in order, handing each to `each`. An MCAP file whose writer was killed gives the
/// records of its closed chunks.
pub fn read_file(path: &Path, mut each: impl FnMut(ReadRecord)) -> anyhow::Result<()> {
    use anyhow::Context;
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    if !is_mcap(path) {
        let text = std::str::from_utf8(&bytes)
            .with_context(|| format!("{} is not text", path.display()))?;
        for (n, line) in text.lines().enumerate() {
            let j = serde_json::from_str(line)
                .with_context(|| format!("{}:{}: not JSON", path.display(), n + 1))?;
            each(ReadRecord::Json(j));
        }
        return Ok(());
    }
    let stream =
        mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
            .with_context(|| format!("{} is not an MCAP file", path.display()))?;
    let mut channels: HashMap<u16, Arc<SampleChannel>> = HashMap::new();
    let mut any = false;
    for m in stream {
        let m = match m {
            Ok(m) => m,
            // A file cut short (the manager was killed): the records before are good.
            Err(e) if any => {
                tracing::warn!(file = %path.display(), error = %e, "MCAP file ends early");
                break;
            }
            Err(e) => {
                return Err(e).with_context(|| format!("reading MCAP file {}", path.display()));
            }
        };
        any = true;
        let topic = &m.channel.topic;
        match m.channel.message_encoding.as_str() {
            "json" => {
                let j = serde_json::from_slice(&m.data).with_context(|| {
                    format!("{}: a message on {topic} is not JSON", path.display())
                })?;
                each(ReadRecord::Json(j));
            }
            "cdr" => {
                let channel = match channels.get(&m.channel.id) {
                    Some(c) => c.clone(),
                    None => {
                        let c = Arc::new(
                            SampleChannel::from_metadata(topic, &m.channel.metadata)
                                .with_context(|| path.display().to_string())?,
                        );
                        channels.insert(m.channel.id, c.clone());
                        c
                    }
                };
                let bytes =
                    skillfab_proto::cdr::decode(&channel.schema, &m.data).with_context(|| {
                        format!(
                            "{}: the sample of cycle {} on {topic}",
                            path.display(),
                            m.sequence
                        )
                    })?;
                let stamp = i128::from(m.publish_time) - channel.clock_offset_ns;
                each(ReadRecord::Sample(ReadSample {
                    cycle: u64::from(m.sequence),
                    stamp_ns: u64::try_from(stamp).unwrap_or(0),
                    channel,
                    bytes,
                }));
            }
            other => anyhow::bail!(
                "{}: channel {topic} is encoded '{other}', not json or cdr: not a skillfab file",
                path.display()
            ),
        }
    }
    Ok(())
}

/// The records of a fabric log file (JSON lines or MCAP), as JSON-lines text (a CDR sample as
/// the JSON record [`ReadSample::to_json`] gives). An MCAP file whose writer was killed gives
/// the records written before.
pub fn read_records(path: &Path) -> anyhow::Result<String> {
    let mut out = String::new();
    read_file(path, |r| {
        let j = match r {
            ReadRecord::Json(j) => j,
            ReadRecord::Sample(s) => s.to_json(),
        };
        out.push_str(&j.to_string());
        out.push('\n');
    })?;
    Ok(out)
}
