//! The multi-process integration tests, as one test binary (one link instead of eight).
//! Each module is one area; every test starts its own fabric in its own domain
//! ([`skillfab_tests::TestDomain`]), so they run in parallel.
//!
//! One area: `cargo test -p skillfab-tests --test it exit_lab::`; one test: its full name.

mod arbitration;
mod bridge;
mod console;
mod control;
mod deliver;
mod denning;
mod exit_lab;
mod fabric;
mod fabric_log;
mod faults;
mod newcomer;
mod polyglot;
mod realtime;
mod replay;
mod ros_tools;
mod sequence;
mod view;
