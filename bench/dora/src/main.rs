//! One dora node that plays each role of the chain (`DORA_ROLE` = `driver`, `link` or `sink`):
//! the driver sends the start stamp on every timer tick, each link forwards what it gets, the
//! sink writes `end - start` to `LATENCY_OUT` — the same endpoints as skillfab's cycle latency
//! (start stamped by the driver before it wakes the first node, end stamped by the last node
//! once it has the sample), on `CLOCK_MONOTONIC`, which every process of the machine shares.

use dora_node_api::dora_core::config::DataId;
use dora_node_api::{DoraNode, Event};
use std::io::Write;

fn now_ns() -> u64 {
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC).map_or(0, |t| {
        (t.tv_sec() as u64) * 1_000_000_000 + t.tv_nsec() as u64
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let role = std::env::var("DORA_ROLE").unwrap_or_else(|_| "link".into());
    let cycles: u64 = std::env::var("CYCLES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000);
    let mut sink = match std::env::var("LATENCY_OUT") {
        Ok(path) if role == "sink" => Some(std::io::BufWriter::new(std::fs::File::create(path)?)),
        _ => None,
    };
    let (mut node, mut events) = DoraNode::init_from_env()?;
    let out = DataId::from("out".to_owned());
    let mut sent = 0u64;
    while let Some(event) = events.recv() {
        match event {
            Event::Input { data, .. } => match role.as_str() {
                "driver" => {
                    if sent >= cycles {
                        break;
                    }
                    sent += 1;
                    node.send_output(out.clone(), Default::default(), now_ns())?;
                }
                "sink" => {
                    let end = now_ns();
                    if let (Some(w), Ok(start)) = (sink.as_mut(), u64::try_from(&data)) {
                        writeln!(w, "{}", end.saturating_sub(start))?;
                    }
                }
                _ => node.send_output(out.clone(), Default::default(), data)?,
            },
            Event::Stop(_) => break,
            _ => {}
        }
    }
    if let Some(mut w) = sink {
        w.flush()?;
    }
    Ok(())
}
