//! Test device `mock-device` (see `skillfab_tests::skills`).
fn main() -> std::process::ExitCode {
    skill_sdk::device_main::<skillfab_tests::skills::MockDevice>()
}
