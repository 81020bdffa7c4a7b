//! The `push_button` skill (see `skills/src/building/push_button.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::building::PushButton>()
}
