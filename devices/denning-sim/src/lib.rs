//! The simulated Denning robot: its world (walls, boxes, door, barcodes) and its model
//! (kinematics, sonar ring, camera). The `denning-sim` binary puts it behind a pty; tools and
//! tests can step it in-process.

pub mod sim;
pub mod world;
