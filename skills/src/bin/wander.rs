//! The `wander` skill (see `skills/src/nav/wander.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::nav::Wander>()
}
