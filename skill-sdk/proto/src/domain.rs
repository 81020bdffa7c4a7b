//! Domains: everything of one fabric lives in one iceoryx2 namespace.
//!
//! A domain name maps to an iceoryx2 [`Config`] built explicitly (never read from an
//! `iceoryx2.toml` in `$PWD`, `$HOME` or `/etc`): file prefix `sf_<domain>_` for every
//! shared-memory object and root path `/tmp/skillfab/<domain>/` for iceoryx2's node and
//! service files. Domain names exclude `_`, so no domain's prefix is a prefix of another's.

use crate::Error;
use iceoryx2::config::Config;
use iceoryx2::prelude::*;
use std::path::PathBuf;

/// Environment variable that selects the domain when `--domain` is not given.
pub const DOMAIN_ENV: &str = "SKILLFAB_DOMAIN";

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
        PathBuf::from(format!("/tmp/skillfab/{}/", self.name))
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
