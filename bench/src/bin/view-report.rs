//! `view-report`: what a live viewer (`skillfab view` with a client subscribed to every
//! channel at full rate) costs the cycle.
//!
//! ```text
//! view-report [--pairs N] [--cycles C] [--world FILE] [--json]
//! ```
//!
//! The exit-lab network in real time at 100 Hz — simulator, Denning device, wander, avoid and
//! barcode_track active, every other standard skill registered and idle (the network of
//! `record-report`) — runs C cycles (default 3000) without a viewer and with one, N times each
//! (default 5), interleaved and alternating which goes first, on release binaries beside this
//! one. With a viewer: `skillfab view` (started first, with the world) and, in this process,
//! a client of the Foxglove WebSocket protocol that subscribes to every channel as it is
//! advertised and reads until the run ends. Per run: the manager's cycle latency (cycle start
//! → last run done) p50/p99 and overruns; per viewed run: frames and bytes the viewer got.

use serde_json::{Value, json};
use skillfab_bench::network::{arg_value, arg_world, because, launch, median};
use std::io::ErrorKind;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tungstenite::Message;
use tungstenite::client::IntoClientRequest;

/// What the viewer got.
#[derive(Default)]
struct Got {
    frames: u64,
    bytes: u64,
    channels: usize,
}

/// A viewer subscribed to every channel, reading until `stop`.
fn viewer(port: u16, stop: &AtomicBool) -> Result<Got, String> {
    let url = format!("ws://127.0.0.1:{port}/");
    let started = Instant::now();
    let (mut ws, _) = loop {
        let mut req = url.as_str().into_client_request().map_err(because("url"))?;
        req.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            tungstenite::http::HeaderValue::from_static("foxglove.websocket.v1"),
        );
        match tungstenite::client::connect(req) {
            Ok(c) => break c,
            Err(e) if started.elapsed() < Duration::from_secs(10) => {
                let _ = e;
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => return Err(format!("viewer: {e}")),
        }
    };
    if let tungstenite::stream::MaybeTlsStream::Plain(s) = ws.get_mut() {
        s.set_read_timeout(Some(Duration::from_millis(50)))
            .map_err(because("read timeout"))?;
    }
    let mut got = Got::default();
    let mut subscribed = std::collections::HashSet::new();
    while !stop.load(Ordering::Relaxed) {
        match ws.read() {
            Ok(Message::Text(t)) => {
                let j: Value = serde_json::from_str(&t).map_err(because("server text"))?;
                if j["op"] == "advertise" {
                    let subs: Vec<Value> = j["channels"]
                        .as_array()
                        .into_iter()
                        .flatten()
                        .filter_map(|c| c["id"].as_u64())
                        .filter(|id| subscribed.insert(*id))
                        .map(|id| json!({"id": id, "channelId": id}))
                        .collect();
                    got.channels = subscribed.len();
                    ws.send(Message::text(
                        json!({"op": "subscribe", "subscriptions": subs}).to_string(),
                    ))
                    .map_err(because("subscribe"))?;
                }
            }
            Ok(Message::Binary(b)) => {
                got.frames += 1;
                got.bytes += b.len() as u64;
            }
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) => return Err(format!("viewer: {e}")),
        }
    }
    let _ = ws.close(None);
    Ok(got)
}

struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(self.0.id() as i32),
            nix::sys::signal::Signal::SIGTERM,
        );
        let _ = self.0.wait();
    }
}

/// One `skillfab up` run, watched or not; returns the manager's report and what the viewer got.
fn run(
    skillfab: &Path,
    dir: &Path,
    tag: &str,
    cycles: u64,
    viewed: bool,
) -> Result<(Value, Option<Got>), String> {
    let link = dir.join(format!("robot-{tag}"));
    let file = dir.join(format!("{tag}.toml"));
    let world = arg_world()?;
    std::fs::write(&file, launch(&world, &link)).map_err(because("launch file"))?;
    let domain = format!("view-{}-{tag}", std::process::id());
    let mut watch = None;
    if viewed {
        let port = skillfab_tests::free_port();
        let view = Command::new(skillfab)
            .args(["view", "--listen", &format!("127.0.0.1:{port}"), "--world"])
            .arg(&world)
            .args(["--domain", &domain])
            .env_remove("SKILLFAB_DOMAIN")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map_err(because("skillfab view"))?;
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        let thread = std::thread::spawn(move || viewer(port, &s));
        watch = Some((Killed(view), stop, thread));
    }
    let out = Command::new(skillfab)
        .arg("up")
        .arg(&file)
        .args(["--cycles", &cycles.to_string(), "--json"])
        .args(["--domain", &domain])
        .env_remove("SKILLFAB_DOMAIN")
        .output()
        .map_err(because("skillfab up"))?;
    let got = match watch {
        Some((view, stop, thread)) => {
            stop.store(true, Ordering::Relaxed);
            let got = thread
                .join()
                .map_err(|_| "viewer thread panicked".to_string())??;
            drop(view);
            Some(got)
        }
        None => None,
    };
    let report = serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("no report ({e}): {}", String::from_utf8_lossy(&out.stderr)))?;
    Ok((report, got))
}

fn main() -> std::process::ExitCode {
    match report() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("view-report: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn report() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    let pairs: u32 = arg_value(&args, "--pairs")
        .and_then(|v| v.parse().ok())
        .unwrap_or(5);
    let cycles: u64 = arg_value(&args, "--cycles")
        .and_then(|v| v.parse().ok())
        .unwrap_or(3000);
    let json_out = args.iter().any(|a| a == "--json");
    let here = std::env::current_exe().map_err(because("own path"))?;
    let skillfab = here.with_file_name("skillfab");
    let dir = std::env::temp_dir().join(format!("view-report-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(because("scratch directory"))?;
    let (mut plain, mut viewed) = (Vec::new(), Vec::new());
    for i in 0..pairs {
        for with in if i % 2 == 0 {
            [false, true]
        } else {
            [true, false]
        } {
            let tag = format!("{i}-{}", if with { "view" } else { "plain" });
            eprintln!(
                "view-report: pair {} of {pairs}, {}",
                i + 1,
                if with { "viewed" } else { "not viewed" }
            );
            let (r, got) = run(&skillfab, &dir, &tag, cycles, with)?;
            let mut row = json!({
                "p50_us": r["latency_us"]["p50"], "p99_us": r["latency_us"]["p99"],
                "overruns": r["overruns"], "cycles": r["cycles"],
            });
            match got {
                Some(g) => {
                    row["viewer"] = json!({"frames": g.frames, "bytes": g.bytes,
                                           "channels": g.channels});
                    viewed.push(row);
                }
                None => plain.push(row),
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    let p50 = |rows: &[Value]| median(rows.iter().filter_map(|r| r["p50_us"].as_f64()).collect());
    let p99 = |rows: &[Value]| median(rows.iter().filter_map(|r| r["p99_us"].as_f64()).collect());
    let summary = json!({
        "pairs": pairs, "cycles": cycles,
        "plain": {"p50_us_median": p50(&plain), "p99_us_median": p99(&plain), "runs": plain},
        "viewed": {"p50_us_median": p50(&viewed), "p99_us_median": p99(&viewed), "runs": viewed},
        "p50_ratio": p50(&viewed) / p50(&plain),
    });
    if json_out {
        println!("{summary}");
        return Ok(());
    }
    println!(
        "exit-lab network, 100 Hz, {cycles} cycles, {pairs} interleaved pairs (medians of the runs' figures)"
    );
    println!(
        "  no viewer:            cycle latency p50 {:.0} µs, p99 {:.0} µs",
        p50(&plain),
        p99(&plain)
    );
    println!(
        "  viewer on everything: cycle latency p50 {:.0} µs, p99 {:.0} µs  (p50 ×{:.3})",
        p50(&viewed),
        p99(&viewed),
        p50(&viewed) / p50(&plain)
    );
    for r in &viewed {
        println!(
            "  viewed run: {} frames, {} bytes, {} channels, {} overruns",
            r["viewer"]["frames"], r["viewer"]["bytes"], r["viewer"]["channels"], r["overruns"]
        );
    }
    Ok(())
}
