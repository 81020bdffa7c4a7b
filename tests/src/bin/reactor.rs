//! Test skill `reactor` (see `skillfab_tests::skills`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::Reactor>()
}
