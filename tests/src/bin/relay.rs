//! Test skill `relay` (see `skillfab_tests::skills::Relay`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::Relay>()
}
