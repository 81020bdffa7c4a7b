//! Domains: everything of one fabric lives in one iceoryx2 namespace.
//!
//! A domain name maps to an iceoryx2 [`Config`] built explicitly (never read from an
//! `iceoryx2.toml` in `$PWD`, `$HOME` or `/etc`): file prefix `sf_<domain>_` for every
//! shared-memory object and root path `/tmp/skillfab/<domain>/` for iceoryx2's node and
//! service files. Domain names exclude `_`, so no domain's prefix is a prefix of another's.
//!
//! A domain belongs to the user who starts it: its root directory is 0700 and every file in
//! `/dev/shm` 0600 ([`Domain::secure_root`] before a node is created, [`Domain::secure_shm`]
//! after). iceoryx2 makes its own directories 0750 and its node counter (`…global_mgmt`,
//! shared by every process of the domain) 0666, with no configuration to change either: the
//! root directory is created 0700 by skillfab first, so nothing below it is reachable by other
//! users, and the node counter is narrowed to 0600 right after the first node of the domain
//! creates it.

use crate::Error;
use iceoryx2::config::Config;
use iceoryx2::prelude::*;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
use std::path::PathBuf;

/// The directory holding every domain's root directory (world-writable and sticky, like /tmp).
pub const ROOTS: &str = "/tmp/skillfab";

/// Environment variable that selects the domain when `--domain` is not given.
pub const DOMAIN_ENV: &str = "SKILLFAB_DOMAIN";

/// How long opening a service waits for another process that is creating it.
pub const CREATION_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// A validated domain name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Domain {
    name: String,
}

impl Domain {
    /// Checks `name`: 1 to 40 of `[A-Za-z0-9.-]`.
    pub fn new(name: &str) -> Result<Domain, Error> {
        let ok = !name.is_empty()
            && name.len() <= 40
            && !name.starts_with('.')
            && name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.');
        if !ok {
            return Err(Error::BadDomain {
                name: name.to_string(),
            });
        }
        Ok(Domain {
            name: name.to_string(),
        })
    }

    /// The domain name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Prefix of every shared-memory file of this domain.
    pub fn prefix(&self) -> String {
        format!("sf_{}_", self.name)
    }

    /// iceoryx2's root directory for this domain.
    pub fn root_path(&self) -> PathBuf {
        PathBuf::from(format!("{ROOTS}/{}/", self.name))
    }

    /// Makes the domain's root directory exist, belong to this user and be 0700 (created
    /// so, or narrowed); refuses a directory of another user (another user's fabric of the
    /// same name, or a squatted name). [`ROOTS`] is created world-writable and sticky.
    pub fn secure_root(&self) -> Result<(), Error> {
        let err = |path: &str, reason: String| Error::DomainAccess {
            domain: self.name.clone(),
            path: path.to_string(),
            reason,
        };
        let me = nix::unistd::geteuid().as_raw();
        match std::fs::DirBuilder::new().mode(0o1777).create(ROOTS) {
            Ok(()) => {
                // The umask took bits off: put them back.
                let _ = std::fs::set_permissions(ROOTS, std::fs::Permissions::from_mode(0o1777));
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                // Ours but not shared (made by an older version or by iceoryx2): share it.
                if std::fs::metadata(ROOTS)
                    .is_ok_and(|m| m.uid() == me && m.mode() & 0o7777 != 0o1777)
                {
                    let _ =
                        std::fs::set_permissions(ROOTS, std::fs::Permissions::from_mode(0o1777));
                }
            }
            Err(e) => return Err(err(ROOTS, e.to_string())),
        }
        let root = self.root_path();
        let shown = root.display().to_string();
        // Created or not, its mode is checked below: iceoryx2 changes the process umask for a
        // moment while it creates a listener, and a directory made by another thread then may
        // lack its owner's bits.
        match std::fs::DirBuilder::new().mode(0o700).create(&root) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(err(&shown, e.to_string())),
        }
        let meta = std::fs::symlink_metadata(&root).map_err(|e| err(&shown, e.to_string()))?;
        if !meta.is_dir() {
            return Err(err(&shown, "not a directory".into()));
        }
        if meta.uid() != me {
            return Err(err(
                &shown,
                format!(
                    "belongs to uid {}, not to this user (uid {me}): another user's domain",
                    meta.uid()
                ),
            ));
        }
        if meta.mode() & 0o777 != 0o700 {
            std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o700))
                .map_err(|e| err(&shown, e.to_string()))?;
        }
        Ok(())
    }

    /// Narrows every file of this domain in `/dev/shm` that this user owns to 0600 (iceoryx2
    /// creates its node counter 0666). Returns how many it changed.
    pub fn secure_shm(&self) -> usize {
        let me = nix::unistd::geteuid().as_raw();
        self.shm_files()
            .into_iter()
            .filter(|f| {
                std::fs::metadata(f).is_ok_and(|m| m.uid() == me && m.mode() & 0o077 != 0)
                    && std::fs::set_permissions(f, std::fs::Permissions::from_mode(0o600)).is_ok()
            })
            .count()
    }

    /// The iceoryx2 configuration of this domain.
    pub fn iceoryx_config(&self) -> Result<Config, Error> {
        let mut config = Config::default();
        let bad = |what: &str| Error::BadDomain {
            name: format!("{} ({what} is not a valid iceoryx2 name)", self.name),
        };
        config.global.prefix =
            FileName::new(self.prefix().as_bytes()).map_err(|_| bad("prefix"))?;
        let root = self.root_path();
        config.global.set_root_path(
            &Path::new(root.to_string_lossy().as_bytes()).map_err(|_| bad("root path"))?,
        );
        // The control server keeps the connection of a client that left while its request is
        // still being carried out until the answer is dropped. iceoryx2 keeps 128 such
        // connections and panics past that when they all hold a request (seen with a hundred
        // clients connecting at once on a loaded machine, each of which may ask again on a new
        // port): room for every client of the control plane four times over.
        config
            .defaults
            .request_response
            .server_expired_connection_buffer = 4 * crate::services::CONTROL_MAX_CLIENTS;
        // A service another process is creating is waited for this long before opening it
        // fails with `HangsInCreation` (iceoryx2's default is 1 s). Twenty processes of a
        // network starting at once on a loaded host took longer, and a skill exited for it
        // ("open topic 'odometry': HangsInCreation", load average 30–100).
        config.global.creation_timeout = CREATION_TIMEOUT;
        Ok(config)
    }

    /// Every file of this domain in `/dev/shm`.
    pub fn shm_files(&self) -> Vec<PathBuf> {
        let prefix = self.prefix();
        let Ok(dir) = std::fs::read_dir("/dev/shm") else {
            return Vec::new();
        };
        dir.filter_map(Result::ok)
            .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
            .map(|e| e.path())
            .collect()
    }

    /// Removes every shared-memory file and the iceoryx2 root directory of this domain.
    /// Only for when no process of the domain is left (tests, `skillfab up` at the very end).
    pub fn remove_all_files(&self) {
        for f in self.shm_files() {
            let _ = std::fs::remove_file(f);
        }
        let _ = std::fs::remove_dir_all(self.root_path());
    }
}

impl std::fmt::Display for Domain {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_checked() {
        assert!(Domain::new("default").is_ok());
        assert!(Domain::new("t-12.3").is_ok());
        assert!(Domain::new("").is_err());
        assert!(Domain::new("a_b").is_err());
        assert!(Domain::new("a/b").is_err());
        assert!(Domain::new(&"x".repeat(41)).is_err());
    }

    #[test]
    fn prefixes_never_nest() {
        let a = Domain::new("a").unwrap().prefix();
        let ab = Domain::new("ab").unwrap().prefix();
        let a_dash = Domain::new("a-b").unwrap().prefix();
        assert!(!ab.starts_with(&a));
        assert!(!a_dash.starts_with(&a));
    }
}
