//! `skillfab console` end to end: the real binary in a pseudo-terminal against a running
//! hello network. Its output is fed to a terminal emulator (vt100) so the test reads the
//! screen a person would see; keys go in through the pty; effects are checked through the
//! client library and `skillfab ctl`.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use nix::pty::{Winsize, openpty};
use skillfab_client::Client;
use skillfab_proto::control::SkillState;
use skillfab_proto::param::ParamValue;
use skillfab_tests::{TestDomain, WAIT};
use std::io::{Read, Write};
use std::num::NonZeroU16;
use std::os::fd::{AsRawFd, OwnedFd};
use std::os::unix::process::CommandExt;
use std::process::{Child, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

fn size(rows: u16, cols: u16) -> Winsize {
    Winsize {
        ws_row: rows,
        ws_col: cols,
        ws_xpixel: 0,
        ws_ypixel: 0,
    }
}

/// `skillfab console` on the slave side of a pty, with a vt100 screen fed from the master.
struct Console {
    child: Child,
    master: std::fs::File,
    screen: Arc<Mutex<vt100::Parser>>,
}

impl Console {
    fn start(t: &TestDomain, rows: u16, cols: u16) -> Console {
        Console::start_with(t, rows, cols, &[])
    }

    /// With more `console` arguments (`--remote ENDPOINT`).
    fn start_with(t: &TestDomain, rows: u16, cols: u16, args: &[&str]) -> Console {
        let pty = openpty(Some(&size(rows, cols)), None).expect("openpty");
        let slave: OwnedFd = pty.slave;
        let mut cmd = t.command("skillfab");
        cmd.arg("console")
            .args(args)
            .env("TERM", "xterm-256color")
            .stdin(Stdio::from(slave.try_clone().unwrap()))
            .stdout(Stdio::from(slave.try_clone().unwrap()))
            .stderr(Stdio::from(slave));
        // SAFETY: only async-signal-safe calls between fork and exec: a new session whose
        // controlling terminal is the pty (stdin), as a shell would give it.
        unsafe {
            cmd.pre_exec(|| {
                nix::unistd::setsid()?;
                if nix::libc::ioctl(0, nix::libc::TIOCSCTTY, 0) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
        let child = cmd.spawn().expect("spawn skillfab console");
        let master = std::fs::File::from(pty.master);
        let screen = Arc::new(Mutex::new(vt100::Parser::new(
            NonZeroU16::new(rows).unwrap(),
            NonZeroU16::new(cols).unwrap(),
            0,
        )));
        let (mut reader, s) = (master.try_clone().unwrap(), screen.clone());
        std::thread::spawn(move || {
            let mut buf = [0u8; 8192];
            // Ends with EIO once the console exits and the slave side is closed.
            while let Ok(n) = reader.read(&mut buf) {
                if n == 0 {
                    break;
                }
                s.lock().unwrap().process(&buf[..n]);
            }
        });
        Console {
            child,
            master,
            screen,
        }
    }

    fn text(&self) -> String {
        self.screen.lock().unwrap().screen().contents()
    }

    fn last_row(&self) -> String {
        let p = self.screen.lock().unwrap();
        let (_, cols) = p.screen().size();
        p.screen().rows(0, cols.get()).last().unwrap_or_default()
    }

    /// Waits until the screen shows `what`.
    fn wait_for(&self, what: &str) -> String {
        let deadline = Instant::now() + WAIT;
        loop {
            let text = self.text();
            if text.contains(what) {
                return text;
            }
            assert!(
                Instant::now() < deadline,
                "the console never showed {what:?}; screen:\n{text}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    fn keys(&mut self, bytes: &[u8]) {
        self.master.write_all(bytes).unwrap();
        self.master.flush().unwrap();
    }

    fn resize(&mut self, rows: u16, cols: u16) {
        self.screen.lock().unwrap().set_size(
            NonZeroU16::new(rows).unwrap(),
            NonZeroU16::new(cols).unwrap(),
        );
        // The kernel sends SIGWINCH to the console, its terminal's foreground group.
        let ws = size(rows, cols);
        // SAFETY: TIOCSWINSZ reads one Winsize from the pointer, which outlives the call.
        let rc = unsafe { nix::libc::ioctl(self.master.as_raw_fd(), nix::libc::TIOCSWINSZ, &ws) };
        assert_eq!(rc, 0, "TIOCSWINSZ");
    }

    fn wait_exit(&mut self) -> std::process::ExitStatus {
        let deadline = Instant::now() + WAIT;
        loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                return s;
            }
            assert!(Instant::now() < deadline, "the console did not exit");
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// Selects scale (its detail pane shows its input and output decoded, and its parameter) and
/// deactivates it with `a`; waits until the manager has it inactive and the console says so.
fn select_and_deactivate_scale(t: &TestDomain, client: &Client, con: &mut Console) {
    let order: Vec<String> = client.list().unwrap().into_iter().map(|s| s.name).collect();
    let scale = order.iter().position(|n| n == "scale").unwrap();
    con.keys("j".repeat(scale).as_bytes());
    let screen = con.wait_for("out scaled");
    assert!(screen.contains("in  tick"), "{screen}");
    assert!(screen.contains("gain"), "{screen}");
    con.keys(b"a");
    t.wait_until("scale to be inactive", || {
        client
            .list()
            .unwrap()
            .iter()
            .any(|s| s.name == "scale" && s.state == SkillState::Inactive)
    });
    con.wait_for("scale deactivated");
}

impl Drop for Console {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn keys_drive_the_fabric() {
    let mut t = TestDomain::new("console");
    let log = t.dir.join("params.jsonl");
    t.hello(&["--param-log", log.to_str().unwrap()]);
    let client = Client::connect(&t.domain).unwrap();

    let mut con = Console::start(&t, 40, 120);
    con.wait_for("skills (3)");
    select_and_deactivate_scale(&t, &client, &mut con);

    // e: edit gain; an out-of-range value is refused with the manager's reason...
    con.keys(b"e");
    con.wait_for("set scale.gain = ");
    con.keys(&[0x7f; 8]);
    con.keys(b"1e9\r");
    con.wait_for("out of range");
    assert_eq!(
        client.get_param("scale", "gain").unwrap(),
        ParamValue::Float(2.0)
    );
    // ...and a good one is applied (and lands in the fabric log).
    con.keys(b"e");
    con.wait_for("set scale.gain = ");
    con.keys(&[0x7f; 8]);
    con.keys(b"5\r");
    t.wait_until("gain = 5", || {
        client.get_param("scale", "gain").unwrap() == ParamValue::Float(5.0)
    });
    assert_eq!(t.ctl(&["get", "scale.gain"]).trim(), "5");
    // The change is in the fabric log: who, when, old and new.
    let changes = std::fs::read_to_string(&log).unwrap();
    let change: serde_json::Value = changes
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .find(|j| j["kind"] == "param")
        .unwrap_or_else(|| panic!("no param line in {changes}"));
    assert_eq!(change["skill"], "scale");
    assert_eq!(change["param"], "gain");
    assert_eq!(change["old"], 2.0);
    assert_eq!(change["new"], 5.0);
    assert!(change["cycle"].as_u64().unwrap() > 0, "{change}");
    assert!(change["by"].as_str().unwrap().contains('-'), "{change}");

    // A resize redraws at the new size: the help line is on the new last row.
    con.resize(30, 110);
    let deadline = Instant::now() + WAIT;
    while !con.last_row().contains("q quit") {
        assert!(
            Instant::now() < deadline,
            "no redraw at 30 rows:\n{}",
            con.text()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    con.keys(b"a");
    t.wait_until("scale to be active again", || {
        client
            .list()
            .unwrap()
            .iter()
            .any(|s| s.name == "scale" && s.state == SkillState::Active)
    });

    // v: the skill's own log lines, every level (the skill applied the new gain).
    con.keys(b"v");
    con.wait_for("parameter set param=gain value=5");

    // l: the skill's samples go to the fabric log until l again.
    con.keys(b"l");
    con.wait_for("logging scale's samples");
    t.wait_until("scale's samples in the fabric log", || {
        std::fs::read_to_string(&log)
            .unwrap()
            .lines()
            .any(|l| l.contains(r#""dir":"out""#) && l.contains(r#""kind":"sample""#))
    });
    con.keys(b"l");
    con.wait_for("no longer logging scale's samples");

    // q: a clean exit.
    con.keys(b"q");
    let status = con.wait_exit();
    assert!(status.success(), "console exit: {status}");
}

#[test]
fn a_remote_console_shows_and_drives_a_domain_through_its_bridge() {
    let mut t = TestDomain::new("consoleremote");
    let endpoint = format!("tcp/127.0.0.1:{}", skillfab_tests::free_port());
    let launch = t.launch_file(&format!(
        "{}[bridge]\nlisten = [\"{endpoint}\"]\n",
        skillfab_tests::HELLO
    ));
    t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let board = t.board();
    t.wait_until("the hello network", || {
        ["ticker", "scale", "smooth"]
            .iter()
            .all(|n| skillfab_tests::registered(&board, n).is_some_and(|s| s.runs > 2))
    });
    let client = Client::connect(&t.domain).unwrap();

    // Everything the console shows and does goes through the bridge.
    let mut con = Console::start_with(&t, 40, 120, &["--remote", &endpoint]);
    con.wait_for("skills (3)");
    select_and_deactivate_scale(&t, &client, &mut con);
    con.keys(b"q");
    assert!(con.wait_exit().success());
}

#[test]
fn waits_for_the_manager_and_reconnects() {
    let mut t = TestDomain::new("conrec");
    let mut con = Console::start(&t, 30, 110);
    con.wait_for("no manager");
    let up = t.hello(&[]);
    con.wait_for("skills (3)");
    // A skill is killed: the manager restarts it (`on-failure`), the console follows.
    let board = t.board();
    let slot = skillfab_tests::registered(&board, "smooth").unwrap().slot;
    // (A slot is registered a moment before its pid is stored: 0 until then.)
    let mut pid = 0;
    t.wait_until("smooth's pid on the board", || {
        pid = board
            .slot(slot)
            .pid
            .load(std::sync::atomic::Ordering::Acquire);
        pid != 0
    });
    // Select smooth (the detail pane's title shows its pid).
    let order: Vec<String> = Client::connect(&t.domain)
        .unwrap()
        .list()
        .unwrap()
        .into_iter()
        .map(|s| s.name)
        .collect();
    let at = order.iter().position(|n| n == "smooth").unwrap();
    con.keys(&vec![b'j'; at]);
    con.wait_for(&format!(
        "smooth · async smooth · active · priority 0 · pid {pid} "
    ));
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(pid as i32),
        nix::sys::signal::Signal::SIGKILL,
    )
    .unwrap();
    // (The new pid is taken where it is seen: a second look at the board may fall between
    // two of its states. A slot registered again holds 0 until its pid is stored, while its
    // run count can already be past 2: 0 is not a pid.)
    let mut new_pid = pid;
    t.wait_until("smooth to be restarted and running", || {
        skillfab_tests::registered(&board, "smooth").is_some_and(|s| {
            new_pid = board
                .slot(s.slot)
                .pid
                .load(std::sync::atomic::Ordering::Acquire);
            new_pid != pid && new_pid != 0 && s.runs > 2
        })
    });
    con.wait_for(&format!("pid {new_pid} "));
    // The manager goes away: the console says so and keeps the last view...
    t.signal(up, nix::sys::signal::Signal::SIGTERM);
    t.wait_exit(up);
    con.wait_for("last known");
    // ...and picks the fabric up again when it is back.
    t.hello(&[]);
    con.wait_for("skills (3)");
}

#[test]
fn ctl_logs_prints_skill_lines() {
    use std::io::BufRead;
    let mut t = TestDomain::new("ctllogs");
    t.hello(&[]);
    let mut logs = t
        .command("skillfab")
        .args(["ctl", "logs", "scale"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let out = logs.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    // A quiet skill's last lines reach a late reader (history), then new ones as they come.
    let mut seen = Vec::new();
    let mut wait_line = |want: &str| {
        let deadline = Instant::now() + WAIT;
        while !seen.iter().any(|l: &String| l.contains(want)) {
            let left = deadline.saturating_duration_since(Instant::now());
            assert!(!left.is_zero(), "no {want:?} in {seen:?}");
            if let Ok(l) = rx.recv_timeout(left) {
                seen.push(l);
            }
        }
    };
    wait_line("INFO  scale: registered");
    t.ctl(&["set", "scale.gain=7"]);
    wait_line("scale: parameter set param=gain value=7");
    assert!(seen.iter().all(|l| l.contains("scale:")), "{seen:?}");
    let _ = logs.kill();
    let _ = logs.wait();
}

#[test]
fn t_shows_the_running_plan_as_a_tree_that_follows_its_events() {
    let mut t = TestDomain::new("consoleplan");
    t.hello(&[]);
    let mut con = Console::start(&t, 40, 120);
    con.wait_for("skills (3)");
    con.keys(b"t");
    con.wait_for("no plan has run since the console connected");
    // A plan started after the console: its tree arrives through the events.
    let plan = t.dir.join("plan.xml");
    std::fs::write(
        &plan,
        r#"<root BTCPP_format="4"><BehaviorTree ID="Main">
             <Sequence name="mission">
               <Activate skills="smooth"/>
               <WaitFor name="released" condition="scale.scaled.value &lt; 0"/>
             </Sequence>
           </BehaviorTree></root>"#,
    )
    .unwrap();
    let mut runner = t
        .command("skillfab")
        .args(["sequence", plan.to_str().unwrap()])
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    // (Each waited for: a frame reaches the emulator in pieces.)
    for want in [
        "plan.xml · 3 nodes · at released",
        "▶ R mission Sequence",
        "S Activate · smooth",
        "▶   R released WaitFor · scale.scaled.value < 0",
        "t skills",
    ] {
        con.wait_for(want);
    }
    // The gain turned negative: the wait ends, the plan succeeds; the tree stays, ended.
    t.ctl(&["set", "scale.gain=-1"]);
    con.wait_for("ended: success");
    con.wait_for("S released WaitFor");
    assert!(runner.wait().unwrap().success());
    con.keys(b"t");
    con.wait_for("skills (3)");
    con.keys(b"q");
    assert!(con.wait_exit().success());
}
