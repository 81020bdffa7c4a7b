//! Two domains joined by two bridges (`skillfab bridge`, Zenoh peers over 127.0.0.1, or
//! across two network namespaces joined by a veth pair): a remote async skill on exported
//! sonar feeding a local skill, remote control as local control, the link cut and restored,
//! refusals that name both sides.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use nix::sys::signal::Signal;
use skillfab_bridge::{ZenohMode, ZenohOptions};
use skillfab_client::{Client, ClientError};
use skillfab_proto::bridge::BridgeStats;
use skillfab_proto::control::{EventKind, MonitorMode};
use skillfab_proto::param::ParamValue;
use skillfab_tests::{TestDomain, WAIT, bin};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// The manager of `t` at 50 Hz.
fn manager(t: &mut TestDomain) {
    t.spawn(
        "skillfab",
        &["manager", "--period-ms", "20", "--deadline-ms", "2000"],
    );
    t.board();
}

/// The simulated robot in [`skillfab_tests::BOX_ROOM`] and its device process, in `t`.
fn robot(t: &mut TestDomain) {
    let world = t.dir.join("room.toml");
    std::fs::write(&world, skillfab_tests::BOX_ROOM).unwrap();
    let link = t.dir.join("robot");
    t.spawn(
        "denning-sim",
        &[
            "--world",
            world.to_str().unwrap(),
            "--link",
            link.to_str().unwrap(),
        ],
    );
    t.wait_until("the simulator's link", || link.exists());
    t.spawn("denning", &["--port", link.to_str().unwrap()]);
}

/// The bridges' reports in `c`'s domain.
fn bridges(c: &Client) -> Vec<BridgeStats> {
    c.stats().map(|s| s.bridges).unwrap_or_default()
}

fn remote(port: u16) -> ZenohOptions {
    ZenohOptions {
        mode: ZenohMode::Client,
        connect: vec![format!("tcp/127.0.0.1:{port}")],
        ..ZenohOptions::default()
    }
}

fn value(c: &Client, path: &str) -> Option<f64> {
    c.query(path).ok().and_then(|(v, _)| v.as_f64())
}

#[test]
fn a_remote_async_skill_computes_on_exported_sonar_and_a_local_skill_uses_it_across_a_link_cut() {
    let (mut a, mut b) = (TestDomain::new("bridgerobot"), TestDomain::new("bridgefar"));
    let port = skillfab_tests::free_port();
    manager(&mut a);
    manager(&mut b);
    robot(&mut a);
    a.spawn("guard", &[]);
    b.spawn("nearest", &[]);
    let (an, bn) = (a.domain.name().to_string(), b.domain.name().to_string());
    let listen = format!("tcp/127.0.0.1:{port}");
    a.spawn(
        "skillfab",
        &[
            "bridge", "--listen", &listen, "--export", "sonar", "--import", "nearest", "--from",
            &bn,
        ],
    );
    let b_args = [
        "bridge",
        "--connect",
        &listen,
        "--export",
        "nearest",
        "--import",
        "sonar",
        "--from",
        &an,
    ];
    let far = b.spawn("skillfab", &b_args);
    let ca = Client::connect(&a.domain).unwrap();
    let cb = Client::connect(&b.domain).unwrap();

    // The local sync skill uses what the remote async skill computed from the local sonar:
    // the nearest wall is 2 m from the robot's centre (the sonar ring is on its 0.36 m hull).
    a.wait_until("guard to use the remote nearest range", || {
        value(&ca, "guard.guard.value").is_some_and(|v| (1.2..2.2).contains(&v))
    });
    let skills = ca.list().unwrap();
    assert!(
        skills.iter().all(|s| s.name != "nearest"),
        "nearest runs only in the far domain"
    );
    let bridge = skills.iter().find(|s| s.name == "bridge").unwrap();
    assert_eq!(
        bridge.mode.to_string(),
        "async",
        "remote producers are async producers here"
    );
    assert!(
        bridge
            .outputs
            .iter()
            .any(|o| o.topic == "nearest" && o.type_name == "skillfab.Scalar")
    );
    assert!(value(&cb, "nearest.nearest.value").is_some_and(|v| (1.2..2.2).contains(&v)));

    // Figures: samples both ways, none lost or refused, a latency measured.
    a.wait_until("the bridge's figures in stats", || {
        bridges(&ca).first().is_some_and(|s| {
            s.links >= 1
                && s.imports.first().is_some_and(|i| i.samples > 20)
                && s.exports.first().is_some_and(|e| e.samples > 20)
        })
    });
    let s = &bridges(&ca)[0];
    let import = &s.imports[0];
    assert_eq!(
        (import.topic.as_str(), import.remote.as_str()),
        ("nearest", bn.as_str())
    );
    assert_eq!((import.lost, import.refused), (0, 0), "{s:?}");
    assert!(import.latency_us.p50 > 0.0, "{s:?}");
    let ctl_stats =
        String::from_utf8_lossy(&a.run("skillfab", &["ctl", "stats"]).stdout).into_owned();
    assert!(
        ctl_stats.contains("import nearest") && ctl_stats.contains("0 lost"),
        "{ctl_stats}"
    );

    // The link cut: the far bridge dies. Here the link goes down, the local skills keep
    // cycling on the last value; nothing else restarts.
    let before = s.imports[0].samples;
    b.signal(far, Signal::SIGKILL);
    b.wait_exit(far);
    a.wait_until("the link to be seen down", || {
        bridges(&ca).first().is_some_and(|s| s.links == 0)
    });
    let (_, cycle) = ca.query("guard.guard").unwrap();
    a.wait_until("guard to keep running", || {
        ca.query("guard.guard").is_ok_and(|(_, c)| c > cycle + 10)
    });
    // Restored: the far bridge is started again and samples flow again.
    b.spawn("skillfab", &b_args);
    a.wait_until("the link to come back and samples to flow", || {
        bridges(&ca).first().is_some_and(|s| {
            s.links >= 1 && s.reconnects >= 1 && s.imports[0].samples > before + 20
        })
    });
    assert!(value(&ca, "guard.guard.value").is_some_and(|v| (1.2..2.2).contains(&v)));
}

#[test]
fn remote_ctl_ls_set_query_monitor_and_logs_behave_as_local_ones() {
    let mut a = TestDomain::new("bridgectl");
    let port = skillfab_tests::free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    // The hello network with a `[bridge]` section: `up` starts and supervises the bridge.
    let launch = a.launch_file(&format!(
        "{}[bridge]\nlisten = [\"{listen}\"]\n",
        skillfab_tests::HELLO
    ));
    a.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let name = a.domain.name().to_string();
    // The bridge serves requests once it is up: connect and ask until it answers, with the
    // three skills registered.
    let mut r = None;
    a.wait_until("the bridge to answer", || {
        r = skillfab_bridge::connect(&name, &remote(port))
            .ok()
            .filter(|c| c.list().is_ok_and(|l| l.len() == 3));
        r.is_some()
    });
    let mut r = r.unwrap();
    assert!(r.is_remote());
    let local = Client::connect(&a.domain).unwrap();

    // ls through the CLI.
    let out = a.run("skillfab", &["ctl", "--remote", &listen, "ls"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for skill in ["ticker", "scale", "smooth"] {
        assert!(text.contains(skill), "{text}");
    }

    // set, get, query.
    r.log_lines().unwrap(); // subscribes to the log stream before the change it will show
    r.set_param("scale", "gain", "3").unwrap();
    assert_eq!(
        local.get_param("scale", "gain").unwrap(),
        ParamValue::Float(3.0)
    );
    a.wait_until("scaled = 3 × tick", || {
        let tick = value(&r, "ticker.tick.value");
        let scaled = value(&r, "scale.scaled.value");
        matches!((tick, scaled), (Some(t), Some(s)) if s == 3.0 * t || s == 3.0 * (t - 1.0))
    });

    // The same refusals, word for word.
    let remote_err = r.set_param("scale", "nope", "1").unwrap_err().to_string();
    let local_err = local
        .set_param("scale", "nope", "1")
        .unwrap_err()
        .to_string();
    assert_eq!(remote_err, local_err);
    let remote_err = r.query("nobody.out").unwrap_err().to_string();
    assert_eq!(
        remote_err,
        local.query("nobody.out").unwrap_err().to_string()
    );
    let cli = a.run(
        "skillfab",
        &["ctl", "--remote", &listen, "set", "scale.nope=1"],
    );
    assert!(!cli.status.success());
    assert!(
        String::from_utf8_lossy(&cli.stderr).contains(&local_err),
        "{cli:?}"
    );

    // A monitor installed remotely fires remotely.
    let id = r
        .add_monitor("ticker.tick.value > 0", MonitorMode::Once, 0)
        .unwrap();
    let deadline = Instant::now() + WAIT;
    let mut fired = false;
    while !fired && Instant::now() < deadline {
        if let Some(ev) = r.next_event(Duration::from_millis(200)).unwrap() {
            fired = matches!(ev.kind, EventKind::MonitorFired { id: m, .. } if m == id);
        }
    }
    assert!(fired, "monitor {id} did not fire remotely");

    // The skill's log line about the change arrives over the link.
    let deadline = Instant::now() + WAIT;
    let mut seen = false;
    while !seen && Instant::now() < deadline {
        seen = r
            .log_lines()
            .unwrap()
            .iter()
            .any(|l| l.skill == "scale" && l.message.contains("parameter set"));
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(
        seen,
        "scale's 'parameter set' line did not come over the bridge"
    );

    // A domain whose bridge is not there: a clear error, not a hang.
    let nobody = skillfab_bridge::connect("nobody-here", &remote(port)).unwrap();
    let mut nobody = nobody;
    nobody.set_timeout(Duration::from_millis(500));
    match nobody.list() {
        Err(e @ ClientError::NoBridge { .. }) => {
            let text = e.to_string();
            assert!(
                text.contains("no bridge of domain 'nobody-here' answered through tcp/127.0.0.1:"),
                "{text}"
            )
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_type_mismatch_and_an_actuator_channel_are_refused_with_both_sides_named() {
    let (mut a, mut b) = (
        TestDomain::new("bridgetype"),
        TestDomain::new("bridgetypefar"),
    );
    manager(&mut a);
    manager(&mut b);
    a.spawn("ticker", &[]);
    // Here `tick` is read as a Scalar; there it is a Tick.
    b.spawn("guard", &["--remap", "nearest=tick"]);
    let board = b.board();
    b.wait_until("guard to register", || {
        skillfab_tests::registered(&board, "guard").is_some()
    });
    let port = skillfab_tests::free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    let an = a.domain.name().to_string();
    a.spawn(
        "skillfab",
        &["bridge", "--listen", &listen, "--export", "tick"],
    );
    b.spawn(
        "skillfab",
        &[
            "bridge",
            "--connect",
            &listen,
            "--import",
            "tick",
            "--from",
            &an,
        ],
    );
    let cb = Client::connect(&b.domain).unwrap();
    a.wait_until("the refusal in the far bridge's report", || {
        bridges(&cb).first().is_some_and(|s| !s.errors.is_empty())
    });
    let why = bridges(&cb)[0].errors[0].clone();
    for part in [
        "type mismatch on imported topic 'tick'",
        &format!("domain '{an}' exports skillfab.Tick"),
        "skill 'guard' input 'nearest'",
        "skillfab.Scalar",
    ] {
        assert!(why.contains(part), "'{part}' not in: {why}");
    }
    assert!(bridges(&cb)[0].imports.is_empty());

    // An actuator channel is a sync input: no remote producer may feed it.
    let out = b.run(
        "skillfab",
        &[
            "bridge",
            "--connect",
            &listen,
            "--import",
            "channel/drive",
            "--from",
            &an,
        ],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("cannot import 'channel/drive'") && err.contains("sync input"),
        "{err}"
    );
}

/// Two network namespaces joined by a veth pair, removed on drop.
struct Namespaces {
    names: [String; 2],
}

impl Namespaces {
    /// `None` (and why) where the machine does not allow it.
    fn create(tag: &str) -> Result<Namespaces, String> {
        let names = [format!("{tag}a"), format!("{tag}b")];
        let ns = Namespaces { names };
        let [na, nb] = &ns.names;
        let (va, vb) = (format!("{tag}va"), format!("{tag}vb"));
        let steps: Vec<Vec<&str>> = vec![
            vec!["netns", "add", na],
            vec!["netns", "add", nb],
            vec!["link", "add", &va, "type", "veth", "peer", "name", &vb],
            vec!["link", "set", &va, "netns", na],
            vec!["link", "set", &vb, "netns", nb],
            vec!["-n", na, "addr", "add", "10.231.0.1/24", "dev", &va],
            vec!["-n", nb, "addr", "add", "10.231.0.2/24", "dev", &vb],
            vec!["-n", na, "link", "set", &va, "up"],
            vec!["-n", nb, "link", "set", &vb, "up"],
            vec!["-n", na, "link", "set", "lo", "up"],
            vec!["-n", nb, "link", "set", "lo", "up"],
        ];
        for step in steps {
            let out = Command::new("ip")
                .args(&step)
                .output()
                .map_err(|e| format!("ip: {e}"))?;
            if !out.status.success() {
                return Err(format!(
                    "ip {}: {}",
                    step.join(" "),
                    String::from_utf8_lossy(&out.stderr).trim()
                ));
            }
        }
        Ok(ns)
    }
}

impl Drop for Namespaces {
    fn drop(&mut self) {
        for n in &self.names {
            let _ = Command::new("ip").args(["netns", "del", n]).output();
        }
    }
}

/// `ip netns exec NS PROGRAM ARGS` in `t`.
fn spawn_in(t: &mut TestDomain, ns: &str, program: &str, args: &[&str]) -> usize {
    let ip = ["/usr/sbin/ip", "/sbin/ip", "/usr/bin/ip"]
        .into_iter()
        .find(|p| Path::new(p).exists())
        .unwrap();
    let path = bin(program);
    let mut all = vec!["netns", "exec", ns, path.to_str().unwrap()];
    all.extend_from_slice(args);
    t.spawn_at(Path::new(ip), &all)
}

#[test]
fn across_two_network_namespaces_joined_by_a_veth_pair() {
    // The namespaces go last, after every process in them.
    let tag = format!("sf{}", std::process::id() % 100_000);
    let ns = match Namespaces::create(&tag) {
        Ok(ns) => ns,
        Err(why) => {
            eprintln!("SKIPPED: network namespaces are not available here: {why}");
            return;
        }
    };
    let (mut a, mut b) = (TestDomain::new("bridgensa"), TestDomain::new("bridgensb"));
    let [na, nb] = ns.names.clone();
    // Every process of a domain in its namespace: here A is 10.231.0.1, B 10.231.0.2.
    spawn_in(&mut a, &na, "skillfab", &["manager", "--period-ms", "20"]);
    spawn_in(&mut a, &na, "ticker", &[]);
    spawn_in(&mut b, &nb, "skillfab", &["manager", "--period-ms", "20"]);
    let an = a.domain.name().to_string();
    let endpoint = "tcp/10.231.0.1:7447";
    spawn_in(
        &mut a,
        &na,
        "skillfab",
        &["bridge", "--listen", endpoint, "--export", "tick"],
    );
    spawn_in(
        &mut b,
        &nb,
        "skillfab",
        &[
            "bridge",
            "--connect",
            endpoint,
            "--import",
            "tick",
            "--from",
            &an,
        ],
    );
    let ctl_in = |t: &TestDomain, ns: &str, args: &[&str]| {
        let mut c = t.command_at(Path::new("ip"));
        c.args([
            "netns",
            "exec",
            ns,
            bin("skillfab").to_str().unwrap(),
            "ctl",
        ])
        .args(args);
        c.output().unwrap()
    };
    // The tick of A, republished in B, advances.
    let tick = |t: &TestDomain| {
        let out = ctl_in(t, &nb, &["query", "bridge.tick.value"]);
        String::from_utf8_lossy(&out.stdout)
            .trim()
            .parse::<f64>()
            .ok()
    };
    let mut first = None;
    b.wait_until("A's tick in B", || {
        first = tick(&b);
        first.is_some()
    });
    b.wait_until("A's tick to advance in B", || tick(&b) > first);
    // Remote control of A from B's namespace, over the veth link.
    let out = ctl_in(&b, &nb, &["--remote", endpoint, "--domain", &an, "ls"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("ticker"));
}
