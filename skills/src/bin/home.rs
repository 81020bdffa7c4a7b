//! The `home` skill (see `skills/src/nav/home.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::nav::Home>()
}
