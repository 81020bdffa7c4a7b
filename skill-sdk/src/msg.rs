//! The fabric's shared message types: the one place where they are defined.

use crate::prelude::Message;

/// A cycle tick (the hello network's `ticker`).
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Tick")]
#[repr(C)]
pub struct Tick {
    /// The cycle number.
    pub value: u64,
}

/// A scaled value (the hello network's `scale`).
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Scaled")]
#[repr(C)]
pub struct Scaled {
    /// gain × tick.
    pub value: f64,
}

/// A smoothed value (the hello network's `smooth`).
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Smoothed")]
#[repr(C)]
pub struct Smoothed {
    /// Exponential moving average.
    pub value: f64,
    /// Number of samples folded in.
    pub samples: u64,
}

/// A generic scalar, for test and example networks.
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Scalar")]
#[repr(C)]
pub struct Scalar {
    /// The value.
    pub value: f64,
    /// Monotonic clock (ns) when the producing run started (for overlap checks).
    pub start_ns: u64,
    /// Monotonic clock (ns) when the producing run finished its work.
    pub end_ns: u64,
}

/// A large block of bytes, for zero-copy payload tests and benchmarks.
#[derive(Message, Debug, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Blob64K")]
#[repr(C)]
pub struct Blob64K {
    /// Number of meaningful bytes.
    pub len: u64,
    /// The bytes.
    pub data: [u8; 65536],
}

/// A synchro-drive command: the `drive` actuator channel.
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Drive")]
#[repr(C)]
pub struct Drive {
    /// Translate velocity (m/s, forward positive).
    pub translate: f64,
    /// Rotate velocity (rad/s, counter-clockwise positive).
    pub rotate: f64,
}

impl crate::actuation::Actuation for Drive {
    /// Stop.
    fn safe() -> Self {
        Drive::default()
    }
}
