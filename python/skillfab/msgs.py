"""The shared message types of skillfab as ctypes structures.

Generated from their message files (skill-sdk/msgs/msg/skillfab/) by
`skillfab schema --python`. Do not edit: a test checks this file is what the
generator writes, and that every size and offset matches Rust.
"""

import ctypes


class Barcodes(ctypes.Structure):
    """Barcode sightings of the latest camera frame."""

    TYPE_NAME = "skillfab.Barcodes"
    _fields_ = [
        ("count", ctypes.c_uint32),
        ("id", (ctypes.c_uint32 * 8)),
        ("bearing", (ctypes.c_double * 8)),
        ("range", (ctypes.c_double * 8)),
        ("age_ms", ctypes.c_double),
    ]


class Battery(ctypes.Structure):
    """Battery voltage."""

    TYPE_NAME = "skillfab.Battery"
    _fields_ = [
        ("volts", ctypes.c_double),
    ]


class Blob64K(ctypes.Structure):
    """A large block of bytes, for zero-copy payload tests and benchmarks."""

    TYPE_NAME = "skillfab.Blob64K"
    _fields_ = [
        ("len", ctypes.c_uint64),
        ("data", (ctypes.c_uint8 * 65536)),
    ]


class Bumpers(ctypes.Structure):
    """Contact sensing."""

    TYPE_NAME = "skillfab.Bumpers"
    _fields_ = [
        ("hit", ctypes.c_uint32),
        ("stall", ctypes.c_bool),
    ]


class Door(ctypes.Structure):
    """A located door opening, in the odometry frame."""

    TYPE_NAME = "skillfab.Door"
    _fields_ = [
        ("found", ctypes.c_bool),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("heading", ctypes.c_double),
        ("width", ctypes.c_double),
    ]


class Drive(ctypes.Structure):
    """A synchro-drive command: the `drive` actuator channel."""

    TYPE_NAME = "skillfab.Drive"
    _fields_ = [
        ("translate", ctypes.c_double),
        ("rotate", ctypes.c_double),
    ]


class Link(ctypes.Structure):
    """The state of a device's link to its hardware."""

    TYPE_NAME = "skillfab.Link"
    _fields_ = [
        ("connected", ctypes.c_bool),
        ("age_ms", ctypes.c_double),
        ("frames", ctypes.c_uint64),
        ("bad_frames", ctypes.c_uint64),
        ("garbage", ctypes.c_uint64),
        ("connects", ctypes.c_uint64),
    ]


class Odometry(ctypes.Structure):
    """Dead-reckoned pose and velocities."""

    TYPE_NAME = "skillfab.Odometry"
    _fields_ = [
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("theta", ctypes.c_double),
        ("v", ctypes.c_double),
        ("w", ctypes.c_double),
    ]


class Scalar(ctypes.Structure):
    """A generic scalar, for test and example networks."""

    TYPE_NAME = "skillfab.Scalar"
    _fields_ = [
        ("value", ctypes.c_double),
        ("start_ns", ctypes.c_uint64),
        ("end_ns", ctypes.c_uint64),
    ]


class Scaled(ctypes.Structure):
    """A scaled value (the hello network's `scale`)."""

    TYPE_NAME = "skillfab.Scaled"
    _fields_ = [
        ("value", ctypes.c_double),
    ]


class Smoothed(ctypes.Structure):
    """A smoothed value (the hello network's `smooth`)."""

    TYPE_NAME = "skillfab.Smoothed"
    _fields_ = [
        ("value", ctypes.c_double),
        ("samples", ctypes.c_uint64),
    ]


class Sonar(ctypes.Structure):
    """The sonar ring: 24 sonars 15° apart, sonar 0 facing forward, counter-clockwise."""

    TYPE_NAME = "skillfab.Sonar"
    _fields_ = [
        ("range", (ctypes.c_double * 24)),
        ("age_ms", (ctypes.c_double * 24)),
    ]


class Target(ctypes.Structure):
    """A tracked barcode, in the odometry frame."""

    TYPE_NAME = "skillfab.Target"
    _fields_ = [
        ("seen", ctypes.c_bool),
        ("visible", ctypes.c_bool),
        ("id", ctypes.c_uint32),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("range", ctypes.c_double),
        ("bearing", ctypes.c_double),
    ]


class Tick(ctypes.Structure):
    """A cycle tick (the hello network's `ticker`)."""

    TYPE_NAME = "skillfab.Tick"
    _fields_ = [
        ("value", ctypes.c_uint64),
    ]


# Every type, by type name.
BY_TYPE_NAME = {
    Barcodes.TYPE_NAME: Barcodes,
    Battery.TYPE_NAME: Battery,
    Blob64K.TYPE_NAME: Blob64K,
    Bumpers.TYPE_NAME: Bumpers,
    Door.TYPE_NAME: Door,
    Drive.TYPE_NAME: Drive,
    Link.TYPE_NAME: Link,
    Odometry.TYPE_NAME: Odometry,
    Scalar.TYPE_NAME: Scalar,
    Scaled.TYPE_NAME: Scaled,
    Smoothed.TYPE_NAME: Smoothed,
    Sonar.TYPE_NAME: Sonar,
    Target.TYPE_NAME: Target,
    Tick.TYPE_NAME: Tick,
}
