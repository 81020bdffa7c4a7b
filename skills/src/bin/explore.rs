//! The `explore` skill (see `skills/src/nav/explore.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::nav::Explore>()
}
