//! `skillfab sequence FILE`: a plan run as the domain's sequencer (the engine is the
//! `skillfab-sequence` crate; this is its command line).

use anyhow::Context;
use skillfab_client::{Client, ZenohOptions};
use skillfab_proto::domain::Domain;
use skillfab_sequence::{Plan, Sequencer, Status};
use std::path::Path;

/// Reads and checks the plan in `file`.
pub fn read_plan(file: &Path) -> anyhow::Result<Plan> {
    let text = std::fs::read_to_string(file).with_context(|| format!("plan {}", file.display()))?;
    Ok(Plan::parse(&text, &file.display().to_string())?)
}

/// Runs the plan in `file` (its tree `tree`, else its main one) on the manager of `domain`,
/// printing each step with the cycle and the fabric's time; an error when the plan fails.
pub fn run(
    domain: &Domain,
    remote: Option<ZenohOptions>,
    file: &Path,
    tree: Option<&str>,
    check: bool,
) -> anyhow::Result<()> {
    let plan = read_plan(file)?;
    let mut seq = Sequencer::new(&plan, tree)?;
    if check {
        println!(
            "{}: {} tree(s), runs '{}'",
            file.display(),
            plan.trees.len(),
            tree.unwrap_or(&plan.main)
        );
        return Ok(());
    }
    let mut client = match &remote {
        Some(o) => Client::connect_remote(domain.name(), o)?,
        None => Client::connect(domain)?,
    };
    crate::demo::catch_interrupts()?;
    let mut print = |c: &Client, what: &str| {
        let cycle = c.stats().map(|s| s.cycles).unwrap_or(0);
        match c.clock() {
            Some(clock) => println!(
                "[cycle {cycle:>6}, t = {:>7.2} s] {what}",
                clock.time.as_secs_f64()
            ),
            None => println!("[cycle {cycle:>6}] {what}"),
        }
    };
    let mut stop = crate::demo::interrupted;
    match skillfab_sequence::run(&mut client, &mut seq, &mut stop, &mut print)? {
        Some(Status::Success) => {
            println!("the plan succeeded");
            Ok(())
        }
        Some(_) => anyhow::bail!("the plan failed"),
        None => {
            println!("halted");
            Ok(())
        }
    }
}
