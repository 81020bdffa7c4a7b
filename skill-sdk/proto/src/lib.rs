//! # skillfab-proto
//!
//! The contract every process of a fabric shares: what lives in a domain's shared memory and
//! what travels between the manager, the skills and the clients. No skill API and no manager
//! logic live here — only the wire, so every other crate can depend on it and on nothing else
//! of the fabric.
//!
//! ## Layout
//! - [`domain`], [`names`], [`services`]: a domain's iceoryx2 namespace, every service name,
//!   and the service builders (sized explicitly) both sides open.
//! - [`board`]: the cycle board, the shared-memory page through which the manager starts
//!   cycles and skills report their runs.
//! - [`header`]: the user header of every data sample (cycle, stamp, slot).
//! - [`schema`], [`value`]: message layouts ([`Message`]), and decoding a sample through its
//!   schema (values, `skill.output[.field][index]` paths).
//! - [`decl`], [`param`]: a skill's declaration (ports, parameters, mode, priority).
//! - [`refs`]: typed references to parameters, ports and message fields (what the derives
//!   generate), and typed value paths built from them.
//! - [`control`]: the control plane, in files named by direction
//!   ([`control::client_to_manager`], [`control::manager_to_client`]) and the event stream.
//! - [`log`]: the log stream's lines and its reader.
//! - [`json`]: values, skills and events as JSON (`ctl --json`, the fabric log, the C ABI).
//! - [`cdr`], [`ros2msg`]: samples as ROS 2's CDR and message schemas as ROS 2 message
//!   definitions (what a recording's sample channels hold, for the ROS tools).
//! - [`realtime`]: real-time mode of a thread (scheduling class, CPU affinity, locked
//!   memory), applied by skills and the manager alike, and what the machine refused.

#![warn(missing_docs)]

extern crate self as skillfab_proto;

pub mod board;
pub mod bridge;
pub mod cdr;
pub mod clean;
pub mod control;
pub mod decl;
pub mod domain;
pub mod doorbell;
pub mod header;
pub mod json;
pub mod log;
pub mod names;
pub mod param;
pub mod realtime;
pub mod refs;
pub mod registration;
pub mod ros2msg;
pub mod schema;
pub mod services;
pub mod value;

/// A fixed-size `#[repr(C)]` message type. Derive it with `#[derive(Message)]` (skill-sdk's
/// prelude).
pub trait Message:
    iceoryx2::prelude::ZeroCopySend + schema::FieldType + std::fmt::Debug + Copy + 'static
{
    /// The type name every process and language uses (also iceoryx2's type name).
    const TYPE_NAME: &'static str;
    /// Layout description.
    fn schema() -> schema::MessageSchema;
}

/// Errors of the fabric's plumbing: names, the board, iceoryx2 services.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
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
    /// The domain's files cannot be made private to this user.
    #[error("domain '{domain}': {path}: {reason}")]
    DomainAccess {
        /// The domain.
        domain: String,
        /// The directory or file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// An iceoryx2 operation failed. iceoryx2's error is kept as it was (downcast `cause` to
    /// tell an exhausted segment from too many loans) and is part of the message, which is
    /// what C and Python skills and the logs show.
    #[error("{what}: {cause}")]
    Transport {
        /// What was attempted.
        what: String,
        /// iceoryx2's error.
        cause: Box<dyn std::error::Error + Send + Sync>,
    },
    /// Encoding or decoding a declaration failed.
    #[error("declaration encoding: {0}")]
    Encoding(#[from] postcard::Error),
}

impl Error {
    /// A failed iceoryx2 operation: `what` was attempted, `e` is iceoryx2's error (kept as
    /// the cause).
    pub fn transport(what: &str, e: impl std::error::Error + Send + Sync + 'static) -> Error {
        Error::Transport {
            what: what.to_string(),
            cause: Box::new(e),
        }
    }
}

#[doc(hidden)]
pub mod __private {
    pub use iceoryx2::prelude::ZeroCopySend;
}
