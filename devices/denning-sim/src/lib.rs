//! The simulated Denning robot: its world (walls, boxes, door, barcodes) and its model
//! (kinematics, sonar ring, camera). The `denning-sim` binary puts it behind a pty; tools and
//! tests can step it in-process; [`truth`] is its ground-truth record, written and read back.

pub mod sim;
pub mod truth;
pub mod world;
