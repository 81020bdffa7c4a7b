//! Arbitrary bytes into the decoder, split at an arbitrary point: it must never panic, and
//! every frame it accepts must decode (or be refused) without panicking either.
#![no_main]

use denning::codec::{Command, Decoder, Packet};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let split = data.first().map_or(0, |b| usize::from(*b)).min(data.len());
    let mut d = Decoder::default();
    d.push(&data[..split]);
    while let Some(f) = d.next_frame() {
        if let Ok(p) = f {
            let _ = Packet::decode(&p);
            let _ = Command::decode(&p);
        }
    }
    d.push(&data[split..]);
    while let Some(f) = d.next_frame() {
        if let Ok(p) = f {
            let _ = Packet::decode(&p);
            let _ = Command::decode(&p);
        }
    }
});
