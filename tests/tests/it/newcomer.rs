//! What a newcomer does: `skillfab new skill` in C, C++ and Python outside the repository
//! (built, its own test run: the skill against the simulated robot in lock-step), and a
//! message package of one's own used from Python and C at once (`skillfab new msg`, generated
//! header and module, `SKILLFAB_MSG_PATH`). The Rust template is built and unit-tested as the
//! `skill_template` binary of the tests crate.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use skillfab_tests::{TestDomain, bin, build_command};
use std::process::Command;

fn ok(c: &mut Command) -> String {
    let out = c.output().unwrap();
    assert!(
        out.status.success(),
        "{c:?}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn new_skills_in_c_cpp_and_python_build_and_pass_their_generated_tests() {
    let t = TestDomain::new("newskills");
    let dir = t.dir.join("mine");
    std::fs::create_dir_all(&dir).unwrap();
    for (name, lang) in [("near_c", "c"), ("near_cpp", "cpp"), ("near_py", "python")] {
        ok(t.command("skillfab")
            .args(["new", "skill", name, "--lang", lang, "--dir"])
            .arg(&dir));
        let at = dir.join(name);
        for f in ["launch.toml", "test.toml", "README.md", "test.sh"] {
            assert!(at.join(f).is_file(), "{name}: {f}");
        }
        if lang != "python" {
            ok(build_command("make").arg("-C").arg(&at));
        }
        let report = ok(Command::new(at.join("test.sh")).env_remove("SKILLFAB_DOMAIN"));
        assert!(
            report.contains(&format!("{name}: 300 runs in 300 cycles, no failure")),
            "{report}"
        );
    }
    // A second skill of the same name is refused, not overwritten.
    let out = t
        .command("skillfab")
        .args(["new", "skill", "near_c", "--lang", "c", "--dir"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("exists already"));
}

const PRODUCER: &str = r#"
import sys
sys.path.insert(0, sys.argv.pop(1))
import skillfab
from my_robot_msgs import Grasp


class Producer(skillfab.Skill):
    outputs = {"grasp": Grasp}

    def compute(self, run, i, o):
        # The cycle's clock: cycle x the 5 ms period.
        if run.time_ns != run.cycle * 5_000_000 or run.period_ns != 5_000_000:
            raise ValueError(f"clock {run.time_ns} in cycle {run.cycle}")
        o.grasp.x = float(run.cycle)
        o.grasp.ids[0] = 7


if __name__ == "__main__":
    skillfab.main(Producer)
"#;

const CONSUMER: &str = r#"
#include <stdio.h>
#include "skillfab.h"
#include "my_robot_msgs.h"

static int IN, OUT;

/* Fails the run unless the grasp is the producer's of this cycle and the clock is the
 * cycle's (cycle x the 5 ms period). */
static int32_t compute(sf_run *run, void *user) {
    (void)user;
    if (sf_run_time_ns(run) != sf_run_cycle(run) * 5000000u || sf_run_period_ns(run) != 5000000u)
        return 1;
    const sf_my_robot_Grasp *g = sf_input(run, IN, sizeof *g);
    if (!g || g->ids[0] != 7 || g->x != (double)sf_input_cycle(run, IN)) return 1;
    sf_Scalar *s = sf_output(run, OUT, sizeof *s);
    if (!s) return 1;
    s->value = 2.0 * g->x;
    return 0;
}

int main(int argc, char **argv) {
    sf_skill *s = sf_skill_new("consumer", SF_SYNC);
    if (!s || (IN = sf_skill_input(s, "grasp", SF_MY_ROBOT_GRASP_TYPE_NAME)) < 0
        || (OUT = sf_skill_output(s, "doubled", SF_SCALAR_TYPE_NAME)) < 0
        || sf_skill_compute(s, compute, NULL) < 0) {
        fprintf(stderr, "consumer: %s\n", sf_last_error());
        return 1;
    }
    return sf_skill_run(s, argc, (const char *const *)argv);
}
"#;

fn skill_of<'a>(report: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    report["skills"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == name)
        .unwrap_or_else(|| panic!("{name} in {report}"))
}

#[test]
fn a_message_package_of_ones_own_carries_data_from_python_to_c() {
    let t = TestDomain::new("ownmsg");
    let msgs = t.dir.join("msg");
    ok(t.command("skillfab")
        .args(["new", "msg", "my_robot", "Grasp", "--dir"])
        .arg(&msgs));
    let listed = ok(t
        .command("skillfab")
        .arg("schema")
        .arg("--msg-path")
        .arg(&msgs));
    assert!(
        listed.contains("my_robot.Grasp") && listed.contains("my_robot/Grasp.msg"),
        "{listed}"
    );
    let gen_dir = t.dir.join("gen");
    std::fs::create_dir_all(&gen_dir).unwrap();
    let header = ok(t
        .command("skillfab")
        .args(["schema", "--c", "--msg-path"])
        .arg(&msgs));
    std::fs::write(gen_dir.join("my_robot_msgs.h"), header).unwrap();
    let module = ok(t
        .command("skillfab")
        .args(["schema", "--python", "--msg-path"])
        .arg(&msgs));
    std::fs::write(gen_dir.join("my_robot_msgs.py"), module).unwrap();

    let inc = skillfab_tests::repo_root().join("skill-sdk/capi/include");
    let lib = bin("skillfab").parent().unwrap().to_path_buf();
    let src = t.dir.join("consumer.c");
    std::fs::write(&src, CONSUMER).unwrap();
    let consumer = t.dir.join("consumer");
    ok(build_command("gcc")
        .args(["-std=c11", "-Wall", "-Werror", "-I"])
        .arg(&inc)
        .arg("-I")
        .arg(&gen_dir)
        .arg(&src)
        .arg("-o")
        .arg(&consumer)
        .arg(format!("-L{}", lib.display()))
        .arg("-lskillfab")
        .arg(format!("-Wl,-rpath,{}", lib.display())));
    let producer = t.dir.join("producer.py");
    std::fs::write(&producer, PRODUCER).unwrap();
    // The skill options `up` gives (--name ...) come after the module's own argument.
    let run_producer = t.dir.join("producer");
    std::fs::write(
        &run_producer,
        format!(
            "#!/bin/sh\nexec python3 {} {} \"$@\"\n",
            producer.display(),
            gen_dir.display()
        ),
    )
    .unwrap();
    std::fs::set_permissions(
        &run_producer,
        std::os::unix::fs::PermissionsExt::from_mode(0o755),
    )
    .unwrap();
    let launch = format!(
        "[manager]\nperiod_ms = 5\n\
         [[process]]\nname = \"producer\"\nbin = \"{}\"\n\
         [[process]]\nname = \"consumer\"\nbin = \"{}\"\n",
        run_producer.display(),
        consumer.display()
    );
    let path = t.launch_file(&launch);
    let out = t
        .command("skillfab")
        .env("SKILLFAB_MSG_PATH", &msgs)
        .env("PYTHONPATH", skillfab_tests::repo_root().join("python"))
        .args(["up", path.to_str().unwrap(), "--cycles", "200", "--json"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for name in ["producer", "consumer"] {
        let s = skill_of(&report, name);
        assert_eq!(s["failures"], 0, "{name}: {report}");
        assert!(s["runs"].as_u64().unwrap() >= 190, "{name}: {report}");
    }
}

#[test]
fn a_package_of_ones_own_has_one_layout_in_rust_c_python_and_at_run_time() {
    use skill_sdk::prelude::Message;
    use skillfab_tests::test_pkg::{Finger, Grasp};
    let dir = skillfab_tests::repo_root().join("tests/msg");
    let (catalog, _) = skillfab_msgs::dynamic::catalog(&[dir]).unwrap();
    // Rust (this crate's build script) = the run-time schema of C, C++ and Python skills.
    for rust in [Grasp::schema(), Finger::schema()] {
        let t = catalog.get(&rust.type_name).unwrap();
        assert_eq!(skillfab_msgs::dynamic::schema(&catalog, t), rust);
    }
    assert_eq!(Grasp::TYPE_NAME, "test_pkg.Grasp");
    assert_eq!(skillfab_tests::test_pkg::registry().len(), 2);
    // C: the compiler's own layout of the generated header agrees.
    let schemas: Vec<_> = catalog
        .types
        .iter()
        .map(|t| skillfab_msgs::dynamic::schema(&catalog, t))
        .collect();
    let t = TestDomain::new("ownlayout");
    std::fs::write(
        t.dir.join("test_pkg_msgs.h"),
        skillfab_codegen::c_header_for(&schemas, "test_pkg"),
    )
    .unwrap();
    let probe = skillfab_codegen::c_layout_probe(&[Grasp::schema(), Finger::schema()]).replace(
        "#include \"skillfab_msgs.h\"",
        "#include \"test_pkg_msgs.h\"",
    );
    std::fs::write(t.dir.join("probe.c"), probe).unwrap();
    let inc = skillfab_tests::repo_root().join("skill-sdk/capi/include");
    ok(build_command("gcc")
        .args(["-std=c11", "-Wall", "-Werror", "-I"])
        .arg(&inc)
        .arg("-I")
        .arg(&t.dir)
        .arg(t.dir.join("probe.c"))
        .arg("-o")
        .arg(t.dir.join("probe")));
    let printed = ok(&mut Command::new(t.dir.join("probe")));
    for rust in [Grasp::schema(), Finger::schema()] {
        let line = printed
            .lines()
            .find(|l| l.contains(&format!("\"{}\"", rust.type_name)))
            .unwrap();
        let c: serde_json::Value = serde_json::from_str(line).unwrap();
        assert_eq!(c["size"], rust.size, "{line}");
        assert_eq!(c["align"], rust.align, "{line}");
        for f in &rust.fields {
            assert_eq!(c["offsets"][&f.name], f.offset, "{line}");
        }
    }
    // Python: the generated module imports and names the same fields.
    let py = skillfab_codegen::python_module_for(&schemas, "test_pkg");
    assert!(py.contains("class Grasp(ctypes.Structure):"), "{py}");
    assert!(py.contains("(\"at\", Odometry),"), "{py}");
    std::fs::write(t.dir.join("test_pkg_msgs.py"), py).unwrap();
    let printed = ok(Command::new("python3")
        // The library of this build (importing skillfab loads it).
        .env("SKILLFAB_LIB", bin("skillfab").with_file_name("libskillfab.so"))
        .env(
            "PYTHONPATH",
            format!(
                "{}:{}",
                t.dir.display(),
                skillfab_tests::repo_root().join("python").display()
            ),
        )
        .args([
            "-c",
            "import ctypes, test_pkg_msgs as m; print(ctypes.sizeof(m.Grasp), m.Grasp.fingers.offset, ctypes.sizeof(m.Finger))",
        ]));
    let f = Grasp::schema()
        .fields
        .iter()
        .find(|f| f.name == "fingers")
        .unwrap()
        .offset;
    assert_eq!(
        printed.trim(),
        format!("{} {f} {}", Grasp::schema().size, Finger::schema().size)
    );
}
