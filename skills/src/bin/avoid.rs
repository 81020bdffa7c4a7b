//! The `avoid` skill (see `skills/src/nav/avoid.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::nav::Avoid>()
}
