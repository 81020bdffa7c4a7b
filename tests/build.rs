//! Generates the Rust types of the test message package `tests/msg/test_pkg` as a skill's
//! own build script would (docs/messages.md): the shipped catalog's files and one's own.

fn main() {
    // Read when the script runs (as the msgs package's script does).
    let here = std::path::PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let dirs = [here.join("../skill-sdk/msgs/msg"), here.join("msg")];
    if let Err(e) = skillfab_msggen::build(&dirs, "test_pkg") {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
