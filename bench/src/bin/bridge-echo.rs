//! `bridge-echo`: the remote async skill of `bridge-report` — copies each `ping` it sees to
//! `pong`, unchanged.
//!
//! `bridge-echo --size 64|1M [skill options]` (`bench.Blob64` or `bench.Blob1M`).

use skill_sdk::foreign::{ForeignSkill, run};
use skill_sdk::prelude::{Message, Mode};
use skillfab_tests::skills::{Blob1M, Blob64};
use std::process::ExitCode;

fn main() -> ExitCode {
    let mut args: Vec<String> = std::env::args().collect();
    let schema = match args.iter().position(|a| a == "--size") {
        Some(i) if args.get(i + 1).map(String::as_str) == Some("64") => {
            args.drain(i..i + 2);
            Blob64::schema()
        }
        Some(i) if args.get(i + 1).map(String::as_str) == Some("1M") => {
            args.drain(i..i + 2);
            Blob1M::schema()
        }
        _ => {
            eprintln!("bridge-echo: --size 64|1M is required");
            return ExitCode::FAILURE;
        }
    };
    let mut skill = match ForeignSkill::new("bridge-echo", Mode::Async, &[]) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("bridge-echo: {e}");
            return ExitCode::FAILURE;
        }
    };
    if let Err(e) = skill
        .input_schema("ping", schema.clone())
        .and_then(|_| skill.output_schema("pong", schema))
    {
        eprintln!("bridge-echo: {e}");
        return ExitCode::FAILURE;
    }
    skill.compute(Box::new(|run| {
        if let Some((bytes, _)) = run.input(0)
            && let Some(out) = run.output(0, false)
        {
            out.copy_from_slice(bytes);
        }
        Ok(())
    }));
    match run(skill, args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("bridge-echo: {e}");
            ExitCode::FAILURE
        }
    }
}
