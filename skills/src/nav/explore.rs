//! `explore`: a systematic search of a room — frontier coverage over an occupancy grid.

use super::*;
use serde::{Deserialize, Serialize};
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};
use std::f64::consts::SQRT_2;

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
    /// Ground nearer than this to an occupied cell costs more to drive through, the nearer
    /// the more (m): paths keep this far from what the ring saw where they can, and to the
    /// middle of a gap narrower than twice this.
    #[param(default = 0.75, min = 0.0, max = 2.0)]
    pub clearance: f64,
    /// Cells within this of an occupied one are not driven through (m): the robot's radius
    /// (0.36 m) and a little. A step through a cell this near costs [`NARROW_COST`] times one
    /// in the open.
    #[param(default = 0.4, min = 0.0, max = 2.0)]
    pub narrow_clearance: f64,
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
/// A step through a cell `narrow_clearance` from an occupied one costs this many times one
/// `clearance` or more from any (the cost grows linearly between them).
pub const NARROW_COST: f64 = 5.0;

type Cell = (i32, i32);

/// Steps from a cell to its neighbours: the four side ones, then the four corner ones (whose
/// length is √2 cells).
const STEPS: [Cell; 8] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (-1, 1),
    (1, -1),
    (-1, -1),
];

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
/// free cell not covered that is cheapest to reach (the frontier of the covered ground): a
/// shortest-path search through free cells more than `narrow_clearance` from occupied ones,
/// stepping to the eight neighbours, where a step costs its length, times up to
/// [`NARROW_COST`] the nearer than `clearance` the cell is to an occupied one — so a path
/// keeps to the middle of a gap, and ground beyond a gap 1.4 m wide is reached at a cost,
/// not only once everything else is covered. The robot follows the path and looks around
/// there. A goal not reached in `give_up_s` (something in the way the ring had not seen) is
/// abandoned and the search goes on from where the robot is. With nothing left to cover,
/// the places looked from are forgotten and the room is covered again. Close obstacles are
/// `avoid`'s (it runs beside, at a higher priority).
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

    /// How far (m, centre to centre) the nearest occupied cell is from `c`, up to `within`.
    fn room(&self, c: Cell, within: f64) -> f64 {
        let n = (within / CELL).ceil() as i32;
        let mut room = within;
        for i in -n..=n {
            for j in -n..=n {
                if self.occupied((c.0 + i, c.1 + j)) {
                    room = room.min(f64::from(i * i + j * j).sqrt() * CELL);
                }
            }
        }
        room
    }

    /// Whether a cell may be driven through: free, and no occupied cell within `clearance`.
    #[cfg(test)]
    fn passable(&self, c: Cell, clearance: f64) -> bool {
        self.free(c) && self.room(c, clearance + CELL) > clearance
    }

    /// The cost of a step of `length` (cells) into `c`: `None` if it may not be driven
    /// through; in thousandths of a cell.
    fn step_cost(&self, c: Cell, length: f64, p: &ExploreParams) -> Option<u64> {
        if !self.free(c) {
            return None;
        }
        let room = self.room(c, p.clearance.max(p.narrow_clearance) + CELL);
        if room <= p.narrow_clearance {
            return None;
        }
        let squeeze = if p.clearance > p.narrow_clearance {
            ((p.clearance - room) / (p.clearance - p.narrow_clearance)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        Some((1000.0 * length * (1.0 + (NARROW_COST - 1.0) * squeeze)).round() as u64)
    }

    /// The path (cells after the robot's, in order) to the passable cell not within `cover`
    /// of a place looked from (nor given up on) that is cheapest to reach; `None` when every
    /// reachable cell is covered.
    fn frontier(&self, from: Cell, p: &ExploreParams) -> Option<Vec<Cell>> {
        let covered = |c: Cell| {
            let (x, y) = centre(c);
            self.looked
                .iter()
                .any(|&(lx, ly)| (x - lx).hypot(y - ly) <= p.cover)
        };
        // Cell → (cost, the cell it is reached from).
        let mut reached: HashMap<Cell, (u64, Cell)> = HashMap::from([(from, (0, from))]);
        let mut queue = BinaryHeap::from([Reverse((0, from))]);
        while let Some(Reverse((cost, c))) = queue.pop() {
            if reached.get(&c).is_some_and(|&(k, _)| k < cost) {
                continue;
            }
            if c != from && !covered(c) && !self.abandoned.contains(&c) {
                let mut path = vec![c];
                let mut at = c;
                while let Some(&(_, up)) = reached.get(&at).filter(|&&(_, up)| up != from) {
                    path.push(up);
                    at = up;
                }
                path.reverse();
                return Some(path);
            }
            for (k, &(i, j)) in STEPS.iter().enumerate() {
                let n = (c.0 + i, c.1 + j);
                let length = if k < 4 { 1.0 } else { SQRT_2 };
                let Some(step) = self.step_cost(n, length, p) else {
                    continue;
                };
                let to = cost + step;
                if reached.get(&n).is_none_or(|&(k, _)| to < k) {
                    reached.insert(n, (to, c));
                    queue.push(Reverse((to, n)));
                }
            }
        }
        None
    }

    /// The next goal from here: the cheapest ground not covered; with none, the room is
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    /// A room of 25 x 11 cells split by a wall two cells thick (columns 10 and 11) with a gap
    /// whose second column is shifted a cell north (as the echoes shift a gap's cells).
    fn split_room() -> Explore {
        room(|i, j| (i == 10 && !(3..=7).contains(&j)) || (i == 11 && !(4..=8).contains(&j)))
    }

    /// A room of 25 x 11 cells, known free but where `wall` says occupied.
    fn room(wall: impl Fn(i32, i32) -> bool) -> Explore {
        let mut e = Explore::default();
        for i in 0..=24 {
            for j in 0..=10 {
                let wall = wall(i, j);
                let evidence = if wall {
                    Evidence {
                        free: 0,
                        occupied: 10,
                    }
                } else {
                    Evidence {
                        free: 10,
                        occupied: 0,
                    }
                };
                e.grid.insert((i, j), evidence);
            }
        }
        e
    }

    fn at(c: Cell) -> Odometry {
        let (x, y) = centre(c);
        Odometry {
            x,
            y,
            ..Odometry::default()
        }
    }

    #[test]
    fn ground_beyond_a_gap_shifted_by_a_cell_is_searched_before_starting_over() {
        let p = ExploreParams::default();
        let mut e = split_room();
        let here = centre((4, 5));
        // Looked around from here: the whole west part is covered (within 3 m).
        e.looked.push(here);
        let Mode::Go { path, .. } = e.next(&at((4, 5)), &p, 0) else {
            panic!("no goal");
        };
        let goal = *path.last().unwrap();
        assert!(goal.0 > 11, "the goal is beyond the wall: {goal:?}");
        assert!(
            path.iter().any(|&(i, j)| i == 10 && (3..=7).contains(&j))
                && path.iter().any(|&(i, j)| i == 11 && (4..=8).contains(&j)),
            "through the gap: {path:?}"
        );
        assert_eq!(e.looked, vec![here], "the covered ground is not forgotten");
    }

    /// A wall across the room (column 10) with a gap 1.5 m wide (j 2-7): the path through it
    /// keeps to its middle (j 4 or 5, 0.5 m or more from either side), and it is taken while
    /// ground on this side is left uncovered farther away (the gap costs less than the way).
    #[test]
    fn a_path_through_a_gap_keeps_to_its_middle_and_the_gap_does_not_wait_for_the_rest() {
        let p = ExploreParams::default();
        let mut e = room(|i, j| i == 10 && !(2..=7).contains(&j));
        e.looked.push(centre((6, 5)));
        // Beyond the gap (column 14, 2 m from it) is nearer than this side's uncovered ground
        // (column 0 and below, more than 3 m from where it looked).
        let Mode::Go { path, .. } = e.next(&at((7, 5)), &p, 0) else {
            panic!("no goal");
        };
        assert!(path.last().unwrap().0 > 10, "beyond the gap: {path:?}");
        let through: Vec<i32> = path.iter().filter(|c| c.0 == 10).map(|c| c.1).collect();
        assert!(
            !through.is_empty() && through.iter().all(|j| (4..=5).contains(j)),
            "through the middle: {path:?}"
        );
    }

    #[test]
    fn ground_beyond_a_gap_only_the_narrow_clearance_opens_is_searched_before_starting_over() {
        let p = ExploreParams::default();
        // A wall one cell thick (column 10), its gap four cells wide (j 3-6, 1 m): nothing
        // in it is passable at `clearance`, (10, 4) and (10, 5) are at `narrow_clearance`.
        let mut e = room(|i, j| i == 10 && !(3..=6).contains(&j));
        let here = centre((4, 5));
        e.looked.push(here);
        assert!(!(0..=10).any(|j| e.passable((10, j), 0.5)));
        assert!(e.passable((10, 4), p.narrow_clearance));
        let Mode::Go { path, .. } = e.next(&at((4, 5)), &p, 0) else {
            panic!("no goal");
        };
        assert!(path.last().unwrap().0 > 10, "beyond the wall: {path:?}");
        assert_eq!(e.looked, vec![here], "the covered ground is not forgotten");
    }

    #[test]
    fn with_nothing_left_beyond_either_the_search_starts_over() {
        let p = ExploreParams::default();
        let mut e = split_room();
        // Looked from both sides: every cell is covered.
        e.looked.extend([centre((4, 5)), centre((18, 5))]);
        assert!(matches!(e.next(&at((4, 5)), &p, 0), Mode::Go { .. }));
        assert!(e.looked.is_empty(), "the places looked from are forgotten");
    }
}
