//! What fabrics leave behind on this machine, and removing it: `skillfab clean`.
//!
//! A domain's files are its cycle board and iceoryx2's shared memory in `/dev/shm` (all named
//! `sf_<domain>_…`) and its root directory under [`ROOTS`]. A process killed with `kill -9`
//! leaves its iceoryx2 node behind (the manager removes those of its own domain while it
//! runs), and iceoryx2's node counter (`…_node.<version>.global_mgmt`) outlives every node by
//! design: the last `skillfab up` of a domain removes it on its way out, and this removes what
//! was left when that did not happen (a killed `up`, a client started after it ended).

use crate::Error;
use crate::board::{Board, MAX_SLOTS, SlotState, pid_alive};
use crate::domain::{Domain, ROOTS};
use iceoryx2::node::{Node, NodeState, NodeView};
use iceoryx2::prelude::*;
use std::os::unix::fs::MetadataExt;
use std::sync::atomic::Ordering;

/// What cleaning one domain did.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct Cleaned {
    /// The domain.
    pub domain: String,
    /// Live processes of the domain (manager, registered units, iceoryx2 nodes; 0 for a node
    /// whose owner this user cannot see): with any, only dead nodes are cleaned.
    pub alive: Vec<u32>,
    /// Dead iceoryx2 nodes whose resources were removed.
    pub dead_nodes: usize,
    /// Files removed from `/dev/shm`.
    pub files: usize,
    /// Their size in bytes.
    pub bytes: u64,
    /// Whether the root directory was removed.
    pub root: bool,
}

/// Every domain with a file in `/dev/shm` or a root directory under [`ROOTS`] that this user
/// owns, by name.
pub fn domains_on_machine() -> Vec<Domain> {
    let me = nix::unistd::geteuid().as_raw();
    let mut names = std::collections::BTreeSet::new();
    let owned = |e: &std::fs::DirEntry| e.metadata().is_ok_and(|m| m.uid() == me);
    if let Ok(dir) = std::fs::read_dir("/dev/shm") {
        for e in dir.flatten().filter(owned) {
            let file = e.file_name().to_string_lossy().into_owned();
            // Domain names exclude '_': the name ends at the first one after "sf_".
            if let Some(rest) = file.strip_prefix("sf_")
                && let Some((name, _)) = rest.split_once('_')
            {
                names.insert(name.to_string());
            }
        }
    }
    if let Ok(dir) = std::fs::read_dir(ROOTS) {
        for e in dir.flatten().filter(owned) {
            names.insert(e.file_name().to_string_lossy().into_owned());
        }
    }
    names
        .into_iter()
        .filter_map(|n| Domain::new(&n).ok())
        .collect()
}

/// The live processes of `domain`: its manager and registered units (from the board) and
/// the owners of its live iceoryx2 nodes (0 where this user cannot tell).
pub fn live_pids(domain: &Domain) -> Vec<u32> {
    let mut pids = Vec::new();
    if let Ok(board) = Board::open(&domain.prefix()) {
        if board.manager_alive() {
            pids.push(board.header().manager_pid.load(Ordering::Acquire));
        }
        for i in 0..MAX_SLOTS {
            let slot = board.slot(i);
            let pid = slot.pid.load(Ordering::Acquire);
            if slot.state() != SlotState::Free && pid != 0 && pid_alive(pid) {
                pids.push(pid);
            }
        }
    }
    if let Ok(config) = domain.iceoryx_config() {
        let _ = Node::<ipc::Service>::list(&config, |state| {
            match state {
                NodeState::Alive(v) => {
                    pids.push(v.id().pid::<ipc::Service>().map_or(0, |p| p.value() as u32))
                }
                NodeState::Inaccessible(_) | NodeState::Undefined(_) => pids.push(0),
                NodeState::Dead(_) => {}
            }
            CallbackProgression::Continue
        });
    }
    pids.sort_unstable();
    pids.dedup();
    pids
}

/// Cleans `domain`: the resources of its dead iceoryx2 nodes, and — when none of its
/// processes is alive — every file it has (`/dev/shm` and the root directory).
pub fn clean(domain: &Domain) -> Result<Cleaned, Error> {
    let mut done = Cleaned {
        domain: domain.name().to_string(),
        ..Cleaned::default()
    };
    let config = domain.iceoryx_config()?;
    let mut dead = Vec::new();
    let _ = Node::<ipc::Service>::list(&config, |state| {
        if let NodeState::Dead(v) = state {
            dead.push(v);
        }
        CallbackProgression::Continue
    });
    for v in dead {
        if v.try_remove_stale_resources().is_ok() {
            done.dead_nodes += 1;
        }
    }
    done.alive = live_pids(domain);
    if !done.alive.is_empty() {
        return Ok(done);
    }
    for f in domain.shm_files() {
        let size = std::fs::metadata(&f).map_or(0, |m| m.len());
        if std::fs::remove_file(&f).is_ok() {
            done.files += 1;
            done.bytes += size;
        }
    }
    done.root = std::fs::remove_dir_all(domain.root_path()).is_ok();
    Ok(done)
}
