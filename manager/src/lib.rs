//! # skillfab
//!
//! The skill manager daemon and the `skillfab` command line.
//!
//! ## Layout
//! - [`engine`]: the cycle engine (registry, readiness, deadlines, liveness, stats).
//! - [`graph`]: wiring checks and the per-cycle plan, pure.
//! - [`stats`]: latency percentiles and the run report.
//! - [`launch`]: launch files, parsed then validated.
//! - [`up`]: `skillfab up`, a manager plus supervised processes.
//!
//! `src/main.rs` only parses arguments and calls into these.

pub mod engine;
pub mod graph;
pub mod launch;
pub mod stats;
pub mod up;
