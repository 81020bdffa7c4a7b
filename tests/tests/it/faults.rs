//! Faults and misuse around a running fabric: who may open a domain, and what is left on the
//! machine after processes die.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use skillfab_tests::{TestDomain, bin, cycle};
use std::os::unix::fs::MetadataExt;

/// Runs `program ARGS` in `t`'s domain as uid/gid 65534 (nobody); returns (success, stderr).
fn as_nobody(t: &TestDomain, program: &str, args: &[&str]) -> (bool, String) {
    let out = std::process::Command::new("setpriv")
        .args(["--reuid=65534", "--regid=65534", "--clear-groups"])
        .arg(bin(program))
        .args(args)
        .env_clear()
        .env("SKILLFAB_DOMAIN", t.domain.name())
        .env("PATH", "/usr/bin:/bin")
        .output()
        .expect("setpriv");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_domain_is_private_to_the_user_who_runs_it() {
    let mut t = TestDomain::new("private");
    t.hello(&[]);
    let me = nix::unistd::geteuid().as_raw();
    let files = t.domain.shm_files();
    assert!(files.len() > 10, "the domain's files: {files:?}");
    for f in &files {
        let m = std::fs::metadata(f).unwrap();
        assert_eq!(
            (m.uid(), m.mode() & 0o777),
            (me, 0o600),
            "{} is not owner-only",
            f.display()
        );
    }
    let root = std::fs::metadata(t.domain.root_path()).unwrap();
    assert_eq!((root.uid(), root.mode() & 0o777), (me, 0o700));

    if me != 0 {
        // Switching to another uid needs root; the modes above are what keep others out.
        eprintln!("not root: the other-user half of this test needs setpriv as root");
        return;
    }
    let board = t.board();
    let before = cycle(&board);
    let (ok, err) = as_nobody(&t, "skillfab", &["ctl", "ls"]);
    assert!(!ok);
    assert!(err.contains("belongs to another user"), "{err}");
    let (ok, err) = as_nobody(&t, "ticker", &[]);
    assert!(!ok);
    assert!(err.contains("another user's domain"), "{err}");
    let (ok, err) = as_nobody(&t, "skillfab-manager", &["manager"]);
    assert!(!ok);
    assert!(err.contains("another user's domain"), "{err}");
    // The fabric did not notice.
    t.wait_until("cycles to go on", || cycle(&board) > before + 10);
    assert_eq!(
        t.ctl(&["ls"])
            .lines()
            .filter(|l| l.contains("active"))
            .count(),
        3
    );
}

#[test]
fn clean_keeps_a_live_domain_and_removes_a_dead_ones_files() {
    let mut t = TestDomain::new("clean");
    let up = t.hello(&[]);
    let board = t.board();
    let out = t.run("skillfab", &["clean", "--json"]);
    assert!(out.status.success());
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(!report["alive"].as_array().unwrap().is_empty(), "{report}");
    assert_eq!(report["files"], 0);
    let k = cycle(&board);
    t.wait_until("cycles to go on after clean", || cycle(&board) > k + 10);
    drop(board);

    // Every process of the domain killed at once, and the `skillfab up` that would restart
    // them: nothing removes its files. (Stopped first, they cannot act on their parent's
    // death either.)
    let pids = skillfab_proto::clean::live_pids(&t.domain);
    assert!(pids.len() >= 4, "manager and three skills: {pids:?}");
    for p in &pids {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(*p as i32),
            nix::sys::signal::Signal::SIGSTOP,
        );
    }
    t.signal(up, nix::sys::signal::Signal::SIGKILL);
    for p in &pids {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(*p as i32),
            nix::sys::signal::Signal::SIGKILL,
        );
    }
    t.wait_until("the domain's processes to be gone", || {
        skillfab_proto::clean::live_pids(&t.domain).is_empty()
    });
    let left = t.domain.shm_files();
    assert!(!left.is_empty(), "kill -9 leaves files behind");
    let out = t.run("skillfab", &["clean", "--json"]);
    assert!(out.status.success());
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["alive"], serde_json::json!([]));
    // The dead nodes' resources first (iceoryx2's own clean-up), then what no node owns:
    // the cycle board and iceoryx2's node counter at least.
    assert!(report["dead_nodes"].as_u64().unwrap() >= 4, "{report}");
    assert!(report["files"].as_u64().unwrap() >= 2, "{report}");
    assert_eq!(report["root"], true);
    assert!(t.domain.shm_files().is_empty());
    assert!(!t.domain.root_path().exists());
}

/// Sends `bytes` on `skillfab/control` as a plain iceoryx2 client would; returns the decoded
/// answer (waits for it with a deadline).
fn raw_request(
    t: &TestDomain,
    port: &iceoryx2::port::client::Client<iceoryx2::prelude::ipc::Service, [u8], (), [u8], ()>,
    wake: &iceoryx2::port::notifier::Notifier<iceoryx2::prelude::ipc::Service>,
    bytes: &[u8],
) -> skillfab_proto::control::Response {
    let pending = port
        .loan_slice_uninit(bytes.len())
        .unwrap()
        .write_from_slice(bytes)
        .send()
        .unwrap();
    wake.notify().unwrap();
    let mut answer = None;
    t.wait_until("an answer to raw bytes", || {
        if let Some(a) = pending.receive().unwrap() {
            let (seq, response) = skillfab_proto::control::decode_response(a.payload()).unwrap();
            // A request the manager could not read is answered under number 0, which every
            // client takes as its own answer (a client's numbers start at 1).
            assert_eq!(seq, 0, "{response:?}");
            answer = Some(response);
        }
        answer.is_some()
    });
    answer.unwrap()
}

#[test]
fn misbehaving_clients_get_clear_errors_and_the_fabric_runs_on() {
    use iceoryx2::prelude::AllocationStrategy;
    use skillfab_client::{Client, ClientError};
    use skillfab_proto::control::{ControlError, MonitorMode};
    use skillfab_proto::{names, services};
    let mut t = TestDomain::new("misbehave");
    t.hello(&[]);
    let board = t.board();
    let good = Client::connect(&t.domain).unwrap();

    // Random bytes on the control service from a plain iceoryx2 client: an error answer.
    let node = services::node(&t.domain, "garbage").unwrap();
    let port = services::control_service(&node)
        .unwrap()
        .client_builder()
        .initial_max_slice_len(4096)
        .allocation_strategy(AllocationStrategy::PowerOfTwo)
        .create()
        .unwrap();
    let wake = services::notifier(&node, &names::control()).unwrap();
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    for len in [0usize, 1, 7, 64, 3000] {
        let bytes: Vec<u8> = (0..len)
            .map(|_| {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                seed as u8
            })
            .collect();
        let answer = raw_request(&t, &port, &wake, &bytes);
        assert!(answer.is_err(), "{len} random bytes: {answer:?}");
    }
    // A client that sends and never reads its answers: its own queue fills, nobody else's.
    for _ in 0..16 {
        let Ok(s) = port.loan_slice_uninit(8) else {
            break;
        };
        if s.write_from_slice(&[1u8; 8]).send().is_err() {
            break;
        }
        let _ = wake.notify();
    }

    // A 10 000-character monitor expression and a 1 MB parameter string: clear errors.
    let long = format!("ticker.tick.value > {}", "1".repeat(10_000));
    match good.add_monitor(&long, MonitorMode::Once, 0) {
        Err(ClientError::Refused(ControlError::BadExpression { expr, .. })) => {
            assert!(expr.ends_with("(10020 bytes in all)"), "{expr}");
        }
        other => panic!("10 000-char expression: {other:?}"),
    }
    let huge = "1".repeat(1 << 20);
    match good.set_param("scale", "gain", &huge) {
        Err(ClientError::Refused(ControlError::RequestTooLarge { bytes, max })) => {
            assert_eq!(max, 65536);
            assert!(bytes > max, "{bytes}");
        }
        other => panic!("1 MB parameter: {other:?}"),
    }
    let err = good
        .set_param("scale", "gain", &"9".repeat(2000))
        .unwrap_err();
    assert!(err.to_string().len() < 300, "{err}");
    assert_eq!(good.get_param("scale", "gain").unwrap().to_string(), "2");

    // 64 slots: the 62 processes beyond hello's three take the rest, the last one is refused.
    let extra: Vec<usize> = (0..62)
        .map(|i| {
            let (name, remap) = (format!("extra{i}"), format!("tick=tick{i}"));
            t.spawn(
                "ticker",
                &["--name", &name, "--remap", &remap, "--inactive"],
            )
        })
        .collect();
    let mut refused = None;
    t.wait_until("61 extra skills registered and one refused", || {
        let registered = (0..62)
            .filter(|i| skillfab_tests::registered(&board, &format!("extra{i}")).is_some())
            .count()
            == 61;
        refused = extra.iter().find_map(|&c| {
            let log = std::fs::read_to_string(t.dir.join(format!("{c}-ticker.log"))).ok()?;
            log.contains("no free skill slot").then_some(c)
        });
        registered && refused.is_some()
    });

    // Everyone else is still served, and the cycle goes on.
    let k = cycle(&board);
    t.wait_until("cycles to go on", || cycle(&board) > k + 20);
    assert_eq!(good.get_param("scale", "gain").unwrap().to_string(), "2");
    assert!(good.list().unwrap().len() >= 64);
}

#[test]
fn a_hundred_clients_at_once_a_flood_and_a_foreign_publisher_of_the_wrong_type() {
    use iceoryx2::prelude::*;
    use skillfab_client::Client;
    use skillfab_proto::{names, services};
    let mut t = TestDomain::new("crowd");
    t.hello(&[]);
    let board = t.board();
    let k0 = cycle(&board);

    // 100 clients at once, each in its own thread and iceoryx2 node: every one is served.
    let domain = t.domain.clone();
    let served: Vec<Result<String, String>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..100)
            .map(|_| {
                let domain = domain.clone();
                s.spawn(move || {
                    let mut c = Client::connect(&domain).map_err(|e| e.to_string())?;
                    // Served is what counts here, not how soon (the suite may load the cores).
                    c.set_timeout(std::time::Duration::from_secs(60));
                    let n = c.list().map_err(|e| e.to_string())?.len();
                    let gain = c.get_param("scale", "gain").map_err(|e| e.to_string())?;
                    Ok(format!("{n} {gain}"))
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let failed: Vec<&String> = served.iter().filter_map(|r| r.as_ref().err()).collect();
    assert!(
        failed.is_empty(),
        "{} refused, the first: {:?}",
        failed.len(),
        failed.first()
    );
    assert!(
        served.iter().all(|r| r.as_deref() == Ok("3 2")),
        "{served:?}"
    );

    // A client that floods requests from 4 threads while another is served.
    let flooding = std::sync::atomic::AtomicBool::new(true);
    let (flood, answered) = std::thread::scope(|s| {
        let floods: Vec<_> = (0..4)
            .map(|_| {
                s.spawn(|| {
                    let c = Client::connect(&t.domain).unwrap();
                    let mut n = 0u64;
                    while flooding.load(std::sync::atomic::Ordering::Relaxed) {
                        c.query("ticker.tick.value").unwrap();
                        n += 1;
                    }
                    n
                })
            })
            .collect();
        let other = Client::connect(&t.domain).unwrap();
        let mut answered = 0;
        for _ in 0..50 {
            assert_eq!(other.get_param("scale", "gain").unwrap().to_string(), "2");
            answered += 1;
        }
        flooding.store(false, std::sync::atomic::Ordering::Relaxed);
        let flood: u64 = floods.into_iter().map(|h| h.join().unwrap()).sum();
        (flood, answered)
    });
    assert!(flood > 0 && answered == 50);

    // A plain iceoryx2 publisher on a fabric topic with another type: iceoryx2 refuses it
    // (the service's type details differ), the fabric's topic is untouched.
    let node = services::node(&t.domain, "foreign").unwrap();
    let wrong = node
        .service_builder(&ServiceName::new(&names::topic("tick")).unwrap())
        .publish_subscribe::<u64>()
        .user_header::<skillfab_proto::header::SampleHeader>()
        .open_or_create();
    let Err(err) = wrong else {
        panic!("a publisher of the wrong type was let in")
    };
    let err = format!("{err:?}");
    assert!(err.contains("IncompatibleTypes"), "{err}");
    // The same on a topic no skill produces yet: a skill that later reads it with the right
    // type is refused with an error naming the topic, and leaves; the fabric runs on.
    let squatter = node
        .service_builder(&ServiceName::new(&names::topic("squat")).unwrap())
        .publish_subscribe::<u64>()
        .user_header::<skillfab_proto::header::SampleHeader>()
        .open_or_create()
        .unwrap();
    let victim = t.spawn(
        "scale",
        &[
            "--name",
            "victim",
            "--remap",
            "tick=squat",
            "--remap",
            "scaled=victim_out",
        ],
    );
    let status = t.wait_exit(victim);
    assert!(!status.success());
    let log = std::fs::read_to_string(t.dir.join(format!("{victim}-scale.log"))).unwrap();
    assert!(log.contains("squat"), "{log}");
    drop(squatter);

    // Everyone else is still served and the cycle went on throughout.
    let c = Client::connect(&t.domain).unwrap();
    t.wait_until("the refused skill gone from the list", || {
        c.list().unwrap().len() == 3
    });
    t.wait_until("cycles to go on", || cycle(&board) > k0 + 50);
}
