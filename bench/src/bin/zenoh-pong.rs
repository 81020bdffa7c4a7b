//! `zenoh-pong`: the far end of `bridge-report`'s raw Zenoh baseline — no skillfab in it.
//!
//! `zenoh-pong --listen tcp/127.0.0.1:PORT`: every payload put on `raw/ping` is put back on
//! `raw/pong`; payloads put on `raw/flood` are counted, and a put on `raw/done` is answered on
//! `raw/counted` with the count (8 bytes, little-endian) and the count reset.

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use zenoh::Wait;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let Some(listen) = args
        .iter()
        .position(|a| a == "--listen")
        .and_then(|i| args.get(i + 1))
    else {
        eprintln!("zenoh-pong: --listen ENDPOINT is required");
        return ExitCode::FAILURE;
    };
    match run(listen) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("zenoh-pong: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(listen: &str) -> Result<(), String> {
    let options = skillfab_bridge::ZenohOptions {
        listen: vec![listen.to_string()],
        ..Default::default()
    };
    let session = skillfab_bridge::link::open(&options).map_err(|e| e.to_string())?;
    let pong = session
        .declare_publisher("raw/pong")
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .express(true)
        .wait()
        .map_err(|e| e.to_string())?;
    let counted = session
        .declare_publisher("raw/counted")
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .map_err(|e| e.to_string())?;
    let _ping = session
        .declare_subscriber("raw/ping")
        .callback(move |s| {
            let _ = pong.put(s.payload().clone()).wait();
        })
        .wait()
        .map_err(|e| e.to_string())?;
    let count = Arc::new(AtomicU64::new(0));
    let c = count.clone();
    let _flood = session
        .declare_subscriber("raw/flood")
        .callback(move |_| {
            c.fetch_add(1, Ordering::Relaxed);
        })
        .wait()
        .map_err(|e| e.to_string())?;
    let _done = session
        .declare_subscriber("raw/done")
        .callback(move |_| {
            let n = count.swap(0, Ordering::Relaxed);
            let _ = counted.put(n.to_le_bytes().to_vec()).wait();
        })
        .wait()
        .map_err(|e| e.to_string())?;
    // Until killed.
    loop {
        std::thread::park();
    }
}
