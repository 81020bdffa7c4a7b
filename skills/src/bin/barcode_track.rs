//! The `barcode_track` skill (see `skills::nav`).
fn main() -> std::process::ExitCode {
    skill_sdk::main::<skills::nav::BarcodeTrack>()
}
