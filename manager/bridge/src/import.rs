//! Imports: topics of a remote domain republished here as the outputs of an async skill (the
//! bridge's own instance), so local skills read them as they read any async producer — the
//! latest sample and its age; the cycle never waits for the network. A sample is published as
//! it arrives (the Zenoh thread wakes the skill), not at the next cycle.

use crate::figures::{Arrival, Refusal, TopicFigures};
use crate::{BridgeError, zenoh_error};
use skill_sdk::foreign::ForeignSkill;
use skill_sdk::prelude::Mode;
use skillfab_proto::bridge::{SampleMeta, unix_now_ns};
use skillfab_proto::control::SkillInfo;
use skillfab_proto::names;
use skillfab_proto::schema::MessageSchema;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::Wait;

/// An imported topic whose remote schema is known.
pub(crate) struct Import {
    /// The topic, here and there.
    pub(crate) topic: String,
    /// The remote domain.
    pub(crate) from: String,
    /// Its message type, as the exporter declared it.
    pub(crate) schema: MessageSchema,
}

/// The remote schema of `topic`, asked of the bridge that exports it (`None`: no exporter
/// answered in `timeout`).
pub(crate) fn remote_schema(
    session: &zenoh::Session,
    from: &str,
    topic: &str,
    timeout: Duration,
) -> Result<Option<MessageSchema>, BridgeError> {
    let replies = session
        .get(names::remote_schema(from, topic))
        .timeout(timeout)
        .wait()
        .map_err(|e| zenoh_error("schema query", e))?;
    while let Ok(reply) = replies.recv() {
        if let Ok(sample) = reply.result() {
            return postcard::from_bytes(&sample.payload().to_bytes())
                .map(Some)
                .map_err(|e| {
                    BridgeError::Remote(format!(
                        "cannot import '{topic}' from domain '{from}': its exporter's schema is \
                         unreadable ({e}; another skillfab version?)"
                    ))
                });
        }
    }
    Ok(None)
}

fn describe(s: &MessageSchema) -> String {
    format!("{} ({} B, align {})", s.type_name, s.size, s.align)
}

/// Why a topic can never be imported: an actuator channel's proposals and commands are
/// arbitrated within one cycle of one manager — a sync input no remote producer can feed.
pub(crate) fn never_importable(topic: &str, from: &str) -> Option<String> {
    topic.starts_with("channel/").then(|| {
        format!(
            "cannot import '{topic}' from domain '{from}': actuator proposals and commands are \
             arbitrated within one cycle of one manager, and a remote producer cannot feed a \
             sync input (run the proposing skill on this host, its manager's)"
        )
    })
}

/// Why `import` cannot be republished here, if it cannot: a topic a local skill produces, or
/// one a local skill declares with another type (both sides named).
pub(crate) fn refusal(import: &Import, skills: &[SkillInfo], bridge: &str) -> Option<String> {
    let topic = &import.topic;
    if let Some(why) = unsound(&import.schema) {
        return Some(format!(
            "cannot import '{topic}' from domain '{}': its exporter declares {}: {why}",
            import.from,
            describe(&import.schema)
        ));
    }
    for s in skills.iter().filter(|s| s.name != bridge) {
        if let Some(o) = s.outputs.iter().find(|o| o.topic == *topic) {
            return Some(format!(
                "cannot import '{topic}' from domain '{}': skill '{}' output '{}' produces it here",
                import.from, s.name, o.port
            ));
        }
        if let Some(i) = s
            .inputs
            .iter()
            .find(|i| i.topic == *topic && i.type_name != import.schema.type_name)
        {
            return Some(format!(
                "type mismatch on imported topic '{topic}': domain '{}' exports {}, but skill \
                 '{}' input '{}' here is '{}'",
                import.from,
                describe(&import.schema),
                s.name,
                i.port,
                i.type_name
            ));
        }
    }
    None
}

/// The largest sample an import takes (a shared-memory sample of this size is set aside per
/// imported topic).
const MAX_IMPORT_SIZE: u32 = 256 << 20;

/// What is wrong with a remote schema no local publisher could be made for.
fn unsound(s: &MessageSchema) -> Option<&'static str> {
    if !s.align.is_power_of_two() || s.align > 4096 {
        Some("its alignment is not a power of two up to 4096")
    } else if !s.size.is_multiple_of(s.align) {
        Some("its size is not a multiple of its alignment")
    } else if s.size > MAX_IMPORT_SIZE {
        Some("it is larger than the 256 MiB an import takes")
    } else {
        None
    }
}

/// The newest sample of each import not yet republished.
type Pending = Arc<Mutex<Vec<Option<(Vec<u8>, SampleMeta)>>>>;

/// Declares the bridge's skill with one output per import, subscribes to each remote topic
/// and runs the skill until SIGINT/SIGTERM. `skill_args` are the usual skill options
/// (`--name`, `--domain`).
pub(crate) fn serve(
    session: &zenoh::Session,
    imports: &[Import],
    figures: &[TopicFigures],
    mut skill_args: Vec<String>,
) -> Result<(), BridgeError> {
    let mut skill = ForeignSkill::new("skillfab-bridge", Mode::Async, &[])?;
    for (i, import) in imports.iter().enumerate() {
        // The port is named after the topic (`ctl query bridge.sonar`); a topic's `/` is not
        // allowed in a port name.
        let mut port = import.topic.replace('/', "_");
        if skill.outputs().iter().any(|p| p.port == port) {
            port = format!("{port}_{i}");
        }
        skill.output_schema(&port, import.schema.clone())?;
        skill_args.extend(["--remap".to_string(), format!("{port}={}", import.topic)]);
    }
    let pending: Pending = Arc::new(Mutex::new(vec![None; imports.len()]));
    let waker = skill.waker();
    // The subscribers live as long as the skill runs.
    let mut subscribers = Vec::new();
    for (i, import) in imports.iter().enumerate() {
        let (pending, waker, fig) = (pending.clone(), waker.clone(), figures[i].clone());
        let (size, align) = (import.schema.size, import.schema.align);
        let topic = import.topic.clone();
        let told = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let sub = session
            .declare_subscriber(names::remote_topic(&import.from, &import.topic))
            .callback(move |s| {
                let meta = s
                    .attachment()
                    .and_then(|a| SampleMeta::decode(&a.to_bytes()).ok());
                let bytes = s.payload().to_bytes();
                let meta = match (fig.arrived(meta.as_ref(), bytes.len(), size, align), meta) {
                    (Arrival::Taken { .. }, Some(meta)) => meta,
                    (Arrival::Refused(why), _) => return refuse(&told, &topic, &why),
                    // Not reached: a sample without its attachment is refused.
                    (Arrival::Taken { .. }, None) => return,
                };
                if let Ok(mut p) = pending.lock() {
                    p[i] = Some((bytes.into_owned(), meta));
                }
                waker.wake();
            })
            .wait()
            .map_err(|e| zenoh_error("subscriber", e))?;
        subscribers.push(sub);
        tracing::info!(topic = %import.topic, from = %import.from, r#type = %import.schema.type_name, "importing");
    }
    let figures = figures.to_vec();
    skill.compute(Box::new(move |run| {
        let taken: Vec<_> = match pending.lock() {
            Ok(mut p) => p.iter_mut().map(Option::take).collect(),
            Err(_) => return Ok(()),
        };
        for (i, sample) in taken.into_iter().enumerate() {
            let Some((bytes, meta)) = sample else {
                continue;
            };
            if let Some(out) = run.output(i, false) {
                out.copy_from_slice(&bytes);
                let now = unix_now_ns();
                figures[i].delivered(now.saturating_sub(meta.sent_unix_ns) as f64 / 1000.0);
            }
        }
        Ok(())
    }));
    skill_sdk::foreign::run(skill, skill_args)?;
    drop(subscribers);
    Ok(())
}

/// A sample that cannot be republished here: dropped, counted (`ctl stats`), said once per
/// topic.
fn refuse(told: &std::sync::atomic::AtomicBool, topic: &str, why: &Refusal) {
    if !told.swap(true, std::sync::atomic::Ordering::Relaxed) {
        tracing::error!(
            topic,
            "remote sample refused: {why} (counted from now on, said once)"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn import(size: u32, align: u32) -> Import {
        Import {
            topic: "tick".into(),
            from: "far".into(),
            schema: MessageSchema {
                type_name: "far.Odd".into(),
                doc: String::new(),
                size,
                align,
                fields: Vec::new(),
            },
        }
    }

    #[test]
    fn a_remote_schema_no_publisher_could_take_is_refused_with_why() {
        assert_eq!(refusal(&import(8, 8), &[], "bridge"), None);
        let why = refusal(&import(8, 3), &[], "bridge").unwrap_or_default();
        assert!(
            why.contains("cannot import 'tick' from domain 'far'")
                && why.contains("far.Odd (8 B, align 3)")
                && why.contains("not a power of two"),
            "{why}"
        );
        assert!(refusal(&import(12, 8), &[], "bridge").is_some());
        assert!(refusal(&import(512 << 20, 8), &[], "bridge").is_some());
    }

    #[test]
    fn an_actuator_channel_is_never_importable() {
        let why = never_importable("channel/drive", "far").unwrap_or_default();
        assert!(why.contains("sync input"), "{why}");
        assert_eq!(never_importable("sonar", "far"), None);
    }
}
