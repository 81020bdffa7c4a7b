//! The `door_locate` skill (see `skills/src/nav/door_locate.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::nav::DoorLocate>()
}
