//! Generates the catalog's Rust types from `msg/skillfab/*.msg` (docs/messages.md).

fn main() {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("msg");
    if let Err(e) = skillfab_msggen::build(&[dir], "skillfab") {
        // The message file's path and line, as cargo shows a build script's error.
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
