//! Opening the fabric's iceoryx2 services with one set of explicit sizes.
//!
//! Every process opens a service with the same settings (`open_or_create`), so whichever
//! comes first creates it and the rest open it. Sizes are explicit: iceoryx2's defaults (two
//! publishers, for instance) would refuse a restarted producer while its dead predecessor's
//! port is not yet cleaned up.

use crate::Error;
use crate::Message;
use crate::header::SampleHeader;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::marker::CustomPayloadMarker;
use iceoryx2::service::static_config::message_type_details::{TypeDetail, TypeVariant};
use std::collections::HashMap;

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
pub const EVENT_MAX_PORTS: usize = 32;

/// The fabric's sizes of a topic service: every opener (typed or not) asks for the same.
fn topic_qos<P: std::fmt::Debug + IceoryxSend + ?Sized, H: std::fmt::Debug + ZeroCopySend>(
    builder: iceoryx2::service::builder::publish_subscribe::Builder<P, H, ipc::Service>,
    topic: &str,
) -> iceoryx2::service::builder::publish_subscribe::Builder<P, H, ipc::Service> {
    let (publishers, buffer) = topic_sizes(topic);
    builder
        .max_publishers(publishers)
        .max_subscribers(TOPIC_MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .history_size(1)
        .subscriber_max_buffer_size(buffer)
        .subscriber_max_borrowed_samples(SUBSCRIBER_BORROWED)
        .enable_safe_overflow(true)
}

/// (max publishers, max subscriber buffer) of a topic: channel proposal topics have many
/// publishers and a buffer for one proposal of each per cycle.
fn topic_sizes(topic: &str) -> (usize, usize) {
    if is_proposals(topic) {
        (CHANNEL_MAX_PUBLISHERS, CHANNEL_MAX_PUBLISHERS)
    } else {
        (TOPIC_MAX_PUBLISHERS, SUBSCRIBER_BUFFER)
    }
}

fn service_name(name: &str) -> Result<ServiceName, Error> {
    ServiceName::new(name).map_err(|e| Error::transport(&format!("service name '{name}'"), e))
}

fn pubsub<T: Message>(
    node: &Node<ipc::Service>,
    topic: &str,
) -> Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, SampleHeader>,
    Error,
> {
    let name = crate::names::topic(topic);
    let builder = node
        .service_builder(&service_name(&name)?)
        .publish_subscribe::<T>()
        .user_header::<SampleHeader>();
    topic_qos(builder, topic)
        .open_or_create()
        .map_err(|e| Error::transport(&format!("open topic '{topic}' ({})", T::TYPE_NAME), e))
}

/// The payload type details of a message known only by its schema (a type declared in a
/// message file at run time): its name, size and alignment, as a Rust type would give them.
fn payload_details(schema: &crate::schema::MessageSchema) -> Result<TypeDetail, Error> {
    TypeDetail::__internal_new_from_parts(
        TypeVariant::FixedSize,
        &schema.type_name,
        schema.size as usize,
        schema.align as usize,
    )
    .map_err(|e| Error::transport(&format!("type name '{}'", schema.type_name), e))
}

/// A publisher of `topic` for messages known only by their schema: the same service a typed
/// publisher of that type opens (iceoryx2's type-details override, as its own gateways and
/// language bindings use it). Samples are `schema.size` bytes, loaned with
/// `loan_custom_payload(1)`; the user header is a [`SampleHeader`] behind
/// [`CustomHeaderMarker`](iceoryx2::service::marker::CustomHeaderMarker).
pub fn raw_publisher(
    node: &Node<ipc::Service>,
    topic: &str,
    schema: &crate::schema::MessageSchema,
) -> Result<
    Publisher<ipc::Service, [CustomPayloadMarker], iceoryx2::service::marker::CustomHeaderMarker>,
    Error,
> {
    let name = crate::names::topic(topic);
    let payload = payload_details(schema)?;
    let header = TypeDetail::__internal_new_from_parts(
        TypeVariant::FixedSize,
        SampleHeader::TYPE_NAME,
        std::mem::size_of::<SampleHeader>(),
        std::mem::align_of::<SampleHeader>(),
    )
    .map_err(|e| Error::transport("the sample header's type name", e))?;
    // SAFETY: the details are those of the type the schema describes (its size and
    // alignment, from the same message file every language is generated from) and of
    // `SampleHeader`; samples are written only as `size` bytes of that layout and a
    // `SampleHeader`.
    let builder = unsafe {
        node.service_builder(&service_name(&name)?)
            .publish_subscribe::<[CustomPayloadMarker]>()
            .user_header::<iceoryx2::service::marker::CustomHeaderMarker>()
            .__internal_set_payload_type_details(&payload)
            .__internal_set_user_header_type_details(&header)
    };
    let factory = topic_qos(builder, topic);
    let factory = iceoryx2::service::builder::publish_subscribe::Builder::<
        [CustomPayloadMarker],
        _,
        _,
    >::open_or_create(factory)
    .map_err(|e| {
        Error::transport(
            &format!("open topic '{topic}' ({}) untyped", schema.type_name),
            e,
        )
    })?;
    factory
        .publisher_builder()
        .max_loaned_samples(2)
        .create()
        .map_err(|e| Error::transport(&format!("untyped publisher on '{topic}'"), e))
}

/// A subscriber of `topic` for messages known only by their schema (see [`raw_publisher`]).
pub fn raw_subscriber(
    node: &Node<ipc::Service>,
    topic: &str,
    schema: &crate::schema::MessageSchema,
) -> Result<Subscriber<ipc::Service, [CustomPayloadMarker], SampleHeader>, Error> {
    raw_factory(node, topic, schema)?
        .subscriber_builder()
        .buffer_size(SUBSCRIBER_BUFFER)
        .history_request(1)
        .create()
        .map_err(|e| Error::transport(&format!("untyped subscriber on '{topic}'"), e))
}

fn raw_factory(
    node: &Node<ipc::Service>,
    topic: &str,
    schema: &crate::schema::MessageSchema,
) -> Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<
        ipc::Service,
        [CustomPayloadMarker],
        SampleHeader,
    >,
    Error,
> {
    let name = crate::names::topic(topic);
    let details = payload_details(schema)?;
    // SAFETY: the details are those of the producer's type (same schema), so the segment
    // holds `size` bytes of that layout per sample; it is only ever read as bytes.
    let builder = unsafe {
        node.service_builder(&service_name(&name)?)
            .publish_subscribe::<[CustomPayloadMarker]>()
            .user_header::<SampleHeader>()
            .__internal_set_payload_type_details(&details)
    };
    topic_qos(builder, topic).open_or_create().map_err(|e| {
        Error::transport(
            &format!("open topic '{topic}' ({}) untyped", schema.type_name),
            e,
        )
    })
}

/// The publisher of `topic`.
pub fn publisher<T: Message>(
    node: &Node<ipc::Service>,
    topic: &str,
) -> Result<Publisher<ipc::Service, T, SampleHeader>, Error> {
    pubsub::<T>(node, topic)?
        .publisher_builder()
        .max_loaned_samples(2)
        .create()
        .map_err(|e| Error::transport(&format!("publisher on '{topic}'"), e))
}

/// Whether `topic` is a channel's proposal topic (many publishers, one per proposer).
fn is_proposals(topic: &str) -> bool {
    topic.starts_with("channel/") && topic.matches('/').count() == 1
}

/// Publishers of a channel's proposal topic: every skill that may propose on it.
pub const CHANNEL_MAX_PUBLISHERS: usize = 16;

/// The subscriber a device holds on a channel's proposal topic: room for one proposal from
/// every proposer per cycle.
pub fn proposal_subscriber<T: Message>(
    node: &Node<ipc::Service>,
    topic: &str,
) -> Result<Subscriber<ipc::Service, T, SampleHeader>, Error> {
    pubsub::<T>(node, topic)?
        .subscriber_builder()
        .buffer_size(CHANNEL_MAX_PUBLISHERS)
        .create()
        .map_err(|e| Error::transport(&format!("proposal subscriber on '{topic}'"), e))
}

/// A subscriber of `topic` that also receives the last sample sent before it connected.
pub fn subscriber<T: Message>(
    node: &Node<ipc::Service>,
    topic: &str,
) -> Result<Subscriber<ipc::Service, T, SampleHeader>, Error> {
    pubsub::<T>(node, topic)?
        .subscriber_builder()
        .buffer_size(SUBSCRIBER_BUFFER)
        .history_request(1)
        .create()
        .map_err(|e| Error::transport(&format!("subscriber on '{topic}'"), e))
}

/// (most notifiers and listeners, most nodes) of event service `name`: every control client
/// has a notifier on the control plane's wake-up, the other events have a few ports each.
fn event_sizes(name: &str) -> (usize, usize) {
    if name == crate::names::control() {
        (CONTROL_MAX_NODES, CONTROL_MAX_NODES)
    } else {
        (EVENT_MAX_PORTS, MAX_NODES)
    }
}

fn event(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>, Error> {
    let (ports, nodes) = event_sizes(name);
    node.service_builder(&service_name(name)?)
        .event()
        .max_notifiers(ports)
        .max_listeners(ports)
        .max_nodes(nodes)
        .open_or_create()
        .map_err(|e| Error::transport(&format!("open event '{name}'"), e))
}

/// A listener on event service `name`.
pub fn listener(node: &Node<ipc::Service>, name: &str) -> Result<Listener<ipc::Service>, Error> {
    event(node, name)?
        .listener_builder()
        .create()
        .map_err(|e| Error::transport(&format!("listener on '{name}'"), e))
}

/// A notifier on an event service that must already exist (never creates it).
pub fn notifier_existing(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<Notifier<ipc::Service>, Error> {
    let (ports, nodes) = event_sizes(name);
    node.service_builder(&service_name(name)?)
        .event()
        .max_notifiers(ports)
        .max_listeners(ports)
        .max_nodes(nodes)
        .open()
        .map_err(|e| Error::transport(&format!("open event '{name}'"), e))?
        .notifier_builder()
        .create()
        .map_err(|e| Error::transport(&format!("notifier on '{name}'"), e))
}

/// A notifier on event service `name`.
pub fn notifier(node: &Node<ipc::Service>, name: &str) -> Result<Notifier<ipc::Service>, Error> {
    event(node, name)?
        .notifier_builder()
        .create()
        .map_err(|e| Error::transport(&format!("notifier on '{name}'"), e))
}

/// A node of `domain` named `name`, with iceoryx2's SIGINT/SIGTERM handling; the domain's
/// files are made private to this user first (see [`crate::domain`]).
pub fn node(domain: &crate::domain::Domain, name: &str) -> Result<Node<ipc::Service>, Error> {
    let config = domain.iceoryx_config()?;
    let node_name =
        NodeName::new(name).map_err(|e| Error::transport(&format!("node name '{name}'"), e))?;
    domain.secure_root()?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(&config)
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<ipc::Service>()
        .map_err(|e| Error::transport(&format!("create node '{name}' in domain '{domain}'"), e))?;
    domain.secure_shm();
    Ok(node)
}

/// Whether SIGINT or SIGTERM reached this process since the last check (which this clears).
/// The first call installs iceoryx2's handler for both signals (the one its WaitSets and
/// `Node::wait` use); after that a check is a flag read, no system call, so units call it
/// before every doorbell wait. A wait cut short by any other signal — a debugger or `strace`
/// attaching, SIGSTOP/SIGCONT — must not end a skill or the manager.
pub fn termination_requested() -> bool {
    iceoryx2_bb_posix::signal::SignalHandler::termination_requested()
}

/// Reads a topic without knowing its Rust type: the bytes of the newest sample, laid out as
/// its [`MessageSchema`](crate::schema::MessageSchema) says. Used by the manager (queries,
/// monitors) and by tools; it relies on iceoryx2's type-details override, the mechanism
/// iceoryx2's own language bindings and gateways use (pinned iceoryx2 version).
pub struct RawReader {
    subscriber: Subscriber<ipc::Service, [CustomPayloadMarker], SampleHeader>,
    latest: Option<iceoryx2::sample::Sample<ipc::Service, [CustomPayloadMarker], SampleHeader>>,
    size: usize,
    /// On a proposal topic, each proposer's newest sample (copied: held samples would use up
    /// the few a subscriber may borrow), by its slot.
    by_slot: Option<HashMap<u32, (Vec<u8>, SampleHeader)>>,
}

impl RawReader {
    /// A reader of `topic`, whose messages have `schema`.
    pub fn open(
        node: &Node<ipc::Service>,
        topic: &str,
        schema: &crate::schema::MessageSchema,
    ) -> Result<RawReader, Error> {
        let factory = raw_factory(node, topic, schema)?;
        let subscriber = factory
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER)
            .history_request(1)
            .create()
            .map_err(|e| Error::transport(&format!("untyped subscriber on '{topic}'"), e))?;
        Ok(RawReader {
            subscriber,
            latest: None,
            size: schema.size as usize,
            by_slot: is_proposals(topic).then(HashMap::new),
        })
    }

    /// Takes every sample that arrived, keeping the newest (and each proposer's newest).
    pub fn poll(&mut self) -> Result<(), Error> {
        self.drain(&mut |_, _| {})
    }

    /// Takes every sample that arrived (keeping the newest, and each proposer's newest),
    /// handing each one's bytes and header to `each` in the order they were published.
    pub fn drain(&mut self, each: &mut dyn FnMut(&[u8], SampleHeader)) -> Result<(), Error> {
        loop {
            match self.subscriber.receive() {
                Ok(Some(s)) => {
                    let ptr = s.payload().as_ptr().cast::<u8>();
                    // SAFETY: as in `latest`: one value of `size` bytes, mapped while held.
                    let bytes = unsafe { std::slice::from_raw_parts(ptr, self.size) };
                    each(bytes, *s.user_header());
                    if let Some(m) = self.by_slot.as_mut()
                        && let Some(slot) = s.user_header().slot.get()
                    {
                        m.insert(slot, (bytes.to_vec(), *s.user_header()));
                    }
                    self.latest = Some(s);
                }
                Ok(None) => return Ok(()),
                Err(e) => return Err(Error::transport("untyped receive", e)),
            }
        }
    }

    /// The newest sample's bytes and header.
    pub fn latest(&self) -> Option<(&[u8], SampleHeader)> {
        let s = self.latest.as_ref()?;
        let ptr = s.payload().as_ptr().cast::<u8>();
        // SAFETY: the sample's payload is one value of the declared type, `size` bytes long,
        // and stays mapped while the sample is held.
        let bytes = unsafe { std::slice::from_raw_parts(ptr, self.size) };
        Some((bytes, *s.user_header()))
    }

    /// The newest sample published from board slot `slot` (on a proposal topic, where every
    /// proposer publishes), or the newest of all when `slot` is `None`.
    pub fn latest_of(&self, slot: Option<u32>) -> Option<(&[u8], SampleHeader)> {
        match (slot, &self.by_slot) {
            (Some(s), Some(m)) => m.get(&s).map(|(b, h)| (b.as_slice(), *h)),
            _ => self.latest(),
        }
    }
}

/// Port factory of the control plane's request-response service.
pub type ControlFactory = iceoryx2::service::port_factory::request_response::PortFactory<
    ipc::Service,
    [u8],
    (),
    [u8],
    (),
>;
/// Port factory of the events stream.
pub type EventsFactory =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, [u8], ()>;

/// Request-response service of the control plane (byte slices).
pub fn control_service(node: &Node<ipc::Service>) -> Result<ControlFactory, Error> {
    let name = crate::names::control();
    node.service_builder(&service_name(&name)?)
        .request_response::<[u8], [u8]>()
        .max_clients(CONTROL_MAX_CLIENTS)
        .max_servers(2)
        .max_nodes(CONTROL_MAX_NODES)
        // A client asks one thing at a time and reads one answer (a repeat goes out on a new
        // port). The server's bookkeeping per client connection grows with the product of
        // these and with the answer segment's 255 possible reallocations: at 4/4/2 it was
        // ~2 M entries per connection and a connection update took a second with 30 clients.
        .max_active_requests_per_client(1)
        .max_loaned_requests(1)
        .max_response_buffer_size(1)
        .max_borrowed_responses_per_pending_response(1)
        .open_or_create()
        .map_err(|e| Error::transport(&format!("open '{name}'"), e))
}

/// Clients of the control plane at once (sequencers, CLI calls, consoles, scripts running
/// `skillfab ctl` in parallel). The manager's answer segment grows with it (about 34 MB of
/// address space at 128, of which only what is used is memory: the file is sparse).
pub const CONTROL_MAX_CLIENTS: usize = 128;
/// Processes on the control plane's services: the clients, the manager, and room for a
/// restarted manager while the dead one's ports are cleaned up.
pub const CONTROL_MAX_NODES: usize = CONTROL_MAX_CLIENTS + 4;
/// Clients reading the events stream at once. Each costs the events publisher
/// [`EVENT_BUFFER`] samples of [`EVENT_MAX_BYTES`] (4 MiB of address space): the stream is
/// subscribed only by clients that read events, so this bounds those, not all clients.
pub const EVENTS_MAX_SUBSCRIBERS: usize = 24;
/// Events a subscriber may queue: for bursts (a subscriber counts gaps by `seq`); 20 s of a
/// monitor firing every cycle at 100 Hz.
pub const EVENT_BUFFER: usize = 2048;
/// Largest encoded event (bytes): the events publisher's fixed sample size. A bigger monitor
/// firing is cut to fit ([`crate::control::encode_event_within`]). A fixed size matters:
/// iceoryx2 keeps a reference counter per sample for every segment a growing publisher may
/// ever allocate (255), which for this service's ~50 000 samples was 160 MB of the manager's
/// memory.
pub const EVENT_MAX_BYTES: usize = 2048;

/// Publish-subscribe service of the events stream (byte slices).
pub fn events_service(node: &Node<ipc::Service>) -> Result<EventsFactory, Error> {
    let name = crate::names::events();
    node.service_builder(&service_name(&name)?)
        .publish_subscribe::<[u8]>()
        .max_publishers(2)
        .max_subscribers(EVENTS_MAX_SUBSCRIBERS)
        .max_nodes(CONTROL_MAX_NODES)
        .history_size(0)
        .subscriber_max_buffer_size(EVENT_BUFFER)
        .subscriber_max_borrowed_samples(2)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| Error::transport(&format!("open '{name}'"), e))
}
