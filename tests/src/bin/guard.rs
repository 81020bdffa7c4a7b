//! Test skill `guard` (see `skillfab_tests::skills::Guard`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::Guard>()
}
