//! # skillfab
//!
//! The skill manager daemon and the `skillfab` command line.
//!
//! ## Layout
//! - [`engine`]: the cycle engine (registry, readiness, deadlines, liveness, stats).
//! - [`graph`]: wiring checks and the per-cycle plan, pure.
//! - [`control`]: the control plane (requests, events); [`monitors`]: conditions on live outputs.
//! - [`stats`]: latency percentiles and the run report.
//! - [`launch`]: launch files, parsed then validated.
//! - [`up`]: `skillfab up`, a manager plus supervised processes.
//! - [`recorder`]: the fabric log (parameter changes, I/O samples) as JSON lines.
//! - [`console`]: `skillfab console`, the terminal debugging interface.
//!
//! `src/main.rs` only parses arguments and calls into these.

pub mod console;
pub mod control;
pub mod ctl;
pub mod demo;
pub mod engine;
pub mod graph;
pub mod launch;
pub mod monitors;
pub mod recorder;
pub mod stats;
pub mod up;
