//! `skillfab new skill NAME --lang rust|c|cpp|python [--dir DIR]` and `skillfab new msg
//! PACKAGE NAME [--dir DIR]`: a skill ready to build, test and run, outside this repository,
//! or a message file in a package of one's own (docs/messages.md).
//!
//! The skill reads the sonar ring and proposes on `drive`: it slows down and turns away from
//! what is near ahead. Next to it: a launch file that runs it in the exit-lab network (the
//! simulator, the Denning device, wander and avoid), and a test — the harness for Rust, a
//! lock-step run of the skill against the simulated robot for C, C++ and Python.

use anyhow::{Context, bail};
use std::path::{Path, PathBuf};

/// The language of a new skill.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Lang {
    /// A Cargo crate.
    Rust,
    /// A C file and a Makefile.
    C,
    /// A C++ file and a Makefile.
    Cpp,
    /// A Python file.
    Python,
}

/// Where this skillfab's repository and binaries are.
struct Sdk {
    root: PathBuf,
    bin: PathBuf,
}

impl Sdk {
    fn find() -> anyhow::Result<Sdk> {
        let exe = std::env::current_exe()?;
        let bin = exe
            .parent()
            .context("skillfab has no directory")?
            .to_path_buf();
        // target/<profile>/skillfab → the repository.
        let root = bin
            .ancestors()
            .find(|d| d.join("skill-sdk/Cargo.toml").is_file())
            .map(Path::to_path_buf)
            .with_context(|| {
                format!(
                    "{} is not inside a skillfab checkout (its skill-sdk is needed)",
                    bin.display()
                )
            })?;
        Ok(Sdk { root, bin })
    }
}

fn check_name(name: &str) -> anyhow::Result<()> {
    let ok = name.starts_with(|c: char| c.is_ascii_lowercase())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
    if !ok {
        bail!("'{name}' cannot name a skill: lower case letters, digits and _, a letter first");
    }
    Ok(())
}

fn write(path: &Path, text: &str, executable: bool) -> anyhow::Result<()> {
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    if executable {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755))?;
    }
    Ok(())
}

/// The exit-lab network with the new skill in it (`bin`: the skill's program).
fn network(sdk: &Sdk, name: &str, bin: &str, lockstep_test: bool) -> String {
    let world = sdk.root.join("devices/denning-sim/worlds/exit-lab.toml");
    let tool = |b: &str| sdk.bin.join(b).display().to_string();
    let link = if lockstep_test {
        format!("/tmp/skillfab-{name}-test")
    } else {
        format!("/tmp/skillfab-{name}")
    };
    let mut s = format!(
        "# {what}\n\
         [manager]\nperiod_ms = 10\n\n\
         [[process]]\nname = \"denning-sim\"\nbin = \"{sim}\"\nregisters = false\n\
         args = [\"--world\", \"{world}\", \"--link\", \"{link}\", \"--seed\", \"1\"{lock}]\n\n\
         [[process]]\nname = \"denning\"\nbin = \"{dev}\"\nargs = [\"--port\", \"{link}\"]\n\n",
        what = if lockstep_test {
            format!("The test network: the robot and {name} alone, in lock-step.")
        } else {
            format!(
                "{name} in the exit-lab network: skillfab up launch.toml (Ctrl-C stops it);\n\
                 # watch it with skillfab console, or skillfab ctl query {name}."
            )
        },
        sim = tool("denning-sim"),
        dev = tool("denning"),
        world = world.display(),
        lock = if lockstep_test {
            ", \"--lockstep\""
        } else {
            ""
        },
    );
    if !lockstep_test {
        for s2 in ["wander", "avoid"] {
            s.push_str(&format!(
                "[[process]]\nname = \"{s2}\"\nbin = \"{}\"\n\n",
                tool(s2)
            ));
        }
    }
    s.push_str(&format!(
        "[[process]]\nname = \"{name}\"\nbin = \"{bin}\"\n"
    ));
    s
}

/// The test of a C, C++ or Python skill: 300 lock-step cycles of it against the simulated
/// robot; it must run every cycle and never fail.
fn test_script(sdk: &Sdk, name: &str) -> String {
    format!(
        "#!/bin/sh\n\
         # {name} against the simulated robot: 300 lock-step cycles; it must run in every one\n\
         # and never fail. Needs the built skill (see README.md); the network's log: test.log.\n\
         set -e\n\
         cd \"$(dirname \"$0\")\"\n\
         report=$({skillfab} up test.toml --lockstep --cycles 300 --json --domain \"{domain}-test-$$\" 2>test.log)\n\
         echo \"$report\" | python3 -c '\n\
         import json, sys\n\
         r = json.load(sys.stdin)\n\
         s = [s for s in r[\"skills\"] if s[\"name\"] == \"{name}\"][0]\n\
         assert s[\"runs\"] == r[\"cycles\"] and s[\"failures\"] == 0, s\n\
         print(\"{name}: %d runs in %d cycles, no failure\" % (s[\"runs\"], r[\"cycles\"]))\n\
         '\n",
        skillfab = sdk.bin.join("skillfab").display(),
        domain = name.replace('_', "-"),
    )
}

const RUST_MAIN: &str = include_str!("../templates/skill.rs");

const C_MAIN: &str = include_str!("../templates/skill.c");

const CPP_MAIN: &str = include_str!("../templates/skill.cpp");

const PY_MAIN: &str = include_str!("../templates/skill.py");

/// `skillfab new skill`.
pub fn new_skill(name: &str, lang: Lang, dir: &Path) -> anyhow::Result<PathBuf> {
    check_name(name)?;
    let sdk = Sdk::find()?;
    let out = dir.join(name);
    if out.exists() {
        bail!("{} exists already", out.display());
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let out = std::fs::canonicalize(&out)?;
    let subst = |t: &str| t.replace("@NAME@", name).replace("MySkill", &camel(name));
    let (program, build, test) = match lang {
        Lang::Rust => {
            std::fs::create_dir_all(out.join("src"))?;
            write(&out.join("src/main.rs"), &subst(RUST_MAIN), false)?;
            write(&out.join("Cargo.toml"), &cargo_toml(&sdk, name), false)?;
            // The versions skillfab was built with, so its build of them is used.
            if let Ok(lock) = std::fs::read_to_string(sdk.root.join("Cargo.lock")) {
                write(&out.join("Cargo.lock"), &lock, false)?;
            }
            std::fs::create_dir_all(out.join(".cargo"))?;
            // The repository's target directory: the SDK and its dependencies, built once
            // for skillfab, are not built again.
            write(
                &out.join(".cargo/config.toml"),
                &format!(
                    "# Shares skillfab's build of the SDK and its dependencies.\n[build]\ntarget-dir = \"{}\"\n",
                    sdk.root.join("target").display()
                ),
                false,
            )?;
            // The profile skillfab itself was built with, so nothing is built twice.
            let release = sdk.bin.ends_with("release");
            let flag = if release { " --release" } else { "" };
            (
                sdk.bin.join(name),
                format!("cargo build{flag}"),
                format!("cargo test{flag}"),
            )
        }
        Lang::C | Lang::Cpp => {
            let (file, text) = if lang == Lang::C {
                (format!("{name}.c"), subst(C_MAIN))
            } else {
                (format!("{name}.cpp"), subst(CPP_MAIN))
            };
            write(&out.join(&file), &text, false)?;
            write(
                &out.join("Makefile"),
                &makefile(&sdk, name, &file, lang),
                false,
            )?;
            write(&out.join("test.sh"), &test_script(&sdk, name), true)?;
            (out.join(name), "make".into(), "make test".into())
        }
        Lang::Python => {
            let file = out.join(format!("{name}.py"));
            write(&file, &subst(PY_MAIN), true)?;
            // The skillfab package and libskillfab next to the skillfab program.
            write(
                &out.join(name),
                &format!(
                    "#!/bin/sh\nexport PYTHONPATH=\"{}${{PYTHONPATH:+:$PYTHONPATH}}\"\nexec python3 \"$(dirname \"$0\")/{name}.py\" \"$@\"\n",
                    sdk.root.join("python").display()
                ),
                true,
            )?;
            write(&out.join("test.sh"), &test_script(&sdk, name), true)?;
            (
                out.join(name),
                "(nothing to build)".into(),
                "./test.sh".into(),
            )
        }
    };
    let bin = program.display().to_string();
    write(
        &out.join("launch.toml"),
        &network(&sdk, name, &bin, false),
        false,
    )?;
    if lang != Lang::Rust {
        write(
            &out.join("test.toml"),
            &network(&sdk, name, &bin, true),
            false,
        )?;
    }
    write(
        &out.join("README.md"),
        &format!(
            "# {name}\n\nA skillfab skill ({lang:?}): it reads the sonar ring and proposes on `drive`.\n\n\
             ```sh\n{build}      # build\n{test}       # its test\n{skillfab} up launch.toml   # run it in the exit-lab network (Ctrl-C stops)\n```\n\n\
             While it runs: `{skillfab} ctl ls`, `{skillfab} ctl set {name}.near=0.8`, `{skillfab} console`.\n",
            skillfab = sdk.bin.join("skillfab").display(),
        ),
        false,
    )?;
    Ok(out)
}

fn camel(name: &str) -> String {
    name.split('_')
        .filter(|w| !w.is_empty())
        .map(|w| {
            let mut c = w.chars();
            c.next()
                .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                .unwrap_or_default()
        })
        .collect()
}

fn cargo_toml(sdk: &Sdk, name: &str) -> String {
    format!(
        "[package]\nname = \"{name}\"\nversion = \"0.1.0\"\nedition = \"2024\"\n\n\
         [dependencies]\nskill-sdk = {{ path = \"{sdk}\" }}\nskillfab-msgs = {{ path = \"{msgs}\" }}\n\n\
         # As skillfab's own workspace builds them, so its build is shared (.cargo/config.toml).\n\
         [profile.dev]\ndebug = \"line-tables-only\"\n\n\
         [profile.dev.package.\"*\"]\ndebug = false\nopt-level = 2\n\n\
         [profile.release]\ndebug = \"line-tables-only\"\n\n\
         [profile.release.package.\"*\"]\ndebug = false\n\n\
         [workspace]\n",
        sdk = sdk.root.join("skill-sdk").display(),
        msgs = sdk.root.join("skill-sdk/msgs").display(),
    )
}

fn makefile(sdk: &Sdk, name: &str, file: &str, lang: Lang) -> String {
    let (cc, flags) = if lang == Lang::C {
        ("$(CC)", "-O2 -Wall -Wextra -Werror")
    } else {
        ("$(CXX)", "-O2 -Wall -Wextra -Werror -std=c++17")
    };
    format!(
        "# Builds {name} against skillfab's C ABI (libskillfab.so beside the skillfab program).\n\
         SKILLFAB_INC ?= {inc}\nSKILLFAB_LIB ?= {lib}\n\n\
         {name}: {file}\n\t{cc} {flags} -I$(SKILLFAB_INC) $< -o $@ -L$(SKILLFAB_LIB) -lskillfab -Wl,-rpath,$(SKILLFAB_LIB) -lm\n\n\
         test: {name}\n\t./test.sh\n\n.PHONY: test\n",
        inc = sdk.root.join("skill-sdk/capi/include").display(),
        lib = sdk.bin.display(),
    )
}

/// `skillfab new msg PACKAGE NAME`: `DIR/PACKAGE/NAME.msg` with an example field, and how to
/// use it from each language.
pub fn new_msg(package: &str, name: &str, dir: &Path) -> anyhow::Result<PathBuf> {
    if !skillfab_msggen::package_name_ok(package) {
        bail!(
            "'{package}' cannot name a message package: lower case letters, digits and _, a letter first"
        );
    }
    if !skillfab_msggen::type_name_ok(name) {
        bail!(
            "'{name}' cannot name a message type: an identifier starting with an upper-case letter"
        );
    }
    let pkg = dir.join(package);
    std::fs::create_dir_all(&pkg).with_context(|| format!("creating {}", pkg.display()))?;
    let file = pkg.join(format!("{name}.msg"));
    if file.exists() {
        bail!("{} exists already", file.display());
    }
    write(
        &file,
        &format!(
            "# {name}: what this message says (the type's doc, generated into every language).\n\
             # Fields: TYPE NAME  # doc. Types: bool u8 u16 u32 u64 i8 i16 i32 i64 f32 f64,\n\
             # a message type (Name, or package.Name such as skillfab.Odometry), TYPE[N] arrays.\n\n\
             f64 x          # An example field (m).\n\
             u32[4] ids     # An example array.\n"
        ),
        false,
    )?;
    Ok(file)
}
