//! The manager's state file: what a manager that dies must not take with it.
//!
//! Clients set things a skill's process does not hold — activation, parameter values,
//! priority, whether its samples are logged — and install monitors. The manager keeps them by
//! skill name (so a restarted skill gets them back, [`super::skills::Kept`]) and writes them,
//! with the last declaration of every name, the monitors, whether cycling is stopped and the
//! clients' holds, to `<domain root>/manager/state` whenever a request or a registration changed them. A manager
//! that starts in a domain whose file is there (its predecessor died, or left while skills ran
//! on) reads it back: skills re-register and get their state, monitors fire again for the
//! clients that installed them. The file goes with the domain (`remove_all_files`, `skillfab
//! clean`). It is written off the cycle's path: only after a request or a registration, and
//! only when its bytes changed.

use super::Manager;
use super::skills::Kept;
use skillfab_proto::control::MonitorMode;
use skillfab_proto::decl::SkillDecl;
use skillfab_proto::domain::Domain;
use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;
use std::os::unix::fs::OpenOptionsExt;
use std::path::PathBuf;

/// First bytes of the file, with its layout's version: a file of another layout is ignored
/// (with a warning), never misread.
const MAGIC: &[u8; 8] = b"sfstate4";

/// A monitor as its client installed it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct SavedMonitor {
    pub(crate) id: u64,
    pub(crate) text: String,
    pub(crate) mode: MonitorMode,
    pub(crate) hold: u32,
    pub(crate) client: String,
}

/// Everything the file holds (ordered maps: the same state gives the same bytes).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Saved {
    pub(crate) kept: BTreeMap<String, Kept>,
    pub(crate) last: BTreeMap<String, SkillDecl>,
    pub(crate) io_logged: BTreeSet<String>,
    pub(crate) monitors: Vec<SavedMonitor>,
    pub(crate) next_monitor: u64,
    pub(crate) paused: bool,
    /// Clients' holds (a client that outlives the manager keeps its hold).
    pub(crate) holds: BTreeMap<String, u64>,
}

/// The state file as the manager keeps it.
#[derive(Debug, Default)]
pub(crate) struct StateFile {
    /// A request or a registration may have changed what the file holds.
    pub(crate) check: bool,
    /// The file's bytes as last written.
    pub(crate) written: Vec<u8>,
}

/// Where a domain's manager keeps its state.
pub(crate) fn path(domain: &Domain) -> PathBuf {
    domain.root_path().join("manager").join("state")
}

impl Saved {
    fn encode(&self) -> Result<Vec<u8>, postcard::Error> {
        let mut bytes = MAGIC.to_vec();
        bytes.extend(postcard::to_allocvec(self)?);
        Ok(bytes)
    }

    /// Reads the domain's state file; `None` if there is none or it cannot be read (said).
    pub(crate) fn load(domain: &Domain) -> Option<Saved> {
        let path = path(domain);
        let bytes = std::fs::read(&path).ok()?;
        let decoded = bytes
            .strip_prefix(MAGIC.as_slice())
            .ok_or_else(|| "not a state file of this version".to_string())
            .and_then(|b| postcard::from_bytes(b).map_err(|e| e.to_string()));
        match decoded {
            Ok(s) => Some(s),
            Err(error) => {
                tracing::warn!(file = %path.display(), %error, "manager state ignored");
                None
            }
        }
    }
}

/// Writes `bytes` as the state file: to a temporary file first, then renamed over it, so a
/// manager killed while writing leaves the previous state, never half of one.
fn write(domain: &Domain, bytes: &[u8]) -> std::io::Result<()> {
    let path = path(domain);
    let dir = path.parent().unwrap_or(&path);
    std::fs::create_dir_all(dir)?;
    let tmp = dir.join("state.new");
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(&tmp)?;
    f.write_all(bytes)?;
    std::fs::rename(&tmp, &path)
}

impl Manager {
    /// The state as it is now.
    fn saved(&self) -> Saved {
        let (kept, last) = self.skills.saved();
        Saved {
            kept,
            last,
            io_logged: self.observers.io_log.keys().cloned().collect(),
            monitors: self
                .observers
                .monitors
                .iter()
                .map(|m| SavedMonitor {
                    id: m.id,
                    text: m.text.clone(),
                    mode: m.mode,
                    hold: m.hold,
                    client: m.client.clone(),
                })
                .collect(),
            next_monitor: self.observers.monitors.next_id(),
            paused: self.cycles.paused,
            holds: self.cycles.holds.all().clone(),
        }
    }

    /// Writes the state file if a request or a registration may have changed it
    /// (`state_check`) and it differs from what was last written.
    pub(crate) fn save_state_if_changed(&mut self) {
        if std::mem::take(&mut self.state.check) {
            self.save_state();
        }
    }

    fn save_state(&mut self) {
        let bytes = match self.saved().encode() {
            Ok(b) => b,
            Err(error) => return tracing::warn!(%error, "manager state not saved"),
        };
        if bytes == self.state.written {
            return;
        }
        match write(&self.config.domain, &bytes) {
            Ok(()) => self.state.written = bytes,
            Err(error) => tracing::warn!(%error, "manager state not saved"),
        }
    }

    /// Takes over the state a previous manager of the domain saved: what clients set and the
    /// last declarations (each skill gets its own back when it registers), logged skills,
    /// monitors (with their ids, for the clients that hold them) and the pause.
    pub(super) fn restore_state(&mut self, saved: Saved) {
        let monitors = saved.monitors.len();
        self.skills.restore(saved.kept, saved.last);
        for name in saved.io_logged {
            // The ports are opened when the skill registers again (as after its own restart).
            self.skills.keep(&name);
            self.observers.io_log.insert(name, Vec::new());
        }
        self.cycles.paused = saved.paused;
        for (client, at) in saved.holds {
            self.cycles.holds.set(&client, Some(at));
        }
        let mut lost = Vec::new();
        let from = self.in_progress() + 1;
        for m in saved.monitors {
            self.observers.monitors.set_next_id(m.id);
            let added = super::requests::add_monitor(
                &mut self.observers,
                &self.skills,
                &self.node,
                &m.client,
                m.text.clone(),
                m.mode,
                m.hold,
                from,
            );
            if let Err(e) = added {
                lost.push(format!("{} ({e})", m.text));
            }
        }
        let next = saved.next_monitor.max(self.observers.monitors.next_id());
        self.observers.monitors.set_next_id(next);
        if !lost.is_empty() {
            tracing::warn!(lost = ?lost, "monitors not restored");
        }
        tracing::info!(
            skills = self.skills.saved().1.len(),
            monitors = monitors - lost.len(),
            paused = self.cycles.paused,
            "state of the previous manager taken over"
        );
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use skillfab_proto::param::ParamValue;

    #[test]
    fn the_state_file_reads_back_what_was_written_and_ignores_other_files() {
        let domain = Domain::new(&format!("t-state-{}", std::process::id())).unwrap();
        let mut saved = Saved {
            next_monitor: 9,
            paused: true,
            holds: [("1-0".to_string(), 70)].into(),
            ..Saved::default()
        };
        saved.kept.insert(
            "scale".into(),
            Kept {
                active: Some(false),
                params: vec![("gain".into(), ParamValue::Float(2.5))],
                priority: Some(4),
                activations: 3,
                wanted: true,
                demanded: false,
            },
        );
        saved.io_logged.insert("scale".into());
        saved.monitors.push(SavedMonitor {
            id: 8,
            text: "scale.scaled.value > 0".into(),
            mode: MonitorMode::Every,
            hold: 1,
            client: "1-0".into(),
        });
        write(&domain, &saved.encode().unwrap()).unwrap();
        assert_eq!(Saved::load(&domain), Some(saved));

        // Another layout (or garbage) is ignored, not misread.
        write(&domain, b"sfstate0 something else").unwrap();
        assert_eq!(Saved::load(&domain), None);
        std::fs::write(path(&domain), b"sfstate1\xff\xff\xff").unwrap();
        assert_eq!(Saved::load(&domain), None);
        domain.remove_all_files();
    }
}
