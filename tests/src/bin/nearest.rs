//! Test skill `nearest` (see `skillfab_tests::skills::Nearest`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::Nearest>()
}
