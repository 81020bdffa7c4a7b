//! The fabric's shared message types. They are declared once, in `msg/skillfab/*.msg`
//! (docs/messages.md); the build script generates the Rust types from them, and the C header
//! and the Python module are generated from the same schemas (`skillfab schema`).

use skill_sdk::foreign::MessageType;

pub mod dynamic;

include!(concat!(env!("OUT_DIR"), "/skillfab.rs"));

/// Number of sonars on the Denning ring (the length of [`Sonar`]'s arrays).
pub const SONARS: usize = 24;

const _: () = assert!(std::mem::size_of::<Sonar>() == 2 * SONARS * 8);

impl skill_sdk::actuation::Actuation for Drive {
    /// Stop.
    fn safe() -> Self {
        Drive::default()
    }
}

/// The shared message type called `type_name`.
pub fn find(type_name: &str) -> Option<&'static MessageType> {
    registry().iter().find(|t| t.type_name == type_name)
}
