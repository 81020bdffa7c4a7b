//! # skill-sdk
//!
//! Everything a skillfab skill is written with, and the client side of the fabric.
//!
//! ## Layout
//! - [`skill`]: the [`Skill`](skill::Skill) trait a skill author implements.
//! - [`ports`], [`params`], [`schema`], [`msg`]: inputs/outputs, typed parameters, message
//!   layouts, and the shared message types.
//! - [`runtime`]: turns a `Skill` into a process (registration, cycles, shutdown); [`main`]
//!   is a skill binary's whole `main`.
//! - [`logs`]: each skill's tracing lines, forwarded over the domain's log stream.
//! - [`harness`]: runs a skill body in-process on scripted inputs, for unit tests.
//! - [`board`], [`names`], [`services`], [`domain`], [`header`]: the wiring shared with the
//!   manager (cycle board, service names, iceoryx2 settings, domains, sample header).
//!
//! A minimal skill (see `skills/src/bin/scale.rs`):
//! ```no_run
//! use skill_sdk::prelude::*;
//! use skill_sdk::msg::{Scaled, Tick};
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

extern crate self as skill_sdk;

pub mod actuation;
pub mod board;
pub mod client;
pub mod codegen;
pub mod control;
pub mod decl;
pub mod device;
pub mod domain;
pub mod expr;
pub mod foreign;
pub mod harness;
pub mod header;
pub mod json;
pub mod logs;
pub mod msg;
pub mod names;
pub mod params;
pub mod ports;
pub mod runtime;
pub mod schema;
pub mod services;
pub mod skill;
pub mod value;

pub use runtime::{device_main, main};

/// A fixed-size `#[repr(C)]` message type. Derive it with `#[derive(Message)]`.
pub trait Message:
    iceoryx2::prelude::ZeroCopySend + schema::FieldType + std::fmt::Debug + Copy + 'static
{
    /// The type name every process and language uses (also iceoryx2's type name).
    const TYPE_NAME: &'static str;
    /// Layout description.
    fn schema() -> schema::MessageSchema;
}

/// Errors of the SDK and the fabric's plumbing.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SdkError {
    /// A domain name that is not allowed.
    #[error("bad domain name '{name}': use 1-40 of [A-Za-z0-9.-]")]
    BadDomain {
        /// The name given.
        name: String,
    },
    /// A skill or topic name that is not allowed.
    #[error("bad {what} name '{name}': use 1-64 of [A-Za-z0-9_-]")]
    BadName {
        /// Skill or topic.
        what: String,
        /// The name given.
        name: String,
    },
    /// The cycle board could not be opened or created.
    #[error("cycle board {name}: {source}")]
    Board {
        /// Its shared-memory name.
        name: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The board exists but its manager has not finished setting it up.
    #[error("the cycle board is not ready yet")]
    BoardNotReady,
    /// Another manager owns the domain.
    #[error("a manager (pid {pid}) already runs in this domain")]
    ManagerRunning {
        /// Its pid.
        pid: u32,
    },
    /// The declaration does not fit the board.
    #[error("skill declaration is {len} bytes, more than the {max} the board holds")]
    DeclTooLarge {
        /// Encoded size.
        len: usize,
        /// Room.
        max: usize,
    },
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
        /// The manager's reason.
        reason: String,
    },
    /// A parameter given at start-up was refused.
    #[error(transparent)]
    Param(#[from] params::ParamError),
    /// A `--remap` that names no port.
    #[error("--remap {port}=...: the skill has no port '{port}'")]
    UnknownPort {
        /// The name given.
        port: String,
    },
    /// An iceoryx2 operation failed.
    #[error("{what}: {detail}")]
    Transport {
        /// What was attempted.
        what: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// Encoding or decoding a declaration failed.
    #[error("declaration encoding: {0}")]
    Encoding(#[from] postcard::Error),
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

/// What skill code imports.
pub mod prelude {
    pub use crate::Message;
    pub use crate::actuation::{Actuation, Command};
    pub use crate::decl::Mode;
    pub use crate::device::{Device, DeviceOptions};
    pub use crate::params::{NoParams, Params};
    pub use crate::ports::{Input, Output, Proposal};
    pub use crate::skill::{Ctx, Skill, SkillError, SkillResult};
    pub use skill_sdk_macros::{Inputs, Message, Outputs, Params};
}

#[doc(hidden)]
pub mod __private {
    pub use iceoryx2::prelude::ZeroCopySend;
}
