//! Benchmarks of skillfab: `benches/` holds the criterion benchmarks, each starting real
//! processes in a private domain (through the tests' `TestDomain` fixture). Build the
//! binaries first: `cargo build --release --workspace --bins`.
