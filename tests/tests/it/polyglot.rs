//! Skills and sequencers in C, C++ and Python through libskillfab's C ABI: the generated
//! message declarations agree with Rust on every size and offset, the example skills (built
//! here with gcc and g++) take part in one cycle with Rust skills and compute the right
//! values, and the C and Python sequencers drive the hello network.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use serde_json::Value as Json;
use skillfab_codegen as codegen;
use skillfab_tests::{TestDomain, bin, build_foreign_examples, repo_root, skill};
use std::process::Command;

/// Compares one language's layout lines (`{"type", "size", "align", "offsets"}`) with Rust's.
fn assert_layouts_match(language: &str, lines: &str) {
    let schemas = codegen::shared_schemas();
    let seen: Vec<Json> = lines
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{language}: {e}: {l}")))
        .collect();
    assert_eq!(seen.len(), schemas.len(), "{language}: one line per type");
    for s in &schemas {
        let got = seen
            .iter()
            .find(|j| j["type"] == s.type_name.as_str())
            .unwrap_or_else(|| panic!("{language} lacks {}", s.type_name));
        assert_eq!(got["size"], s.size, "{language} size of {}", s.type_name);
        assert_eq!(
            got["align"], s.align,
            "{language} alignment of {}",
            s.type_name
        );
        for f in &s.fields {
            assert_eq!(
                got["offsets"][&f.name], f.offset,
                "{language} offset of {}.{}",
                s.type_name, f.name
            );
        }
    }
}

fn python() -> Command {
    let mut c = Command::new("python3");
    c.env("PYTHONPATH", repo_root().join("python"))
        .env("SKILLFAB_LIB", lib_path());
    c
}

fn lib_path() -> std::path::PathBuf {
    bin("skillfab").with_file_name("libskillfab.so")
}

/// Runs `cmd` to completion, asserts it succeeded and returns its standard output.
fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("{cmd:?}: {e}"));
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{cmd:?}: {stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// An executable Python skill script in the test's scratch dir: the `skillfab` package from
/// the repository imported, then `body`.
fn python_skill(t: &TestDomain, file: &str, body: &str) -> std::path::PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let script = t.dir.join(file);
    let header = format!(
        "#!/usr/bin/env python3\nimport sys\nsys.path.insert(0, \"{}\")\nimport skillfab\n",
        repo_root().join("python").display()
    );
    std::fs::write(&script, header + body).unwrap();
    std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
    script
}

#[test]
fn generated_c_and_python_layouts_agree_with_rust() {
    let t = TestDomain::new("layout");
    // The committed Python module is what the generator writes (the C header is checked by
    // the capi crate's own test).
    let committed = std::fs::read_to_string(repo_root().join("python/skillfab/msgs.py")).unwrap();
    assert!(
        committed == codegen::python_module(&codegen::shared_schemas()),
        "python/skillfab/msgs.py is out of date: target/debug/skillfab schema --python > python/skillfab/msgs.py"
    );

    // C: the compiler's own sizeof/alignof/offsetof of the committed header.
    let probe = t.dir.join("probe.c");
    std::fs::write(&probe, codegen::c_layout_probe(&codegen::shared_schemas())).unwrap();
    let exe = t.dir.join("probe");
    run_ok(
        skillfab_tests::build_command("gcc")
            .args(["-std=c11", "-Wall", "-Werror", "-I"])
            .arg(repo_root().join("skill-sdk/capi/include"))
            .arg(&probe)
            .arg("-o")
            .arg(&exe),
    );
    let out = Command::new(&exe).output().unwrap();
    assert_layouts_match("C", &String::from_utf8_lossy(&out.stdout));

    // Python: ctypes' own view of the generated classes.
    let script = r#"
import ctypes, json
from skillfab import msgs
for cls in msgs.BY_TYPE_NAME.values():
    print(json.dumps({"type": cls.TYPE_NAME, "size": ctypes.sizeof(cls),
                      "align": ctypes.alignment(cls),
                      "offsets": {f: getattr(cls, f).offset for f, _ in cls._fields_}}))
"#;
    assert_layouts_match("Python", &run_ok(python().args(["-c", script])));
}

/// The polyglot launch file with its Python script at an absolute path and `extra` appended
/// to the process named `name` (TOML keys).
fn polyglot(edit: Option<(&str, &str)>) -> String {
    let text = std::fs::read_to_string(repo_root().join("skills/launch/polyglot.toml")).unwrap();
    let script = repo_root().join("skills/python/smooth_py.py");
    let mut text = text.replace(
        "bin = \"../python/smooth_py.py\"",
        &format!("bin = \"{}\"", script.display()),
    );
    if let Some((from, to)) = edit {
        assert!(text.contains(from));
        text = text.replace(from, to);
    }
    // A loaded test machine may be slow; a late run must not be cut off by the deadline.
    text.replace("period_ms = 10", "period_ms = 5\ndeadline_ms = 5000")
}

#[test]
fn c_cpp_python_and_rust_skills_share_a_cycle_with_the_right_values() {
    build_foreign_examples();
    let t = TestDomain::new("polyglot");
    let report = t.up_json(&polyglot(None), &["--cycles", "100"]);
    assert_eq!(report["cycles"], 100);
    assert_eq!(report["overruns"], 0);
    for name in [
        "ticker",
        "scale_c",
        "smooth_py",
        "scale",
        "smooth_cpp",
        "check_chain",
    ] {
        let s = skill(&report, name);
        assert_eq!(s["runs"], 100, "{name}: {s}");
        assert_eq!(s["failures"], 0, "{name}: {s}");
        assert_eq!(s["skips"], 0, "{name}: {s}");
    }
    assert_eq!(skill(&report, "scale_c")["kind"], "scale_c");

    // The check is real: a Python stage with another alpha is caught in every cycle but the
    // first (the first sample is the average whatever alpha is).
    let t = TestDomain::new("polyglotbad");
    let report = t.up_json(
        &polyglot(Some((
            "params = { alpha = 0.1 }\nremap = { scaled = \"scaled_c\"",
            "params = { alpha = 0.3 }\nremap = { scaled = \"scaled_c\"",
        ))),
        &["--cycles", "50"],
    );
    let check = skill(&report, "check_chain");
    assert_eq!(check["failures"], 49, "{check}");
    assert_eq!(check["runs"], 1, "{check}");
}

#[test]
fn a_c_skill_links_statically_too() {
    let t = TestDomain::new("static");
    let lib = bin("skillfab").with_file_name("libskillfab.a");
    assert!(
        lib.is_file(),
        "{} is missing: cargo build --workspace",
        lib.display()
    );
    let exe = t.dir.join("scale_c_static");
    run_ok(
        skillfab_tests::build_command("gcc")
            .arg("-I")
            .arg(repo_root().join("skill-sdk/capi/include"))
            .arg(repo_root().join("skills/c/scale_c.c"))
            .arg(&lib)
            .args(["-lpthread", "-ldl", "-lm", "-lrt", "-o"])
            .arg(&exe),
    );
    // It runs without libskillfab.so: a bad option gets the SDK's usage and exit code 2.
    let out = t.command_at(&exe).arg("--no-such-option").output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("unexpected argument"));
}

#[test]
fn sequencers_in_c_and_python_drive_the_hello_network() {
    build_foreign_examples();
    let mut t = TestDomain::new("sequencers");
    t.hello(&[]);
    let domain = t.domain.name().to_string();

    let stdout = run_ok(t.command("sequencer_c").arg(&domain));
    assert!(stdout.contains("scale.gain = 3"), "{stdout}");
    assert!(stdout.contains("refused: "), "{stdout}");
    assert!(stdout.contains("\"event\":\"monitor_fired\""), "{stdout}");
    assert!(
        stdout.contains("wanted smooth with scale, released both"),
        "{stdout}"
    );
    assert!(
        stdout.contains("want refused: unknown skill 'ghost'"),
        "{stdout}"
    );
    assert!(stdout.trim_end().ends_with("ok"), "{stdout}");

    let stdout = run_ok(
        python()
            .arg(repo_root().join("skills/python/sequencer_py.py"))
            .arg(&domain),
    );
    assert!(stdout.contains("skills: "), "{stdout}");
    assert!(stdout.contains("refused: "), "{stdout}");
    assert!(stdout.contains("'event': 'monitor_fired'"), "{stdout}");
    assert!(
        stdout.contains("wanted smooth with scale, released both"),
        "{stdout}"
    );
    assert!(stdout.trim_end().ends_with("ok"), "{stdout}");
    assert_eq!(t.ctl(&["get", "scale.gain"]).trim(), "3");

    // An event too large for the caller's buffer is an error that keeps the event for the
    // next call; a bad expression is refused with the parser's reason.
    let script = r#"
import ctypes, json, sys, skillfab
from skillfab import lib
c = skillfab.Client(sys.argv[1])
try:
    c.monitor("scale.scaled.value >")
    raise SystemExit("a bad expression was accepted")
except skillfab.FabricError as e:
    print("refused:", e)
c.monitor("scale.scaled.value > 0", mode="once")
small = ctypes.create_string_buffer(8)
while True:
    rc = lib.sf_client_next_event(c._c, 5000, small, 8)
    if rc != -9:
        assert rc == 1, rc
        continue
    print("too small:", lib.sf_last_error().decode())
    ev = c.next_event(timeout=0)
    print("kept:", json.dumps(ev))
    break
"#;
    let stdout = run_ok(python().args(["-c", script, &domain]));
    assert!(stdout.contains("refused: "), "{stdout}");
    assert!(
        stdout.contains("too small: the buffer holds 8 bytes"),
        "{stdout}"
    );
    assert!(stdout.contains("kept: {"), "{stdout}");
}

#[test]
fn a_python_skill_that_raises_fails_its_run_and_keeps_serving() {
    let t = TestDomain::new("pyraise");
    let script = python_skill(
        &t,
        "flaky.py",
        r#"from skillfab.msgs import Tick, Scalar

class Flaky(skillfab.Skill):
    inputs = {"tick": Tick}
    outputs = {"out": Scalar}
    def compute(self, run, i, o):
        if i.tick.value % 2 == 0:
            raise ValueError("even tick")
        o.out.value = i.tick.value

skillfab.main(Flaky)
"#,
    );
    // libskillfab is found next to `skillfab` (SKILLFAB_BIN_DIR, set by `skillfab up`).
    let launch = format!(
        "[manager]\nperiod_ms = 5\ndeadline_ms = 5000\n[[process]]\nname = \"ticker\"\nbin = \"{{bin:ticker}}\"\n\
         [[process]]\nname = \"flaky\"\nbin = \"{}\"\n",
        script.display()
    );
    let report = t.up_json(&launch, &["--cycles", "40"]);
    let s = skill(&report, "flaky");
    assert_eq!(s["failures"], 20, "{s}");
    assert_eq!(s["runs"], 20, "{s}");
}

#[test]
fn the_c_avoid_routine_turns_away_from_an_obstacle() {
    build_foreign_examples();
    let mut t = TestDomain::new("avoidc");
    // A sonar ring with one echo 0.3 m away, 15° to the left of the heading.
    let script = python_skill(
        &t,
        "sonar_script.py",
        r#"from skillfab.msgs import Tick, Sonar

class Script(skillfab.Skill):
    inputs = {"tick": Tick}
    outputs = {"sonar": Sonar}
    def compute(self, run, i, o):
        for k in range(24):
            o.sonar.range[k] = float("inf")
        o.sonar.range[1] = 0.3

skillfab.main(Script)
"#,
    );
    let launch = t.launch_file(&format!(
        "[manager]\nperiod_ms = 5\n[[process]]\nname = \"ticker\"\nbin = \"{{bin:ticker}}\"\n\
         [[process]]\nname = \"sonar\"\nbin = \"{}\"\n\
         [[process]]\nname = \"avoid_c\"\nbin = \"{{bin:avoid_c}}\"\n",
        script.display()
    ));
    t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let board = t.board();
    t.wait_until("avoid_c to run", || {
        skillfab_tests::registered(&board, "avoid_c").is_some_and(|s| s.runs > 3)
    });
    let number = |path: &str| -> f64 {
        let out = t.ctl(&["--json", "query", path]);
        let j: Json = serde_json::from_str(&out).unwrap();
        j["value"]
            .as_f64()
            .unwrap_or_else(|| panic!("{path}: {out}"))
    };
    // Backs off and turns right, away from the echo on the left: push (0.6 - 0.3) / 0.6 =
    // 0.5 from 15° left, translate = speed × (-0.5 cos 15°).
    let push_x = -0.5 * 15f64.to_radians().cos();
    assert!((number("avoid_c.drive.translate") - 0.3 * push_x).abs() < 1e-9);
    assert!(number("avoid_c.drive.rotate") < 0.0);
    // A parameter set at run time reaches the C body.
    t.ctl(&["set", "avoid_c.speed=0.1"]);
    t.wait_until("the new speed in avoid_c's proposal", || {
        (number("avoid_c.drive.translate") - 0.1 * push_x).abs() < 1e-9
    });
    let s = skillfab_tests::registered(&board, "avoid_c").unwrap();
    assert_eq!(s.failures, 0);
    assert_eq!(s.decl.priority, 10);
}
