//! `skillfab sequence FILE --check [--launch L.toml]`: a plan's names checked before it runs.
//! Every skill it activates, every parameter it sets (with the value's type and bounds) and
//! every path of its conditions (skill, output, field, a number where one is compared) is
//! checked against the skills' declarations — a launch file's, from each skill binary's
//! `--describe` with the launch file's arguments, or a running domain's, from its manager —
//! with the checks the manager makes of the same requests ([`skillfab_manager::checks`]). A
//! renamed port fails here, with the plan's line, instead of in the middle of a mission.

use anyhow::Context;
use skillfab_client::{Address, Client};
use skillfab_manager::checks;
use skillfab_manager::launch::Launch;
use skillfab_proto::control::{ControlError, ParamArg};
use skillfab_proto::decl::SkillDecl;
use skillfab_proto::param::ParamError;
use skillfab_sequence::{Plan, Reference, Use};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::{Command, Stdio};

/// The skills a plan is checked against.
#[derive(Debug, Clone, Default)]
pub struct Declarations {
    /// Each skill instance's declaration, by name.
    pub skills: BTreeMap<String, SkillDecl>,
    /// The launch file's processes (`None`: a running domain, whose processes are not known).
    pub processes: Option<BTreeSet<String>>,
    /// Where they come from, for the report.
    pub from: String,
}

/// Why a name of a plan does not fit the skills.
#[derive(Debug, thiserror::Error)]
pub enum Problem {
    /// No skill of that name.
    #[error("no skill '{skill}' (skills: {})", known.join(", "))]
    UnknownSkill {
        /// The name used.
        skill: String,
        /// The skills there are.
        known: Vec<String>,
    },
    /// A parameter that is not declared, or a value of the wrong type or out of bounds.
    #[error("{skill}: {error}")]
    Param {
        /// The skill.
        skill: String,
        /// What is wrong.
        error: ParamError,
    },
    /// A condition that does not parse, or a path that names no number of an output.
    #[error(transparent)]
    Condition(ControlError),
    /// A process the launch file does not start.
    #[error("no process '{process}' in the launch file")]
    UnknownProcess {
        /// The name used.
        process: String,
    },
}

impl Declarations {
    /// The declarations of the skills `launch` starts: each skill binary run with the
    /// launch file's arguments and `--describe` (it prints its declaration and exits).
    pub fn of_launch(path: &Path) -> anyhow::Result<Declarations> {
        let launch = Launch::load(path)?;
        let mut skills = BTreeMap::new();
        for p in launch.processes.iter().filter(|p| p.registers && !p.plan) {
            let mut cmd = Command::new(&p.program);
            cmd.args(&p.args)
                .arg("--describe")
                .stdin(Stdio::null())
                .stderr(Stdio::piped());
            // Skills in other languages find libskillfab next to this program, as under `up`.
            if let Some(dir) = std::env::current_exe()
                .ok()
                .and_then(|e| e.parent().map(Path::to_path_buf))
            {
                cmd.env("SKILLFAB_BIN_DIR", dir);
            }
            let out = cmd
                .output()
                .with_context(|| format!("process '{}': {}", p.name, p.program.display()))?;
            anyhow::ensure!(
                out.status.success(),
                "process '{}' ({} --describe): {}",
                p.name,
                p.program.display(),
                String::from_utf8_lossy(&out.stderr).trim()
            );
            let decl: SkillDecl = serde_json::from_slice(&out.stdout).with_context(|| {
                format!(
                    "process '{}' ({} --describe) printed no declaration",
                    p.name,
                    p.program.display()
                )
            })?;
            skills.insert(decl.name.clone(), decl);
        }
        Ok(Declarations {
            skills,
            processes: Some(launch.processes.iter().map(|p| p.name.clone()).collect()),
            from: format!("the skills of {}", path.display()),
        })
    }

    /// The declarations of the skills registered with `client`'s manager.
    pub fn of_domain(client: &Client, address: &Address) -> anyhow::Result<Declarations> {
        let mut skills = BTreeMap::new();
        for s in client.list()? {
            skills.insert(s.name.clone(), client.declaration(&s.name)?);
        }
        Ok(Declarations {
            skills,
            processes: None,
            from: format!("the skills registered in {address}"),
        })
    }

    fn skill(&self, name: &str) -> Result<&SkillDecl, Problem> {
        self.skills.get(name).ok_or_else(|| Problem::UnknownSkill {
            skill: name.into(),
            known: self.skills.keys().cloned().collect(),
        })
    }
}

/// Every use of a name in `plan` that does not fit `decls`, in the order written.
pub fn check<'p>(plan: &'p Plan, decls: &Declarations) -> Vec<(Use<'p>, Problem)> {
    plan.uses()
        .into_iter()
        .filter_map(|u| {
            let problem = match u.what {
                Reference::Skill(s) => decls.skill(s).err(),
                Reference::Param {
                    skill,
                    param,
                    value,
                } => match decls.skill(skill) {
                    Err(p) => Some(p),
                    Ok(d) => checks::param_value(d, param, ParamArg::Text(value.into()))
                        .err()
                        .map(|error| Problem::Param {
                            skill: skill.into(),
                            error,
                        }),
                },
                Reference::Condition(text) => {
                    match checks::expression(text, &|s| decls.skills.get(s)) {
                        Err(ControlError::UnknownSkill(skill)) => decls.skill(&skill).err(),
                        Err(e) => Some(Problem::Condition(e)),
                        Ok(_) => None,
                    }
                }
                Reference::Process(p) => decls
                    .processes
                    .as_ref()
                    .filter(|all| !all.contains(p))
                    .map(|_| Problem::UnknownProcess { process: p.into() }),
            };
            problem.map(|p| (u, p))
        })
        .collect()
}
