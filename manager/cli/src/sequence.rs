//! `skillfab sequence FILE`: a plan run as the domain's sequencer (the engine is the
//! `skillfab-sequence` crate; this is its command line). The plan's state is kept in the
//! domain's shared memory after every tick: a runner started after this one dies resumes it
//! (docs/sequence.md, "A plan that survives its runner").
//!
//! Exit status: 0 the plan succeeded (or was halted by Ctrl-C/SIGTERM), 1 it failed,
//! [`UNFINISHED`] it could not be run to its end (no manager, the fabric gone): its state is
//! kept, and `up` starts a runner again.

use anyhow::Context;
use skillfab_client::{Address, Client};
use skillfab_proto::control::SkillState;
use skillfab_proto::domain::Domain;
use skillfab_sequence::{Plan, PlanStore, Sequencer, Status};
use std::path::Path;
use std::time::{Duration, Instant};

/// The exit status of a runner that could not take its plan to its end.
pub const UNFINISHED: u8 = 3;

/// The plan could not be run to its end (exit status [`UNFINISHED`]).
#[derive(Debug, thiserror::Error)]
#[error("the plan was not run to its end (its state is kept for the next runner): {0:#}")]
pub struct Unfinished(anyhow::Error);

/// How `skillfab sequence` runs its plan.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// The tree to run (else the plan's main one).
    pub tree: Option<String>,
    /// Only check the plan (its form, and its names against `launch` or the running domain).
    pub check: bool,
    /// The launch file whose skills `check` checks the plan's names against.
    pub launch: Option<std::path::PathBuf>,
    /// Start over whatever a runner before left.
    pub fresh: bool,
    /// Skills to wait for (registered, not starting) before the first tick.
    pub wait_for: Vec<String>,
    /// How long to wait for the manager and those skills.
    pub wait: Duration,
    /// Plan again when a step fails (the plan is the planner's for this route).
    pub replan: Option<crate::replan::Replanning>,
}

/// Reads and checks the plan in `file`.
pub fn read_plan(file: &Path) -> anyhow::Result<Plan> {
    let text = std::fs::read_to_string(file).with_context(|| format!("plan {}", file.display()))?;
    Ok(Plan::parse(&text, &file.display().to_string())?)
}

/// Connects to `domain`'s manager on this host, waiting up to `wait` for it and for the
/// skills of `wait_for` to have registered.
fn connect_waiting(domain: &Domain, wait_for: &[String], wait: Duration) -> anyhow::Result<Client> {
    let deadline = Instant::now() + wait;
    loop {
        let missing = match Client::connect(domain) {
            Ok(c) => match c.list() {
                Ok(list) => {
                    let ready = |name: &String| {
                        list.iter()
                            .any(|s| s.name == *name && s.state != SkillState::Starting)
                    };
                    let missing: Vec<&String> = wait_for.iter().filter(|n| !ready(n)).collect();
                    if missing.is_empty() {
                        return Ok(c);
                    }
                    format!(
                        "skills not registered: {}",
                        missing
                            .iter()
                            .map(|s| s.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                }
                Err(e) => e.to_string(),
            },
            Err(e) => e.to_string(),
        };
        if Instant::now() >= deadline {
            anyhow::bail!("{missing}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `--check`: the plan's form (read already), then its names against the launch file's
/// skills, else the running domain's, else not (said).
fn check(
    plan: &Plan,
    file: &Path,
    tree: Option<&str>,
    address: &Address,
    opts: &RunOptions,
) -> anyhow::Result<()> {
    let form = format!(
        "{}: {} tree(s), runs '{}'",
        file.display(),
        plan.trees.len(),
        tree.unwrap_or(&plan.main)
    );
    let decls = match &opts.launch {
        Some(l) => Some(crate::check::Declarations::of_launch(l)?),
        None => match address.connect() {
            Ok(c) => Some(crate::check::Declarations::of_domain(&c, address)?),
            Err(_) => None,
        },
    };
    let Some(decls) = decls else {
        println!("{form}; its names are not checked: no --launch, and no manager at {address}");
        return Ok(());
    };
    let problems = crate::check::check(plan, &decls);
    if problems.is_empty() {
        println!(
            "{form}; every skill, parameter, output and field it names is in {}",
            decls.from
        );
        return Ok(());
    }
    for (u, p) in &problems {
        println!(
            "{}:{}: {} (tree '{}'): {p}",
            file.display(),
            u.line,
            u.node,
            u.tree
        );
    }
    anyhow::bail!(
        "{} name(s) of the plan do not fit {}",
        problems.len(),
        decls.from
    )
}

/// Runs the plan in `file` on the manager at `address` (its progress kept in this host's
/// `domain`), printing each step with the cycle and the fabric's time; an error when the plan
/// fails.
pub fn run(
    domain: &Domain,
    address: Address,
    file: &Path,
    opts: &RunOptions,
) -> anyhow::Result<()> {
    let plan = read_plan(file)?;
    let tree = opts.tree.as_deref();
    if opts.check {
        // (A tree the plan does not have is refused here too.)
        Sequencer::new(&plan, tree)?;
        return check(&plan, file, tree, &address, opts);
    }
    let store = PlanStore::of(domain);
    // With --replan: the route the plan was planned from, and a plan made again that a runner
    // before this one left running.
    let mut replanner = match &opts.replan {
        Some(r) => {
            let text = std::fs::read_to_string(file)?;
            Some(crate::replan::Replanner::new(r, file, &text)?)
        }
        None => None,
    };
    let kept = match replanner.as_mut() {
        Some(r) if opts.fresh => {
            r.forget();
            None
        }
        Some(r) => r.kept(&store)?,
        None => None,
    };
    let (plan, file) = match kept {
        Some(f) => (read_plan(&f)?, f),
        None => (plan, file.to_path_buf()),
    };
    let name = file.display().to_string();
    let mut seq = Sequencer::kept(&plan, tree, &name, store.clone(), opts.fresh)?;
    let mut client = match &address {
        Address::Remote { .. } => address.connect().map_err(|e| Unfinished(e.into()))?,
        Address::Local(domain) => {
            connect_waiting(domain, &opts.wait_for, opts.wait).map_err(Unfinished)?
        }
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
    loop {
        let ended = skillfab_sequence::run(&mut client, &mut seq, &mut stop, &mut print)
            .map_err(|e| Unfinished(e.into()))?;
        let done = match ended {
            Some(Status::Success) => Some("the plan succeeded"),
            None => Some("halted"),
            Some(_) => None,
        };
        if let Some(done) = done {
            if let Some(r) = &replanner {
                r.forget();
            }
            println!("{done}");
            return Ok(());
        }
        let Some(r) = replanner.as_mut() else {
            anyhow::bail!("the plan failed");
        };
        let live = seq.live();
        let again = match r.after_failure(live.shape(), live.status()) {
            Ok(a) => a,
            Err(e) => {
                r.forget();
                print(&client, &format!("not planned again: {e:#}"));
                // (The last line a plan's runner writes when its plan failed.)
                anyhow::bail!("the plan failed");
            }
        };
        print(
            &client,
            &format!(
                "a step failed with the robot believed to be {}: planned again from there ({} of at most {}), {}",
                again.at,
                r.replans,
                crate::replan::MAX_REPLANS,
                again.file.display()
            ),
        );
        for line in again.planned.route.to_string().lines() {
            print(&client, &format!("  {line}"));
        }
        let plan = read_plan(&again.file)?;
        seq = Sequencer::kept(
            &plan,
            None,
            &again.file.display().to_string(),
            store.clone(),
            false,
        )?;
    }
}
