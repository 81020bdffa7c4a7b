//! # libskillfab — the C ABI of skill-sdk
//!
//! C, C++ and (through `ctypes`) Python programs use this library to be skills and
//! sequencers. The header `include/skillfab.h` is generated from this crate by cbindgen (a
//! test keeps it in sync); the message structs are in `include/skillfab_msgs.h`, generated
//! from the Rust message schemas.
//!
//! ## Layout (one module each)
//! - `error`: every call returns a status (`SF_OK` or a negative `SF_ERR_*`) or a null
//!   pointer, and `sf_last_error()` says what went wrong, in words, on the calling thread;
//! - `skill`: `sf_skill_new`, `sf_skill_input/output/proposal`, `sf_skill_param_*`,
//!   `sf_skill_compute`, then `sf_skill_run` (registration, cycles, parameter updates and
//!   shutdown are the SDK's);
//! - `run`, inside the compute callback: `sf_input`, `sf_output`, `sf_param_*`, `sf_run_cycle`,
//!   `sf_run_fail`;
//! - `client`, a sequencer: `sf_client_*` (activate, parameters, queries, monitors and their events);
//! - `sf_log` (in `run`): a log line on the skill's log stream.
//!
//! Nothing here can crash the process on bad arguments: null pointers, strings that are not
//! UTF-8, unknown message types, wrong sizes and out-of-range indexes are errors, and a
//! panic inside the library is caught at the boundary and reported as `SF_ERR_INTERNAL`.

#![warn(missing_docs)]
#![allow(non_camel_case_types)]

mod client;
mod error;
mod run;
mod skill;
#[cfg(test)]
mod tests;

pub use client::*;
pub use error::sf_last_error;
pub use run::*;
pub use skill::*;

use skill_sdk::foreign::ForeignSkill;
use skillfab_client::Client;
use std::ffi::{CString, c_void};

/// Success.
pub const SF_OK: i32 = 0;
/// A required pointer was NULL.
pub const SF_ERR_NULL: i32 = -1;
/// A name or text that is not allowed (not UTF-8, bad characters, declared twice, ...).
pub const SF_ERR_INVALID: i32 = -2;
/// No shared message type of that name.
pub const SF_ERR_UNKNOWN_TYPE: i32 = -3;
/// A size that does not match the message type.
pub const SF_ERR_SIZE: i32 = -4;
/// An input, output or parameter index that does not exist, or an input with no sample.
pub const SF_ERR_INDEX: i32 = -5;
/// A parameter declaration or value that is refused (bounds, type).
pub const SF_ERR_PARAM: i32 = -6;
/// The fabric failed or refused: no manager, a refused request, a transport error.
pub const SF_ERR_FABRIC: i32 = -7;
/// No answer in time.
pub const SF_ERR_TIMEOUT: i32 = -8;
/// The caller's buffer is too small (the message says how large it must be).
pub const SF_ERR_BUFFER: i32 = -9;
/// A bug in the library, caught at the boundary.
pub const SF_ERR_INTERNAL: i32 = -10;

/// Runs once per cycle when all its inputs for that cycle exist; the cycle waits for it.
pub const SF_SYNC: i32 = 0;
/// Free-running on the latest inputs; the cycle never waits for it.
pub const SF_ASYNC: i32 = 1;

/// Monitor fires the first cycle its condition holds, then is removed.
pub const SF_MONITOR_ONCE: i32 = 0;
/// Monitor fires each cycle its condition becomes true.
pub const SF_MONITOR_EDGE: i32 = 1;
/// Monitor fires every cycle its condition holds.
pub const SF_MONITOR_EVERY: i32 = 2;

/// Log levels of `sf_log`.
pub const SF_LOG_ERROR: i32 = 0;
/// Warning.
pub const SF_LOG_WARN: i32 = 1;
/// Information.
pub const SF_LOG_INFO: i32 = 2;
/// Debugging detail (shown with RUST_LOG=debug or the console's verbose mode).
pub const SF_LOG_DEBUG: i32 = 3;

/// A skill being declared (opaque).
pub struct sf_skill {
    inner: ForeignSkill,
}

/// One run of a skill, valid only during the compute callback (opaque).
pub struct sf_run {
    _private: [u8; 0],
}

/// A sequencer's connection to a domain's manager (opaque).
pub struct sf_client {
    inner: Client,
    /// An event that did not fit the caller's buffer, returned again by the next call.
    pending: Option<CString>,
}

/// The compute callback: return 0 for success, anything else fails the run (its outputs are
/// then not sent). `user` is the pointer given to `sf_skill_compute`.
pub type sf_compute_fn = Option<unsafe extern "C" fn(run: *mut sf_run, user: *mut c_void) -> i32>;
