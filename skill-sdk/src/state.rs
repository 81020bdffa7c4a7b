//! A skill's memory across the death of its process: declared once, kept by the runtime.
//!
//! A skill whose value holds what it learnt over many cycles (a map of where the robot has
//! been, a door's estimate, a timer, the phase of a manoeuvre) declares that value its
//! state: it derives serde's `Serialize` and `Deserialize` and sets [`Skill::STATE`] to
//! [`State::kept`]. Nothing else is written by hand:
//!
//! ```
//! use serde::{Deserialize, Serialize};
//! use skill_sdk::prelude::*;
//! use skillfab_msgs::Tick;
//!
//! #[derive(Outputs)]
//! pub struct Out<'a> { pub count: Output<'a, Tick> }
//!
//! #[derive(Default, Serialize, Deserialize)]
//! pub struct Count { runs: u64 }
//! impl Skill for Count {
//!     type Params = NoParams;
//!     type Inputs<'a> = ();
//!     type Outputs<'a> = Out<'a>;
//!     const STATE: State<Self> = State::kept(1);
//!     fn compute(&mut self, _: &Ctx<NoParams>, _: (), o: &mut Out) -> SkillResult {
//!         self.runs += 1;
//!         o.count.set(Tick { value: self.runs });
//!         Ok(())
//!     }
//! }
//! ```
//!
//! What the runtime does with it (docs/architecture.md, "Faults"):
//! - after every run that returned `Ok`, once its outputs are sent and before the run is
//!   stamped on the board, the value is encoded (postcard) into the skill's own
//!   shared-memory object, `/dev/shm/sf_<domain>_state_<name>`: two slots written in turn and
//!   one atomic counter saying which is whole, so a `kill -9` at any instant leaves the state
//!   of the last completed run — never a torn one, never one a second old;
//! - a run that fails (an error or a panic) changes nothing: the value goes back to the
//!   state of the last completed run, as its outputs are dropped;
//! - the next process of the same instance name loads it before its first run; a process
//!   that leaves cleanly (SIGTERM, `ctl` shutdown) removes it, so the next one starts afresh;
//! - the stored state carries a fingerprint of the type (its name, size and the declared
//!   version): state of another version of the skill is not decoded but dropped, and the log
//!   says which it was — restored, another version, or unreadable.
//!
//! Fields that are a cache (rebuilt from the kept ones) are marked `#[serde(skip)]`.
//!
//! [`Skill::STATE`]: crate::skill::Skill::STATE

use serde::Serialize;
use serde::de::DeserializeOwned;

/// How a skill's state is kept: [`State::NONE`] (the default: nothing) or [`State::kept`].
pub struct State<S> {
    codec: Option<Codec<S>>,
}

/// The encoding of one state type.
struct Codec<S> {
    version: u32,
    encode: fn(&S, &mut Vec<u8>) -> Result<(), postcard::Error>,
    decode: fn(&[u8]) -> Result<S, postcard::Error>,
}

impl<S> State<S> {
    /// Nothing kept: a restarted instance starts from `Default`.
    pub const NONE: State<S> = State { codec: None };
}

impl<S: Serialize + DeserializeOwned> State<S> {
    /// The skill's whole value is its state. `version` is raised when a change of the type
    /// keeps its name and size but changes what its bytes mean.
    pub const fn kept(version: u32) -> State<S> {
        State {
            codec: Some(Codec {
                version,
                encode: encode::<S>,
                decode: decode::<S>,
            }),
        }
    }
}

fn encode<S: Serialize>(value: &S, buf: &mut Vec<u8>) -> Result<(), postcard::Error> {
    buf.clear();
    *buf = postcard::to_extend(value, std::mem::take(buf))?;
    Ok(())
}

fn decode<S: DeserializeOwned>(bytes: &[u8]) -> Result<S, postcard::Error> {
    postcard::from_bytes(bytes)
}

impl<S> State<S> {
    /// Whether anything is kept.
    pub fn is_kept(&self) -> bool {
        self.codec.is_some()
    }

    /// What tells this type's state from another's: the type's name, its size and the
    /// declared version (FNV-1a). `None` when nothing is kept.
    pub fn fingerprint(&self) -> Option<u64> {
        let c = self.codec.as_ref()?;
        let text = format!(
            "{}/{}/{}",
            std::any::type_name::<S>(),
            std::mem::size_of::<S>(),
            c.version
        );
        Some(text.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        }))
    }

    /// Encodes `value` into `buf` (replacing its contents). `Ok(false)` when nothing is kept.
    pub fn encode(&self, value: &S, buf: &mut Vec<u8>) -> Result<bool, StateError> {
        let Some(c) = &self.codec else {
            return Ok(false);
        };
        (c.encode)(value, buf).map_err(|source| StateError::Encode { source })?;
        Ok(true)
    }

    /// Decodes what [`State::encode`] wrote.
    pub fn decode(&self, bytes: &[u8]) -> Result<S, StateError> {
        let c = self.codec.as_ref().ok_or(StateError::NotKept)?;
        (c.decode)(bytes).map_err(|source| StateError::Decode { source })
    }
}

/// Why a state could not be kept or taken back.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StateError {
    /// The skill declares no state.
    #[error("the skill keeps no state")]
    NotKept,
    /// The value could not be encoded (a type serde cannot write, e.g. a map with
    /// non-string keys is fine, but an unsized sequence is not).
    #[error("the state could not be encoded")]
    Encode {
        /// postcard's reason.
        #[source]
        source: postcard::Error,
    },
    /// Bytes of the same fingerprint that do not decode (corrupted, or a change of meaning
    /// without a change of version).
    #[error("the kept state does not decode")]
    Decode {
        /// postcard's reason.
        #[source]
        source: postcard::Error,
    },
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, Default, PartialEq, Serialize, Deserialize)]
    struct Memory {
        seen: Vec<(f64, f64)>,
        phase: u8,
        #[serde(skip)]
        cache: u32,
    }

    #[derive(Debug, Default, PartialEq, Serialize, Deserialize)]
    struct Other {
        phase: u8,
    }

    #[test]
    fn a_kept_value_comes_back_as_it_was_but_for_its_skipped_cache() {
        let s = State::<Memory>::kept(1);
        let m = Memory {
            seen: vec![(1.0, 2.0), (3.5, -4.0)],
            phase: 3,
            cache: 7,
        };
        let mut buf = vec![0xFF; 3];
        assert!(s.encode(&m, &mut buf).unwrap());
        let back = s.decode(&buf).unwrap();
        assert_eq!(back.seen, m.seen);
        assert_eq!(back.phase, 3);
        assert_eq!(back.cache, 0);
    }

    #[test]
    fn versions_and_types_have_their_own_fingerprints() {
        let a = State::<Memory>::kept(1).fingerprint().unwrap();
        assert_eq!(Some(a), State::<Memory>::kept(1).fingerprint());
        assert_ne!(Some(a), State::<Memory>::kept(2).fingerprint());
        assert_ne!(Some(a), State::<Other>::kept(1).fingerprint());
        assert_eq!(State::<Memory>::NONE.fingerprint(), None);
        assert!(
            !State::<Memory>::NONE
                .encode(&Memory::default(), &mut Vec::new())
                .unwrap()
        );
    }

    #[test]
    fn bytes_that_are_not_a_state_are_an_error_not_a_value() {
        let s = State::<Memory>::kept(1);
        assert!(matches!(
            s.decode(&[0xFF, 0xFF, 0xFF]),
            Err(StateError::Decode { .. })
        ));
    }
}
