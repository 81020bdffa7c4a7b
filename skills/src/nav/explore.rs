//! `explore`: a systematic search of a room — frontier coverage over an occupancy grid.

use super::*;
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, VecDeque};

/// Parameters of [`Explore`].
#[derive(Params, Debug, Clone)]
pub struct ExploreParams {
    /// Forward speed (m/s).
    #[param(default = 0.35, min = 0.0, max = 1.0)]
    pub speed: f64,
    /// Largest turn rate (rad/s); looking around turns at this rate.
    #[param(default = 0.8, min = 0.1, max = 2.0)]
    pub turn: f64,
    /// Ground within this of a place it looked around from counts as covered (m). The camera
    /// sees 6 m: looking around from within 3 m of every free cell, every wall is seen
    /// from 3 m or so (nearer ground hides less behind boxes).
    #[param(default = 3.0, min = 0.5, max = 10.0)]
    pub cover: f64,
    /// Cells within this of an occupied one are not driven through (m): the robot's radius
    /// and a margin.
    #[param(default = 0.5, min = 0.0, max = 2.0)]
    pub clearance: f64,
    /// A goal not reached in this long is given up (s of fabric time).
    #[param(default = 30.0, min = 1.0, max = 600.0)]
    pub give_up_s: f64,
}

/// Inputs of [`Explore`].
#[derive(Inputs)]
pub struct ExploreIn<'a> {
    /// The ring.
    pub sonar: Input<'a, Sonar>,
    /// Odometry (the grid is held in its frame).
    pub odometry: Input<'a, Odometry>,
}

/// Cell size of the grid (m).
const CELL: f64 = 0.25;
/// Sonar readings mark free ground up to this far (m from the centre): farther, a cone is
/// too wide to say which cells it crossed.
const FREE_MAX: f64 = 3.5;
/// Readings shorter than this (m, from the ring) also mark the cell they echo from occupied.
const OCCUPIED_MAX: f64 = 3.0;
/// A goal is reached within this (m).
const REACHED: f64 = 0.35;
/// The waypoint followed is this far along the path (cells).
const LOOKAHEAD: usize = 4;

type Cell = (i32, i32);

fn cell(x: f64, y: f64) -> Cell {
    ((x / CELL).floor() as i32, (y / CELL).floor() as i32)
}

fn centre(c: Cell) -> (f64, f64) {
    ((f64::from(c.0) + 0.5) * CELL, (f64::from(c.1) + 0.5) * CELL)
}

/// Evidence for one cell: rays that crossed it, echoes from it.
#[derive(Debug, Default, Clone, Copy, Serialize, Deserialize)]
struct Evidence {
    free: u16,
    occupied: u16,
}

/// What it is doing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
enum Mode {
    /// Turning once round on the spot (rad still to turn), the camera sweeping the room.
    Look { left: f64 },
    /// Driving along a path (cells, from the robot) to a place to look from, since a cycle.
    Go { path: Vec<Cell>, since: u64 },
}

/// A systematic search for something the camera must see (a door's barcode): look around
/// on the spot, then go to the nearest place not yet covered and look around again, until
/// the room is covered.
///
/// The ring builds an occupancy grid in the odometry frame (0.25 m cells: each new reading
/// marks the cells along its axis free, up to 3.5 m, and the cell it echoes from occupied).
/// Ground within `cover` of a place it looked around from is covered. The next goal is the
/// nearest free cell that is not covered, by a breadth-first search through free cells kept
/// `clearance` from occupied ones (the frontier of the covered ground); the robot follows
/// the path and looks around there. A goal not reached in `give_up_s` (something in the way
/// the ring had not seen) is abandoned and the search goes on from where the robot is. With
/// nothing left to cover, the places looked from are forgotten and the room is covered
/// again. Close obstacles are `avoid`'s (it runs beside, at a higher priority).
///
/// Unlike `wander`, which draws legs through the least visited ground, every part of a
/// closed room is looked at from within `cover` after a bounded drive, whatever the seed.
#[derive(Default, Serialize, Deserialize)]
pub struct Explore {
    activation: Activation,
    grid: HashMap<Cell, Evidence>,
    /// Places it looked around from (odometry frame).
    looked: Vec<(f64, f64)>,
    mode: Option<Mode>,
    /// Per sonar: the age of the reading last used (a smaller one is a new reading).
    ages: [f64; SONARS],
    /// Heading last cycle (turning is measured from it).
    last_theta: Option<f64>,
    /// Goals given up on (not chosen again until the room has been covered).
    abandoned: Vec<Cell>,
}

impl Explore {
    fn free(&self, c: Cell) -> bool {
        self.grid
            .get(&c)
            .is_some_and(|e| u32::from(e.free) > 2 * u32::from(e.occupied))
    }

    fn occupied(&self, c: Cell) -> bool {
        self.grid
            .get(&c)
            .is_some_and(|e| e.occupied > 0 && 2 * u32::from(e.occupied) >= u32::from(e.free))
    }

    /// Takes in the ring's new readings.
    fn map(&mut self, s: &Sonar, od: &Odometry) {
        for k in 0..SONARS {
            let age = s.age_ms[k];
            let new = age < self.ages[k];
            self.ages[k] = age;
            let Some(r) = range(s, k).filter(|_| new) else {
                continue;
            };
            let a = od.theta + sonar_angle(k);
            let (c, sn) = (a.cos(), a.sin());
            let hit = r + RING;
            let free_to = (hit - CELL).min(FREE_MAX);
            // The cell `d` along the sonar's axis.
            let along = |d: f64| cell(od.x + d * c, od.y + d * sn);
            // From the centre: the robot's own ground is free.
            let mut d = 0.0;
            while d < free_to {
                let e = self.grid.entry(along(d)).or_default();
                e.free = e.free.saturating_add(1);
                d += CELL / 2.0;
            }
            if r < OCCUPIED_MAX {
                let e = self.grid.entry(along(hit)).or_default();
                e.occupied = e.occupied.saturating_add(2);
            }
        }
    }

    /// Whether a cell may be driven through: free, and no occupied cell within `clearance`.
    fn passable(&self, c: Cell, clearance: f64) -> bool {
        let n = (clearance / CELL).ceil() as i32;
        self.free(c)
            && (-n..=n).all(|i| {
                (-n..=n).all(|j| {
                    f64::from(i * i + j * j).sqrt() * CELL > clearance
                        || !self.occupied((c.0 + i, c.1 + j))
                })
            })
    }

    /// The path (cells after the robot's, in order) to the nearest passable cell not within
    /// `cover` of a place looked from; `None` when every reachable cell is covered.
    fn frontier(&self, from: Cell, p: &ExploreParams) -> Option<Vec<Cell>> {
        let covered = |c: Cell| {
            let (x, y) = centre(c);
            self.looked
                .iter()
                .any(|&(lx, ly)| (x - lx).hypot(y - ly) <= p.cover)
        };
        let mut parent: HashMap<Cell, Cell> = HashMap::new();
        let mut queue = VecDeque::from([from]);
        parent.insert(from, from);
        while let Some(c) = queue.pop_front() {
            if c != from && !covered(c) && !self.abandoned.contains(&c) {
                let mut path = vec![c];
                let mut at = c;
                while let Some(&up) = parent.get(&at).filter(|&&up| up != from) {
                    path.push(up);
                    at = up;
                }
                path.reverse();
                return Some(path);
            }
            for (i, j) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                let n = (c.0 + i, c.1 + j);
                if !parent.contains_key(&n) && self.passable(n, p.clearance) {
                    parent.insert(n, c);
                    queue.push_back(n);
                }
            }
        }
        None
    }

    /// The next goal from here: the nearest ground not covered; with none, the room is
    /// covered: start over (forget the places looked from and the goals given up).
    fn next(&mut self, od: &Odometry, p: &ExploreParams, cycle: u64) -> Mode {
        let from = cell(od.x, od.y);
        let path = self.frontier(from, p).or_else(|| {
            self.looked.clear();
            self.abandoned.clear();
            self.frontier(from, p)
        });
        match path {
            Some(path) => Mode::Go { path, since: cycle },
            // Nothing passable known around (hemmed in, or no readings yet): look again.
            None => Mode::Look { left: TAU },
        }
    }
}

impl Skill for Explore {
    type Params = ExploreParams;
    type Inputs<'a> = ExploreIn<'a>;
    type Outputs<'a> = DriveOut<'a>;
    const STATE: State<Self> = State::kept(1);
    const PRIORITY: i32 = 2;
    fn compute(&mut self, ctx: &Ctx<ExploreParams>, i: ExploreIn, o: &mut DriveOut) -> SkillResult {
        let (p, s, od) = (ctx.params, &*i.sonar, &*i.odometry);
        if self.activation.begins(ctx) {
            // The grid stays (the room is the same); the search starts with a look round.
            self.mode = None;
            self.last_theta = None;
            self.ages = [f64::INFINITY; SONARS];
        }
        self.map(s, od);
        let turned = self
            .last_theta
            .replace(od.theta)
            .map_or(0.0, |t| wrap(od.theta - t).abs());
        let period_s = period_ms(ctx) / 1000.0;
        let mode = match self.mode.take() {
            None => Mode::Look { left: TAU },
            Some(Mode::Look { left }) if left - turned <= 0.0 => {
                self.looked.push((od.x, od.y));
                self.next(od, p, ctx.cycle)
            }
            Some(Mode::Look { left }) => Mode::Look {
                left: left - turned,
            },
            Some(Mode::Go { path, since }) => {
                let goal = path.last().map(|&c| centre(c));
                let late = (ctx.cycle - since) as f64 * period_s > p.give_up_s;
                match goal {
                    Some((gx, gy)) if (od.x - gx).hypot(od.y - gy) < REACHED => {
                        Mode::Look { left: TAU }
                    }
                    Some(_) if late => {
                        self.abandoned.extend(path.last());
                        self.next(od, p, ctx.cycle)
                    }
                    Some(_) => Mode::Go { path, since },
                    None => self.next(od, p, ctx.cycle),
                }
            }
        };
        let drive = match &mode {
            Mode::Look { .. } => Drive {
                translate: 0.0,
                rotate: p.turn,
            },
            Mode::Go { path, .. } => {
                // The waypoint: the path cell LOOKAHEAD on from the nearest one.
                let here = (od.x, od.y);
                let near = path
                    .iter()
                    .enumerate()
                    .min_by(|a, b| {
                        let (ax, ay) = centre(*a.1);
                        let (bx, by) = centre(*b.1);
                        (ax - here.0)
                            .hypot(ay - here.1)
                            .total_cmp(&(bx - here.0).hypot(by - here.1))
                    })
                    .map_or(0, |(k, _)| k);
                let (wx, wy) = centre(path[(near + LOOKAHEAD).min(path.len() - 1)]);
                let err = wrap((wy - od.y).atan2(wx - od.x) - od.theta);
                Drive {
                    translate: if err.abs() < 0.8 {
                        p.speed * err.cos().powi(2)
                    } else {
                        0.0
                    },
                    rotate: (2.0 * err).clamp(-p.turn, p.turn),
                }
            }
        };
        self.mode = Some(mode);
        o.drive.set(drive);
        Ok(())
    }
}
