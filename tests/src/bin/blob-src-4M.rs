//! Benchmark skill `blob-src-4M` (see `skillfab_tests::skills::BlobSrc4M`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skillfab_tests::skills::BlobSrc4M>()
}
