//! Benchmark skill `blob-sink-64K` (see `skillfab_tests::skills::BlobSink64K`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::BlobSink64K>()
}
