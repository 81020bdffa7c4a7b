//! Input and output ports as a skill body sees them.
//!
//! A body gets its inputs as `Input<'a, T>` (a reference into the producer's shared-memory
//! sample, plus the cycle it was made in) and writes outputs through `Output<'a, T>`, which
//! loans a shared-memory sample on first write. The runtime sends the written samples only
//! when the body returns `Ok`. The same types work over plain memory in the test harness.

use crate::Message;
use crate::decl::{PortDecl, PortKind};
use crate::header::SampleHeader;
use crate::refs::{InputRef, OutputRef};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::ipc;
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use std::any::Any;
use std::ops::Deref;

/// Cycle bookkeeping of one input sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputMeta {
    /// The cycle in which the sample was produced.
    pub cycle: u64,
    /// How many cycles old it is now (0 for a same-cycle input).
    pub age: u64,
    /// Board slot of the producer; on a device's command topic, of the winning proposer
    /// (`None`: nobody proposed, the safe command, or the command was blended).
    pub source: Option<u32>,
}

/// Where a body's inputs come from: the runtime's subscribers or the harness's script.
pub trait InputSource {
    /// The latest value of input `idx` (a `&T` of the port's message type) and its meta.
    fn get(&self, idx: usize) -> Option<(&dyn Any, InputMeta)>;
}

/// One input as the body sees it: dereferences to the message.
#[derive(Debug)]
pub struct Input<'a, T> {
    value: &'a T,
    meta: InputMeta,
}

impl<'a, T> Input<'a, T> {
    /// The cycle the value was produced in.
    pub fn cycle(&self) -> u64 {
        self.meta.cycle
    }
    /// Age in cycles (0: produced in this cycle).
    pub fn age(&self) -> u64 {
        self.meta.age
    }
    /// The value.
    pub fn value(&self) -> &'a T {
        self.value
    }
}

impl<T> Deref for Input<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.value
    }
}

/// A field type of an `Inputs` struct (generated code uses it).
pub trait InputField<'a>: Sized {
    /// The message type the port carries (what its [`InputRef`] is typed by).
    type Message: Message;
    /// The port's declaration.
    fn decl(port: &str) -> PortDecl;
    /// Takes input `idx` from `src`; `None` if it is missing.
    fn fetch(src: &'a dyn InputSource, idx: usize) -> Option<Self>;
    /// The runtime port of input `idx` (a subscriber).
    fn make(maker: &PortMaker<'_>, idx: usize) -> Result<Box<dyn ErasedInput>, crate::SdkError>;
}

impl<'a, T: Message> InputField<'a> for Input<'a, T> {
    type Message = T;
    fn decl(port: &str) -> PortDecl {
        PortDecl::of::<T>(port)
    }
    fn fetch(src: &'a dyn InputSource, idx: usize) -> Option<Self> {
        let (any, meta) = src.get(idx)?;
        Some(Input {
            value: any.downcast_ref::<T>()?,
            meta,
        })
    }
    fn make(maker: &PortMaker<'_>, idx: usize) -> Result<Box<dyn ErasedInput>, crate::SdkError> {
        let node = maker.node.ok_or(crate::SdkError::NoNode)?;
        let topic = maker.topic(idx)?;
        Ok(Box::new(InputPort::<T> {
            subscriber: crate::services::subscriber::<T>(node, &topic)?,
            latest: None,
            fresh: false,
        }))
    }
}

/// The reference to input `name`, a field of type `F` of the input struct `Of`, carrying `T`
/// (generated code uses it: the bound checks the type the derive read off the field).
pub const fn input_ref<'a, F: InputField<'a, Message = T>, T, Of>(
    name: &'static str,
) -> InputRef<T, Of> {
    InputRef::new(name)
}

/// Builds runtime ports for a skill's declared inputs or outputs.
pub struct PortMaker<'n> {
    /// The process's node; `None` builds in-memory cells (harness).
    pub node: Option<&'n iceoryx2::node::Node<ipc::Service>>,
    /// Each port, in declaration order (after remapping).
    pub ports: Vec<PortDecl>,
}

impl PortMaker<'_> {
    /// The declaration of port `idx`.
    pub(crate) fn port(&self, idx: usize) -> Result<&PortDecl, crate::SdkError> {
        self.ports.get(idx).ok_or(crate::SdkError::NoNode)
    }

    fn topic(&self, idx: usize) -> Result<String, crate::SdkError> {
        self.port(idx).map(|p| p.topic.clone())
    }
}

/// A runtime input port: the subscriber and its latest sample (the runtime owns the
/// topic's event listener, which needs no type).
pub struct InputPort<T: Message> {
    subscriber: iceoryx2::port::subscriber::Subscriber<ipc::Service, T, SampleHeader>,
    latest: Option<iceoryx2::sample::Sample<ipc::Service, T, SampleHeader>>,
    fresh: bool,
}

/// Type-erased runtime input port.
pub trait ErasedInput {
    /// Drains the subscriber, keeping the newest sample.
    fn poll(&mut self) -> Result<(), crate::SdkError>;
    /// Header of the newest sample.
    fn latest_header(&self) -> Option<SampleHeader>;
    /// The newest sample's payload (`&T`).
    fn latest_any(&self) -> Option<&dyn Any>;
    /// Whether a sample arrived since [`ErasedInput::consume`].
    fn is_fresh(&self) -> bool;
    /// Marks the newest sample as seen.
    fn consume(&mut self);
}

impl<T: Message> ErasedInput for InputPort<T> {
    fn poll(&mut self) -> Result<(), crate::SdkError> {
        loop {
            match self.subscriber.receive() {
                Ok(Some(s)) => {
                    self.latest = Some(s);
                    self.fresh = true;
                }
                Ok(None) => return Ok(()),
                Err(e) => {
                    return Err(crate::SdkError::transport(
                        &format!("receive {}", T::TYPE_NAME),
                        e,
                    ));
                }
            }
        }
    }
    fn latest_header(&self) -> Option<SampleHeader> {
        self.latest.as_ref().map(|s| *s.user_header())
    }
    fn latest_any(&self) -> Option<&dyn Any> {
        self.latest.as_ref().map(|s| s.payload() as &dyn Any)
    }
    fn is_fresh(&self) -> bool {
        self.fresh
    }
    fn consume(&mut self) {
        self.fresh = false;
    }
}

/// A skill's inputs. Derive it with `#[derive(Inputs)]`; `()` is "no inputs".
pub trait InputSet<'a>: Sized {
    /// Declarations in field order.
    fn ports() -> Vec<PortDecl>;
    /// All inputs from `src`, or `None` if one is missing.
    fn fetch(src: &'a dyn InputSource) -> Option<Self>;
    /// One runtime port per field, in order.
    fn make(maker: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedInput>>, crate::SdkError>;
}

impl<'a> InputSet<'a> for () {
    fn ports() -> Vec<PortDecl> {
        Vec::new()
    }
    fn fetch(_: &'a dyn InputSource) -> Option<Self> {
        Some(())
    }
    fn make(_: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedInput>>, crate::SdkError> {
        Ok(Vec::new())
    }
}

enum Pending<T: Message> {
    /// A loaned shared-memory sample (zero-copy).
    Shm(SampleMut<ipc::Service, T, SampleHeader>),
    /// A heap buffer: the test harness, or a fallback when no sample could be loaned.
    Heap(Box<T>),
}

/// Storage behind one `Output<'a, T>`: a publisher's loan or, in the harness, the heap.
pub struct OutputCell<T: Message> {
    publisher: Option<Publisher<ipc::Service, T, SampleHeader>>,
    notifier: Option<iceoryx2::port::notifier::Notifier<ipc::Service>>,
    pending: Option<Pending<T>>,
    /// A sample loaned ahead, while the unit waited: the next run writes into it without
    /// loaning on the cycle's critical path (see [`ErasedOutputCell::prepare`]).
    ahead: Option<SampleMutUninit<ipc::Service, std::mem::MaybeUninit<T>, SampleHeader>>,
    /// Loaned samples (by address) this cell has initialised once: their bytes are a valid
    /// T from then on, as only this publisher writes them.
    initialised: std::collections::HashSet<usize>,
}

impl<T: Message> OutputCell<T> {
    /// A cell that publishes through `publisher` and then wakes the topic's listeners.
    pub fn shm(
        publisher: Publisher<ipc::Service, T, SampleHeader>,
        notifier: iceoryx2::port::notifier::Notifier<ipc::Service>,
    ) -> Self {
        OutputCell {
            publisher: Some(publisher),
            notifier: Some(notifier),
            pending: None,
            ahead: None,
            initialised: std::collections::HashSet::new(),
        }
    }

    /// A cell that keeps the written value in memory (test harness).
    pub fn memory() -> Self {
        OutputCell {
            publisher: None,
            notifier: None,
            pending: None,
            ahead: None,
            initialised: std::collections::HashSet::new(),
        }
    }

    /// The value of this run, loaned at first access; `clear`: zeroed then, else zeroed only
    /// the first time this cell gets that sample.
    fn slot(&mut self, clear: bool) -> &mut T {
        if self.pending.is_none() {
            let initialised = &mut self.initialised;
            let ahead = self.ahead.take();
            let publisher = self.publisher.as_ref();
            let loan = ahead
                .map(Ok)
                .or_else(|| publisher.map(|p| crate::allocs::in_loan(|| p.loan_uninit())));
            let loaned = loan.and_then(|loan| match loan {
                Ok(mut s) => {
                    let p = s.payload_mut().as_mut_ptr();
                    // Outputs start zeroed: every Message is valid when all bytes are zero.
                    // A sample this cell zeroed before still holds a valid T: only this
                    // publisher writes its samples.
                    if clear || initialised.insert(p as usize) {
                        // SAFETY: `p` points to one writable, properly aligned T in the loan.
                        unsafe { std::ptr::write_bytes(p, 0, 1) };
                    }
                    // SAFETY: the bytes are a valid T: zeroed just above, or zeroed and then
                    // written only as a T by this cell in an earlier cycle.
                    Some(Pending::Shm(unsafe { s.assume_init() }))
                }
                Err(e) => {
                    tracing::warn!(error = ?e, "no sample to loan; this output is copied instead");
                    None
                }
            });
            self.pending = Some(loaned.unwrap_or_else(|| {
                // SAFETY: every Message is valid when all bytes are zero (FieldType contract).
                Pending::Heap(unsafe { Box::<T>::new_zeroed().assume_init() })
            }));
        }
        match self.pending.as_mut() {
            Some(Pending::Shm(s)) => s.payload_mut(),
            Some(Pending::Heap(b)) => b,
            // Filled just above.
            None => unreachable!("pending output filled above"),
        }
    }
}

/// Type-erased access to an [`OutputCell`], for the runtime and the harness.
pub trait ErasedOutputCell {
    /// For downcasting to the concrete `OutputCell<T>`.
    fn as_any_mut(&mut self) -> &mut dyn Any;
    /// Whether the body wrote this output.
    fn is_written(&self) -> bool;
    /// Sends the written value with `header`; returns whether something was sent. Readers
    /// outside the fabric are woken by [`ErasedOutputCell::announce`], afterwards.
    fn commit(&mut self, header: SampleHeader) -> Result<bool, crate::SdkError>;
    /// Notifies the topic's iceoryx2 event service that a sample was sent: wakes listeners
    /// outside the fabric (the fabric's own consumers were woken by their doorbells first).
    fn announce(&self);
    /// Drops an unsent value (the body failed).
    fn discard(&mut self);
    /// Loans the next run's sample now, off the critical path (the runtime calls it before
    /// it sleeps): loaning touches the publisher's shared-memory bookkeeping, which after an
    /// idle period is cold and costs several µs. Nothing is sent or marked written.
    fn prepare(&mut self);
    /// Takes a value written in memory (harness): a `Box<T>`.
    fn take_memory(&mut self) -> Option<Box<dyn Any>>;
    /// The value of this run as bytes, loaned at first access (see [`Output::get_mut`] and,
    /// for `clear` false, [`Output::fill_in_place`]); marks the output written. For bodies
    /// in other languages, which write the message's `#[repr(C)]` layout.
    fn bytes_mut(&mut self, clear: bool) -> &mut [u8];
}

impl<T: Message> ErasedOutputCell for OutputCell<T> {
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
    fn is_written(&self) -> bool {
        self.pending.is_some()
    }
    fn commit(&mut self, header: SampleHeader) -> Result<bool, crate::SdkError> {
        fn send_err(
            ty: &str,
            e: impl std::error::Error + Send + Sync + 'static,
        ) -> crate::SdkError {
            crate::SdkError::transport(&format!("send on {ty}"), e)
        }
        match self.pending.take() {
            None => return Ok(false),
            Some(Pending::Shm(mut s)) => {
                *s.user_header_mut() = header;
                s.send().map_err(|e| send_err(T::TYPE_NAME, e))?;
            }
            Some(Pending::Heap(b)) => match &self.publisher {
                Some(p) => {
                    let mut s = crate::allocs::in_loan(|| p.loan_uninit())
                        .map_err(|e| send_err(T::TYPE_NAME, e))?
                        .write_payload(*b);
                    *s.user_header_mut() = header;
                    s.send().map_err(|e| send_err(T::TYPE_NAME, e))?;
                }
                None => {
                    self.pending = Some(Pending::Heap(b));
                    return Ok(true);
                }
            },
        }
        Ok(true)
    }
    fn announce(&self) {
        // After the send: a reader woken by this finds the sample. Without listeners outside
        // the fabric this makes no system call.
        if let Some(n) = &self.notifier
            && let Err(e) = n.notify()
        {
            tracing::warn!(type_name = T::TYPE_NAME, error = ?e, "event notification failed");
        }
    }
    fn discard(&mut self) {
        self.pending = None;
    }
    fn prepare(&mut self) {
        if self.ahead.is_none()
            && self.pending.is_none()
            && let Some(p) = &self.publisher
        {
            // A failed loan is tried again by the run (which says why).
            self.ahead = crate::allocs::in_loan(|| p.loan_uninit()).ok();
        }
    }
    fn bytes_mut(&mut self, clear: bool) -> &mut [u8] {
        let value: *mut T = self.slot(clear);
        // SAFETY: `value` is one valid, exclusively borrowed T (borrowed from `self` for the
        // returned lifetime); a Message is plain old data, so its bytes may be viewed and
        // written as bytes (bool fields are normalised by the foreign runtime before the
        // value is sent).
        unsafe { std::slice::from_raw_parts_mut(value.cast::<u8>(), std::mem::size_of::<T>()) }
    }
    fn take_memory(&mut self) -> Option<Box<dyn Any>> {
        match self.pending.take() {
            Some(Pending::Heap(b)) => Some(b),
            other => {
                self.pending = other;
                None
            }
        }
    }
}

/// A boxed output cell, as the runtime and harness hold them.
pub type ErasedOutput = Box<dyn ErasedOutputCell>;

/// One output as the body sees it. Write it with [`Output::set`] or fill it in place with
/// [`Output::get_mut`] (zero-copy for large messages). Unwritten outputs are not published.
pub struct Output<'a, T: Message> {
    cell: &'a mut OutputCell<T>,
}

impl<T: Message> Output<'_, T> {
    /// Writes the whole value.
    pub fn set(&mut self, value: T) {
        *self.cell.slot(true) = value;
    }
    /// The value to fill in place; zeroed at first access in a run.
    pub fn get_mut(&mut self) -> &mut T {
        self.cell.slot(true)
    }
    /// The value to fill in place, **not cleared**: fields the body does not write hold what
    /// this output held in some earlier cycle (zeros the first time). For large messages
    /// (images, scans) that are overwritten in place: clearing 4 MiB costs more than the rest
    /// of a cycle, and this makes an output's latency independent of its size.
    pub fn fill_in_place(&mut self) -> &mut T {
        self.cell.slot(false)
    }
    /// Whether the body wrote this output in this run.
    pub fn is_written(&self) -> bool {
        self.cell.pending.is_some()
    }
}

/// Hands out the cells of an output set in order (generated code uses it).
pub struct OutputSlots<'a> {
    it: std::slice::IterMut<'a, ErasedOutput>,
}

impl<'a> OutputSlots<'a> {
    /// Iterates over `slots`.
    pub fn new(slots: &'a mut [ErasedOutput]) -> Self {
        OutputSlots {
            it: slots.iter_mut(),
        }
    }
    /// The next cell.
    pub fn take_next(&mut self) -> &'a mut ErasedOutput {
        // The runtime and the harness build exactly one cell per declared output, in order,
        // from the same `OutputSet::ports()` the generated `bind` walks.
        #[allow(clippy::expect_used)]
        self.it.next().expect("one output cell per declared output")
    }
}

/// A field type of an `Outputs` struct (generated code uses it).
pub trait OutputField<'a>: Sized {
    /// The message type the port carries (what its [`OutputRef`] is typed by).
    type Message: Message;
    /// The port's declaration.
    fn decl(port: &str) -> PortDecl;
    /// Binds the field to its cell.
    fn bind(cell: &'a mut ErasedOutput) -> Self;
    /// The cell for output `idx`: a publisher (runtime) or memory (harness).
    fn make(maker: &PortMaker<'_>, idx: usize) -> Result<ErasedOutput, crate::SdkError>;
}

impl<'a, T: Message> OutputField<'a> for Output<'a, T> {
    type Message = T;
    fn decl(port: &str) -> PortDecl {
        PortDecl::of::<T>(port)
    }
    fn bind(cell: &'a mut ErasedOutput) -> Self {
        // Cells are made by `new_cell` of this same field type, so the downcast cannot fail.
        #[allow(clippy::expect_used)]
        let cell = cell
            .as_any_mut()
            .downcast_mut::<OutputCell<T>>()
            .expect("output cell of the declared type");
        Output { cell }
    }
    fn make(maker: &PortMaker<'_>, idx: usize) -> Result<ErasedOutput, crate::SdkError> {
        Ok(match maker.node {
            None => Box::new(OutputCell::<T>::memory()),
            Some(node) => {
                let topic = maker.topic(idx)?;
                Box::new(OutputCell::shm(
                    crate::services::publisher::<T>(node, &topic)?,
                    crate::services::notifier(node, &crate::names::topic(&topic))?,
                ))
            }
        })
    }
}

/// The reference to output `name`, a field of type `F` of the output struct `Of`, carrying
/// `T` (generated code uses it: the bound checks the type the derive read off the field).
pub const fn output_ref<'a, F: OutputField<'a, Message = T>, T, Of>(
    name: &'static str,
) -> OutputRef<T, Of> {
    OutputRef::new(name)
}

/// A proposal on an actuator channel: written like an [`Output`]; the device serving the
/// channel arbitrates among the cycle's proposals by the proposers' priorities.
pub struct Proposal<'a, T: Message> {
    inner: Output<'a, T>,
}

impl<T: Message> Proposal<'_, T> {
    /// Proposes this command for the cycle.
    pub fn set(&mut self, value: T) {
        self.inner.set(value);
    }
    /// The command to fill in place.
    pub fn get_mut(&mut self) -> &mut T {
        self.inner.get_mut()
    }
    /// Whether the body proposed in this run.
    pub fn is_written(&self) -> bool {
        self.inner.is_written()
    }
}

impl<'a, T: Message> OutputField<'a> for Proposal<'a, T> {
    type Message = T;
    fn decl(port: &str) -> PortDecl {
        PortDecl::channel::<T>(port, PortKind::Proposal)
    }
    fn bind(cell: &'a mut ErasedOutput) -> Self {
        Proposal {
            inner: <Output<'a, T> as OutputField<'a>>::bind(cell),
        }
    }
    fn make(maker: &PortMaker<'_>, idx: usize) -> Result<ErasedOutput, crate::SdkError> {
        <Output<'a, T> as OutputField<'a>>::make(maker, idx)
    }
}

/// A skill's outputs. Derive it with `#[derive(Outputs)]`; `()` is "no outputs".
pub trait OutputSet<'a>: Sized {
    /// Declarations in field order.
    fn ports() -> Vec<PortDecl>;
    /// Binds every field to its cell, in order.
    fn bind(slots: &'a mut [ErasedOutput]) -> Self;
    /// One cell per field, in order.
    fn make(maker: &PortMaker<'_>) -> Result<Vec<ErasedOutput>, crate::SdkError>;
}

impl<'a> OutputSet<'a> for () {
    fn ports() -> Vec<PortDecl> {
        Vec::new()
    }
    fn bind(_: &'a mut [ErasedOutput]) -> Self {}
    fn make(_: &PortMaker<'_>) -> Result<Vec<ErasedOutput>, crate::SdkError> {
        Ok(Vec::new())
    }
}
