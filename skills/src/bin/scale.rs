//! The `scale` skill (see `skills::hello`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::hello::Scale>()
}
