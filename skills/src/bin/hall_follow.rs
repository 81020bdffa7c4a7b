//! The `hall_follow` skill (see `skills/src/building/hall_follow.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::building::HallFollow>()
}
