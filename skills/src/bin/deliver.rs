//! The `deliver` skill (see `skills/src/building/deliver.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::building::Deliver>()
}
