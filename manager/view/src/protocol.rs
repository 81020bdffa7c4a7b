//! The Foxglove WebSocket protocol, version 1 (`foxglove.websocket.v1`), as published in
//! foxglove/ws-protocol's `docs/spec.md`: JSON text messages told apart by `op`, and binary
//! messages told apart by their first byte, integers little-endian.
//!
//! Only what this server speaks is here: the server's `serverInfo`, `status`, `advertise`,
//! `unadvertise`, `parameterValues`, `advertiseServices`, `serviceCallFailure`, message data
//! and service call responses; the client's `subscribe`, `unsubscribe`, `getParameters`,
//! `setParameters`, `(un)subscribeParameterUpdates` and service call requests. Anything else
//! a client sends is answered with an error `status` naming it.

use serde::{Deserialize, Serialize};
use serde_json::Value as Json;

/// The WebSocket subprotocol a client must offer.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// Binary opcode (server → client): a message on a subscription.
pub const OP_MESSAGE_DATA: u8 = 0x01;
/// Binary opcode (server → client): the answer to a service call.
pub const OP_SERVICE_CALL_RESPONSE: u8 = 0x03;
/// Binary opcode (client → server): a message on a channel the client advertised.
pub const OP_CLIENT_MESSAGE_DATA: u8 = 0x01;
/// Binary opcode (client → server): a service call.
pub const OP_SERVICE_CALL_REQUEST: u8 = 0x02;

/// How severe a `status` message is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// For information.
    Info = 0,
    /// Something the client should know went wrong, the connection goes on.
    Warning = 1,
    /// A request was refused.
    Error = 2,
}

/// A channel as advertised.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Channel {
    /// Its id, unique for the server's life.
    pub id: u32,
    /// The topic (`/<fabric topic>` or one of the view's own, `/tf`, `/scene`, …).
    pub topic: String,
    /// `cdr` (fabric topics) or `json` (the view's own channels).
    pub encoding: String,
    /// `skillfab/msg/Sonar`, `foxglove.SceneUpdate`, …
    pub schema_name: String,
    /// The schema's text.
    pub schema: String,
    /// `ros2msg` or `jsonschema`.
    pub schema_encoding: String,
}

/// A parameter: its name (`/<skill>/<param>`) and value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Parameter {
    /// `/<skill>/<param>`.
    pub name: String,
    /// A number, a bool, a string, or an array.
    pub value: Json,
    /// `float64` for a float, so a client keeps `2.0` a float; absent otherwise.
    #[serde(rename = "type", default, skip_serializing_if = "Option::is_none")]
    pub ty: Option<String>,
}

/// The schema of a service's request or response.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct ServiceSchema {
    /// `json`.
    pub encoding: String,
    /// Its name.
    pub schema_name: String,
    /// `jsonschema`.
    pub schema_encoding: String,
    /// The JSON Schema.
    pub schema: String,
}

/// A service as advertised.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Service {
    /// Its id.
    pub id: u32,
    /// `/skillfab/activate`, …
    pub name: String,
    /// Its type.
    #[serde(rename = "type")]
    pub ty: String,
    /// The request.
    pub request: ServiceSchema,
    /// The response.
    pub response: ServiceSchema,
    /// The request's schema again, as clients of the protocol's first revision read it.
    pub request_schema: String,
    /// The response's schema, likewise.
    pub response_schema: String,
}

/// What the server sends as text.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "op", rename_all = "camelCase")]
pub enum ServerMessage {
    /// The first message of a connection.
    #[serde(rename_all = "camelCase")]
    ServerInfo {
        /// The server's name.
        name: String,
        /// What it supports.
        capabilities: Vec<String>,
        /// Encodings it accepts from clients (service calls).
        supported_encodings: Vec<String>,
        /// The domain, the world, …
        metadata: serde_json::Map<String, Json>,
        /// Changes when the server restarts.
        session_id: String,
    },
    /// Information, a warning or an error for this client.
    Status {
        /// 0 info, 1 warning, 2 error.
        level: u8,
        /// What happened.
        message: String,
        /// The request it answers, when it answers one.
        #[serde(skip_serializing_if = "Option::is_none")]
        id: Option<String>,
    },
    /// New channels.
    Advertise {
        /// The channels.
        channels: Vec<Channel>,
    },
    /// Channels gone.
    #[serde(rename_all = "camelCase")]
    Unadvertise {
        /// Their ids.
        channel_ids: Vec<u32>,
    },
    /// Parameter values: an answer to `getParameters`/`setParameters` (with its `id`), or
    /// an update to a subscriber.
    ParameterValues {
        /// The values.
        parameters: Vec<Parameter>,
        /// The request answered.
        #[serde(skip_serializing_if = "Option::is_none")]
        id: Option<String>,
    },
    /// The services.
    AdvertiseServices {
        /// The services.
        services: Vec<Service>,
    },
    /// A service call that failed.
    #[serde(rename_all = "camelCase")]
    ServiceCallFailure {
        /// The service.
        service_id: u32,
        /// The call.
        call_id: u32,
        /// Why.
        message: String,
    },
}

impl ServerMessage {
    /// A `status` message.
    pub fn status(level: Level, message: impl Into<String>, id: Option<String>) -> ServerMessage {
        ServerMessage::Status {
            level: level as u8,
            message: message.into(),
            id,
        }
    }

    /// The message's text.
    pub fn to_text(&self) -> String {
        // Every field is a string, a number, a bool or JSON already: cannot fail.
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// One subscription a client asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "camelCase", deny_unknown_fields)]
pub struct Subscription {
    /// The client's id for it (message data carries it).
    pub id: u32,
    /// The channel.
    pub channel_id: u32,
}

/// What a client sends as text.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "op", rename_all = "camelCase")]
pub enum ClientMessage {
    /// Subscribe to channels.
    Subscribe {
        /// The subscriptions.
        subscriptions: Vec<Subscription>,
    },
    /// End subscriptions.
    #[serde(rename_all = "camelCase")]
    Unsubscribe {
        /// Their ids.
        subscription_ids: Vec<u32>,
    },
    /// Ask for parameter values (none named: all of them).
    #[serde(rename_all = "camelCase")]
    GetParameters {
        /// The names.
        #[serde(default)]
        parameter_names: Vec<String>,
        /// Echoed in the answer.
        #[serde(default)]
        id: Option<String>,
    },
    /// Set parameters.
    SetParameters {
        /// Names and new values.
        parameters: Vec<Parameter>,
        /// When present, the new values are sent back with it.
        #[serde(default)]
        id: Option<String>,
    },
    /// Be told when these parameters change.
    #[serde(rename_all = "camelCase")]
    SubscribeParameterUpdates {
        /// The names (none: all).
        #[serde(default)]
        parameter_names: Vec<String>,
    },
    /// No longer be told.
    #[serde(rename_all = "camelCase")]
    UnsubscribeParameterUpdates {
        /// The names (none: all).
        #[serde(default)]
        parameter_names: Vec<String>,
    },
}

/// Why a client's message was not understood.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BadMessage {
    /// Not JSON, or not one of the ops this server takes, or missing fields.
    #[error(
        "message not understood ({0}); ops taken: subscribe, unsubscribe, getParameters, setParameters, subscribeParameterUpdates, unsubscribeParameterUpdates"
    )]
    Text(String),
    /// A binary message shorter than its header.
    #[error("binary message of {len} bytes is too short for opcode {op:#04x}")]
    Short {
        /// Its opcode.
        op: u8,
        /// Its length.
        len: usize,
    },
    /// A binary opcode this server does not take.
    #[error(
        "binary opcode {0:#04x} is not taken here (client publishing is not offered; service calls are 0x02)"
    )]
    Opcode(u8),
}

/// Parses a client's text message.
pub fn parse_text(text: &str) -> Result<ClientMessage, BadMessage> {
    serde_json::from_str(text).map_err(|e| {
        let op = serde_json::from_str::<Json>(text)
            .ok()
            .and_then(|j| j.get("op").and_then(Json::as_str).map(str::to_string));
        BadMessage::Text(match op {
            Some(op) => format!("op {op:?}: {e}"),
            None => e.to_string(),
        })
    })
}

/// A service call request (binary opcode 0x02).
#[derive(Debug, Clone, PartialEq)]
pub struct ServiceCall {
    /// The service.
    pub service_id: u32,
    /// The client's id for the call.
    pub call_id: u32,
    /// The request's encoding (`json`).
    pub encoding: String,
    /// The request.
    pub payload: Vec<u8>,
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

/// Parses a client's binary message: only service calls are taken.
pub fn parse_binary(b: &[u8]) -> Result<ServiceCall, BadMessage> {
    let Some(&op) = b.first() else {
        return Err(BadMessage::Short { op: 0, len: 0 });
    };
    if op != OP_SERVICE_CALL_REQUEST {
        return Err(BadMessage::Opcode(op));
    }
    let short = BadMessage::Short { op, len: b.len() };
    let (Some(service_id), Some(call_id), Some(n)) = (u32_at(b, 1), u32_at(b, 5), u32_at(b, 9))
    else {
        return Err(short);
    };
    let end = 13usize.checked_add(n as usize).ok_or(short.clone())?;
    let encoding = b.get(13..end).ok_or(short)?;
    Ok(ServiceCall {
        service_id,
        call_id,
        encoding: String::from_utf8_lossy(encoding).into_owned(),
        payload: b[end..].to_vec(),
    })
}

/// A message data frame: opcode, subscription id, receive time (ns since the Unix epoch),
/// payload.
pub fn message_data(subscription: u32, time_ns: u64, payload: &[u8]) -> Vec<u8> {
    let mut b = Vec::with_capacity(13 + payload.len());
    b.push(OP_MESSAGE_DATA);
    b.extend_from_slice(&subscription.to_le_bytes());
    b.extend_from_slice(&time_ns.to_le_bytes());
    b.extend_from_slice(payload);
    b
}

/// A service call response frame.
pub fn service_response(service_id: u32, call_id: u32, encoding: &str, payload: &[u8]) -> Vec<u8> {
    let mut b = Vec::with_capacity(13 + encoding.len() + payload.len());
    b.push(OP_SERVICE_CALL_RESPONSE);
    b.extend_from_slice(&service_id.to_le_bytes());
    b.extend_from_slice(&call_id.to_le_bytes());
    b.extend_from_slice(&(encoding.len() as u32).to_le_bytes());
    b.extend_from_slice(encoding.as_bytes());
    b.extend_from_slice(payload);
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn client_messages_parse_as_the_spec_writes_them() {
        let m = parse_text(r#"{"op":"subscribe","subscriptions":[{"id":0,"channelId":3}]}"#);
        assert_eq!(
            m,
            Ok(ClientMessage::Subscribe {
                subscriptions: vec![Subscription {
                    id: 0,
                    channel_id: 3
                }]
            })
        );
        let m = parse_text(r#"{"op":"getParameters","parameterNames":[],"id":"r1"}"#);
        assert_eq!(
            m,
            Ok(ClientMessage::GetParameters {
                parameter_names: vec![],
                id: Some("r1".into())
            })
        );
        let m = parse_text(r#"{"op":"setParameters","parameters":[{"name":"/a/b","value":2.5}]}"#)
            .unwrap();
        let ClientMessage::SetParameters { parameters, id } = m else {
            panic!("{m:?}")
        };
        assert_eq!((parameters[0].name.as_str(), id), ("/a/b", None));
        assert_eq!(parameters[0].value, serde_json::json!(2.5));
    }

    #[test]
    fn garbage_and_unknown_ops_are_refused_with_what_was_wrong() {
        let e = parse_text("not json").unwrap_err().to_string();
        assert!(e.contains("not understood"), "{e}");
        let e = parse_text(r#"{"op":"fly","to":"moon"}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("\"fly\""), "{e}");
        let e = parse_text(r#"{"op":"subscribe"}"#).unwrap_err().to_string();
        assert!(e.contains("subscriptions"), "{e}");
    }

    #[test]
    fn binary_service_calls_parse_and_short_or_foreign_frames_are_refused() {
        let mut b = vec![OP_SERVICE_CALL_REQUEST];
        b.extend_from_slice(&7u32.to_le_bytes());
        b.extend_from_slice(&9u32.to_le_bytes());
        b.extend_from_slice(&4u32.to_le_bytes());
        b.extend_from_slice(b"json{}");
        let c = parse_binary(&b).unwrap();
        assert_eq!(
            (c.service_id, c.call_id, c.encoding.as_str()),
            (7, 9, "json")
        );
        assert_eq!(c.payload, b"{}");
        assert_eq!(
            parse_binary(&b[..10]),
            Err(BadMessage::Short { op: 2, len: 10 })
        );
        let mut long = b[..13].to_vec();
        long[9..13].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(parse_binary(&long), Err(BadMessage::Short { .. })));
        assert_eq!(parse_binary(&[1, 0, 0]), Err(BadMessage::Opcode(1)));
        assert!(matches!(parse_binary(&[]), Err(BadMessage::Short { .. })));
    }

    #[test]
    fn frames_are_laid_out_little_endian_after_their_opcode() {
        let f = message_data(5, 0x0102_0304_0506_0708, b"xy");
        assert_eq!(f[0], OP_MESSAGE_DATA);
        assert_eq!(&f[1..5], &5u32.to_le_bytes());
        assert_eq!(&f[5..13], &0x0102_0304_0506_0708u64.to_le_bytes());
        assert_eq!(&f[13..], b"xy");
        let r = service_response(1, 2, "json", b"{}");
        assert_eq!(r[0], OP_SERVICE_CALL_RESPONSE);
        assert_eq!(&r[9..13], &4u32.to_le_bytes());
        assert_eq!(&r[13..17], b"json");
        let t = ServerMessage::status(Level::Error, "no", Some("x".into())).to_text();
        assert_eq!(t, r#"{"op":"status","level":2,"message":"no","id":"x"}"#);
    }
}
