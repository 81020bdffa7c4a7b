//! Benchmark skill `blob-sink-64` (see `skillfab_tests::skills::BlobSink64`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::BlobSink64>()
}
