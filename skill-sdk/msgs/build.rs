//! Generates the catalog's Rust types from `msg/skillfab/*.msg` (docs/messages.md), and
//! embeds the files' text, so the catalog can resolve other packages' references to it at run
//! time.

use std::fmt::Write;

fn main() {
    // Read when the script runs, not when it is compiled: a build script compiled in one
    // checkout may be run for another sharing the target directory.
    let manifest = std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default();
    let dir = std::path::PathBuf::from(manifest).join("msg");
    if let Err(e) = skillfab_msggen::build(std::slice::from_ref(&dir), "skillfab") {
        // The message file's path and line, as cargo shows a build script's error.
        eprintln!("error: {e}");
        std::process::exit(1);
    }
    let mut files: Vec<_> = std::fs::read_dir(dir.join("skillfab"))
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    files.retain(|p: &std::path::PathBuf| p.extension().is_some_and(|e| e == "msg"));
    files.sort();
    let mut out = String::from("/// The shipped message files: (path in the repository, text).\n");
    out.push_str("pub const SOURCES: &[(&str, &str)] = &[\n");
    for f in files {
        let name = f
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let _ = writeln!(
            out,
            "    ({:?}, include_str!({:?})),",
            format!("skill-sdk/msgs/msg/skillfab/{name}"),
            f.display().to_string()
        );
    }
    out.push_str("];\n");
    let target = std::path::PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default())
        .join("sources.rs");
    if let Err(e) = std::fs::write(&target, out) {
        eprintln!("error: writing {}: {e}", target.display());
        std::process::exit(1);
    }
}
