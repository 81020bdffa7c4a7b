//! Every name skillfab gives to an iceoryx2 service or a shared-memory file: the one place
//! where they are formatted. The scheme is documented in the README ("Naming scheme") so any
//! iceoryx2 client can find a skill's outputs.
//!
//! All of them live inside the domain's iceoryx2 namespace (see [`crate::domain`]).

/// Publish-subscribe service carrying the messages of `topic` (payload = the message type,
/// user header = [`crate::header::SampleHeader`]); the event service of the same name is
/// notified after every send.
pub fn topic(topic: &str) -> String {
    format!("skillfab/topic/{topic}")
}

/// Topic on which skills propose commands for actuator channel `channel` (many publishers;
/// the sample header names the proposer's slot).
pub fn channel_topic(channel: &str) -> String {
    format!("channel/{channel}")
}

/// Topic on which the device publishes the arbitrated command of each cycle.
pub fn command_topic(channel: &str) -> String {
    format!("channel/{channel}/command")
}

/// Request-response service of the control plane.
pub fn control() -> String {
    "skillfab/control".to_string()
}

/// Event service through which the manager wakes control client `id` when its answer is in.
pub fn client(id: &str) -> String {
    format!("skillfab/client/{id}")
}

/// Publish-subscribe (and paired event) service of the events stream.
pub fn events() -> String {
    "skillfab/events".to_string()
}

/// Publish-subscribe service of the log stream: every skill's forwarded tracing lines
/// (postcard [`crate::log::LogLine`] as byte slices; no event service — readers poll).
pub fn logs() -> String {
    "skillfab/logs".to_string()
}

/// Zenoh key expression under which a bridge of `domain` publishes the samples of `topic`
/// (payload = the message's bytes, attachment = [`crate::bridge::SampleMeta`]).
pub fn remote_topic(domain: &str, topic: &str) -> String {
    format!("skillfab/{domain}/topic/{topic}")
}

/// Zenoh queryable answering the [`crate::schema::MessageSchema`] of an exported `topic`.
pub fn remote_schema(domain: &str, topic: &str) -> String {
    format!("skillfab/{domain}/schema/{topic}")
}

/// Zenoh queryable carrying control requests to the manager of `domain` (query payload = an
/// encoded request, reply = the encoded response).
pub fn remote_control(domain: &str) -> String {
    format!("skillfab/{domain}/control")
}

/// Zenoh key expression of the events stream of `domain` (payload = an encoded event).
pub fn remote_events(domain: &str) -> String {
    format!("skillfab/{domain}/events")
}

/// Zenoh key expression of the log stream of `domain` (payload = an encoded log line).
pub fn remote_logs(domain: &str) -> String {
    format!("skillfab/{domain}/logs")
}

/// POSIX shared-memory name (for `shm_open`) of the domain's cycle board.
pub fn board(prefix: &str) -> String {
    format!("/{prefix}board")
}

/// Shared-memory object holding the state of skill instance `name` as of its last completed
/// run (the SDK's `state` module), kept across the deaths of its process.
pub fn state(prefix: &str, name: &str) -> String {
    format!("/{prefix}state_{name}")
}

/// Checks a skill or topic name: 1 to 64 of `[A-Za-z0-9_-]`, `/` allowed inside a topic.
pub fn check_name(what: &str, name: &str, allow_slash: bool) -> Result<(), crate::Error> {
    let ok_char =
        |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '-' || (allow_slash && c == '/');
    if name.is_empty() || name.len() > 64 || !name.chars().all(ok_char) || name.starts_with('/') {
        return Err(crate::Error::BadName {
            what: what.to_string(),
            name: name.to_string(),
        });
    }
    Ok(())
}
