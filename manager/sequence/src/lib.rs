//! `skillfab sequence`: a sequencer that is a plan, not a hand-written state machine.
//!
//! A plan is a BehaviorTree.CPP v4 XML file (the format of Nav2, editable in Groot): control
//! nodes (`Sequence`, `Fallback`, `Parallel`), decorators (`RetryUntilSuccessful`,
//! `Timeout`, `Inverter`, `ForceSuccess`, `ForceFailure`, and `WithParam`: a parameter set
//! while its child runs, restored after) and the fabric's actions (`Activate`, `Deactivate`,
//! `SetParam`, `WaitFor` a monitor condition, `Sleep`, `Log`). Times are the fabric's (cycle ×
//! period), so a plan run in lock-step is as deterministic as the skills. See
//! docs/sequence.md.
//!
//! Layout: [`plan`] reads and checks the file; [`tree`] is the behaviour tree engine over a
//! [`tree::Fabric`] (unit-tested without a fabric); [`live`] reports each node's status to
//! the manager (the plan as a live tree); [`run`] drives a real one through the client
//! library.

#![warn(missing_docs)]

pub mod keep;
pub mod live;
pub mod plan;
pub mod run;
pub mod tree;

#[cfg(test)]
mod tests;

pub use keep::{Kept, PlanState, PlanStore};
pub use live::LiveTree;
pub use plan::{Plan, PlanError, Reference, Use};
pub use run::{ClientFabric, LockStep, Opening, Sequencer, run};
pub use tree::{Fabric, FabricError, SeqError, Status};
