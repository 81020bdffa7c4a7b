//! `skillfab view`: the Foxglove WebSocket server over a running exit-lab network, checked by a
//! client written from the protocol's published description (tests/scripts/foxglove_client.py,
//! with the PyPI packages `websockets` and `mcap-ros2-support`), by fifty clients at once, and
//! by its snapshot.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use skillfab_client::Client;
use skillfab_proto::control::SkillState;
use skillfab_tests::{TestDomain, free_port, python_deps, repo_root};
use std::net::TcpStream;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The exit-lab network with `explore` and `avoid` active, the simulator writing its ground
/// truth, a plan that activates them and then waits for ever, and the view on `port`.
struct Lab {
    // Dropped before the domain's files are removed.
    client: Client,
    t: TestDomain,
    port: u16,
    world: PathBuf,
    truth: PathBuf,
}

const PLAN: &str = r#"<root BTCPP_format="4" main_tree_to_execute="Look">
  <BehaviorTree ID="Look">
    <Sequence>
      <Activate skills="explore, avoid"/>
      <WaitFor name="never" condition="explore.drive.translate > 1000"/>
    </Sequence>
  </BehaviorTree>
</root>
"#;

impl Lab {
    fn start(tag: &str) -> Lab {
        let mut t = TestDomain::new(tag);
        let world = repo_root().join("devices/denning-sim/worlds/exit-lab.toml");
        let (link, truth) = (t.dir.join("link"), t.dir.join("truth.csv"));
        let mut launch = format!(
            "[manager]\nperiod_ms = 10\n[[process]]\nname = \"denning-sim\"\nbin = \"{{bin:denning-sim}}\"\nargs = [\"--world\", \"{}\", \"--link\", \"{}\", \"--trajectory\", \"{}\"]\nregisters = false\n[[process]]\nname = \"denning\"\nbin = \"{{bin:denning}}\"\nargs = [\"--port\", \"{}\"]\n",
            world.display(),
            link.display(),
            truth.display(),
            link.display()
        );
        for s in ["explore", "avoid", "wander", "barcode_track"] {
            launch.push_str(&format!(
                "[[process]]\nname = \"{s}\"\nbin = \"{{bin:{s}}}\"\nactive = false\n"
            ));
        }
        let file = t.launch_file(&launch);
        t.spawn("skillfab", &["up", file.to_str().unwrap()]);
        t.board();
        let client = Client::connect(&t.domain).expect("client");
        t.wait_until("the network to register", || {
            client.list().is_ok_and(|l| {
                ["denning", "explore", "avoid", "wander"]
                    .iter()
                    .all(|n| l.iter().any(|s| s.name == *n))
            })
        });
        let plan = t.dir.join("look.xml");
        std::fs::write(&plan, PLAN).unwrap();
        t.spawn("skillfab", &["sequence", plan.to_str().unwrap()]);
        let port = free_port();
        let listen = format!("127.0.0.1:{port}");
        t.spawn(
            "skillfab",
            &[
                "view",
                "--listen",
                &listen,
                "--world",
                world.to_str().unwrap(),
                "--truth",
                truth.to_str().unwrap(),
            ],
        );
        t.wait_until("the view to listen", || {
            TcpStream::connect(("127.0.0.1", port)).is_ok()
        });
        Lab {
            t,
            client,
            port,
            world,
            truth,
        }
    }

    fn runs(&self, skill: &str) -> u64 {
        self.client
            .list()
            .ok()
            .and_then(|l| l.into_iter().find(|s| s.name == skill))
            .map_or(0, |s| s.figures.runs)
    }
}

#[test]
fn a_client_written_from_the_protocol_subscribes_decodes_sets_a_parameter_and_activates_a_skill() {
    let lab = Lab::start("view");
    let deps = python_deps();
    let script = repo_root().join("tests/scripts/foxglove_client.py");
    let out = lab
        .t
        .command_at(std::path::Path::new("python3"))
        .env("PYTHONPATH", &deps)
        .args([
            script.to_str().unwrap(),
            &format!("ws://127.0.0.1:{}/", lab.port),
        ])
        .output()
        .expect("python3");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the protocol client failed:\n{}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_str(stdout.trim()).expect("JSON report");
    // Every topic of the domain is a channel, beside the view's own.
    let channels = report["channels"].as_array().unwrap();
    for c in [
        "/sonar",
        "/odometry",
        "/tf",
        "/scene",
        "/robot",
        "/plan",
        "/events",
        "/log",
    ] {
        assert!(
            channels.iter().any(|x| x == c),
            "{c} not advertised: {channels:?}"
        );
    }
    assert!(
        report["plan"]["plan"]
            .as_str()
            .unwrap()
            .ends_with("look.xml"),
        "{report}"
    );
    assert!(
        report["plan"]["running"]
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n == "never"),
        "{report}"
    );
    assert_eq!(report["refusals"].as_array().unwrap().len(), 7, "{report}");
    // The parameter the client set is the manager's, and the skill it activated runs.
    let safe = lab.client.get_param("avoid", "safe_distance").unwrap();
    assert_eq!(safe, skillfab_proto::param::ParamValue::Float(0.45));
    let list = lab.client.list().unwrap();
    let wander = list.iter().find(|s| s.name == "wander").unwrap();
    assert_eq!(wander.state, SkillState::Active, "{wander:?}");
    let before = lab.runs("wander");
    lab.t
        .wait_until("wander to run", || lab.runs("wander") > before + 5);
}

#[test]
fn fifty_viewers_at_once_are_served_and_the_fabric_is_not_held_up() {
    let lab = Lab::start("view50");
    let cycles = || lab.client.stats().map_or(0, |s| s.cycles);
    let start = cycles();
    let started = Instant::now();
    let viewers: Vec<_> = (0..50)
        .map(|_| {
            let port = lab.port;
            std::thread::spawn(move || viewer(port))
        })
        .collect();
    let got: Vec<usize> = viewers
        .into_iter()
        .map(|v| v.join().expect("viewer thread"))
        .collect();
    assert!(
        got.iter().all(|n| *n > 0),
        "every viewer got messages: {got:?}"
    );
    // The fabric cycled on meanwhile, at about its period (10 ms) — not held by the viewers.
    let ran = cycles() - start;
    let elapsed = started.elapsed().as_secs_f64();
    assert!(
        ran as f64 > elapsed * 100.0 * 0.5,
        "{ran} cycles in {elapsed:.1} s"
    );
    // A client that does not speak the protocol is refused, and the view goes on.
    let refused = tungstenite::client::connect(format!("ws://127.0.0.1:{}/", lab.port));
    assert!(
        refused.is_err(),
        "a connection without the subprotocol was accepted"
    );
    assert!(viewer(lab.port) > 0);
}

/// A viewer that subscribes to every channel for a second; returns the messages it got.
fn viewer(port: u16) -> usize {
    use tungstenite::client::IntoClientRequest;
    let mut req = format!("ws://127.0.0.1:{port}/")
        .into_client_request()
        .unwrap();
    req.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.websocket.v1".parse().unwrap(),
    );
    let (mut ws, _) = tungstenite::client::connect(req).expect("viewer connects");
    let mut got = 0;
    let mut subscribed = std::collections::HashSet::new();
    let until = Instant::now() + Duration::from_secs(2);
    if let tungstenite::stream::MaybeTlsStream::Plain(s) = ws.get_mut() {
        s.set_read_timeout(Some(Duration::from_millis(100)))
            .unwrap();
    }
    while Instant::now() < until {
        match ws.read() {
            Ok(tungstenite::Message::Text(t)) => {
                let j: serde_json::Value = serde_json::from_str(&t).unwrap();
                if j["op"] == "advertise" {
                    let subs: Vec<_> = j["channels"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .filter_map(|c| c["id"].as_u64())
                        .filter(|id| subscribed.insert(*id))
                        .map(|id| serde_json::json!({"id": id, "channelId": id}))
                        .collect();
                    ws.send(tungstenite::Message::text(
                        serde_json::json!({"op": "subscribe", "subscriptions": subs}).to_string(),
                    ))
                    .unwrap();
                }
                got += 1;
            }
            Ok(tungstenite::Message::Binary(b)) => {
                assert_eq!(b[0], 1, "message data");
                got += 1;
            }
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => panic!("viewer: {e}"),
        }
    }
    let _ = ws.close(None);
    got
}

#[test]
fn a_snapshot_draws_the_floor_the_robot_its_sonar_and_the_running_branch() {
    let lab = Lab::start("viewsnap");
    let out = lab.t.dir.join("snap.svg");
    let run = lab.t.run(
        "skillfab",
        &[
            "view",
            "--world",
            lab.world.to_str().unwrap(),
            "--truth",
            lab.truth.to_str().unwrap(),
            "--snapshot",
            out.to_str().unwrap(),
        ],
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let svg = std::fs::read_to_string(&out).unwrap();
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    assert!(
        svg.matches("<polygon").count() > 20,
        "walls and sonar cones"
    );
    assert!(svg.contains("look.xml at cycle"), "the plan panel");
    assert!(svg.contains("never"), "the running branch");
    assert!(svg.contains("stroke-dasharray"), "the true pose");
}
