//! The `barcode_track` skill (see `skills/src/nav/barcode_track.rs`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::nav::BarcodeTrack>()
}
