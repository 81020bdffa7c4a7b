//! Benchmark skill `blob-src-1M` (see `skillfab_tests::skills::BlobSrc1M`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::BlobSrc1M>()
}
