//! The `sign_read` skill (see `skills/src/building/sign_read.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::building::SignRead>()
}
