//! Test skill `counter` (see `skillfab_tests::skills`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::Counter>()
}
