//! What travels between two domains over a bridge (`skillfab bridge`, on Zenoh): the metadata
//! of each bridged sample, the answer of a failed remote request, and the figures a bridge
//! reports to its manager (shown by `ctl stats`). Encoded with postcard, like the control plane.
//!
//! Key expressions are formatted in [`crate::names`] (`remote_*`).

use crate::control::Percentiles;
use serde::{Deserialize, Serialize};

/// The Zenoh attachment of every bridged sample: the message type it holds (checked against
/// the importing side's declaration), its place in the exporter's sequence (gaps are losses)
/// and when it left (one-way latency).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleMeta {
    /// The message's type name (iceoryx2's and every language's).
    pub type_name: String,
    /// Its size in bytes.
    pub size: u32,
    /// Its alignment in bytes.
    pub align: u32,
    /// Number of this sample among the exporter's samples of the topic, from 1.
    pub seq: u64,
    /// The producer's sample header: the cycle it was produced in.
    pub cycle: u64,
    /// Wall-clock time (ns since the Unix epoch) when the exporter sent it.
    pub sent_unix_ns: u64,
}

impl SampleMeta {
    /// Encodes for a Zenoh attachment.
    pub fn encode(&self) -> Result<Vec<u8>, postcard::Error> {
        postcard::to_allocvec(self)
    }

    /// Decodes an attachment.
    pub fn decode(bytes: &[u8]) -> Result<SampleMeta, postcard::Error> {
        postcard::from_bytes(bytes)
    }
}

/// Why a bridge could not carry a remote control request (the manager's own refusals travel
/// as ordinary answers).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, thiserror::Error)]
#[non_exhaustive]
pub enum RemoteFailure {
    /// No manager runs in the bridge's domain.
    #[error("no manager is running in domain '{0}'")]
    NoManager(String),
    /// The manager did not answer in time (ms).
    #[error("no answer from the manager within {0} ms")]
    Timeout(u64),
    /// The bridge's worker for this client stopped (it panicked); the next request gets a
    /// new one.
    #[error("the bridge's worker for this client failed")]
    WorkerFailed,
    /// Every place on the manager's control plane stayed taken (how many it serves).
    #[error("the manager serves at most {0} clients at once and none left")]
    Full(u32),
    /// The bridge's own client of the manager failed (shared memory, or an answer it could
    /// not read); the bridge's log says how.
    #[error("the bridge could not reach its manager (see the bridge's log)")]
    BridgeClient,
}

/// Wall-clock time in ns since the Unix epoch (one-way latency between hosts needs a shared
/// clock: on one host it is exact; between hosts it is as good as their time sync).
pub fn unix_now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// One bridged topic's figures.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TopicStats {
    /// The local topic.
    pub topic: String,
    /// The remote domain an import comes from (empty for an export: whoever subscribes).
    pub remote: String,
    /// Its message type.
    pub type_name: String,
    /// Samples carried.
    pub samples: u64,
    /// Samples lost on the way (gaps in the exporter's sequence), imports only.
    pub lost: u64,
    /// Samples refused (a type that does not match), imports only.
    pub refused: u64,
    /// One-way latency of the last samples (exporter sent → republished here), imports only.
    pub latency_us: Percentiles,
}

/// What a bridge reports to its manager, about once a second.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BridgeStats {
    /// The bridge's name in its domain.
    pub name: String,
    /// The Zenoh sessions it is connected to now (0: the link is down).
    pub links: u32,
    /// Times the link came back after it was lost.
    pub reconnects: u64,
    /// Topics sent out.
    pub exports: Vec<TopicStats>,
    /// Topics brought in.
    pub imports: Vec<TopicStats>,
    /// Remote control requests carried.
    pub requests: u64,
    /// Topics refused and why (a type mismatch names both sides).
    pub errors: Vec<String>,
}
