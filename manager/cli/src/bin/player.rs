//! `skillfab-player`: the player of `skillfab replay`. A sync source unit that publishes, in
//! each cycle, the recorded samples of that cycle on the topics the replayed skills read and do
//! not produce — the bytes as recorded, so the skills see exactly what they saw.
//!
//! `skillfab-player --script FILE [skill arguments]`; the script (written by `skillfab
//! replay`) is text: `topic <index> <topic> <type>` lines, then `sample <cycle> <index> <hex>`
//! lines.

use skill_sdk::foreign::{ForeignSkill, run};
use skill_sdk::prelude::Mode;
use std::collections::HashMap;
use std::process::ExitCode;

/// The samples to publish, by cycle: (output index, bytes).
type Script = HashMap<u64, Vec<(usize, Vec<u8>)>>;

fn load(path: &str) -> Result<(Vec<(String, String)>, Script), String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("reading {path}: {e}"))?;
    let mut topics = Vec::new();
    let mut script: Script = HashMap::new();
    for (n, line) in text.lines().enumerate() {
        let bad = || format!("{path}:{}: cannot read '{line}'", n + 1);
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.as_slice() {
            ["topic", i, topic, ty] if i.parse::<usize>().ok() == Some(topics.len()) => {
                topics.push((topic.to_string(), ty.to_string()));
            }
            ["sample", cycle, i, hex] => {
                let cycle: u64 = cycle.parse().map_err(|_| bad())?;
                let i: usize = i.parse().map_err(|_| bad())?;
                let bytes = skillfab_manager::recorder::unhex(hex).ok_or_else(bad)?;
                script.entry(cycle).or_default().push((i, bytes));
            }
            [] => {}
            _ if line.starts_with('#') => {}
            _ => return Err(bad()),
        }
    }
    Ok((topics, script))
}

fn main() -> ExitCode {
    let mut args: Vec<String> = std::env::args().collect();
    let Some(at) = args.iter().position(|a| a == "--script") else {
        eprintln!("skillfab-player: --script FILE is required");
        return ExitCode::FAILURE;
    };
    let Some(path) = args.get(at + 1).cloned() else {
        eprintln!("skillfab-player: --script needs a file");
        return ExitCode::FAILURE;
    };
    args.drain(at..at + 2);
    let (topics, script) = match load(&path) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("skillfab-player: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut skill = match ForeignSkill::new("player", Mode::Sync, skillfab_msgs::registry()) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("skillfab-player: {e}");
            return ExitCode::FAILURE;
        }
    };
    for (i, (topic, ty)) in topics.iter().enumerate() {
        let port = format!("p{i}");
        if let Err(e) = skill.output(&port, ty) {
            eprintln!("skillfab-player: topic {topic}: {e}");
            return ExitCode::FAILURE;
        }
        args.extend(["--remap".to_string(), format!("{port}={topic}")]);
    }
    skill.compute(Box::new(move |run| {
        for (i, bytes) in script.get(&run.cycle).into_iter().flatten() {
            match run.output(*i, false) {
                Some(out) if out.len() == bytes.len() => out.copy_from_slice(bytes),
                _ => run.fail(&format!(
                    "cycle {}: a recorded sample of output {i} does not fit its type",
                    run.cycle
                )),
            }
        }
        Ok(())
    }));
    match run(skill, args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("skillfab-player: {e}");
            ExitCode::FAILURE
        }
    }
}
