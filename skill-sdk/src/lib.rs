//! # skill-sdk
//!
//! Everything a skillfab skill is written with: the `Skill` trait, ports, parameters, the
//! runtime that makes a skill a process, and its test harness. (Sequencers and tools talk to
//! the manager through `skillfab-client`; the message types are in `skillfab-msgs`.)
//!
//! ## Layout
//! - [`skill`]: the [`Skill`](skill::Skill) trait a skill author implements; [`state`]: what
//!   of a skill the runtime keeps across the deaths of its process.
//! - [`ports`], [`params`]: inputs/outputs and typed parameters; [`Message`]: what a port
//!   carries (derived for the types of `skillfab-msgs`).
//! - [`actuation`]: proposing on actuator channels; [`device`]: device processes (the
//!   arbitration's other side); [`foreign`]: skills declared at run time (the C ABI, replay).
//! - `runtime`: turns a `Skill` into a process (registration, cycles, shutdown); [`main`]
//!   is a skill binary's whole `main`, [`device_main`] a device's.
//! - [`logs`]: each skill's tracing lines, forwarded over the domain's log stream.
//! - [`allocs`]: the program's global allocator, counting allocations per thread (the check
//!   that a cycle's path does not allocate; feature `count-allocs`, on by default).
//! - [`harness`]: runs a skill body in-process on scripted inputs, for unit tests.
//! - [`refs`]: typed references to parameters, ports and message fields. The derives make
//!   one per field (`P::GAIN`, `In::TICK`, `Out::SCALED`, `Tick::VALUE`): the harness takes
//!   a skill's own, a sequencer's client any (`docs/references.md`).
//!
//! A minimal skill (see `skills/src/bin/scale.rs`):
//! ```no_run
//! use skill_sdk::prelude::*;
//! use skillfab_msgs::{Scaled, Tick};
//!
//! #[derive(Params, Debug, Clone)]
//! struct P { /// Factor applied to the tick.
//!            #[param(default = 2.0, min = -1e6, max = 1e6)] gain: f64 }
//! #[derive(Inputs)]  struct In<'a>  { tick: Input<'a, Tick> }
//! #[derive(Outputs)] struct Out<'a> { scaled: Output<'a, Scaled> }
//! #[derive(Default)] struct Scale;
//! impl Skill for Scale {
//!     type Params = P; type Inputs<'a> = In<'a>; type Outputs<'a> = Out<'a>;
//!     fn compute(&mut self, ctx: &Ctx<P>, i: In, o: &mut Out) -> SkillResult {
//!         o.scaled.set(Scaled { value: ctx.params.gain * i.tick.value as f64 });
//!         Ok(())
//!     }
//! }
//! fn main() -> std::process::ExitCode { skill_sdk::main::<Scale>() }
//! ```
//! Its test ([`harness`]) names ports and parameters by the references the derives made, so
//! a renamed one or a value of another type does not compile: `h.set(P::GAIN, 3.0)`,
//! `h.input(In::TICK, Tick { value: 5 })`, `h.step()?.output(Out::SCALED)`.

#![warn(missing_docs)]

extern crate self as skill_sdk;

pub mod actuation;
pub mod allocs;
pub mod device;
pub mod foreign;
pub mod harness;
pub mod logs;
pub mod params;
pub mod ports;
mod runtime;
pub mod skill;
pub mod state;

// The wire types the SDK is built on, under the names its modules use.
pub(crate) use skillfab_proto::{board, decl, domain, header, names, schema, services, value};

pub use runtime::{DeviceArgs, SkillArgs, Waker, device_main, init_tracing, main};
pub use skillfab_proto::Message;
pub use skillfab_proto::refs;

/// Errors of the SDK: a skill's start-up, declaration and ports.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SdkError {
    /// The fabric's plumbing failed (names, board, iceoryx2).
    #[error(transparent)]
    Fabric(#[from] skillfab_proto::Error),
    /// Every slot of the board is taken.
    #[error("no free skill slot in this domain (at most {max} skills)")]
    BoardFull {
        /// Slot count.
        max: usize,
    },
    /// The manager refused the registration.
    #[error("the manager refused skill '{name}': {reason}")]
    Refused {
        /// Instance name.
        name: String,
        /// Why (boxed: the other errors are small).
        reason: Box<skillfab_proto::registration::Refusal>,
    },
    /// `--describe` could not write the declaration as JSON.
    #[error("writing the declaration (--describe): {0}")]
    Describe(serde_json::Error),
    /// A parameter given at start-up was refused.
    #[error(transparent)]
    Param(#[from] params::ParamError),
    /// A `--remap` that names no port.
    #[error("--remap {port}=...: the skill has no port '{port}'")]
    UnknownPort {
        /// The name given.
        port: String,
    },
    /// `--policy C=blend` on a channel whose command type has non-float fields.
    #[error("channel '{channel}' cannot blend: {type_name} has fields that are not floats")]
    NotBlendable {
        /// Channel.
        channel: String,
        /// Its command type.
        type_name: String,
    },
    /// A device could not open its hardware.
    #[error("device start-up failed: {reason}")]
    DeviceInit {
        /// Why.
        reason: String,
    },
    /// `--policy` with an unknown policy.
    #[error("unknown policy '{policy}': use priority or blend")]
    BadPolicy {
        /// As given.
        policy: String,
    },
    /// A runtime port was asked for without a node.
    #[error("internal: port requested without a node or topic")]
    NoNode,
}

impl SdkError {
    /// A failed iceoryx2 operation: `what` was attempted, `e` is iceoryx2's error.
    pub(crate) fn transport(
        what: &str,
        e: impl std::error::Error + Send + Sync + 'static,
    ) -> SdkError {
        SdkError::Fabric(skillfab_proto::Error::transport(what, e))
    }
}

/// What skill code imports.
pub mod prelude {
    pub use crate::Message;
    pub use crate::actuation::{Actuation, Command};
    pub use crate::decl::Mode;
    pub use crate::device::{Device, DeviceOptions};
    pub use crate::params::{NoParams, Params};
    pub use crate::ports::{Input, Output, Proposal};
    pub use crate::skill::{Clock, Ctx, Skill, SkillError, SkillResult};
    pub use crate::state::State;
    pub use skill_sdk_macros::{Channels, Inputs, Message, Outputs, Params};
}

/// What the derives generate code against; not an API.
#[doc(hidden)]
pub mod __private {
    pub use skillfab_proto as proto;
}
