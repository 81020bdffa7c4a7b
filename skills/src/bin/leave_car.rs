//! The `leave_car` skill (see `skills/src/building/leave_car.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::building::LeaveCar>()
}
