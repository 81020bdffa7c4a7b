//! Ports of message types known only by their schema: a type declared in a message file that
//! no Rust code of this process was compiled with (a C or Python skill using its own package,
//! found on `SKILLFAB_MSG_PATH`). They open the same iceoryx2 services as typed ports of that
//! type (same type name, size and alignment) and hand the body the message's bytes, zero-copy.

use crate::header::SampleHeader;
use crate::ports::{ErasedInput, ErasedOutputCell, PortMaker};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use iceoryx2::service::marker::{CustomHeaderMarker, CustomPayloadMarker};
use std::any::Any;
use std::mem::MaybeUninit;

/// The newest sample's bytes, as a raw input hands them out through `&dyn Any`: valid while
/// the input holds the sample (until its next poll), which the runtime guarantees for a run.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RawView {
    ptr: *const u8,
    len: usize,
}

/// The bytes behind a [`RawView`] held as `&dyn Any`.
pub(crate) fn view_bytes(any: &dyn Any) -> Option<&[u8]> {
    let v = any.downcast_ref::<RawView>()?;
    // SAFETY: the view points into the payload of the sample its input holds, `len` bytes,
    // mapped and unchanged while held; the borrow of `any` does not outlive the run.
    Some(unsafe { std::slice::from_raw_parts(v.ptr, v.len) })
}

/// An input of a schema-only type.
pub(crate) struct RawInput {
    subscriber: Subscriber<ipc::Service, [CustomPayloadMarker], SampleHeader>,
    latest: Option<Sample<ipc::Service, [CustomPayloadMarker], SampleHeader>>,
    view: Option<RawView>,
    size: usize,
    fresh: bool,
}

/// Builds input `idx` (its declaration carries the schema).
pub(crate) fn make_input(
    maker: &PortMaker<'_>,
    idx: usize,
) -> Result<Box<dyn ErasedInput>, crate::SdkError> {
    let node = maker.node.ok_or(crate::SdkError::NoNode)?;
    let port = maker.port(idx)?;
    let schema = &port.schema;
    Ok(Box::new(RawInput {
        subscriber: crate::services::raw_subscriber(node, &port.topic, schema)?,
        latest: None,
        view: None,
        size: schema.size as usize,
        fresh: false,
    }))
}

impl ErasedInput for RawInput {
    fn poll(&mut self) -> Result<(), crate::SdkError> {
        loop {
            match self.subscriber.receive() {
                Ok(Some(s)) => {
                    self.view = Some(RawView {
                        ptr: s.payload().as_ptr().cast::<u8>(),
                        len: self.size,
                    });
                    self.latest = Some(s);
                    self.fresh = true;
                }
                Ok(None) => return Ok(()),
                Err(e) => return Err(crate::SdkError::transport("receive (untyped)", e)),
            }
        }
    }
    fn latest_header(&self) -> Option<SampleHeader> {
        self.latest.as_ref().map(|s| *s.user_header())
    }
    fn latest_any(&self) -> Option<&dyn Any> {
        self.view.as_ref().map(|v| v as &dyn Any)
    }
    fn is_fresh(&self) -> bool {
        self.fresh
    }
    fn consume(&mut self) {
        self.fresh = false;
    }
}

type RawLoan =
    SampleMutUninit<ipc::Service, [MaybeUninit<CustomPayloadMarker>], CustomHeaderMarker>;

/// An output of a schema-only type.
pub(crate) struct RawOutput {
    publisher: Publisher<ipc::Service, [CustomPayloadMarker], CustomHeaderMarker>,
    notifier: iceoryx2::port::notifier::Notifier<ipc::Service>,
    pending: Option<RawLoan>,
    size: usize,
    type_name: String,
    /// Loaned samples (by address) zeroed once: only this publisher writes them after.
    initialised: std::collections::HashSet<usize>,
}

/// Builds output `idx` (its declaration carries the schema).
pub(crate) fn make_output(
    maker: &PortMaker<'_>,
    idx: usize,
) -> Result<crate::ports::ErasedOutput, crate::SdkError> {
    let node = maker.node.ok_or(crate::SdkError::NoNode)?;
    let port = maker.port(idx)?;
    let schema = &port.schema;
    Ok(Box::new(RawOutput {
        publisher: crate::services::raw_publisher(node, &port.topic, schema)?,
        notifier: crate::services::notifier(node, &crate::names::topic(&port.topic))?,
        pending: None,
        size: schema.size as usize,
        type_name: schema.type_name.clone(),
        initialised: std::collections::HashSet::new(),
    }))
}

impl ErasedOutputCell for RawOutput {
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
    fn is_written(&self) -> bool {
        self.pending.is_some()
    }
    fn commit(&mut self, header: SampleHeader) -> Result<bool, crate::SdkError> {
        let Some(mut s) = self.pending.take() else {
            return Ok(false);
        };
        let h: *mut CustomHeaderMarker = s.user_header_mut();
        // SAFETY: the service's user header is declared as a `SampleHeader` (size and
        // alignment), so the header slot holds one.
        unsafe { h.cast::<SampleHeader>().write(header) };
        // SAFETY: every byte of the payload was zeroed when first loaned and only written as
        // bytes since.
        let s = unsafe { s.assume_init() };
        s.send()
            .map_err(|e| crate::SdkError::transport(&format!("send on {}", self.type_name), e))?;
        Ok(true)
    }
    fn announce(&self) {
        if let Err(e) = self.notifier.notify() {
            tracing::warn!(type_name = %self.type_name, error = ?e, "event notification failed");
        }
    }
    fn discard(&mut self) {
        self.pending = None;
    }
    fn prepare(&mut self) {}
    fn take_memory(&mut self) -> Option<Box<dyn Any>> {
        None
    }
    fn bytes_mut(&mut self, clear: bool) -> &mut [u8] {
        if self.pending.is_none() {
            let publisher = &self.publisher;
            // SAFETY: the type variant is fixed-size, so one element is loaned.
            let loan = || unsafe { publisher.loan_custom_payload(1) };
            match crate::allocs::in_loan(loan) {
                Ok(s) => self.pending = Some(s),
                Err(e) => {
                    tracing::error!(type_name = %self.type_name, error = ?e, "no sample to loan");
                }
            }
        }
        let Some(s) = self.pending.as_mut() else {
            return &mut [];
        };
        let p = s.payload_mut().as_mut_ptr().cast::<u8>();
        if clear || self.initialised.insert(p as usize) {
            // SAFETY: the loan holds `size` writable bytes at `p`.
            unsafe { std::ptr::write_bytes(p, 0, self.size) };
        }
        // SAFETY: `size` bytes, initialised above (now or when first loaned), exclusively
        // borrowed from `self` for the returned lifetime.
        unsafe { std::slice::from_raw_parts_mut(p, self.size) }
    }
}
