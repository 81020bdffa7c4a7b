//! The `stop` skill (see `skills/src/nav/stop.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::nav::Stop>()
}
