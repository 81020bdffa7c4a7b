/* The shared message types of skillfab, generated from their message files
 * (skill-sdk/msgs/msg/skillfab/) by `skillfab schema --c`. Do not edit: a test
 * checks this file is what the generator writes, and that every size and offset
 * matches Rust. */
#ifndef SKILLFAB_MSGS_H
#define SKILLFAB_MSGS_H

#include <stdbool.h>
#include <stdint.h>

/** The button pusher as the robot reports it. */
typedef struct sf_Arm {
    uint32_t strokes;
    uint32_t pressed;
    uint32_t hits;
    double age_ms;
} sf_Arm;
#define SF_ARM_TYPE_NAME "skillfab.Arm"
#define SF_ARM_SIZE 24

/** Barcode sightings of the latest camera frame. */
typedef struct sf_Barcodes {
    uint32_t count;
    uint32_t id[8];
    double bearing[8];
    double range[8];
    double age_ms;
} sf_Barcodes;
#define SF_BARCODES_TYPE_NAME "skillfab.Barcodes"
#define SF_BARCODES_SIZE 176

/** Battery voltage. */
typedef struct sf_Battery {
    double volts;
} sf_Battery;
#define SF_BATTERY_TYPE_NAME "skillfab.Battery"
#define SF_BATTERY_SIZE 8

/** A large block of bytes, for zero-copy payload tests and benchmarks. */
typedef struct sf_Blob64K {
    uint64_t len;
    uint8_t data[65536];
} sf_Blob64K;
#define SF_BLOB64K_TYPE_NAME "skillfab.Blob64K"
#define SF_BLOB64K_SIZE 65544

/** Contact sensing. */
typedef struct sf_Bumpers {
    uint32_t hit;
    bool stall;
} sf_Bumpers;
#define SF_BUMPERS_TYPE_NAME "skillfab.Bumpers"
#define SF_BUMPERS_SIZE 8

/** An elevator car whose doors are open on this floor, seen by its hall lantern. */
typedef struct sf_Car {
    uint32_t id;
    double x;
    double y;
    double heading;
} sf_Car;
#define SF_CAR_TYPE_NAME "skillfab.Car"
#define SF_CAR_SIZE 32

/** A located door opening, in the odometry frame. */
typedef struct sf_Door {
    bool found;
    double x;
    double y;
    double heading;
    double width;
} sf_Door;
#define SF_DOOR_TYPE_NAME "skillfab.Door"
#define SF_DOOR_SIZE 40

/** Side doors passed along a corridor, from the sonar ring. */
typedef struct sf_Doors {
    uint32_t left;
    uint32_t right;
    int32_t beside;
} sf_Doors;
#define SF_DOORS_TYPE_NAME "skillfab.Doors"
#define SF_DOORS_SIZE 12

/** A synchro-drive command: the `drive` actuator channel. */
typedef struct sf_Drive {
    double translate;
    double rotate;
} sf_Drive;
#define SF_DRIVE_TYPE_NAME "skillfab.Drive"
#define SF_DRIVE_SIZE 16

/** Corridor intersections, from the sonar ring. */
typedef struct sf_Junction {
    uint32_t count;
    bool inside;
    bool left;
    bool right;
    bool ahead;
} sf_Junction;
#define SF_JUNCTION_TYPE_NAME "skillfab.Junction"
#define SF_JUNCTION_SIZE 8

/** The state of a device's link to its hardware. */
typedef struct sf_Link {
    bool connected;
    double age_ms;
    uint64_t frames;
    uint64_t bad_frames;
    uint64_t garbage;
    uint64_t connects;
} sf_Link;
#define SF_LINK_TYPE_NAME "skillfab.Link"
#define SF_LINK_SIZE 48

/** Dead-reckoned pose and velocities. */
typedef struct sf_Odometry {
    double x;
    double y;
    double theta;
    double v;
    double w;
} sf_Odometry;
#define SF_ODOMETRY_TYPE_NAME "skillfab.Odometry"
#define SF_ODOMETRY_SIZE 40

/** How far a skill with one job is (entering a car, leaving it, pushing a button). */
typedef struct sf_Progress {
    bool done;
    uint32_t phase;
    double value;
} sf_Progress;
#define SF_PROGRESS_TYPE_NAME "skillfab.Progress"
#define SF_PROGRESS_SIZE 16

/** The button pusher: the `push` actuator channel. The safe command is "retracted". */
typedef struct sf_Push {
    bool press;
} sf_Push;
#define SF_PUSH_TYPE_NAME "skillfab.Push"
#define SF_PUSH_SIZE 1

/** What a device's safety layer did to the drive command (devices/denning: its speed limit by the nearest fresh sonar echo along the direction of travel and by the link's health). */
typedef struct sf_Safety {
    double limit;
    double clear_m;
    uint32_t action;
    uint64_t slowed;
    uint64_t stopped;
    uint64_t blind;
} sf_Safety;
#define SF_SAFETY_TYPE_NAME "skillfab.Safety"
#define SF_SAFETY_SIZE 48

/** A message for the robot's speaker and display: the `say` actuator channel. The safe command (seq 0) says nothing. */
typedef struct sf_Say {
    uint32_t seq;
    uint32_t len;
    uint8_t text[64];
} sf_Say;
#define SF_SAY_TYPE_NAME "skillfab.Say"
#define SF_SAY_SIZE 72

/** A generic scalar, for test and example networks. */
typedef struct sf_Scalar {
    double value;
    uint64_t start_ns;
    uint64_t end_ns;
} sf_Scalar;
#define SF_SCALAR_TYPE_NAME "skillfab.Scalar"
#define SF_SCALAR_SIZE 24

/** A scaled value (the hello network's `scale`). */
typedef struct sf_Scaled {
    double value;
} sf_Scaled;
#define SF_SCALED_TYPE_NAME "skillfab.Scaled"
#define SF_SCALED_SIZE 8

/** What the camera reads on signs (barcodes by the building's convention: 900 + floor on a floor sign or a car's floor indicator, a room number beside a door). */
typedef struct sf_Signs {
    bool floor_known;
    bool at_floor;
    int32_t floor;
    uint32_t room;
    double room_range;
    double room_bearing;
} sf_Signs;
#define SF_SIGNS_TYPE_NAME "skillfab.Signs"
#define SF_SIGNS_SIZE 32

/** A smoothed value (the hello network's `smooth`). */
typedef struct sf_Smoothed {
    double value;
    uint64_t samples;
} sf_Smoothed;
#define SF_SMOOTHED_TYPE_NAME "skillfab.Smoothed"
#define SF_SMOOTHED_SIZE 16

/** The sonar ring: 24 sonars 15° apart, sonar 0 facing forward, counter-clockwise. */
typedef struct sf_Sonar {
    double range[24];
    double age_ms[24];
} sf_Sonar;
#define SF_SONAR_TYPE_NAME "skillfab.Sonar"
#define SF_SONAR_SIZE 384

/** A tracked barcode, in the odometry frame. */
typedef struct sf_Target {
    bool seen;
    bool visible;
    uint32_t id;
    double x;
    double y;
    double range;
    double bearing;
} sf_Target;
#define SF_TARGET_TYPE_NAME "skillfab.Target"
#define SF_TARGET_SIZE 40

/** A cycle tick (the hello network's `ticker`). */
typedef struct sf_Tick {
    uint64_t value;
} sf_Tick;
#define SF_TICK_TYPE_NAME "skillfab.Tick"
#define SF_TICK_SIZE 8

/** The robot's speaker and display as the robot reports them. */
typedef struct sf_Voice {
    uint32_t said;
    uint32_t seq;
} sf_Voice;
#define SF_VOICE_TYPE_NAME "skillfab.Voice"
#define SF_VOICE_SIZE 8

#endif /* SKILLFAB_MSGS_H */
