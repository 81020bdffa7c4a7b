//! The `door_detect` skill (see `skills/src/building/door_detect.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::building::DoorDetect>()
}
