//! Exports: every sample of a local topic, as it is published, put on Zenoh under
//! `skillfab/<domain>/topic/<topic>` with a [`SampleMeta`] attachment; the topic's whole
//! message schema answered by a queryable beside it.

use crate::figures::TopicFigures;
use crate::{BridgeError, zenoh_error};
use skillfab_client::{Client, ClientError};
use skillfab_proto::bridge::{SampleMeta, unix_now_ns};
use skillfab_proto::control::ControlError;
use skillfab_proto::domain::Domain;
use skillfab_proto::names;
use skillfab_proto::schema::MessageSchema;
use skillfab_proto::services::{self, RawReader};
use std::time::Duration;
use zenoh::Wait;

/// How often an exporter looks for the end of the process while no sample comes.
const IDLE: Duration = Duration::from_millis(200);

/// The message type of `topic` as the domain's skills declare it (its producer first), once
/// one of them has registered.
pub(crate) fn local_schema(
    client: &Client,
    topic: &str,
) -> Result<Option<MessageSchema>, BridgeError> {
    match client.topic_schema(topic) {
        Ok(s) => Ok(Some(s)),
        Err(ClientError::Refused(ControlError::UnknownTopic(_))) => Ok(None),
        Err(e) => Err(e.into()),
    }
}

/// Carries the samples of `topic` (of `schema`) to Zenoh until the process is asked to end.
pub(crate) fn serve(
    session: &zenoh::Session,
    domain: &Domain,
    bridge: &str,
    topic: &str,
    schema: &MessageSchema,
    figures: &TopicFigures,
) -> Result<(), BridgeError> {
    let node = services::node(
        domain,
        &format!("{bridge}-export-{}", topic.replace('/', "-")),
    )?;
    let mut reader = RawReader::open(&node, topic, schema)?;
    let listener = services::listener(&node, &names::topic(topic))?;
    let encoded_schema = postcard::to_allocvec(schema).map_err(skillfab_proto::Error::from)?;
    let schema_key = names::remote_schema(domain.name(), topic);
    session
        .declare_queryable(schema_key.clone())
        .callback(move |q| {
            if let Err(e) = q.reply(schema_key.clone(), encoded_schema.clone()).wait() {
                tracing::warn!(error = %e, "schema reply failed");
            }
        })
        .background()
        .wait()
        .map_err(|e| zenoh_error("schema queryable", e))?;
    // Samples wait for a slow link rather than vanish: losses are counted on the far side.
    let publisher = session
        .declare_publisher(names::remote_topic(domain.name(), topic))
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .express(true)
        .wait()
        .map_err(|e| zenoh_error("publisher", e))?;
    let mut seq = 0u64;
    tracing::info!(topic, r#type = %schema.type_name, "exporting");
    while !crate::stopping() {
        let _ = listener.timed_wait(|_| {}, IDLE);
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
                Err(e) => failed = Some(e.to_string()),
            }
        })?;
        if let Some(e) = failed {
            tracing::warn!(topic, error = %e, "put failed");
        }
    }
    Ok(())
}
