//! `check_chain`: a reference model of scale → smooth that fails any cycle two implementations
//! of the chain disagree with it (see `skills/launch/polyglot.toml`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::hello::CheckChain>()
}
