//! Opening the fabric's iceoryx2 services with one set of explicit sizes.
//!
//! Every process opens a service with the same settings (`open_or_create`), so whichever
//! comes first creates it and the rest open it. Sizes are explicit: iceoryx2's defaults (two
//! publishers, for instance) would refuse a restarted producer while its dead predecessor's
//! port is not yet cleaned up.

use crate::Message;
use crate::SdkError;
use crate::header::SampleHeader;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

/// Publishers per topic: one producer, plus room for a restarted one during cleanup.
pub const TOPIC_MAX_PUBLISHERS: usize = 4;
/// Subscribers per topic (consumers, manager, console, recorders, CLI queries).
pub const TOPIC_MAX_SUBSCRIBERS: usize = 16;
/// Processes per service.
pub const MAX_NODES: usize = 32;
/// Samples a subscriber may queue: the fabric only ever needs the newest.
pub const SUBSCRIBER_BUFFER: usize = 2;
/// Samples a subscriber may hold while it receives the next one.
pub const SUBSCRIBER_BORROWED: usize = 2;
/// Notifiers and listeners per event service.
pub const EVENT_MAX_PORTS: usize = 16;

fn transport(what: String, e: impl std::fmt::Debug) -> SdkError {
    SdkError::Transport {
        what,
        detail: format!("{e:?}"),
    }
}

fn service_name(name: &str) -> Result<ServiceName, SdkError> {
    ServiceName::new(name).map_err(|e| transport(format!("service name '{name}'"), e))
}

fn pubsub<T: Message>(
    node: &Node<ipc::Service>,
    topic: &str,
) -> Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, SampleHeader>,
    SdkError,
> {
    let name = crate::names::topic(topic);
    node.service_builder(&service_name(&name)?)
        .publish_subscribe::<T>()
        .user_header::<SampleHeader>()
        .max_publishers(TOPIC_MAX_PUBLISHERS)
        .max_subscribers(TOPIC_MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .history_size(1)
        .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
        .subscriber_max_borrowed_samples(SUBSCRIBER_BORROWED)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| transport(format!("open topic '{topic}' ({})", T::TYPE_NAME), e))
}

/// The publisher of `topic`.
pub fn publisher<T: Message>(
    node: &Node<ipc::Service>,
    topic: &str,
) -> Result<Publisher<ipc::Service, T, SampleHeader>, SdkError> {
    pubsub::<T>(node, topic)?
        .publisher_builder()
        .max_loaned_samples(2)
        .create()
        .map_err(|e| transport(format!("publisher on '{topic}'"), e))
}

/// A subscriber of `topic` that also receives the last sample sent before it connected.
pub fn subscriber<T: Message>(
    node: &Node<ipc::Service>,
    topic: &str,
) -> Result<Subscriber<ipc::Service, T, SampleHeader>, SdkError> {
    pubsub::<T>(node, topic)?
        .subscriber_builder()
        .buffer_size(SUBSCRIBER_BUFFER)
        .history_request(1)
        .create()
        .map_err(|e| transport(format!("subscriber on '{topic}'"), e))
}

fn event(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>, SdkError> {
    node.service_builder(&service_name(name)?)
        .event()
        .max_notifiers(EVENT_MAX_PORTS)
        .max_listeners(EVENT_MAX_PORTS)
        .max_nodes(MAX_NODES)
        .open_or_create()
        .map_err(|e| transport(format!("open event '{name}'"), e))
}

/// A listener on event service `name`.
pub fn listener(node: &Node<ipc::Service>, name: &str) -> Result<Listener<ipc::Service>, SdkError> {
    event(node, name)?
        .listener_builder()
        .create()
        .map_err(|e| transport(format!("listener on '{name}'"), e))
}

/// A notifier on event service `name`.
pub fn notifier(node: &Node<ipc::Service>, name: &str) -> Result<Notifier<ipc::Service>, SdkError> {
    event(node, name)?
        .notifier_builder()
        .create()
        .map_err(|e| transport(format!("notifier on '{name}'"), e))
}

/// A node of `domain` named `name`, with iceoryx2's SIGINT/SIGTERM handling.
pub fn node(domain: &crate::domain::Domain, name: &str) -> Result<Node<ipc::Service>, SdkError> {
    let config = domain.iceoryx_config()?;
    let node_name = NodeName::new(name).map_err(|e| transport(format!("node name '{name}'"), e))?;
    NodeBuilder::new()
        .name(&node_name)
        .config(&config)
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(|e| transport(format!("create node '{name}' in domain '{domain}'"), e))
}
