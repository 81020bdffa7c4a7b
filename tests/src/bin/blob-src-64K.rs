//! Benchmark skill `blob-src-64K` (see `skillfab_tests::skills::BlobSrc64K`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::BlobSrc64K>()
}
