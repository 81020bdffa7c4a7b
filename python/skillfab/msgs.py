"""The shared message types of skillfab as ctypes structures.

Generated from their message files (skill-sdk/msgs/msg/skillfab/) by
`skillfab schema --python`. Do not edit: a test checks this file is what the
generator writes, and that every size and offset matches Rust.
"""

import ctypes


class Arm(ctypes.Structure):
    """The button pusher as the robot reports it."""

    TYPE_NAME = "skillfab.Arm"
    _fields_ = [
        ("strokes", ctypes.c_uint32),
        ("pressed", ctypes.c_uint32),
        ("hits", ctypes.c_uint32),
        ("age_ms", ctypes.c_double),
    ]


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


class Car(ctypes.Structure):
    """An elevator car whose doors are open on this floor, seen by its hall lantern."""

    TYPE_NAME = "skillfab.Car"
    _fields_ = [
        ("id", ctypes.c_uint32),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("heading", ctypes.c_double),
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


class Doors(ctypes.Structure):
    """Side doors passed along a corridor, from the sonar ring."""

    TYPE_NAME = "skillfab.Doors"
    _fields_ = [
        ("left", ctypes.c_uint32),
        ("right", ctypes.c_uint32),
        ("beside", ctypes.c_int32),
    ]


class Drive(ctypes.Structure):
    """A synchro-drive command: the `drive` actuator channel."""

    TYPE_NAME = "skillfab.Drive"
    _fields_ = [
        ("translate", ctypes.c_double),
        ("rotate", ctypes.c_double),
    ]


class Junction(ctypes.Structure):
    """Corridor intersections, from the sonar ring."""

    TYPE_NAME = "skillfab.Junction"
    _fields_ = [
        ("count", ctypes.c_uint32),
        ("inside", ctypes.c_bool),
        ("left", ctypes.c_bool),
        ("right", ctypes.c_bool),
        ("ahead", ctypes.c_bool),
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


class Progress(ctypes.Structure):
    """How far a skill with one job is (entering a car, leaving it, pushing a button)."""

    TYPE_NAME = "skillfab.Progress"
    _fields_ = [
        ("done", ctypes.c_bool),
        ("phase", ctypes.c_uint32),
        ("value", ctypes.c_double),
    ]


class Push(ctypes.Structure):
    """The button pusher: the `push` actuator channel. The safe command is 'retracted'."""

    TYPE_NAME = "skillfab.Push"
    _fields_ = [
        ("press", ctypes.c_bool),
    ]


class Safety(ctypes.Structure):
    """What a device's safety layer did to the drive command (devices/denning: its speed limit by the nearest fresh sonar echo along the direction of travel and by the link's health)."""

    TYPE_NAME = "skillfab.Safety"
    _fields_ = [
        ("limit", ctypes.c_double),
        ("clear_m", ctypes.c_double),
        ("action", ctypes.c_uint32),
        ("slowed", ctypes.c_uint64),
        ("stopped", ctypes.c_uint64),
        ("blind", ctypes.c_uint64),
    ]


class Say(ctypes.Structure):
    """A message for the robot's speaker and display: the `say` actuator channel. The safe command (seq 0) says nothing."""

    TYPE_NAME = "skillfab.Say"
    _fields_ = [
        ("seq", ctypes.c_uint32),
        ("len", ctypes.c_uint32),
        ("text", (ctypes.c_uint8 * 64)),
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


class Signs(ctypes.Structure):
    """What the camera reads on signs (barcodes by the building's convention: 900 + floor on a floor sign or a car's floor indicator, a room number beside a door)."""

    TYPE_NAME = "skillfab.Signs"
    _fields_ = [
        ("floor_known", ctypes.c_bool),
        ("at_floor", ctypes.c_bool),
        ("floor", ctypes.c_int32),
        ("room", ctypes.c_uint32),
        ("room_range", ctypes.c_double),
        ("room_bearing", ctypes.c_double),
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


class Voice(ctypes.Structure):
    """The robot's speaker and display as the robot reports them."""

    TYPE_NAME = "skillfab.Voice"
    _fields_ = [
        ("said", ctypes.c_uint32),
        ("seq", ctypes.c_uint32),
    ]


# Every type, by type name.
BY_TYPE_NAME = {
    Arm.TYPE_NAME: Arm,
    Barcodes.TYPE_NAME: Barcodes,
    Battery.TYPE_NAME: Battery,
    Blob64K.TYPE_NAME: Blob64K,
    Bumpers.TYPE_NAME: Bumpers,
    Car.TYPE_NAME: Car,
    Door.TYPE_NAME: Door,
    Doors.TYPE_NAME: Doors,
    Drive.TYPE_NAME: Drive,
    Junction.TYPE_NAME: Junction,
    Link.TYPE_NAME: Link,
    Odometry.TYPE_NAME: Odometry,
    Progress.TYPE_NAME: Progress,
    Push.TYPE_NAME: Push,
    Safety.TYPE_NAME: Safety,
    Say.TYPE_NAME: Say,
    Scalar.TYPE_NAME: Scalar,
    Scaled.TYPE_NAME: Scaled,
    Signs.TYPE_NAME: Signs,
    Smoothed.TYPE_NAME: Smoothed,
    Sonar.TYPE_NAME: Sonar,
    Target.TYPE_NAME: Target,
    Tick.TYPE_NAME: Tick,
    Voice.TYPE_NAME: Voice,
}
