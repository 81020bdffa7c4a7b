//! Benchmark skill `blob-src-64` (see `skillfab_tests::skills::BlobSrc64`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::BlobSrc64>()
}
