//! The fabric's shared message types. They are declared once, in `msg/skillfab/*.msg`
//! (docs/messages.md); the build script generates the Rust types from them, and the C header
//! and the Python module are generated from the same schemas (`skillfab schema`).

#![warn(missing_docs)]

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

impl skill_sdk::actuation::Actuation for Push {
    /// Retracted.
    fn safe() -> Self {
        Push::default()
    }
}

impl skill_sdk::actuation::Actuation for Say {
    /// Silent (seq 0).
    fn safe() -> Self {
        Say::new(0, "")
    }
}

impl Say {
    /// Message number `seq` saying `text` (cut to 64 bytes at a character boundary).
    pub fn new(seq: u32, text: &str) -> Say {
        let mut end = text.len().min(64);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        let mut s = Say {
            seq,
            len: end as u32,
            text: [0; 64],
        };
        s.text[..end].copy_from_slice(&text.as_bytes()[..end]);
        s
    }

    /// The text.
    pub fn text(&self) -> &[u8] {
        &self.text[..(self.len as usize).min(64)]
    }
}

/// The shared message type called `type_name`.
pub fn find(type_name: &str) -> Option<&'static MessageType> {
    registry().iter().find(|t| t.type_name == type_name)
}
