//! Why the manager refused a skill's registration. The manager writes the [`Refusal`] into the
//! slot's message area (postcard) before it sets the slot `Refused`; the skill reads it back as
//! a value it can match (`SdkError::Refused`), and its text is made there, at the edge.

use crate::board::MSG_BYTES;
use serde::{Deserialize, Serialize};

/// Why a registration was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Refusal {
    /// The declaration's bytes do not decode (a skill built against another version).
    #[error("malformed declaration: {0}")]
    Malformed(postcard::Error),
    /// A skill or topic name that is not allowed.
    #[error("bad {what} name '{name}': use 1-64 of [A-Za-z0-9_-]")]
    BadName {
        /// "skill" or "topic".
        what: String,
        /// The name given.
        name: String,
    },
    /// More ports than a slot holds.
    #[error("at most {max} inputs and {max} outputs per skill ({inputs} and {outputs} declared)")]
    TooManyPorts {
        /// Inputs declared.
        inputs: u32,
        /// Outputs declared.
        outputs: u32,
        /// The limit of each.
        max: u32,
    },
    /// The skill does not fit the data-flow graph of the skills registered.
    #[error(transparent)]
    Wiring(WiringError),
    /// The manager's answer does not decode (a manager of another version).
    #[error("the manager's answer could not be read (a manager of another version?)")]
    Unreadable,
}

/// A port's message type as the wiring checks compare it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TypeDesc {
    /// The type's name (`skillfab.Drive`).
    pub name: String,
    /// Size (bytes).
    pub size: u32,
    /// Alignment (bytes).
    pub align: u32,
}

impl std::fmt::Display for TypeDesc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({} B, align {})", self.name, self.size, self.align)
    }
}

/// Which end of a topic a port is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Side {
    /// It reads the topic.
    Input,
    /// It publishes on the topic.
    Output,
}

impl std::fmt::Display for Side {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Side::Input => "input",
            Side::Output => "output",
        })
    }
}

/// Why a skill does not fit the data-flow graph of the skills registered.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize, Deserialize)]
#[non_exhaustive]
pub enum WiringError {
    /// Another live instance has the name.
    #[error("a skill named '{name}' is already registered (pid {pid})")]
    DuplicateName {
        /// The name.
        name: String,
        /// The live instance's pid.
        pid: u32,
    },
    /// Two producers for one topic.
    #[error(
        "topic '{topic}' is already produced by skill '{producer}'; '{skill}' cannot publish it too"
    )]
    TwoProducers {
        /// The topic.
        topic: String,
        /// Its producer.
        producer: String,
        /// The newcomer.
        skill: String,
    },
    /// The two ends of a topic disagree on its message type.
    #[error(
        "type mismatch on topic '{topic}': skill '{skill}' {side} '{port}' is '{ty}', \
         but skill '{other}' {other_side} '{other_port}' is '{other_ty}'"
    )]
    TypeMismatch {
        /// The topic.
        topic: String,
        /// The newcomer.
        skill: String,
        /// Its end of the topic.
        side: Side,
        /// Its port.
        port: String,
        /// Its type.
        ty: TypeDesc,
        /// The registered skill it clashes with.
        other: String,
        /// That skill's end of the topic.
        other_side: Side,
        /// Its port.
        other_port: String,
        /// Its type.
        other_ty: TypeDesc,
    },
    /// A second device for a channel.
    #[error(
        "channel '{channel}' is already served by device '{device}'; '{skill}' cannot serve it too"
    )]
    ChannelServed {
        /// The channel.
        channel: String,
        /// The device serving it.
        device: String,
        /// The newcomer.
        skill: String,
    },
    /// Sync skills would wait on each other in a loop.
    #[error(
        "data-flow loop among sync skills: {} (make one of them async to break it)",
        skills.join(" -> ")
    )]
    Loop {
        /// The skills of the loop in data-flow order, the first again at the end (`a -> b -> a`);
        /// "…" in the middle where a loop too long for the answer was cut.
        skills: Vec<String>,
    },
}

impl Refusal {
    /// The bytes for the slot's message area: at most [`MSG_BYTES`]. A loop too long for it
    /// keeps its first and last skills with "…" between them. (Names are at most 64 bytes, so
    /// nothing else should be too long; if it were, the cut bytes read as
    /// [`Refusal::Unreadable`].)
    pub fn encode(&self) -> Vec<u8> {
        let encode = |r: &Refusal| postcard::to_allocvec(r).unwrap_or_default();
        let bytes = encode(self);
        if bytes.len() <= MSG_BYTES {
            return bytes;
        }
        if let Refusal::Wiring(WiringError::Loop { skills }) = self {
            for keep in (1..skills.len() / 2).rev() {
                let cut = [
                    &skills[..keep],
                    &["…".to_string()],
                    &skills[skills.len() - keep..],
                ]
                .concat();
                let bytes = encode(&Refusal::Wiring(WiringError::Loop { skills: cut }));
                if bytes.len() <= MSG_BYTES {
                    return bytes;
                }
            }
        }
        bytes[..MSG_BYTES].to_vec()
    }

    /// Reads the manager's answer from the slot's message area.
    pub fn decode(bytes: &[u8]) -> Refusal {
        postcard::from_bytes(bytes).unwrap_or(Refusal::Unreadable)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refusal_reads_back_as_the_value_it_was_and_a_long_loop_is_cut_to_fit() {
        let r = Refusal::Wiring(WiringError::TypeMismatch {
            topic: "tick".into(),
            skill: "b".into(),
            side: Side::Input,
            port: "x".into(),
            ty: TypeDesc {
                name: "hello.Tick".into(),
                size: 8,
                align: 8,
            },
            other: "a".into(),
            other_side: Side::Output,
            other_port: "y".into(),
            other_ty: TypeDesc {
                name: "hello.Tock".into(),
                size: 16,
                align: 8,
            },
        });
        assert_eq!(Refusal::decode(&r.encode()), r);
        assert_eq!(
            r.to_string(),
            "type mismatch on topic 'tick': skill 'b' input 'x' is 'hello.Tick (8 B, align 8)', \
             but skill 'a' output 'y' is 'hello.Tock (16 B, align 8)'"
        );

        let skills: Vec<String> = (0..64).map(|i| format!("skill_{i:0>58}")).collect();
        let long = Refusal::Wiring(WiringError::Loop { skills });
        let bytes = long.encode();
        assert!(bytes.len() <= MSG_BYTES);
        let Refusal::Wiring(WiringError::Loop { skills: cut }) = Refusal::decode(&bytes) else {
            panic!("a loop comes back a loop");
        };
        assert!(cut.len() < 64 && cut.contains(&"…".to_string()), "{cut:?}");
        assert_eq!(
            cut.first().map(String::as_str),
            Some(&*format!("skill_{:0>58}", 0))
        );
        assert_eq!(
            cut.last().map(String::as_str),
            Some(&*format!("skill_{:0>58}", 63))
        );

        assert_eq!(Refusal::decode(b"\xff\xff"), Refusal::Unreadable);
    }
}
