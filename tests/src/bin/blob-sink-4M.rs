//! Benchmark skill `blob-sink-4M` (see `skillfab_tests::skills::BlobSink4M`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::BlobSink4M>()
}
