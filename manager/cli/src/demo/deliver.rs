//! `skillfab demo deliver`: the planner's plan from the building's route map (or a tree of a
//! plan file, as written), run on the building with the judge's goal at the room's door.

use anyhow::Context;
use std::path::{Path, PathBuf};

use crate::{DemoRuns, FaultArgs, plan, report, sequence};

/// `skillfab demo deliver`'s options.
#[derive(clap::Args, Debug)]
pub(crate) struct DeliverArgs {
    /// Building file.
    #[arg(long, default_value = "devices/denning-sim/buildings/building-a.toml")]
    building: PathBuf,
    /// The building's route map the planner plans on (default: beside the building
    /// file, NAME.map.toml; docs/maps.md).
    #[arg(long, value_name = "FILE.map.toml")]
    map: Option<PathBuf>,
    /// The room to take the message to (default: the map's office). The judge's goal
    /// moves to that room's door.
    #[arg(long, value_name = "ROOM")]
    to: Option<u32>,
    /// Then back to the lab: the planner's round trip, judged as the message delivered and
    /// the plan ended with the robot in front of the lab's door (the simulator's `at_lab`).
    #[arg(long, conflicts_with = "tree")]
    and_back: bool,
    /// The subtrees the planner builds the plan from (docs/sequence.md); with --tree, the
    /// plan to run.
    #[arg(
        long,
        value_name = "FILE.xml",
        default_value = "skills/plans/deliver.xml"
    )]
    plan: PathBuf,
    /// Run this tree of --plan as it is written, not the planner's (e.g. the routes
    /// written by hand before the planner: manager/planner/tests/fixtures/hand-written.xml).
    #[arg(long)]
    tree: Option<String>,
    #[command(flatten)]
    run: DemoRuns,
    /// Do not plan again when a step fails (the planner's plan runs once, as written).
    #[arg(long, conflicts_with = "tree")]
    no_replan: bool,
    /// Simulated seconds before a run counts as failed (20 minutes).
    #[arg(long, default_value_t = 1200.0)]
    limit_s: f64,
    #[command(flatten)]
    faults: FaultArgs,
}

/// Runs `skillfab demo deliver`. The planner's plan and a building whose goal is another room
/// live in a directory of their own while the runs last (each run copies the plan into its
/// own directory).
pub(crate) fn run(args: DeliverArgs) -> anyhow::Result<()> {
    let work = std::env::temp_dir().join(format!("skillfab-deliver-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    let delivered = deliver(args, &work);
    let _ = std::fs::remove_dir_all(&work);
    delivered
}

/// `skillfab demo deliver`: the planner's plan to the room (or a tree of a plan file, as
/// written), the judge's goal at that room; `work` holds the files this writes.
fn deliver(args: DeliverArgs, work: &Path) -> anyhow::Result<()> {
    let DeliverArgs {
        building,
        map,
        to,
        and_back,
        plan,
        tree,
        no_replan,
        run,
        limit_s,
        faults,
    } = args;
    let json = run.json;
    let mut replan = None;
    let (plan, room) = match &tree {
        Some(_) => {
            sequence::read_plan(&plan)?;
            (plan, to)
        }
        None => {
            // The runner plans again with the same map and library, from the run's directory.
            let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
            let map = map.unwrap_or_else(|| skillfab_planner::map_beside(&building));
            let trip = plan::Trip {
                from: plan::Place::Lab,
                to: to.map(plan::Place::Room),
                and_back,
            };
            let p = plan::plan(&map, trip, &plan)
                .with_context(|| format!("planning on {}", map.display()))?;
            if !json {
                println!("{}", p.route);
            }
            let file = work.join(format!("{}.xml", p.route.tree_id()));
            std::fs::write(&file, &p.xml)?;
            if !no_replan {
                replan = Some(skillfab_manager::launch::ReplanSection {
                    map: absolute(&map).to_string_lossy().into_owned(),
                    to,
                    and_back,
                    library: absolute(&plan).to_string_lossy().into_owned(),
                });
            }
            (file, Some(p.route.room))
        }
    };
    let site = match room {
        Some(r) => plan::building_for_room(&building, r, work)?,
        None => None,
    }
    .unwrap_or(building);
    let mut opts = run.options(super::Site::Building(site), plan, limit_s)?;
    opts.faults = faults.faults(opts.lockstep, opts.seed)?;
    opts.tree = tree;
    opts.and_back = and_back;
    opts.replan = replan;
    let summary = super::demo(&opts)?;
    if and_back {
        report(
            &summary,
            json,
            "delivered the message and came back to the lab",
        )?;
        if summary.successes == 0 {
            anyhow::bail!("the robot did not deliver the message and come back");
        }
        return Ok(());
    }
    report(&summary, json, "delivered the message")?;
    if summary.successes == 0 {
        anyhow::bail!("the robot did not deliver the message");
    }
    Ok(())
}
