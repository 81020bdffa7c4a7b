//! Exports: every sample of a local topic this reader sees (its queue holds the two newest,
//! as every reader's in the fabric), put on Zenoh as it is published, under
//! `skillfab/<domain>/topic/<topic>` with a [`SampleMeta`] attachment; the topic's whole
//! message schema answered by a queryable beside it.

use crate::figures::TopicFigures;
use crate::{BridgeError, Stop, zenoh_error};
use skillfab_client::{Client, ClientError};
use skillfab_proto::bridge::{SampleMeta, unix_now_ns};
use skillfab_proto::control::ControlError;
use skillfab_proto::domain::Domain;
use skillfab_proto::names;
use skillfab_proto::schema::MessageSchema;
use skillfab_proto::services::{self, RawReader};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// How often an exporter looks for the end of the process while no sample comes.
const IDLE: Duration = Duration::from_millis(200);

/// How long an exporter waits before asking again for a topic no local skill declares yet.
const SCHEMA_WAIT: Duration = Duration::from_secs(2);

/// The message type of `topic` as the domain's skills declare it (its producer first), once
/// one of them has registered (`None`: asked to stop first).
fn local_schema(
    domain: &Domain,
    topic: &str,
    stop: &Stop,
) -> Result<Option<MessageSchema>, BridgeError> {
    let mut told = false;
    while !stop.is_set() {
        // A manager that is away (restarting) is waited for like a topic not declared yet.
        match Client::connect(domain).and_then(|c| c.topic_schema(topic)) {
            Ok(s) => return Ok(Some(s)),
            Err(
                ClientError::Refused(ControlError::UnknownTopic(_)) | ClientError::NoManager(_),
            ) => {}
            Err(e) => return Err(e.into()),
        }
        if !told {
            tracing::info!(topic, "waiting for a local skill that declares the topic");
            told = true;
        }
        let waited = Instant::now();
        while !stop.is_set() && waited.elapsed() < SCHEMA_WAIT {
            std::thread::sleep(IDLE);
        }
    }
    Ok(None)
}

/// Carries the samples of `topic` to Zenoh until the bridge stops, once a local skill has
/// declared it (its type is then `figures`' type).
pub(crate) fn serve(
    session: &zenoh::Session,
    domain: &Domain,
    bridge: &str,
    topic: &str,
    figures: &TopicFigures,
    stop: &Stop,
) -> Result<(), BridgeError> {
    let Some(schema) = local_schema(domain, topic, stop)? else {
        return Ok(());
    };
    figures.set_type(&schema.type_name);
    let node = services::node(
        domain,
        &format!("{bridge}-export-{}", topic.replace('/', "-")),
    )?;
    let mut reader = RawReader::open(&node, topic, &schema)?;
    let listener = services::listener(&node, &names::topic(topic))?;
    let encoded_schema = postcard::to_allocvec(&schema).map_err(skillfab_proto::Error::from)?;
    let schema_key = names::remote_schema(domain.name(), topic);
    // Answered while this export runs: an export that failed is not offered any more.
    let _queryable = session
        .declare_queryable(schema_key.clone())
        .callback(move |q| {
            if let Err(e) = q.reply(schema_key.clone(), encoded_schema.clone()).wait() {
                tracing::warn!(error = %e, "schema reply failed");
            }
        })
        .wait()
        .map_err(|e| zenoh_error("schema queryable", e))?;
    // Samples wait for a slow link rather than vanish on the wire; what the link loses the
    // far side counts (gaps in `seq`).
    let publisher = session
        .declare_publisher(names::remote_topic(domain.name(), topic))
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .express(true)
        .wait()
        .map_err(|e| zenoh_error("publisher", e))?;
    let mut seq = 0u64;
    tracing::info!(topic, r#type = %schema.type_name, "exporting");
    let (mut wait_failing, mut put_failing) = (false, false);
    while !stop.is_set() {
        match listener.timed_wait(|_| {}, IDLE) {
            Ok(_) => wait_failing = false,
            Err(e) => {
                // Not woken: the samples are still read at each IDLE.
                crate::warn_once(&mut wait_failing, "topic event not waited for", &e);
                std::thread::sleep(IDLE);
            }
        }
        let mut failed = None;
        reader.drain(&mut |bytes, header| {
            seq += 1;
            let meta = SampleMeta {
                type_name: schema.type_name.clone(),
                size: schema.size,
                align: schema.align,
                seq,
                cycle: header.cycle,
                sent_unix_ns: unix_now_ns(),
            };
            let Ok(attachment) = meta.encode() else {
                return;
            };
            match publisher.put(bytes.to_vec()).attachment(attachment).wait() {
                Ok(()) => figures.sent(),
                Err(e) => failed = Some(e),
            }
        })?;
        match failed {
            Some(e) => crate::warn_once(&mut put_failing, "sample not put on Zenoh", &e),
            None => put_failing = false,
        }
    }
    Ok(())
}
