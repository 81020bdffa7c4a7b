//! The fabric's shared message types: the one place where they are defined.

use skill_sdk::foreign::MessageType;
use skill_sdk::prelude::Message;

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

impl skill_sdk::actuation::Actuation for Drive {
    /// Stop.
    fn safe() -> Self {
        Drive::default()
    }
}

/// Number of sonars on the Denning ring.
pub const SONARS: usize = 24;

/// The sonar ring: 24 sonars 15° apart, sonar 0 facing forward, counter-clockwise.
#[derive(Message, Debug, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Sonar")]
#[repr(C)]
pub struct Sonar {
    /// Latest range of each sonar (m); `f64::INFINITY`: no echo; NaN: never read.
    pub range: [f64; SONARS],
    /// Age of each reading (ms).
    pub age_ms: [f64; SONARS],
}

/// Dead-reckoned pose and velocities.
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Odometry")]
#[repr(C)]
pub struct Odometry {
    /// x (m), from where the device connected.
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// Heading (rad).
    pub theta: f64,
    /// Translate velocity (m/s).
    pub v: f64,
    /// Rotate velocity (rad/s).
    pub w: f64,
}

/// Contact sensing.
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Bumpers")]
#[repr(C)]
pub struct Bumpers {
    /// Bit i: bumper segment i hit (front first, clockwise).
    pub hit: u32,
    /// Whether the drive stalls.
    pub stall: bool,
}

/// Battery voltage.
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Battery")]
#[repr(C)]
pub struct Battery {
    /// Volts.
    pub volts: f64,
}

/// Barcode sightings of the latest camera frame.
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Barcodes")]
#[repr(C)]
pub struct Barcodes {
    /// Number of valid entries.
    pub count: u32,
    /// Barcode ids.
    pub id: [u32; 8],
    /// Bearings (rad, counter-clockwise from the front).
    pub bearing: [f64; 8],
    /// Ranges (m).
    pub range: [f64; 8],
    /// Age of the sightings (ms).
    pub age_ms: f64,
}

/// The state of a device's link to its hardware.
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Link")]
#[repr(C)]
pub struct Link {
    /// Whether the link is up.
    pub connected: bool,
    /// Age of the latest data (ms).
    pub age_ms: f64,
    /// Good frames received.
    pub frames: u64,
    /// Frames dropped (bad checksum or COUNT).
    pub bad_frames: u64,
    /// Bytes skipped as garbage.
    pub garbage: u64,
    /// Successful handshakes.
    pub connects: u64,
}

/// A tracked barcode, in the odometry frame.
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Target")]
#[repr(C)]
pub struct Target {
    /// Whether it has been seen at all.
    pub seen: bool,
    /// Whether it is in view in this cycle.
    pub visible: bool,
    /// Its id.
    pub id: u32,
    /// Estimated position (m, odometry frame).
    pub x: f64,
    /// Estimated position (m, odometry frame).
    pub y: f64,
    /// Distance from the robot now (m).
    pub range: f64,
    /// Bearing from the robot's heading now (rad).
    pub bearing: f64,
}

/// A located door opening, in the odometry frame.
#[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
#[message(type_name = "skillfab.Door")]
#[repr(C)]
pub struct Door {
    /// Whether an opening was found.
    pub found: bool,
    /// Centre of the opening (m, odometry frame).
    pub x: f64,
    /// Centre of the opening (m, odometry frame).
    pub y: f64,
    /// Direction to drive through it (rad, odometry frame).
    pub heading: f64,
    /// Width of the opening (m).
    pub width: f64,
}

/// Every shared message type, in the order the generated C header and Python module list
/// them: what a skill declared at run time (C, C++, Python) may name its ports' types with.
pub fn registry() -> &'static [MessageType] {
    static REGISTRY: [MessageType; 14] = [
        MessageType::of::<Tick>(),
        MessageType::of::<Scaled>(),
        MessageType::of::<Smoothed>(),
        MessageType::of::<Scalar>(),
        MessageType::of::<Blob64K>(),
        MessageType::of::<Drive>(),
        MessageType::of::<Sonar>(),
        MessageType::of::<Odometry>(),
        MessageType::of::<Bumpers>(),
        MessageType::of::<Battery>(),
        MessageType::of::<Barcodes>(),
        MessageType::of::<Link>(),
        MessageType::of::<Target>(),
        MessageType::of::<Door>(),
    ];
    &REGISTRY
}

/// The shared message type called `type_name`.
pub fn find(type_name: &str) -> Option<&'static MessageType> {
    registry().iter().find(|t| t.type_name == type_name)
}
