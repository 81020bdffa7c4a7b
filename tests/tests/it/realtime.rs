//! Real-time mode (issue 33) end to end: the scheduling class, priority, CPU affinity and
//! locked memory of the skills' and the manager's threads as the kernel shows them in `/proc`;
//! what a machine refuses, said in the log while the fabric cycles on; deadline misses; and the
//! check that the cycle's path allocates nothing. Priorities stay low (10, 11): a test must not
//! starve the machine it runs on.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use skillfab_proto::realtime::{CpuList, RealTime};
use skillfab_tests::{TestDomain, registered, skill};

/// `SCHED_OTHER` and `SCHED_FIFO` as `/proc/<pid>/stat` gives a thread's policy.
const SCHED_OTHER: u32 = 0;
const SCHED_FIFO: u32 = 1;

/// A thread's scheduling policy and real-time priority (`/proc/<pid>/task/<tid>/stat`).
fn sched_of(pid: u32, tid: u32) -> (u32, u32) {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/task/{tid}/stat")).unwrap();
    // Fields after the command's closing parenthesis start at field 3 (state); rt_priority
    // is field 40 and policy field 41.
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .unwrap()
        .1
        .split_whitespace()
        .collect();
    (fields[38].parse().unwrap(), fields[37].parse().unwrap())
}

/// The threads of a process.
fn threads(pid: u32) -> Vec<u32> {
    std::fs::read_dir(format!("/proc/{pid}/task"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().parse().unwrap())
        .collect()
}

/// A line of a thread's `status` (`Cpus_allowed_list`, `VmLck`), without its name.
fn status(pid: u32, tid: u32, key: &str) -> String {
    std::fs::read_to_string(format!("/proc/{pid}/task/{tid}/status"))
        .unwrap()
        .lines()
        .find_map(|l| {
            l.strip_prefix(&format!("{key}:"))
                .map(|v| v.trim().to_string())
        })
        .unwrap_or_else(|| panic!("no {key} in /proc/{pid}/task/{tid}/status"))
}

/// Whether this machine grants `fifo:1` to a thread of this process (asked on a thread that
/// ends right after).
fn fifo_granted() -> bool {
    std::thread::spawn(|| {
        let applied = "fifo:1".parse::<RealTime>().unwrap().apply();
        applied.refused.is_empty()
    })
    .join()
    .unwrap()
}

/// The last CPU this process may run on (a test pins there, off CPU 0's interrupts).
fn a_cpu() -> usize {
    let list: CpuList = status(std::process::id(), std::process::id(), "Cpus_allowed_list")
        .parse()
        .unwrap();
    *list.cpus().last().unwrap()
}

/// The process `pid`'s serving thread (its main thread) runs under `want` (policy, priority)
/// and every other thread of it is an ordinary one.
fn assert_only_the_main_thread_is(pid: u32, want: (u32, u32), who: &str) {
    assert_eq!(sched_of(pid, pid), want, "{who}'s serving thread");
    for tid in threads(pid).into_iter().filter(|&t| t != pid) {
        assert_eq!(
            sched_of(pid, tid).0,
            SCHED_OTHER,
            "{who}'s thread {tid} is not the serving one and stays ordinary"
        );
    }
}

#[test]
fn a_realtime_launch_makes_each_serving_thread_real_time_pinned_and_locked() {
    let mut t = TestDomain::new("rtlaunch");
    let cpu = a_cpu();
    let launch = t.launch_file(&format!(
        r#"
[manager]
period_ms = 5
deadline_ms = 2000
[realtime]
priority = 10
cpus = [{cpu}]
[[process]]
name = "ticker"
bin = "{{bin:ticker}}"
[[process]]
name = "relay"
bin = "{{bin:relay}}"
remap = {{ prev = "tick", tick = "t1" }}
[[process]]
name = "plain"
bin = "{{bin:relay}}"
remap = {{ prev = "t1", tick = "t2" }}
realtime = false
"#
    ));
    let up = t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let board = t.board();
    let names = ["ticker", "relay", "plain"];
    t.wait_until("the chain to run", || {
        names
            .iter()
            .all(|n| registered(&board, n).is_some_and(|s| s.runs > 20))
    });
    let granted = fifo_granted();
    let manager = board
        .header()
        .manager_pid
        .load(std::sync::atomic::Ordering::Acquire);
    for (who, pid, priority) in [
        ("ticker", registered(&board, "ticker").unwrap().decl.pid, 10),
        ("relay", registered(&board, "relay").unwrap().decl.pid, 10),
        ("the manager", manager, 11),
    ] {
        let want = if granted {
            (SCHED_FIFO, priority)
        } else {
            (SCHED_OTHER, 0)
        };
        assert_only_the_main_thread_is(pid, want, who);
        assert_eq!(
            status(pid, pid, "Cpus_allowed_list"),
            cpu.to_string(),
            "{who} is pinned"
        );
    }
    let plain = registered(&board, "plain").unwrap().decl.pid;
    assert_eq!(sched_of(plain, plain), (SCHED_OTHER, 0), "plain opted out");
    // What each was granted or refused is in the log (children's stderr is up's).
    let log = t.log(up);
    if granted {
        let line = format!(
            "real-time mode of the skill's thread: SCHED_FIFO priority 10, pinned to CPU {cpu}"
        );
        assert_eq!(log.matches(&line).count(), 2, "ticker and relay: {log}");
        assert!(
            log.contains(&format!(
                "real-time mode of the manager's cycle thread: SCHED_FIFO priority 11, pinned to CPU {cpu}"
            )),
            "{log}"
        );
    } else {
        assert!(log.contains("SCHED_FIFO priority 10 refused"), "{log}");
    }
    // Locked memory, or the reason it is not.
    let ticker = registered(&board, "ticker").unwrap().decl.pid;
    if log.contains("memory locked") {
        let locked: u64 = status(ticker, ticker, "VmLck")
            .trim_end_matches(" kB")
            .parse()
            .unwrap();
        assert!(locked > 0, "the ticker's memory is locked");
    } else {
        assert!(log.contains("locking memory"), "{log}");
    }
    // The fabric cycles, and its figures carry the new counts.
    let runs = registered(&board, "relay").unwrap().runs;
    t.wait_until("the chain to go on", || {
        registered(&board, "relay").is_some_and(|s| s.runs > runs + 50)
    });
    let stats: serde_json::Value = serde_json::from_str(&t.ctl(&["--json", "stats"])).unwrap();
    assert!(stats["late_starts"].is_u64(), "{stats}");
    for s in stats["skills"].as_array().unwrap() {
        assert!(s["deadline_misses"].is_u64(), "{s}");
        assert!(s["cycle_allocs"].is_u64(), "counted in every skill: {s}");
    }
    let text = t.ctl(&["stats"]);
    assert!(text.contains("late starts"), "{text}");
    assert!(text.contains("deadline misses"), "{text}");
}

#[test]
fn a_cpu_that_does_not_exist_is_said_and_the_fabric_cycles_on() {
    let t = TestDomain::new("rtnocpu");
    let launch = t.launch_file(
        r#"
[manager]
period_ms = 2
deadline_ms = 2000
[realtime]
priority = 10
cpus = [1000]
lock_memory = false
[[process]]
name = "ticker"
bin = "{bin:ticker}"
[[process]]
name = "relay"
bin = "{bin:relay}"
remap = { prev = "tick", tick = "t1" }
"#,
    );
    let out = t.run(
        "skillfab",
        &["up", launch.to_str().unwrap(), "--cycles", "100", "--json"],
    );
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["cycles"], 100, "{r}");
    for name in ["ticker", "relay"] {
        assert_eq!(skill(&r, name)["runs"], 100, "{r}");
    }
    let online = std::fs::read_to_string("/sys/devices/system/cpu/online").unwrap();
    let online: CpuList = online.trim().parse().unwrap();
    let refused = format!(
        "CPU 1000 does not exist ({} online: {online}); not pinned, running on any CPU",
        online.cpus().len()
    );
    assert!(
        log.contains(&format!(
            "real-time mode of the manager's cycle thread: {refused}"
        )),
        "{log}"
    );
    assert_eq!(
        log.matches(&format!("real-time mode of the skill's thread: {refused}"))
            .count(),
        2,
        "ticker and relay: {log}"
    );
}

#[test]
fn a_skill_without_the_privilege_is_told_how_to_get_it_and_runs_on() {
    use std::os::unix::process::CommandExt;
    let mut t = TestDomain::new("rtnopriv");
    t.spawn("skillfab", &["manager", "--period-ms", "5"]);
    let board = t.board();
    let mut ticker = t.command("ticker");
    ticker.args(["--realtime", "fifo:10"]);
    // SAFETY: only async-signal-safe system calls run between fork and exec.
    unsafe {
        ticker.pre_exec(|| {
            // No real-time priority allowed by limit, and (for root) no CAP_SYS_NICE after
            // exec: out of the bounding set and the ambient one (both fail harmlessly for a
            // process that may not change them, which has no such capability anyway).
            let none = nix::libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            if nix::libc::setrlimit(nix::libc::RLIMIT_RTPRIO, &none) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            nix::libc::prctl(nix::libc::PR_CAPBSET_DROP, 23, 0, 0, 0);
            nix::libc::prctl(
                nix::libc::PR_CAP_AMBIENT,
                nix::libc::PR_CAP_AMBIENT_CLEAR_ALL,
                0,
                0,
                0,
            );
            Ok(())
        });
    }
    let i = t.spawn_command(ticker);
    t.wait_until("the ticker to run without real-time mode", || {
        registered(&board, "ticker").is_some_and(|s| s.runs > 20)
    });
    let log = t.log(i);
    assert!(
        log.contains(
            "real-time mode of the skill's thread: SCHED_FIFO priority 10 refused (EPERM): \
             needs CAP_SYS_NICE or `ulimit -r` ≥ 10 (now 0; rtprio in /etc/security/limits.d, \
             LimitRTPRIO= for a systemd service); running on under SCHED_OTHER"
        ),
        "{log}"
    );
    let pid = t.pid(i);
    assert_eq!(sched_of(pid, pid), (SCHED_OTHER, 0));
}

#[test]
fn a_run_past_the_deadline_is_its_skills_miss_not_its_consumers() {
    let t = TestDomain::new("rtmiss");
    // `slow` runs 300 ms of every 250 ms cycle whose deadline is 200 ms: each of its runs is
    // in progress at the deadline or ends after it. `ticker` has 200 ms for a tick; `sink`
    // waits for `slow` (its miss is slow's, not its own).
    let r = t.up_json(
        r#"
[manager]
period_ms = 250
deadline_ms = 200
[[process]]
name = "ticker"
bin = "{bin:ticker}"
[[process]]
name = "slow"
bin = "{bin:work}"
params = { sleep_ms = 300.0 }
remap = { out = "mid" }
[[process]]
name = "sink"
bin = "{bin:sink}"
remap = { input = "mid" }
"#,
        &["--cycles", "6"],
    );
    assert_eq!(r["cycles"], 6, "{r}");
    let overruns = r["overruns"].as_u64().unwrap();
    assert!(overruns >= 5, "the deadline closes the cycles: {r}");
    let slow = skill(&r, "slow")["deadline_misses"].as_u64().unwrap();
    assert!(slow >= overruns, "every overrun is slow's miss: {r}");
    assert_eq!(skill(&r, "ticker")["deadline_misses"], 0, "{r}");
    assert_eq!(
        skill(&r, "sink")["deadline_misses"],
        0,
        "waiting for a late producer is not a miss: {r}"
    );
}

/// A chain of the shipped skills and the test relay, and a device with two proposers.
const SHIPPED: &str = r#"
[manager]
period_ms = 2
deadline_ms = 2000
[[process]]
name = "ticker"
bin = "{bin:ticker}"
[[process]]
name = "r1"
bin = "{bin:relay}"
remap = { prev = "tick", tick = "t1" }
[[process]]
name = "r2"
bin = "{bin:relay}"
remap = { prev = "t1", tick = "t2" }
[[process]]
name = "scale"
bin = "{bin:scale}"
[[process]]
name = "smooth"
bin = "{bin:smooth}"
[[process]]
name = "dev"
bin = "{bin:mock-device}"
[[process]]
name = "p1"
bin = "{bin:proposer}"
priority = 2
params = { translate = 0.5, rotate = 0.1 }
[[process]]
name = "p2"
bin = "{bin:proposer}"
priority = 1
params = { translate = 0.2, rotate = 0.1 }
"#;

#[test]
fn the_shipped_skills_and_a_device_do_not_allocate_on_the_cycle_path() {
    let t = TestDomain::new("rtalloc");
    let r = t.up_json(SHIPPED, &["--cycles", "300"]);
    assert_eq!(r["cycles"], 300, "{r}");
    for s in r["skills"].as_array().unwrap() {
        assert!(s["runs"].as_u64().unwrap() > 100, "{s}");
        assert_eq!(
            s["cycle_allocs"], 0,
            "{} allocated on the cycle's path after its warm-up: {s}",
            s["name"]
        );
    }
}

#[test]
fn a_body_that_allocates_is_counted_and_warned_about_in_real_time_mode() {
    let t = TestDomain::new("rtallocs");
    let launch = t.launch_file(
        r#"
[manager]
period_ms = 2
deadline_ms = 2000
[[process]]
name = "ticker"
bin = "{bin:ticker}"
[[process]]
name = "grows"
bin = "{bin:work}"
params = { allocate_bytes = 256 }
realtime = { priority = 10, lock_memory = false }
"#,
    );
    let out = t.run(
        "skillfab",
        &["up", launch.to_str().unwrap(), "--cycles", "300", "--json"],
    );
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let grows = skill(&r, "grows");
    let runs = grows["runs"].as_u64().unwrap();
    let allocs = grows["cycle_allocs"].as_u64().unwrap();
    // One allocation per run after the 10 warm-up runs, but for the few runs whose wake-up
    // also checked liveness (once a second) or applied parameters (the first).
    assert!(
        (runs - 10 - 4..=runs - 10).contains(&allocs),
        "{allocs} allocations in {runs} runs: {grows}"
    );
    assert_eq!(skill(&r, "ticker")["cycle_allocs"], 0, "{r}");
    assert!(
        log.contains("a run allocated on the cycle's path in real-time mode")
            && log.contains("allocations=1"),
        "{log}"
    );
}

#[test]
fn an_iceoryx2_loan_allocates_one_block_which_the_count_leaves_out() {
    use skill_sdk::allocs::thread_allocs;
    let t = TestDomain::new("rtloan");
    let node = skillfab_proto::services::node(&t.domain, "loaner").unwrap();
    let publisher =
        skillfab_proto::services::publisher::<skillfab_msgs::Tick>(&node, "tick").unwrap();
    drop(publisher.loan_uninit().unwrap()); // (a first loan may set up what later ones share)
    let before = thread_allocs().unwrap();
    for _ in 0..100 {
        drop(std::hint::black_box(publisher.loan_uninit().unwrap()));
    }
    assert_eq!(
        thread_allocs().unwrap() - before,
        100,
        "iceoryx2 0.10 allocates one block per loan; the runtime's count leaves exactly these \
         out (skill_sdk::allocs::in_loan): if this changed, so must that"
    );
}
