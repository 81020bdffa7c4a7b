//! `skillfab sequence --replan MAP`: a planner's plan whose runner plans again when a step
//! fails. The route's tree says, for each of its steps, where the robot is believed to be if
//! that step fails ([`Route::believed`]); the runner reads which step failed in the plan's
//! live tree, says where the robot is believed to be, and runs the plan the planner makes
//! from there ([`Route::replanned`]), written beside the plan file as
//! `NAME.replanned-from-PLACE.xml`. A runner that dies while a plan planned again runs is
//! started again on the first plan's file: it finds the plan planned again kept for it and
//! resumes that one (docs/maps.md, "Planning again").

use crate::plan::{self, Place, Planned};
use anyhow::Context;
use skillfab_planner::{Believed, From, Map, Route};
use skillfab_proto::control::{NodeStatus, PlanNode};
use skillfab_sequence::{Kept, PlanStore};
use std::path::{Path, PathBuf};

/// At most this many plans made again in one run of a plan.
pub const MAX_REPLANS: u32 = 3;

/// What the runner plans again from: the route's map, destination, trip and library (those
/// the plan file was planned with: `skillfab plan --map MAP [--to ROOM] [--and-back]`).
#[derive(Debug, Clone)]
pub struct Replanning {
    /// The route map.
    pub map: PathBuf,
    /// The room (default: the map's office).
    pub to: Option<u32>,
    /// To the room and back to the lab.
    pub and_back: bool,
    /// The subtrees the plan is built from.
    pub library: PathBuf,
}

/// The route being run, and how to plan again from where one of its steps fails.
pub struct Replanner {
    map: Map,
    args: Replanning,
    /// The plan file the runner was given (the first route's).
    file: PathBuf,
    /// The first route (its destination and trip are every plan's).
    first: Route,
    /// The route of the plan running now.
    route: Route,
    /// Plans made again so far.
    pub replans: u32,
}

/// A plan made again: where from, its route, and its file.
pub struct Replanned {
    /// Where the robot is believed to be.
    pub at: Believed,
    /// The new route and its plan.
    pub planned: Planned,
    /// The file it is written to.
    pub file: PathBuf,
}

/// The text of a plan after its leading comment (the route in words, the map's path).
fn body(xml: &str) -> &str {
    xml.find("<root").map_or(xml, |i| &xml[i..])
}

impl Replanner {
    /// The planner's route for `args` from the lab, checked to be the one `file` (text
    /// `text`) was planned from: the same tree, node for node.
    pub fn new(args: &Replanning, file: &Path, text: &str) -> anyhow::Result<Replanner> {
        let trip = plan::Trip {
            from: Place::Lab,
            to: args.to.map(Place::Room),
            and_back: args.and_back,
        };
        let planned = plan::plan(&args.map, trip, &args.library)
            .with_context(|| format!("--replan: planning on {}", args.map.display()))?;
        if body(&planned.xml) != body(text) {
            anyhow::bail!(
                "--replan: {} is not the plan `skillfab plan --map {}{}{}` writes with {}: the runner could not say where a failed step leaves the robot",
                file.display(),
                args.map.display(),
                args.to.map(|r| format!(" --to {r}")).unwrap_or_default(),
                if args.and_back { " --and-back" } else { "" },
                args.library.display()
            );
        }
        Ok(Replanner {
            map: skillfab_planner::Map::load(&args.map)?,
            args: args.clone(),
            file: file.to_path_buf(),
            first: planned.route.clone(),
            route: planned.route,
            replans: 0,
        })
    }

    /// The file a plan made again from `at` is written to, beside the first plan's.
    fn file_for(&self, at: Believed) -> PathBuf {
        let stem = self
            .file
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let place = at.at.to_string().replace(':', "-");
        let back = if at.back { "-back" } else { "" };
        self.file
            .with_file_name(format!("{stem}.replanned-from-{place}{back}.xml"))
    }

    /// Where a file of [`Replanner::file_for`] says the robot was believed to be.
    fn believed_from_file(&self, file: &Path) -> Option<Believed> {
        if file.parent() != self.file.parent() {
            return None;
        }
        let stem = self.file.file_stem()?.to_string_lossy().into_owned();
        let name = file.file_name()?.to_string_lossy().into_owned();
        let rest = name
            .strip_prefix(&format!("{stem}.replanned-from-"))?
            .strip_suffix(".xml")?;
        let (place, back) = match rest.strip_suffix("-back") {
            Some(p) => (p, true),
            None => (rest, false),
        };
        let at: From = place.replacen('-', ":", 1).parse().ok()?;
        Some(Believed { at, back })
    }

    /// A plan made again that a runner before this one was running: the one its kept state
    /// (in `store`) names, or, nothing being kept, the newest plan made again beside the
    /// plan file (a runner killed after its plan failed and before the plan made again was
    /// first kept; the files are removed when a plan ends, [`Replanner::forget`]). It is run
    /// instead of the first plan.
    pub fn kept(&mut self, store: &PlanStore) -> anyhow::Result<Option<PathBuf>> {
        let file = match store.load() {
            Kept::State(state) => PathBuf::from(&state.file),
            Kept::Nothing => match self.made_again().into_iter().max_by_key(|(t, _)| *t) {
                Some((_, f)) => f,
                None => return Ok(None),
            },
            Kept::Unreadable(_) => return Ok(None),
        };
        let Some(at) = self.believed_from_file(&file).filter(|_| file.is_file()) else {
            return Ok(None);
        };
        self.route = self.first.replanned(&self.map, at)?;
        self.replans = 1;
        Ok(Some(file))
    }

    /// The plans made again beside the plan file, with when each was written.
    fn made_again(&self) -> Vec<(std::time::SystemTime, PathBuf)> {
        let Some(dir) = self.file.parent() else {
            return Vec::new();
        };
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        let Ok(entries) = std::fs::read_dir(dir) else {
            return Vec::new();
        };
        entries
            .flatten()
            .map(|e| self.file.with_file_name(e.file_name()))
            .filter(|f| self.believed_from_file(f).is_some())
            .filter_map(|f| Some((std::fs::metadata(&f).ok()?.modified().ok()?, f)))
            .collect()
    }

    /// The plan ended (or starts over, `--fresh`): the plans made again are removed, so a
    /// runner started on the plan file later starts it from its first node.
    pub fn forget(&self) {
        for (_, f) in self.made_again() {
            let _ = std::fs::remove_file(f);
        }
    }

    /// The plan failed with its live tree's statuses (`shape` and `status`, as
    /// [`LiveTree`] has them): where its failed step leaves the robot, and the plan from
    /// there, written to its file. `Err` when the failed step is not one the plan goes on
    /// from, or no more plans are made again.
    pub fn after_failure(
        &mut self,
        shape: &[PlanNode],
        status: &[NodeStatus],
    ) -> anyhow::Result<Replanned> {
        // The route's tree's `Sequence` is node 0; its children are the route's nodes.
        let children: Vec<usize> = shape
            .iter()
            .enumerate()
            .filter(|(_, n)| n.parent == Some(0))
            .map(|(i, _)| i)
            .collect();
        let Some(k) = children
            .iter()
            .position(|&i| status.get(i) == Some(&NodeStatus::Failure))
        else {
            anyhow::bail!("the plan failed, and no step of its route is marked failed");
        };
        let node = &shape[children[k]];
        let step = self.route.node_steps()?.get(k).copied().unwrap_or(0);
        let words = self
            .route
            .steps
            .get(step)
            .map(ToString::to_string)
            .unwrap_or_default();
        let believed = self.route.believed()?;
        let Some(at) = believed.get(k).copied().flatten() else {
            anyhow::bail!(
                "step {} of the route ({words}) failed, in its node '{}': the planner does not plan on from there",
                step + 1,
                node.name
            );
        };
        if self.replans >= MAX_REPLANS {
            anyhow::bail!(
                "the plan failed at '{}' with the robot {at}, after {MAX_REPLANS} plans made again",
                node.name
            );
        }
        let route = self.first.replanned(&self.map, at)?;
        let planned = plan::written(route, &self.args.map, &self.args.library)?;
        let file = self.file_for(at);
        let aside = file.with_extension("xml.new");
        std::fs::write(&aside, &planned.xml)
            .and_then(|()| std::fs::rename(&aside, &file))
            .with_context(|| format!("writing {}", file.display()))?;
        self.route = planned.route.clone();
        self.replans += 1;
        Ok(Replanned { at, planned, file })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]

    use super::*;

    fn repo() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
    }

    fn replanner(dir: &Path, and_back: bool) -> Replanner {
        replanner_on(dir, "building-a", 405, and_back)
    }

    fn replanner_on(dir: &Path, building: &str, room: u32, and_back: bool) -> Replanner {
        let args = Replanning {
            map: repo().join(format!("devices/denning-sim/buildings/{building}.map.toml")),
            to: Some(room),
            and_back,
            library: repo().join("skills/plans/deliver.xml"),
        };
        let trip = plan::Trip {
            from: Place::Lab,
            to: Some(Place::Room(room)),
            and_back,
        };
        let p = plan::plan(&args.map, trip, &args.library).unwrap();
        let file = dir.join("plan.xml");
        std::fs::write(&file, &p.xml).unwrap();
        Replanner::new(&args, &file, &p.xml).unwrap()
    }

    /// The live tree of the plan in `file` with its `n`-th route node failed (the others
    /// before it succeeded).
    fn failed_at(r: &Replanner, file: &Path, n: usize) -> (Vec<PlanNode>, Vec<NodeStatus>) {
        let plan = crate::sequence::read_plan(file).unwrap();
        let seq = skillfab_sequence::Sequencer::new(&plan, None).unwrap();
        let shape = seq.live().shape().to_vec();
        let children: Vec<usize> = (0..shape.len())
            .filter(|&i| shape[i].parent == Some(0))
            .collect();
        assert_eq!(children.len(), r.route.believed().unwrap().len());
        let mut status = vec![NodeStatus::Idle; shape.len()];
        for &c in &children[..n] {
            status[c] = NodeStatus::Success;
        }
        status[children[n]] = NodeStatus::Failure;
        status[0] = NodeStatus::Failure;
        (shape, status)
    }

    /// The nodes whose failure leaves the robot at a place `kept` keeps.
    fn nodes_at(believed: &[Option<Believed>], kept: fn(&From) -> bool) -> Vec<usize> {
        (0..believed.len())
            .filter(|&i| believed[i].is_some_and(|b| kept(&b.at)))
            .collect()
    }

    #[test]
    fn a_car_that_does_not_come_is_planned_on_from_its_lobby_and_the_plan_is_kept_by_name() {
        let dir = std::env::temp_dir().join(format!("sf-replan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut r = replanner(&dir, true);
        let believed = r.route.believed().unwrap();
        let boards = |b: &[Option<Believed>]| nodes_at(b, |at| matches!(at, From::Lobby { .. }));
        let board = boards(&believed);
        // Building A's round trip rides twice: up from floor 0, down from floor 4.
        assert_eq!(board.len(), 2);
        let first = dir.join("plan.xml");
        let (shape, status) = failed_at(&r, &first, board[0]);
        let again = r.after_failure(&shape, &status).unwrap();
        assert_eq!(
            again.at,
            Believed {
                at: From::Lobby { floor: 0 },
                back: false
            }
        );
        assert_eq!(again.file, dir.join("plan.replanned-from-lobby-0.xml"));
        assert!(again.planned.xml.contains("<SubTree ID=\"InALobby\"/>"));
        // Still the round trip: the way back is in it, and its own car's step too.
        assert_eq!(again.planned.route.trip, skillfab_planner::Trip::RoundTrip);
        let believed = again.planned.route.believed().unwrap();
        assert_eq!(boards(&believed).len(), 2);
        // On the way back, a car that does not come on floor 4: back to the lab from there.
        let down = boards(&believed)[1];
        let (shape, status) = failed_at(&r, &again.file, down);
        let back = r.after_failure(&shape, &status).unwrap();
        assert_eq!(
            back.at,
            Believed {
                at: From::Lobby { floor: 4 },
                back: true
            }
        );
        assert_eq!(
            back.planned.route.trip,
            skillfab_planner::Trip::BackToTheLab
        );
        assert!(matches!(
            back.planned.route.steps.last(),
            Some(skillfab_planner::Step::AtTheLab { .. })
        ));
        // The name says where from: a runner started again finds the route.
        assert_eq!(r.believed_from_file(&back.file), Some(back.at));
        assert_eq!(r.believed_from_file(&dir.join("other.xml")), None);
        // A step the plan does not go on from fails the plan, saying which.
        let (shape, status) = failed_at(&r, &back.file, 0);
        let e = r.after_failure(&shape, &status).err().unwrap().to_string();
        assert!(e.contains("does not plan on from there"), "{e}");
        assert!(
            e.starts_with("step 1 of the route (a car from floor 4 to floor 0)"),
            "{e}"
        );
        // A runner killed before the plan made again was first kept: nothing kept, the
        // newest plan made again is run. Once the plan ended they are gone.
        let mut next = replanner(&dir, true);
        let store = PlanStore::at(dir.join("state"));
        let newest = std::fs::File::options()
            .append(true)
            .open(&back.file)
            .unwrap();
        newest
            .set_modified(std::time::SystemTime::now() + std::time::Duration::from_secs(1))
            .unwrap();
        assert_eq!(next.kept(&store).unwrap(), Some(back.file.clone()));
        assert_eq!(next.route.trip, skillfab_planner::Trip::BackToTheLab);
        next.forget();
        assert!(!back.file.exists() && !again.file.exists() && first.exists());
        let mut last = replanner(&dir, true);
        assert_eq!(last.kept(&store).unwrap(), None);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Building A's ride up: its tries all failed (a car stopped between floors), the robot is
    /// in the car; the plan from there rides again without boarding, and its file says so.
    #[test]
    fn a_ride_that_fails_is_planned_on_from_the_car() {
        let dir = std::env::temp_dir().join(format!("sf-replan-car-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut r = replanner(&dir, true);
        let believed = r.route.believed().unwrap();
        let ride = nodes_at(&believed, |at| matches!(at, From::Car { .. }))[0];
        let (shape, status) = failed_at(&r, &dir.join("plan.xml"), ride);
        let again = r.after_failure(&shape, &status).unwrap();
        assert_eq!(
            again.at,
            Believed {
                at: From::Car { floor: 0 },
                back: false
            }
        );
        assert_eq!(again.at.to_string(), "in a car boarded on floor 0");
        assert_eq!(again.file, dir.join("plan.replanned-from-car-0.xml"));
        assert_eq!(r.believed_from_file(&again.file), Some(again.at));
        assert!(again.planned.xml.contains("<SubTree ID=\"InACar\"/>"));
        assert_eq!(
            again.planned.route.steps[0].to_string(),
            "a car from floor 0 to floor 4"
        );
        assert_eq!(again.planned.route.trip, skillfab_planner::Trip::RoundTrip);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Building E: 'the crossing: left' counted at a door before it, the robot went straight
    /// on into the east arm and stopped at its end; the wait for 407's sign fails there.
    #[test]
    fn a_missed_turn_is_planned_on_from_the_dead_end_straight_on() {
        let dir = std::env::temp_dir().join(format!("sf-replan-end-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut r = replanner_on(&dir, "heldout/building-e", 407, false);
        let believed = r.route.believed().unwrap();
        let office = (0..believed.len())
            .rfind(|&i| believed[i].is_some())
            .unwrap();
        let (shape, status) = failed_at(&r, &dir.join("plan.xml"), office);
        let again = r.after_failure(&shape, &status).unwrap();
        let east = r
            .map
            .legs
            .iter()
            .position(|l| l.name == "the east arm")
            .unwrap();
        assert_eq!(
            again.at,
            Believed {
                at: From::DeadEnd { leg: east },
                back: false
            }
        );
        assert_eq!(
            again.at.to_string(),
            format!("at the dead end of the map's leg {}", east + 1)
        );
        assert_eq!(
            again.file,
            dir.join(format!("plan.replanned-from-end-{}.xml", east + 1))
        );
        assert_eq!(r.believed_from_file(&again.file), Some(again.at));
        assert!(again.planned.xml.contains("<SubTree ID=\"AtADeadEnd\"/>"));
        assert_eq!(
            again.planned.route.steps[0].to_string(),
            "turned round at the end of 'the east arm'"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_plan_file_that_is_not_the_planners_route_is_refused() {
        let dir = std::env::temp_dir().join(format!("sf-replan-x-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let r = replanner(&dir, false);
        let other = plan::plan(
            &r.args.map,
            plan::Trip {
                from: Place::Lab,
                to: Some(Place::Room(403)),
                and_back: false,
            },
            &r.args.library,
        )
        .unwrap();
        let e = Replanner::new(&r.args, &dir.join("plan.xml"), &other.xml)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("is not the plan"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
