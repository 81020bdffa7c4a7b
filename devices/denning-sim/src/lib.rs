//! The simulated Denning robot and the places it lives in. The `denning-sim` binary puts it
//! behind a pty; tools and tests can step it in-process.
//!
//! - [`world`]: a one-room world file (walls, boxes, door, barcodes) and the ray geometry.
//! - [`building`]: a building file: floors laid out like worlds, an elevator bank, the goal,
//!   and the barcode conventions the skills rely on.
//! - [`elevator`]: the cars — doors, calls, light curtain, other passengers' traffic.
//! - [`site`]: a building with the robot in it: its floor, the car it rides, and what its body
//!   and sensors meet there.
//! - [`sim`]: the robot (kinematics, sonar ring, camera, button pusher, speaker) in a world
//!   or a building.
//! - [`truth`]: its ground-truth record, written and read back.

#![warn(missing_docs)]

pub mod building;
pub mod elevator;
pub mod sim;
pub mod site;
pub mod truth;
pub mod world;
