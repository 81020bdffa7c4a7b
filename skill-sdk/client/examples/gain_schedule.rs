//! A sequencer written against the client library: gain scheduling on the hello network
//! (ticker → scale → smooth). While the ticker's count is between 100 and 200, `scale` runs
//! with three times its gain; outside it, with the gain it had. Monitors tell the sequencer
//! when to switch; it prints each switch with the cycle and the values the monitor read.
//!
//! ```sh
//! target/release/skillfab up skills/launch/hello.toml --domain demo &
//! SKILLFAB_DOMAIN=demo cargo run --release -p skillfab-client --example gain_schedule
//! ```
//!
//! (Missions are written as plans, `skillfab sequence FILE.xml`: docs/sequence.md. A Rust
//! sequencer is for what a plan cannot say.)

use skillfab_client::Client;
use skillfab_msgs::Tick;
use skillfab_proto::control::{EventKind, MonitorMode};
use skillfab_proto::domain::{DOMAIN_ENV, Domain};
// The skills' own references: a renamed parameter or port stops this compiling.
use skills::hello::{ScaleParams, TickOut};
use std::time::{Duration, Instant};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let domain = Domain::new(&std::env::var(DOMAIN_ENV).unwrap_or_else(|_| "default".into()))?;
    let mut c = Client::connect(&domain)?;
    c.subscribe()?;
    let gain = c.get("scale", ScaleParams::GAIN)?;
    let tick = TickOut::TICK.field(Tick::VALUE);
    let (now, _) = c.read("ticker", &tick)?;
    println!("ticker at {now}, scale.gain = {gain}");

    let high = c.add_monitor(&format!("ticker.{tick} >= 100"), MonitorMode::Once, 0)?;
    let low = c.add_monitor(&format!("ticker.{tick} >= 200"), MonitorMode::Once, 0)?;
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut switched = 0;
    while switched < 2 && Instant::now() < deadline {
        let Some(ev) = c.next_event(Duration::from_millis(500))? else {
            continue;
        };
        let EventKind::MonitorFired { id, values, .. } = ev.kind else {
            continue;
        };
        let to = if id == high {
            3.0 * gain
        } else if id == low {
            gain
        } else {
            continue;
        };
        // Refused values come back as `ControlError::Param { error: ParamError }`.
        c.set("scale", ScaleParams::GAIN, to)?;
        println!("cycle {}: {values:?} -> scale.gain = {to}", ev.cycle);
        switched += 1;
    }
    // What a sequencer installed goes with it (the manager would drop it once the process is
    // gone, in real time).
    for id in [high, low] {
        let _ = c.remove_monitor(id);
    }
    if switched < 2 {
        c.set("scale", ScaleParams::GAIN, gain)?;
        return Err("the ticker did not reach 200 within 60 s".into());
    }
    Ok(())
}
