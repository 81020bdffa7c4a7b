//! `skillfab replay --kill SKILL@CYCLE [--forget]`: a replayed skill killed (SIGKILL) after
//! its run of a cycle, with the manager stopped there, and started again by `up` before the
//! next; its outputs from there on are compared like any others.

use anyhow::{Context, bail};
use serde::Serialize;
use skillfab_client::Client;
use skillfab_proto::control::SkillState;
use skillfab_proto::domain::Domain;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// A kill asked for: the skill, killed after its run of `cycle`.
#[derive(Debug, Clone, PartialEq)]
pub struct KillAt {
    /// Instance name.
    pub skill: String,
    /// The cycle after whose run it is killed.
    pub cycle: u64,
}

pub(super) fn kill_at(text: &str) -> Result<KillAt, String> {
    let (skill, cycle) = text
        .rsplit_once('@')
        .ok_or_else(|| format!("'{text}' is not SKILL@CYCLE"))?;
    let cycle = cycle
        .parse()
        .map_err(|e| format!("'{text}': the cycle '{cycle}' is not a number ({e})"))?;
    if skill.is_empty() {
        return Err(format!("'{text}' names no skill"));
    }
    Ok(KillAt {
        skill: skill.to_string(),
        cycle,
    })
}

/// A kill done, and the process that took the skill's place.
#[derive(Debug, Clone, Serialize)]
pub struct Killed {
    /// Instance name.
    pub skill: String,
    /// The cycle after whose run it was killed.
    pub cycle: u64,
    /// The process killed.
    pub pid: u32,
    /// The process that replaced it.
    pub new_pid: u32,
    /// Whether its kept state was removed first (`--forget`).
    pub forgot: bool,
}

/// Kills replayed skills and waits for `up` to start them again.
pub(super) struct Killer<'a> {
    pub(super) domain: &'a Domain,
    pub(super) forget: bool,
    pub(super) log: PathBuf,
}

impl Killer<'_> {
    /// Kills `skill` (its kept state removed first with `forget`) and waits until a new
    /// process has it again, in the state (active or not) it was in.
    pub(super) fn kill(&self, c: &Client, at: &KillAt) -> anyhow::Result<Killed> {
        let find = || -> anyhow::Result<Option<(u32, SkillState)>> {
            Ok(c.list()?
                .into_iter()
                .find(|s| s.name == at.skill)
                .map(|s| (s.pid, s.state)))
        };
        let (pid, was) = find()?.with_context(|| format!("{} is not registered", at.skill))?;
        if self.forget {
            let name = skillfab_proto::names::state(&self.domain.prefix(), &at.skill);
            // Removed while the process still runs (the fabric is stopped: it commits
            // nothing), so the next one finds no state whatever instant `up` restarts it.
            match nix::sys::mman::shm_unlink(name.as_str()) {
                Ok(()) | Err(nix::errno::Errno::ENOENT) => {}
                Err(e) => bail!("removing {name}: {e}"),
            }
        }
        nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(i32::try_from(pid)?),
            nix::sys::signal::Signal::SIGKILL,
        )
        .with_context(|| format!("SIGKILL to {} ({pid})", at.skill))?;
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Some((new_pid, state)) = find()?
                && new_pid != pid
                && state == was
            {
                return Ok(Killed {
                    skill: at.skill.clone(),
                    cycle: at.cycle,
                    pid,
                    new_pid,
                    forgot: self.forget,
                });
            }
            if Instant::now() > deadline {
                bail!(
                    "{} killed after cycle {} was not back within 30 s (see {})",
                    at.skill,
                    at.cycle,
                    self.log.display()
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}
