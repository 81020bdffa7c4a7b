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
    t.hello(&[]);
    let board = t.board();
    let out = t.run("skillfab", &["clean", "--json"]);
    assert!(out.status.success());
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(!report["alive"].as_array().unwrap().is_empty(), "{report}");
    assert_eq!(report["files"], 0);
    let k = cycle(&board);
    t.wait_until("cycles to go on after clean", || cycle(&board) > k + 10);
    drop(board);

    // Every process of the domain killed at once: nothing removes its files.
    let pids = skillfab_proto::clean::live_pids(&t.domain);
    assert!(pids.len() >= 4, "manager and three skills: {pids:?}");
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
