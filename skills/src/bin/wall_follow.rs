//! The `wall_follow` skill (see `skills/src/nav/wall_follow.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::nav::WallFollow>()
}
