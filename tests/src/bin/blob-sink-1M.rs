//! Benchmark skill `blob-sink-1M` (see `skillfab_tests::skills::BlobSink1M`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::BlobSink1M>()
}
