//! The standard skill library. Each skill is a type here (so unit tests drive it through the
//! SDK's harness) and a binary in `src/bin/` whose `main` is one line.

#![warn(missing_docs)]

pub mod building;
pub mod hello;
pub mod nav;
