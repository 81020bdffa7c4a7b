//! The `enter_car` skill (see `skills/src/building/enter_car.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::building::EnterCar>()
}
