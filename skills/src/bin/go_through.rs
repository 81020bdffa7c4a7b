//! The `go_through` skill (see `skills/src/nav/go_through.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::nav::GoThrough>()
}
