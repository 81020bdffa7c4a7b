//! Test fixture and test skills for skillfab's multi-process tests.
//!
//! - [`TestDomain`]: a unique domain per test; child processes in their own process groups,
//!   killed and reaped on drop; the domain's `/dev/shm` files and iceoryx2 root removed.
//! - [`skills`]: skills made for tests (configurable work, checks, failures), built as the
//!   binaries of this package.
//!
//! Binaries of the other packages (`skillfab`, `ticker`, ...) are found next to this
//! package's own (`target/<profile>/`); the README's test command builds them first.

// Test support: a failed set-up step should stop the test right there, with its message.
#![allow(clippy::expect_used, clippy::unwrap_used)]

pub mod skills;

use skillfab_proto::board::{Board, MAX_SLOTS, SlotState};
use skillfab_proto::decl::SkillDecl;
use skillfab_proto::domain::Domain;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

/// How long a test waits for a condition before it fails.
pub const WAIT: Duration = Duration::from_secs(30);

/// A program of the workspace, from `target/<profile>/`.
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> -> target/<profile>/; a binary of the workspace (a
    // benchmark report) sits in target/<profile>/ itself.
    let parent = exe.parent().expect("target directory");
    let dir = if parent.ends_with("deps") {
        parent.parent().expect("target directory")
    } else {
        parent
    };
    let path = dir.join(name);
    assert!(
        path.is_file(),
        "{} is missing: build the workspace binaries first (cargo build --workspace)",
        path.display()
    );
    path
}

/// The repository's root directory.
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate is in the repository")
        .to_path_buf()
}

/// A compiler or `make` command that writes its outputs with umask 022 whatever this
/// process's umask is at the moment it forks: iceoryx2 sets the process-wide umask for an
/// instant while it creates an event listener, and a compiler started by another test in that
/// instant would write an executable nobody may run.
pub fn build_command(program: &str) -> Command {
    let mut c = Command::new("sh");
    c.args(["-c", "umask 022 && exec \"$0\" \"$@\"", program]);
    c
}

/// Builds the C and C++ example skills and sequencer (`make -C skills`, gcc and g++) next to
/// the workspace's programs, once per test process; they link to `libskillfab.so` there.
pub fn build_foreign_examples() {
    static BUILT: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    let result = BUILT.get_or_init(|| {
        let out = bin("skillfab")
            .parent()
            .expect("target directory")
            .to_path_buf();
        if !out.join("libskillfab.so").is_file() {
            return Err(format!(
                "{}/libskillfab.so is missing: build the workspace first (cargo build --workspace)",
                out.display()
            ));
        }
        let r = build_command("make")
            .arg("-C")
            .arg(repo_root().join("skills"))
            .arg(format!("OUT={}", out.display()))
            .output()
            .map_err(|e| format!("make: {e}"))?;
        if !r.status.success() {
            return Err(format!(
                "make -C skills failed:\n{}{}",
                String::from_utf8_lossy(&r.stdout),
                String::from_utf8_lossy(&r.stderr)
            ));
        }
        Ok(())
    });
    if let Err(e) = result {
        panic!("{e}");
    }
}

/// The hello network as a launch file for [`TestDomain::launch_file`].
pub const HELLO: &str = "[manager]\nperiod_ms = 5\n[[process]]\nname = \"ticker\"\nbin = \"{bin:ticker}\"\n[[process]]\nname = \"scale\"\nbin = \"{bin:scale}\"\n[[process]]\nname = \"smooth\"\nbin = \"{bin:smooth}\"\n";

/// One test's private fabric.
pub struct TestDomain {
    /// The domain.
    pub domain: Domain,
    /// A private scratch directory.
    pub dir: PathBuf,
    children: Vec<Child>,
}

impl TestDomain {
    /// A fresh domain named after `tag`.
    pub fn new(tag: &str) -> TestDomain {
        static N: AtomicU32 = AtomicU32::new(0);
        let n = N.fetch_add(1, Ordering::Relaxed);
        let mut tag: String = tag
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .take(16)
            .collect();
        if tag.is_empty() {
            tag.push('t');
        }
        let name = format!("t-{tag}-{}-{n}", std::process::id());
        let domain = Domain::new(&name).expect("valid test domain");
        domain.remove_all_files();
        let dir = std::env::temp_dir().join("skillfab-tests").join(&name);
        std::fs::create_dir_all(&dir).expect("scratch dir");
        TestDomain {
            domain,
            dir,
            children: Vec::new(),
        }
    }

    /// A command for `program` in this domain, with a scrubbed environment.
    pub fn command(&self, program: &str) -> Command {
        self.command_at(&bin(program))
    }

    /// A command for the program at `path` (a script, a compiled example) in this domain.
    pub fn command_at(&self, path: &Path) -> Command {
        let mut c = Command::new(path);
        c.env_clear()
            .env("PATH", std::env::var_os("PATH").unwrap_or_default())
            .env("SKILLFAB_DOMAIN", self.domain.name())
            .env("SKILLFAB_LOG_DIR", &self.dir)
            .env("RUST_LOG", "info")
            .stdin(Stdio::null());
        c
    }

    /// Starts `program` with `args` in its own process group; returns its index.
    pub fn spawn(&mut self, program: &str, args: &[&str]) -> usize {
        use std::os::unix::process::CommandExt;
        let mut c = self.command(program);
        let log = self
            .dir
            .join(format!("{}-{program}.log", self.children.len()));
        let log = std::fs::File::create(&log).expect("child log file");
        c.args(args)
            .process_group(0)
            .stdout(Stdio::null())
            .stderr(log);
        let child = c.spawn().unwrap_or_else(|e| panic!("spawn {program}: {e}"));
        self.children.push(child);
        self.children.len() - 1
    }

    /// Process id of child `i`.
    pub fn pid(&self, i: usize) -> u32 {
        self.children[i].id()
    }

    /// Sends `signal` to child `i`.
    pub fn signal(&self, i: usize, signal: nix::sys::signal::Signal) {
        let pid = nix::unistd::Pid::from_raw(self.children[i].id() as i32);
        nix::sys::signal::kill(pid, signal).expect("signal child");
    }

    /// Waits for child `i` to exit (at most [`WAIT`]) and returns its status.
    pub fn wait_exit(&mut self, i: usize) -> std::process::ExitStatus {
        let deadline = Instant::now() + WAIT;
        loop {
            if let Some(s) = self.children[i].try_wait().expect("poll child") {
                return s;
            }
            assert!(Instant::now() < deadline, "child {i} did not exit");
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// Runs `program` to completion in this domain.
    pub fn run(&self, program: &str, args: &[&str]) -> Output {
        self.command(program)
            .args(args)
            .output()
            .unwrap_or_else(|e| panic!("run {program}: {e}"))
    }

    /// Writes a launch file into the scratch directory; `{bin:x}` expands to program x's path.
    pub fn launch_file(&self, text: &str) -> PathBuf {
        let mut out = text.to_string();
        while let Some(start) = out.find("{bin:") {
            let end = out[start..].find('}').expect("closing brace") + start;
            let name = out[start + 5..end].to_string();
            out.replace_range(start..=end, &bin(&name).display().to_string());
        }
        let path = self.dir.join("launch.toml");
        std::fs::write(&path, out).expect("write launch file");
        path
    }

    /// Runs `skillfab up` on `launch` text with extra arguments and `--json`; returns the report.
    pub fn up_json(&self, launch: &str, args: &[&str]) -> serde_json::Value {
        let path = self.launch_file(launch);
        let out = self.run(
            "skillfab",
            &[&["up", path.to_str().expect("utf-8 path"), "--json"], args].concat(),
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "skillfab up failed: {stderr}");
        serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
            panic!(
                "report is not JSON ({e}): {}",
                String::from_utf8_lossy(&out.stdout)
            )
        })
    }

    /// Starts the hello network (ticker → scale → smooth, 5 ms period) under `skillfab up`
    /// with `extra` arguments and waits until all three skills run; returns the child's index.
    pub fn hello(&mut self, extra: &[&str]) -> usize {
        let launch = self.launch_file(HELLO);
        let up = self.spawn(
            "skillfab",
            &[&["up", launch.to_str().expect("utf-8 path")], extra].concat(),
        );
        let board = self.board();
        self.wait_until("the hello network to run", || {
            ["ticker", "scale", "smooth"]
                .iter()
                .all(|n| registered(&board, n).is_some_and(|s| s.runs > 2))
        });
        up
    }

    /// Runs `skillfab ctl ARGS`, asserts it succeeded and returns its standard output.
    pub fn ctl(&self, args: &[&str]) -> String {
        let out = self.run("skillfab", &[&["ctl"], args].concat());
        assert!(
            out.status.success(),
            "ctl {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// The domain's board, once the manager has created it.
    pub fn board(&self) -> Board {
        let mut board = None;
        self.wait_until("the manager's board", || {
            board = Board::open(&self.domain.prefix())
                .ok()
                .filter(Board::manager_alive);
            board.is_some()
        });
        board.expect("board")
    }

    /// Polls `cond` until it holds; fails the test after [`WAIT`].
    pub fn wait_until(&self, what: &str, mut cond: impl FnMut() -> bool) {
        let deadline = Instant::now() + WAIT;
        while !cond() {
            assert!(Instant::now() < deadline, "timed out waiting for {what}");
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

impl Drop for TestDomain {
    fn drop(&mut self) {
        if std::thread::panicking() {
            // Show what the children said: the test failed.
            if let Ok(dir) = std::fs::read_dir(&self.dir) {
                for e in dir
                    .flatten()
                    .filter(|e| e.path().extension().is_some_and(|x| x == "log"))
                {
                    let text = std::fs::read_to_string(e.path()).unwrap_or_default();
                    eprintln!("----- {} -----\n{text}", e.path().display());
                }
            }
        }
        for c in &mut self.children {
            let pgid = nix::unistd::Pid::from_raw(-(c.id() as i32));
            let _ = nix::sys::signal::kill(pgid, nix::sys::signal::Signal::SIGKILL);
            let _ = c.wait();
        }
        // `skillfab up` puts its children in process groups of their own (they get SIGTERM
        // when it dies, and may still write while they go): every process of the domain is
        // killed and gone before its files are removed, or one would make them again.
        let me = std::process::id();
        let deadline = std::time::Instant::now() + Duration::from_secs(5);
        loop {
            let left: Vec<u32> = skillfab_proto::clean::live_pids(&self.domain)
                .into_iter()
                .filter(|&p| p != 0 && p != me)
                .collect();
            if left.is_empty() || std::time::Instant::now() > deadline {
                break;
            }
            for p in left {
                let _ = nix::sys::signal::kill(
                    nix::unistd::Pid::from_raw(p as i32),
                    nix::sys::signal::Signal::SIGKILL,
                );
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        self.domain.remove_all_files();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A registered skill as the board shows it.
#[derive(Debug, Clone)]
pub struct SlotView {
    /// Board slot.
    pub slot: usize,
    /// Its declaration.
    pub decl: SkillDecl,
    /// Completed runs.
    pub runs: u64,
    /// Failed runs.
    pub failures: u64,
    /// Skipped cycles.
    pub skips: u64,
}

/// The registered skill named `name` whose ports are open, if any.
pub fn registered(board: &Board, name: &str) -> Option<SlotView> {
    (0..MAX_SLOTS).find_map(|i| {
        let s = board.slot(i);
        if s.state() != SlotState::Ready {
            return None;
        }
        let decl: SkillDecl = postcard::from_bytes(&s.read_decl()).ok()?;
        (decl.name == name).then(|| SlotView {
            slot: i,
            decl,
            runs: s.runs.load(Ordering::Acquire),
            failures: s.failures.load(Ordering::Acquire),
            skips: s.skips.load(Ordering::Acquire),
        })
    })
}

/// The cycle the manager is in.
pub fn cycle(board: &Board) -> u64 {
    board.header().cycle.load(Ordering::Acquire)
}

/// The entry of skill `name` in a report.
pub fn skill<'a>(report: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    report["skills"]
        .as_array()
        .and_then(|a| a.iter().find(|s| s["name"] == name))
        .unwrap_or_else(|| panic!("no skill '{name}' in report {report}"))
}

/// A 7 m × 5 m room with a 1.2 m door in the east wall and the barcode 0.7 m north of it;
/// the robot starts 4 m away, facing the barcode's wall.
pub const DOORWAY: &str = r#"
name = "test-doorway"
start = [3.0, 3.2, 0.0]
outside = { min = [7.5, -10.0], max = [20.0, 15.0] }
[[wall]]
from = [0.0, 0.0]
to = [7.0, 0.0]
[[wall]]
from = [7.0, 0.0]
to = [7.0, 1.8]
[[wall]]
from = [7.0, 3.0]
to = [7.0, 5.0]
[[wall]]
from = [7.0, 5.0]
to = [0.0, 5.0]
[[wall]]
from = [0.0, 5.0]
to = [0.0, 0.0]
[[door]]
from = [7.0, 1.8]
to = [7.0, 3.0]
[[barcode]]
id = 7
at = [6.95, 3.7]
"#;

impl TestDomain {
    /// Writes [`DOORWAY`] into the scratch directory; returns its path.
    pub fn doorway(&self) -> PathBuf {
        let path = self.dir.join("doorway.toml");
        std::fs::write(&path, DOORWAY).expect("write the world");
        path
    }
}
