//! The `intersection` skill (see `skills/src/building/intersection.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::building::Intersection>()
}
