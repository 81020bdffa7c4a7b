//! A building in use: the floor the robot is on, the car it is in, the cars, and what the
//! robot's body and sensors meet there — the segments and barcodes of its floor and of the
//! cars in sight — rebuilt only when something in sight changed (a door moved, a car came or
//! went, the robot changed floors), so a step in a corridor costs what it costs in a world.
//!
//! On floor f the robot meets the floor's walls and boxes; each car's doorway, shut unless the
//! car is at f, where its leaves are as open as its doors and its cabin's walls stand behind.
//! It sees the floor's signs, the call button, the lanterns of the cars at f with their doors
//! not fully closed, and the panels and indicators of the cars at f. Riding a car between
//! floors it meets and sees only that car: cabin walls, closed doors, panel, indicator.
//!
//! The robot is inside car k when its centre is in the cabin; the car then carries it: the
//! robot's floor is the car's whenever the car is at a floor.

use crate::building::{Building, CALL, CarLayout, INDICATOR, LANTERN, MAX_CARS, PANEL};
use crate::elevator::{Bank, Doors, Rider};
use crate::sim::Rng;
use crate::world::{Barcode, P, Segment, World};

/// What a barcode in the robot's surroundings is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mark {
    /// A sign: the lab door's, a room number.
    Sign,
    /// The hall call button.
    Call,
    /// A car's hall lantern (0-based car).
    Lantern(usize),
    /// A car's panel button.
    Panel {
        /// The car (0-based).
        car: usize,
        /// The floor it asks for.
        floor: i32,
    },
    /// A car's floor indicator (0-based car).
    Indicator(usize),
}

impl Mark {
    /// Whether the pusher can press it.
    pub fn is_button(self) -> bool {
        matches!(self, Mark::Call | Mark::Panel { .. })
    }
}

/// How a car looks from where the robot is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum CarView {
    /// Not there at all: the robot rides another car between floors.
    Hidden,
    /// Elsewhere: its doorway on the robot's floor is shut.
    Shut,
    /// Here, or carrying the robot.
    Present {
        /// Door open fraction.
        open: f64,
        /// Whether its lantern is lit.
        lit: bool,
        /// The floor its indicator shows.
        shows: i32,
    },
}

/// Everything the segments and barcodes are built from.
#[derive(Debug, Clone, Copy, PartialEq)]
struct View {
    /// The floor in sight (`None`: riding between floors).
    floor: Option<i32>,
    cars: [CarView; MAX_CARS],
}

/// A building with the robot in it.
#[derive(Debug, Clone)]
pub struct Site {
    building: Building,
    layouts: Vec<CarLayout>,
    /// Each floor's walls and boxes, by level: they never change.
    fixed: Vec<Vec<Segment>>,
    bank: Bank,
    /// The robot's floor (while it rides between floors: the one it left).
    floor: i32,
    /// The car the robot is inside.
    inside: Option<usize>,
    /// What the surroundings were last built from (`None`: never built).
    view: Option<View>,
    /// The floor whose world the simulator holds.
    world_floor: i32,
}

impl Site {
    /// The robot on the start floor of `building` (checked by [`Building::parse`]), the cars
    /// placed with `rng`.
    pub fn new(building: Building, rng: Rng) -> Site {
        let n = building.floors.len();
        let fixed = (0..n as i32)
            .map(|l| building.world(l).map(|w| w.segments()).unwrap_or_default())
            .collect();
        Site {
            layouts: building.layouts(),
            fixed,
            bank: Bank::new(&building.elevator, n, rng),
            floor: building.start_floor.clamp(0, n.saturating_sub(1) as i32),
            inside: None,
            view: None,
            world_floor: building.start_floor,
            building,
        }
    }

    /// The building.
    pub fn building(&self) -> &Building {
        &self.building
    }

    /// The cars' fixtures.
    pub fn layouts(&self) -> &[CarLayout] {
        &self.layouts
    }

    /// The cars.
    pub fn bank(&self) -> &Bank {
        &self.bank
    }

    /// The robot's floor (riding between floors: the one it left).
    pub fn floor(&self) -> i32 {
        self.floor
    }

    /// The car the robot is inside (0-based).
    pub fn inside(&self) -> Option<usize> {
        self.inside
    }

    /// Whether the robot rides a car between floors.
    pub fn in_transit(&self) -> bool {
        self.inside
            .is_some_and(|k| self.bank.cars().get(k).is_some_and(|c| c.floor().is_none()))
    }

    /// The robot's floor as a world (its fixed layout).
    pub fn world(&self) -> Option<World> {
        self.building.world(self.floor)
    }

    /// The new floor's world, once after the robot changed floors.
    pub(crate) fn moved_floor(&mut self) -> Option<World> {
        if self.floor == self.world_floor {
            return None;
        }
        self.world_floor = self.floor;
        self.world()
    }

    /// Whether a message said at `at` is delivered: on the goal floor, near the goal.
    pub fn at_goal(&self, at: P) -> bool {
        let g = &self.building.goal;
        !self.in_transit()
            && self.floor == g.floor
            && (at[0] - g.at[0]).hypot(at[1] - g.at[1]) <= g.radius
    }

    /// Whether the robot's centre at `at` is back at the lab: on the lab's floor, near the
    /// lab's goal ([`Building::lab_goal`]), not riding a car.
    pub fn at_lab(&self, at: P) -> bool {
        self.building.lab_goal().is_some_and(|g| {
            !self.in_transit()
                && self.floor == g.floor
                && (at[0] - g.at[0]).hypot(at[1] - g.at[1]) <= g.radius
        })
    }

    /// Advances the cars `dt` seconds with the robot's centre at `at`.
    pub(crate) fn step(&mut self, dt: f64, at: P) {
        self.locate(at);
        let rider = Rider {
            at,
            floor: (!self.in_transit()).then_some(self.floor),
            inside: self.inside,
        };
        self.bank.step(dt, rider);
        self.locate(at);
    }

    /// Puts the robot at `at` on `floor` (resuming): a car it is inside is parked there.
    pub(crate) fn place(&mut self, floor: i32, at: P) {
        self.floor = floor.clamp(0, self.fixed.len().saturating_sub(1) as i32);
        self.inside = self.layouts.iter().position(|l| l.contains(at));
        if let Some(k) = self.inside {
            self.bank.park(k, self.floor);
        }
        self.view = None;
    }

    /// The cars out of service (fault injection) or back: out, a car whose doors are closed
    /// stays where it is.
    pub(crate) fn out_of_service(&mut self, out: bool) {
        self.bank.out_of_service = out;
    }

    /// A button pressed.
    pub(crate) fn press(&mut self, mark: Mark) {
        match mark {
            Mark::Call if !self.in_transit() => {
                let car = self.bank.hall_call(self.floor);
                tracing::debug!(floor = self.floor, car = car + 1, "hall call answered");
            }
            Mark::Panel { car, floor } => self.bank.car_call(car, floor),
            _ => {}
        }
    }

    fn locate(&mut self, at: P) {
        self.inside = self.layouts.iter().position(|l| l.contains(at));
        if let Some(f) = self
            .inside
            .and_then(|k| self.bank.cars().get(k))
            .and_then(|c| c.floor())
        {
            self.floor = f;
        }
    }

    fn view(&self) -> View {
        let transit = self.in_transit();
        let mut cars = [CarView::Hidden; MAX_CARS];
        for (k, (car, view)) in self.bank.cars().iter().zip(cars.iter_mut()).enumerate() {
            *view = if transit {
                if self.inside == Some(k) {
                    CarView::Present {
                        open: car.open_fraction(),
                        lit: false,
                        shows: car.nearest_floor(),
                    }
                } else {
                    CarView::Hidden
                }
            } else if car.floor() == Some(self.floor) {
                CarView::Present {
                    open: car.open_fraction(),
                    lit: car.doors() != Doors::Closed,
                    shows: self.floor,
                }
            } else {
                CarView::Shut
            };
        }
        View {
            floor: (!transit).then_some(self.floor),
            cars,
        }
    }

    /// Rebuilds what the robot meets and sees, if anything in sight changed; returns whether
    /// it did.
    pub(crate) fn refresh(
        &mut self,
        segments: &mut Vec<Segment>,
        barcodes: &mut Vec<Barcode>,
        marks: &mut Vec<Mark>,
    ) -> bool {
        let view = self.view();
        if self.view == Some(view) {
            return false;
        }
        segments.clear();
        barcodes.clear();
        marks.clear();
        let mut put = |id: u16, at: P, mark: Mark| {
            barcodes.push(Barcode { id, at });
            marks.push(mark);
        };
        if let Some(f) = view.floor {
            if let Some(fixed) = usize::try_from(f).ok().and_then(|i| self.fixed.get(i)) {
                segments.extend_from_slice(fixed);
            }
            for b in self.building.floor(f).iter().flat_map(|fl| &fl.barcode) {
                put(b.id, b.at, Mark::Sign);
            }
            put(CALL, self.building.elevator.call, Mark::Call);
        }
        for (k, (layout, car)) in self.layouts.iter().zip(view.cars).enumerate() {
            match car {
                CarView::Hidden => {}
                CarView::Shut => segments.push(layout.door),
                CarView::Present { open, lit, shows } => {
                    segments.extend(layout.leaves(open));
                    segments.extend_from_slice(&layout.walls);
                    // k < MAX_CARS and floors < MAX_FLOORS: the ids stay in their decades.
                    if lit {
                        put(LANTERN + k as u16 + 1, layout.lantern, Mark::Lantern(k));
                    }
                    for (f, at) in layout.panel.iter().enumerate() {
                        let floor = f as i32;
                        put(PANEL + f as u16, *at, Mark::Panel { car: k, floor });
                    }
                    put(
                        INDICATOR + shows as u16,
                        layout.indicator,
                        Mark::Indicator(k),
                    );
                }
            }
        }
        self.view = Some(view);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::building::{START_CLEARANCE, clearance};
    use crate::elevator::Car;
    use crate::sim::Sim;
    use std::path::Path;

    fn building(file: &str) -> Building {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("buildings")
            .join(file);
        Building::load(&path).unwrap()
    }

    /// Building A without other passengers: only the robot moves the cars.
    fn quiet() -> Building {
        let mut b = building("building-a.toml");
        b.elevator.traffic_s = 1e9;
        b
    }

    /// The unit vector from the lobby into the cabins.
    fn inward(site: &Site) -> P {
        let l = &site.layouts()[1];
        let m = [
            (l.door.from[0] + l.door.to[0]) / 2.0,
            (l.door.from[1] + l.door.to[1]) / 2.0,
        ];
        let d = [m[0] - l.lantern[0], m[1] - l.lantern[1]];
        let n = d[0].hypot(d[1]);
        [d[0] / n, d[1] / n]
    }

    /// Puts the robot at `p` facing `toward` and lets the simulator see it there.
    fn stand(sim: &mut Sim, p: P, toward: P) {
        sim.pose = [p[0], p[1], (toward[1] - p[1]).atan2(toward[0] - p[0])];
        sim.step(0.01);
    }

    /// The robot `back` metres in front of the call button, facing it.
    fn at_call(sim: &mut Sim, back: f64) {
        let site = sim.site().unwrap();
        let (n, c) = (inward(site), site.building().elevator.call);
        stand(sim, [c[0] - back * n[0], c[1] - back * n[1]], c);
    }

    fn lanterns(sim: &mut Sim) -> Vec<u16> {
        let mut ids: Vec<u16> = sim.camera().iter().map(|s| s.id).collect();
        ids.retain(|id| (811..=819).contains(id));
        ids
    }

    fn run_until(sim: &mut Sim, seconds: f64, mut done: impl FnMut(&mut Sim) -> bool) -> bool {
        for _ in 0..(seconds * 100.0) as usize {
            sim.step(0.01);
            if done(sim) {
                return true;
            }
        }
        false
    }

    #[test]
    fn shipped_buildings_start_clear_of_walls_for_every_seed() {
        for file in [
            "building-a.toml",
            "building-b.toml",
            "heldout/building-c.toml",
            "heldout/building-d.toml",
            "heldout/building-e.toml",
            "heldout/building-f.toml",
            "heldout/building-g.toml",
        ] {
            let b = building(file);
            let segs = b.segments(b.start_floor);
            let mut starts = Vec::new();
            for seed in 1..=20 {
                let sim = Sim::in_building(b.clone(), seed);
                let c = clearance(&segs, [sim.pose[0], sim.pose[1]]);
                assert!(c >= START_CLEARANCE, "{file} seed {seed}: {c}");
                assert_eq!(sim.floor(), 0);
                assert!(!sim.outside());
                starts.push(sim.pose);
            }
            starts.dedup();
            assert_eq!(starts.len(), 20, "{file}: the seeds move the start");
        }
    }

    #[test]
    fn a_called_car_comes_and_opens_and_its_lantern_shows_only_then() {
        for seed in 1..=4 {
            let mut sim = Sim::in_building(quiet(), seed);
            at_call(&mut sim, 0.6);
            assert_eq!(sim.push(), CALL);
            // 5 m back the camera's field holds all four doorways.
            at_call(&mut sim, 5.0);
            let mut lit_seen = Vec::new();
            run_until(&mut sim, 40.0, |sim| {
                for id in lanterns(sim) {
                    let k = usize::from(id - 811);
                    let car = &sim.site().unwrap().bank().cars()[k];
                    assert_eq!(car.floor(), Some(0), "seed {seed}: lit away from the floor");
                    assert_ne!(car.doors(), Doors::Closed, "seed {seed}: lit while closed");
                    lit_seen.push(k);
                }
                false
            });
            lit_seen.dedup();
            assert_eq!(
                lit_seen.len(),
                1,
                "seed {seed}: one car answered: {lit_seen:?}"
            );
            let car = &sim.site().unwrap().bank().cars()[lit_seen[0]];
            assert_eq!(car.floor(), Some(0));
            assert_eq!(car.doors(), Doors::Closed, "dwell over: closed again");
            assert!(lanterns(&mut sim).is_empty());
        }
    }

    #[test]
    fn a_press_needs_reach_and_alignment() {
        let mut sim = Sim::in_building(quiet(), 1);
        at_call(&mut sim, 0.6);
        assert_eq!(sim.push(), CALL, "in reach, straight ahead");
        at_call(&mut sim, 0.9);
        assert_eq!(sim.push(), 0, "too far");
        at_call(&mut sim, 0.6);
        sim.pose[2] += 20f64.to_radians();
        assert_eq!(sim.push(), 0, "turned 20° away");
        sim.pose[2] -= 30f64.to_radians();
        assert_eq!(sim.push(), CALL, "10° off still presses");
        assert_eq!((sim.strokes, sim.presses), (4, 2));
    }

    #[test]
    fn a_robot_pressing_864_in_a_car_is_carried_to_floor_4_and_sees_904() {
        let mut sim = Sim::in_building(quiet(), 2);
        at_call(&mut sim, 0.6);
        sim.push();
        at_call(&mut sim, 5.0);
        let mut lit = Vec::new();
        assert!(run_until(&mut sim, 40.0, |sim| {
            lit = lanterns(sim);
            !lit.is_empty()
        }));
        let k = usize::from(lit[0] - 811);
        let (layout, n) = {
            let site = sim.site().unwrap();
            (site.layouts()[k].clone(), inward(site))
        };
        // Into the cabin, 0.5 m from its back wall, turned to the 4th-floor button.
        let c = layout.cabin;
        let centre = [(c.min[0] + c.max[0]) / 2.0, (c.min[1] + c.max[1]) / 2.0];
        let spot = [centre[0] + 0.35 * n[0], centre[1] + 0.35 * n[1]];
        stand(&mut sim, spot, layout.panel[4]);
        assert_eq!(sim.site().unwrap().inside(), Some(k));
        assert_eq!(sim.push(), PANEL + 4);
        let mut rode = false;
        let carried = run_until(&mut sim, 40.0, |sim| {
            if sim.in_transit() {
                rode = true;
                // Between floors only the cabin is there: every echo is near.
                for i in 0..crate::sim::SONARS {
                    assert!(sim.sonar(i).is_none_or(|r| r < 2.0), "sonar {i}");
                }
            }
            let car = &sim.site().unwrap().bank().cars()[k];
            car.floor() == Some(4) && car.open_fraction() > 0.9
        });
        assert!(rode && carried);
        assert_eq!(sim.floor(), 4);
        let door = [
            (layout.door.from[0] + layout.door.to[0]) / 2.0,
            (layout.door.from[1] + layout.door.to[1]) / 2.0,
        ];
        stand(&mut sim, spot, door);
        let seen: Vec<u16> = sim.camera().iter().map(|s| s.id).collect();
        assert!(seen.contains(&(INDICATOR + 4)), "{seen:?}");
    }

    #[test]
    fn the_light_curtain_keeps_the_doors_open_while_the_robot_stands_in_the_doorway() {
        let mut sim = Sim::in_building(quiet(), 3);
        at_call(&mut sim, 0.6);
        sim.push();
        assert!(run_until(&mut sim, 40.0, |sim| {
            let site = sim.site().unwrap();
            site.bank()
                .cars()
                .iter()
                .any(|c| c.floor() == Some(0) && c.open_fraction() >= 1.0)
        }));
        let site = sim.site().unwrap();
        let k = site
            .bank()
            .cars()
            .iter()
            .position(|c| c.floor() == Some(0))
            .unwrap();
        let (door, n) = (site.layouts()[k].door, inward(site));
        let m = [
            (door.from[0] + door.to[0]) / 2.0,
            (door.from[1] + door.to[1]) / 2.0,
        ];
        let in_door = [m[0] - 0.1 * n[0], m[1] - 0.1 * n[1]];
        stand(&mut sim, in_door, m);
        for _ in 0..3000 {
            sim.step(0.01);
            let car = &sim.site().unwrap().bank().cars()[k];
            assert!(car.open_fraction() > 0.99, "{car:?}");
        }
        let away = [m[0] - 3.0 * n[0], m[1] - 3.0 * n[1]];
        stand(&mut sim, away, m);
        assert!(run_until(&mut sim, 12.0, |sim| {
            sim.site().unwrap().bank().cars()[k].doors() == Doors::Closed
        }));
    }

    /// Puts the robot at `at` on `floor`, facing +x.
    fn put(sim: &mut Sim, floor: i32, at: P) {
        let mut p = sim.physical();
        p.pose = [at[0], at[1], 0.0];
        p.floor = floor;
        sim.resume(p);
    }

    #[test]
    fn say_counts_and_delivers_only_near_the_goal_on_the_goal_floor() {
        let b = quiet();
        let goal = b.goal;
        let mut sim = Sim::in_building(b, 4);
        assert_eq!(sim.say("hello"), 1);
        put(&mut sim, 0, goal.at);
        assert_eq!(sim.say("wrong floor"), 2);
        put(&mut sim, 4, [goal.at[0] + goal.radius + 0.5, goal.at[1]]);
        assert_eq!(sim.say("too far"), 3);
        assert_eq!(sim.delivered, None);
        put(&mut sim, 4, [goal.at[0] + goal.radius - 0.5, goal.at[1]]);
        sim.step(0.5);
        assert_eq!(sim.floor(), 4);
        assert_eq!(sim.say("the message"), 4);
        assert_eq!(sim.delivered, Some(sim.time));
        let first = sim.time;
        sim.step(1.0);
        sim.say("again");
        assert_eq!((sim.said, sim.delivered), (5, Some(first)));
    }

    #[test]
    fn back_at_the_lab_only_near_its_goal_on_its_floor() {
        let b = quiet();
        let lab = b.lab_goal().unwrap();
        let mut sim = Sim::in_building(b, 4);
        assert!(!sim.at_lab(), "inside the lab, at the start");
        put(&mut sim, 0, lab.at);
        assert!(sim.at_lab());
        put(&mut sim, 0, [lab.at[0], lab.at[1] + lab.radius + 0.5]);
        assert!(!sim.at_lab(), "too far");
        put(&mut sim, 4, lab.at);
        assert!(!sim.at_lab(), "another floor");
    }

    #[test]
    fn the_same_seed_gives_the_same_elevator_schedule() {
        let schedule = |seed| {
            let mut sim = Sim::in_building(building("building-a.toml"), seed);
            let mut out: Vec<Vec<Car>> = Vec::new();
            for _ in 0..300 {
                for _ in 0..100 {
                    sim.step(0.01);
                }
                out.push(sim.site().unwrap().bank().cars().to_vec());
            }
            out
        };
        let a = schedule(11);
        assert_eq!(a, schedule(11));
        assert_ne!(a, schedule(12));
        let moves = a.windows(2).filter(|w| w[0] != w[1]).count();
        assert!(moves > 10, "the cars come and go: {moves}");
    }
}
