//! The Denning-style robot's client side.
//!
//! ## Layout
//! - [`codec`]: the frame codec of `PROTOCOL.md` — pure, unit-, property- and fuzz-tested.
//! - [`transport`]: byte transports: a serial port (a real tty or the simulator's pty) and an
//!   in-memory fake for unit tests.
//! - [`driver`]: the thread that owns the port: handshake, reading, the latest sample,
//!   commands, keep-alive, resynchronisation and reconnection.
//! - [`safety`]: the speed limit no skill can override — by the nearest fresh echo along the
//!   direction of travel and by the link's health (pure).
//!
//! The device process that puts this robot on a fabric is `device/` (crate `denning-device`).

#![warn(missing_docs)]

pub mod codec;
pub mod driver;
pub mod safety;
pub mod transport;
