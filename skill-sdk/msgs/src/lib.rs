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

/// What one sonar of the ring heard, as [`Sonar::echo`] decodes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Echo {
    /// An echo from this far (m, from the ring).
    Range(f64),
    /// No echo: nothing within the sonar's reach.
    Silent,
}

impl Echo {
    /// The range (m), or `far` when there was no echo.
    pub fn range_or(self, far: f64) -> f64 {
        match self {
            Echo::Range(r) => r,
            Echo::Silent => far,
        }
    }
}

/// The ring's wire convention, decoded here and nowhere else: in `range`, ∞ is "no echo" (as
/// in ROS `sensor_msgs/Range`) and NaN "never read" (with an `age_ms` of ∞). C, C++ and
/// Python skills read the same two arrays.
impl Sonar {
    /// What sonar `i` heard last; `None` if it was never read.
    pub fn echo(&self, i: usize) -> Option<Echo> {
        match self.range[i] {
            r if r.is_nan() => None,
            r if r == f64::INFINITY => Some(Echo::Silent),
            r => Some(Echo::Range(r)),
        }
    }

    /// Records sonar `i`'s newest reading, `age_ms` old.
    pub fn set_reading(&mut self, i: usize, echo: Echo, age_ms: f64) {
        self.range[i] = echo.range_or(f64::INFINITY);
        self.age_ms[i] = age_ms;
    }

    /// Records that sonar `i` was never read.
    pub fn set_unread(&mut self, i: usize) {
        self.range[i] = f64::NAN;
        self.age_ms[i] = f64::INFINITY;
    }
}

/// The shared message type called `type_name`.
pub fn find(type_name: &str) -> Option<&'static MessageType> {
    registry().iter().find(|t| t.type_name == type_name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sonar_reading_survives_the_wire_convention() {
        let mut s = Sonar::default();
        s.set_reading(0, Echo::Range(1.5), 20.0);
        s.set_reading(1, Echo::Silent, 30.0);
        s.set_unread(2);
        assert_eq!(s.echo(0), Some(Echo::Range(1.5)));
        assert_eq!(s.echo(1), Some(Echo::Silent));
        assert_eq!(s.echo(2), None);
        // What C, C++ and Python skills read.
        assert_eq!((s.range[1], s.age_ms[1]), (f64::INFINITY, 30.0));
        assert!(s.range[2].is_nan() && s.age_ms[2] == f64::INFINITY);
        assert_eq!(Echo::Silent.range_or(10.0), 10.0);
    }
}
