//! # skillfab-manager
//!
//! The skill manager of a domain (the paper's do-periodic-step and update-record) and the
//! supervisor that starts a launch file's processes around it. The `skillfab-manager` binary
//! runs either; `skillfab manager …` and `skillfab up …` run that binary.
//!
//! ## Layout
//! - [`engine`]: the manager, its state in parts that each own one job: the loop and report
//!   (`mod.rs`), the cycle state machine (`cycle.rs`), the registry (`skills.rs`) with
//!   registration and liveness (`registry.rs`), the observers (`observers.rs`, `record.rs`),
//!   the clients' holds (`holds.rs`), the state file (`state.rs`), and the requests, whose
//!   handlers get the parts they need and return typed effects (`requests/`).
//! - [`graph`]: wiring checks and the per-cycle plan, pure.
//! - [`control`]: the control plane's transport (requests in, answers and events out, on a
//!   thread of its own); [`monitors`]: conditions on live outputs — the installed ones and
//!   their bookkeeping ([`monitors::Monitors`]), and their expression language.
//! - [`stats`]: latency percentiles and the run report.
//! - [`recorder`]: the fabric log (parameter changes, I/O samples) as JSON lines or MCAP.
//! - [`launch`]: launch files, parsed then validated; [`up`]: a manager plus supervised
//!   processes.
//! - [`args`]: the command-line arguments of `manager` and `up`, shared with `skillfab`.

#![warn(missing_docs)]

pub mod args;
pub mod checks;
pub mod control;
pub mod engine;
pub mod graph;
pub mod launch;
pub mod monitors;
pub mod recorder;
pub mod stats;
pub mod up;
