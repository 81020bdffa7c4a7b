//! Where a plan's execution state waits for the next runner: one file per domain in the
//! domain's shared memory (`/dev/shm/sf_<domain>_plan`, removed with the domain's files),
//! replaced whole after every tick (written aside, then renamed: a runner killed at any
//! instant leaves the last tick's state or the one before, never a torn one).
//!
//! What is kept: which plan (its file, tree and fingerprint), each node's state, the
//! monitors that fired and were not yet taken, the parameters its `WithParam`s set with the
//! values to restore ([`Override`], written before the parameter is set), and the ids of the
//! runners so far (their monitors are taken over or removed).

use crate::tree::{Override, Saved};
use serde::{Deserialize, Serialize};
use skillfab_proto::domain::Domain;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// The format's version: a kept state of another is unreadable (and said so).
const VERSION: u32 = 2;

/// A plan's execution state, as kept between runners.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanState {
    /// [`VERSION`].
    pub version: u32,
    /// The plan file, as its runner named it.
    pub file: String,
    /// The tree run.
    pub tree: String,
    /// The file's fingerprint ([`crate::Plan::fingerprint`]).
    pub fingerprint: u64,
    /// The client ids of the plan's runners, first to last.
    pub runners: Vec<String>,
    /// Each node's state, in preorder.
    pub nodes: Vec<Saved>,
    /// Monitors that fired and were not yet taken by their `WaitFor`.
    pub fired: Vec<u64>,
    /// Parameters set by running `WithParam`s, with the values to restore, in the order set.
    pub overrides: Vec<Override>,
    /// When the plan started by the wall clock (the origin of its time over a bridge).
    pub started: SystemTime,
    /// The fabric's time at the plan's last tick: none before its first, or after a halt.
    pub ticked: Option<Duration>,
}

/// What a runner found.
#[derive(Debug)]
pub enum Kept {
    /// No plan was running (or the last one ended).
    Nothing,
    /// A plan's state.
    State(Box<PlanState>),
    /// Something that cannot be read: why.
    Unreadable(String),
}

/// The file a domain's plan state is kept in.
#[derive(Debug, Clone)]
pub struct PlanStore {
    path: PathBuf,
}

impl PlanStore {
    /// The store of `domain`'s plan.
    pub fn of(domain: &Domain) -> PlanStore {
        PlanStore::at(Path::new("/dev/shm").join(format!("{}plan", domain.prefix())))
    }

    /// A store in file `path` (tests).
    pub fn at(path: PathBuf) -> PlanStore {
        PlanStore { path }
    }

    /// Its file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What the last runner left.
    pub fn load(&self) -> Kept {
        let bytes = match std::fs::read(&self.path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Kept::Nothing,
            Err(e) => return Kept::Unreadable(format!("{}: {e}", self.path.display())),
        };
        match serde_json::from_slice::<PlanState>(&bytes) {
            Ok(s) if s.version == VERSION => Kept::State(Box::new(s)),
            Ok(s) => Kept::Unreadable(format!(
                "{}: format {} (this runner reads {VERSION})",
                self.path.display(),
                s.version
            )),
            Err(e) => Kept::Unreadable(format!("{}: {e}", self.path.display())),
        }
    }

    /// Replaces the kept state by `state`, whole.
    pub fn save(&self, state: &PlanState) -> std::io::Result<()> {
        let bytes = serde_json::to_vec(state)?;
        let aside = self
            .path
            .with_extension(format!("{}.new", std::process::id()));
        std::fs::write(&aside, bytes)?;
        std::fs::rename(&aside, &self.path)
    }

    /// Forgets the plan: it ended.
    pub fn remove(&self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

impl PlanState {
    /// A new state for `file`'s tree `tree` (fingerprint `fingerprint`), run by `runner`.
    pub fn new(file: &str, tree: &str, fingerprint: u64, runner: &str) -> PlanState {
        PlanState {
            version: VERSION,
            file: file.to_string(),
            tree: tree.to_string(),
            fingerprint,
            runners: vec![runner.to_string()],
            nodes: Vec::new(),
            fired: Vec::new(),
            overrides: Vec::new(),
            started: SystemTime::now(),
            ticked: None,
        }
    }
}
