//! The `car_watch` skill (see `skills/src/building/car_watch.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::building::CarWatch>()
}
