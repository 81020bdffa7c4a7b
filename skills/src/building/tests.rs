//! The building skills through the SDK's harness, most of them in closed loop with the
//! simulated robot in small buildings: corridors with doors and side corridors, an elevator
//! lobby with a bank of cars.

use super::*;
use crate::nav::{Avoid, BarcodeTrack};
use denning_sim::sim::Sim;
use denning_sim::world::{World, point_segment};
use skill_sdk::harness::{HARNESS_PERIOD, Harness};
use skill_sdk::ports::{InputMeta, InputSet, InputSource, OutputSet, PortMaker};
use std::any::Any;

// ---------------------------------------------------------------------------------------
// The robot: the simulator with the device's view of it.

/// Cycles between two status packets of the robot (100 ms at the harness's 10 ms): each
/// brings odometry, one group of 8 sonars, and a camera frame.
const STATUS_CYCLES: u64 = 10;

/// Barcodes a stroke can press (the hall call button, the car panel).
const BUTTONS: std::ops::RangeInclusive<u32> = 850..=869;

/// The simulated robot as the device reports it: a status every 100 ms with odometry and
/// one sonar group (each sonar is fresh every 300 ms), camera frames (kept with their age
/// when nothing is in view), the pusher (the simulator's rule: a stroke presses the nearest
/// button within 0.75 m of the robot's centre and ±12° of its heading, reported with the
/// next status) and the speaker (each new non-zero `seq` said once).
struct Robot {
    sim: Sim,
    seed: u64,
    sonar: Sonar,
    barcodes: Barcodes,
    odometry: Odometry,
    arm: Arm,
    voice: Voice,
    cycles: u64,
    group: usize,
    pressing: bool,
    /// A stroke made, reported with the next status.
    stroke: Option<u32>,
    /// The least gap there has been between the robot's body and a wall (m; in a plain
    /// world: a building's cars are not in its fixed walls).
    closest: f64,
    /// In a building: the simulator's pusher and speaker act on it.
    building: bool,
}

impl Robot {
    fn new(world: &str, seed: u64) -> Robot {
        Robot::with(Sim::new(World::parse(world, "test").unwrap(), seed), seed)
    }

    /// The robot in a shipped building at `pose` on `floor` (odometry from there, heading
    /// as the pose's).
    fn in_building(file: &str, seed: u64, floor: i32, pose: [f64; 3]) -> Robot {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../devices/denning-sim/buildings")
            .join(file);
        let b = denning_sim::building::Building::load(&path).unwrap();
        let mut sim = Sim::in_building(b, seed);
        sim.resume(denning_sim::sim::Physical {
            pose,
            odom: [0.0, 0.0, pose[2]],
            vel: [0.0; 2],
            collisions: 0,
            time: 0.0,
            floor,
        });
        let mut r = Robot::with(sim, seed);
        r.building = true;
        r
    }

    fn with(mut sim: Sim, seed: u64) -> Robot {
        sim.enabled = true;
        let mut r = Robot {
            sim,
            seed,
            sonar: Sonar {
                range: [f64::NAN; SONARS],
                age_ms: [f64::INFINITY; SONARS],
            },
            barcodes: Barcodes {
                age_ms: f64::INFINITY,
                ..Barcodes::default()
            },
            odometry: Odometry::default(),
            arm: Arm {
                age_ms: f64::INFINITY,
                ..Arm::default()
            },
            voice: Voice::default(),
            cycles: 0,
            group: 0,
            pressing: false,
            stroke: None,
            closest: f64::INFINITY,
            building: false,
        };
        // A whole ring, as after the device's first three statuses.
        for _ in 0..3 {
            r.status();
        }
        r
    }

    /// The same robot in another world (doors opened or closed, a lantern lit or not).
    fn set_world(&mut self, world: &str) {
        let body = self.sim.physical();
        self.sim = Sim::new(World::parse(world, "test").unwrap(), self.seed);
        self.sim.resume(body);
        self.sim.enabled = true;
    }

    fn status(&mut self) {
        for i in (0..SONARS).filter(|i| i % 3 == self.group) {
            self.sonar.range[i] = self.sim.sonar(i).unwrap_or(f64::INFINITY);
            self.sonar.age_ms[i] = 0.0;
        }
        self.group = (self.group + 1) % 3;
        let [x, y, theta] = self.sim.odom;
        let [v, w] = self.sim.vel;
        self.odometry = Odometry { x, y, theta, v, w };
        let seen = self.sim.camera();
        if !seen.is_empty() {
            let mut b = Barcodes::default();
            for s in seen.iter().take(8) {
                let k = b.count as usize;
                b.id[k] = u32::from(s.id);
                b.bearing[k] = (f64::from(s.bearing) / 10.0).to_radians();
                b.range[k] = f64::from(s.range) / 1000.0;
                b.count += 1;
            }
            self.barcodes = b;
        }
        if let Some(pressed) = self.stroke.take() {
            self.arm.strokes += 1;
            self.arm.pressed = pressed;
            self.arm.hits += u32::from(pressed != 0);
            self.arm.age_ms = 0.0;
        }
    }

    /// The button a stroke from the true pose presses now (0: none).
    fn pressable(&self) -> u32 {
        let [x, y, th] = self.sim.pose;
        self.sim
            .world
            .barcode
            .iter()
            .filter(|b| BUTTONS.contains(&u32::from(b.id)))
            .map(|b| {
                let (dx, dy) = (b.at[0] - x, b.at[1] - y);
                (b.id, dx.hypot(dy), wrap(dy.atan2(dx) - th))
            })
            .filter(|&(_, r, bearing)| r <= 0.75 && bearing.abs() <= 12f64.to_radians())
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(0, |b| u32::from(b.0))
    }

    /// One 10 ms cycle with the cycle's winning commands.
    fn cycle(&mut self, drive: Drive, push: Push, say: Say) {
        self.sim.cmd = [drive.translate, drive.rotate];
        self.sim.step(0.01);
        let [x, y, _] = self.sim.pose;
        let gap = if self.building {
            f64::INFINITY
        } else {
            self.sim
                .world
                .segments()
                .iter()
                .map(|s| point_segment([x, y], s).0)
                .fold(f64::INFINITY, f64::min)
                - denning_sim::sim::RADIUS
        };
        self.closest = self.closest.min(gap);
        if push.press && !self.pressing {
            self.stroke = Some(if self.building {
                u32::from(self.sim.push())
            } else {
                self.pressable()
            });
        }
        self.pressing = push.press;
        if say.seq != 0 && say.seq != self.voice.seq {
            self.voice.seq = say.seq;
            self.voice.said += 1;
            if self.building {
                self.sim.say(MESSAGE);
            }
        }
        for a in &mut self.sonar.age_ms {
            *a += 10.0;
        }
        self.barcodes.age_ms += 10.0;
        self.arm.age_ms += 10.0;
        self.cycles += 1;
        if self.cycles.is_multiple_of(STATUS_CYCLES) {
            self.status();
        }
    }

    fn drive(&mut self, drive: Drive) {
        self.cycle(drive, Push::default(), silent());
    }

    /// What barcode_track (`h`) makes of this cycle's camera report.
    fn track(&self, h: &mut Harness<BarcodeTrack>) -> Target {
        h.input("barcodes", self.barcodes)
            .input("odometry", self.odometry);
        *h.step().unwrap().output::<Target>("target").unwrap()
    }

    /// A world point in the odometry frame (odometry starts at the world's start, same
    /// heading; drift aside).
    fn to_odom(&self, x: f64, y: f64) -> (f64, f64) {
        let [sx, sy, _] = self.sim.world.start;
        (x - sx, y - sy)
    }
}

/// The speaker's safe command: nothing to say.
fn silent() -> Say {
    Say::new(0, "")
}

/// The winning command of a cycle: the proposal of highest priority, or the safe one.
fn arbitrate(proposals: &[(i32, Option<Drive>)]) -> Drive {
    proposals
        .iter()
        .filter_map(|&(p, d)| d.map(|d| (p, d)))
        .max_by_key(|&(p, _)| p)
        .map_or_else(Drive::default, |(_, d)| d)
}

// ---------------------------------------------------------------------------------------
// Worlds.

/// World text: a start and wall segments (x0, y0, x1, y1), then any extra TOML.
fn world(start: [f64; 3], walls: &[[f64; 4]], extra: &str) -> String {
    let mut w = format!(
        "name = 't'\nstart = [{}, {}, {}]\n",
        start[0], start[1], start[2]
    );
    for [x0, y0, x1, y1] in walls {
        w += &format!("[[wall]]\nfrom = [{x0}, {y0}]\nto = [{x1}, {y1}]\n");
    }
    w + extra
}

fn barcode(id: u32, x: f64, y: f64) -> String {
    format!("[[barcode]]\nid = {id}\nat = [{x}, {y}]\n")
}

/// A corridor along x (y within ±1.2, from x = 0 to `len`) whose walls have gaps (x0, x1)
/// on the left (top) and on the right; each gap opens into a 3 m deep room, or (`corridor`)
/// a side corridor 10 m long.
fn corridor(len: f64, left: &[(f64, f64, bool)], right: &[(f64, f64, bool)]) -> Vec<[f64; 4]> {
    let mut w = vec![[0.0, -1.2, 0.0, 1.2], [len, -1.2, len, 1.2]];
    for (gaps, y, out) in [(left, 1.2, 1.0), (right, -1.2, -1.0)] {
        let mut x = 0.0;
        for &(a, b, side_corridor) in gaps {
            w.push([x, y, a, y]);
            let depth = if side_corridor { 10.0 } else { 3.0 };
            let (lo, hi) = if side_corridor {
                (a, b)
            } else {
                (a - 1.0, b + 1.0)
            };
            let far = y + out * depth;
            w.push([lo, y, lo, far]);
            w.push([lo, far, hi, far]);
            w.push([hi, far, hi, y]);
            x = b;
        }
        w.push([x, y, len, y]);
    }
    w
}

// ---------------------------------------------------------------------------------------
// A driver that can leave cycles out: the harness steps cycle after cycle, but a skill the
// sequencer deactivated and activates again sees a gap in the cycles.

struct Gapped<S: Skill> {
    skill: S,
    params: S::Params,
    inputs: Vec<(String, Option<Box<dyn Any>>)>,
    names: Vec<String>,
    outputs: Vec<skill_sdk::ports::ErasedOutput>,
}

struct Given<'a>(&'a [(String, Option<Box<dyn Any>>)], u64);

impl InputSource for Given<'_> {
    fn get(&self, idx: usize) -> Option<(&dyn Any, InputMeta)> {
        let v = self.0.get(idx)?.1.as_ref()?;
        Some((
            v.as_ref(),
            InputMeta {
                cycle: self.1,
                age: 0,
                source: None,
            },
        ))
    }
}

impl<S: Skill> Gapped<S> {
    fn new() -> Self {
        let inputs = <S::Inputs<'static> as InputSet<'static>>::ports()
            .into_iter()
            .map(|p| (p.port, None))
            .collect();
        let ports = <S::Outputs<'static> as OutputSet<'static>>::ports();
        let names = ports.iter().map(|p| p.port.clone()).collect();
        let maker = PortMaker { node: None, ports };
        let outputs = <S::Outputs<'static> as OutputSet<'static>>::make(&maker).unwrap();
        Gapped {
            skill: S::default(),
            params: S::Params::default(),
            inputs,
            names,
            outputs,
        }
    }

    fn input<T: Message>(&mut self, port: &str, value: T) -> &mut Self {
        let slot = self.inputs.iter_mut().find(|i| i.0 == port).unwrap();
        slot.1 = Some(Box::new(value));
        self
    }

    /// Runs the body in `cycle`; returns output `port` if it was written.
    fn step_at<T: Message + Copy>(&mut self, cycle: u64, port: &str) -> Option<T> {
        let src = Given(&self.inputs, cycle);
        let input = <S::Inputs<'_> as InputSet<'_>>::fetch(&src).unwrap();
        {
            let mut out = <S::Outputs<'_> as OutputSet<'_>>::bind(&mut self.outputs);
            let ctx = Ctx {
                params: &self.params,
                cycle,
                name: "gapped",
                clock: Clock {
                    time: HARNESS_PERIOD * u32::try_from(cycle).unwrap(),
                    period: Some(HARNESS_PERIOD),
                    lockstep: true,
                },
            };
            self.skill.compute(&ctx, input, &mut out).unwrap();
        }
        let mut wanted = None;
        for (name, cell) in self.names.iter().zip(&mut self.outputs) {
            let v = cell.take_memory();
            if name == port {
                wanted = v.and_then(|v| v.downcast_ref::<T>().copied());
            }
        }
        wanted
    }
}

// ---------------------------------------------------------------------------------------
// Helpers on sonar rings.

fn ring(f: impl Fn(f64) -> f64) -> Sonar {
    let mut s = Sonar {
        range: [0.0; SONARS],
        age_ms: [10.0; SONARS],
    };
    for i in 0..SONARS {
        s.range[i] = f(crate::nav::sonar_angle(i));
    }
    s
}

// ---------------------------------------------------------------------------------------
// Corridors.

/// One instance of each corridor skill, stepped together with avoid as a plan runs them.
#[derive(Default)]
struct Corridor {
    intersection: Harness<Intersection>,
    hall: Harness<HallFollow>,
    doors: Harness<DoorDetect>,
    avoid: Harness<Avoid>,
    junction: Junction,
    seen_doors: Doors,
    /// Cycles in which avoid took over.
    avoided: u64,
}

impl Corridor {
    fn cycle(&mut self, r: &mut Robot) -> Drive {
        self.intersection
            .input("sonar", r.sonar)
            .input("odometry", r.odometry);
        self.junction = *self
            .intersection
            .step()
            .unwrap()
            .output::<Junction>("junction")
            .unwrap();
        self.doors
            .input("sonar", r.sonar)
            .input("odometry", r.odometry);
        self.seen_doors = *self.doors.step().unwrap().output::<Doors>("doors").unwrap();
        self.hall
            .input("sonar", r.sonar)
            .input("odometry", r.odometry)
            .input("junction", self.junction);
        let hall = self.hall.step().unwrap().output::<Drive>("drive").copied();
        self.avoid.input("sonar", r.sonar);
        let avoid = self.avoid.step().unwrap().output::<Drive>("drive").copied();
        self.avoided += u64::from(avoid.is_some());
        let d = arbitrate(&[(8, avoid), (3, hall)]);
        r.drive(d);
        d
    }
}

#[test]
fn a_side_corridor_opens_a_side_and_a_door_does_not() {
    // Down a corridor on its centre line: a door on the left at 5..6, a side corridor on the
    // left at 10..12.4, driven straight through.
    let walls = corridor(20.0, &[(5.0, 6.0, false), (10.0, 12.4, true)], &[]);
    let mut r = Robot::new(&world([1.5, 0.0, 0.0], &walls, ""), 1);
    let mut h = Harness::<Intersection>::new();
    let mut opened_at = Vec::new();
    let mut j = Junction::default();
    while r.sim.pose[0] < 16.0 {
        h.input("sonar", r.sonar).input("odometry", r.odometry);
        j = *h.step().unwrap().output::<Junction>("junction").unwrap();
        if j.left {
            opened_at.push(r.sim.pose[0]);
        }
        assert!(
            !j.right,
            "nothing opens on the right: {j:?} at {:?}",
            r.sim.pose
        );
        assert!(j.ahead, "the corridor goes on: {j:?}");
        r.drive(Drive {
            translate: 0.35,
            rotate: 0.0,
        });
    }
    assert!(!opened_at.is_empty(), "the side corridor opens the left");
    assert!(
        opened_at.iter().all(|&x| (10.0..12.4).contains(&x)),
        "only beside the side corridor, never at the door: {opened_at:?}"
    );
    assert_eq!(j.count, 1, "one intersection entered: {j:?}");
    assert!(!j.inside, "walls on both sides again: {j:?}");
}

#[test]
fn hall_follow_turns_left_at_a_junction_and_stops_at_the_end_without_a_collision() {
    // A T: the main corridor along x, a side corridor to the left at x 12..14.4, up to y 12.
    let walls = corridor(24.0, &[(12.0, 14.4, true)], &[]);
    let mut r = Robot::new(&world([1.5, 0.3, 0.1], &walls, ""), 2);
    let mut c = Corridor::default();
    c.hall.set_param("turn=1").unwrap();
    let mut worst = f64::INFINITY;
    for _ in 0..9000 {
        c.cycle(&mut r);
        if r.sim.pose[0] > 3.0 && r.sim.pose[0] < 11.0 {
            worst = worst.min(1.2 - r.sim.pose[1].abs());
        }
    }
    let [x, y, th] = r.sim.pose;
    assert_eq!(r.sim.collisions, 0, "never touched a wall");
    assert!(
        r.closest > 0.4,
        "never nearer a wall than 0.4 m: {}",
        r.closest
    );
    assert!(
        worst > 0.8,
        "centred along the corridor (1.2 m at the middle): {worst}"
    );
    assert!((x - 13.2).abs() < 0.3, "up the side corridor, centred: {x}");
    assert!(
        y > 9.5 && y < 11.0,
        "stopped before its end wall at 12: {y}"
    );
    assert!(wrap(th - FRAC_PI_2).abs() < 0.1, "heading up it: {th}");
    assert_eq!(c.junction.count, 1);
    assert!(r.sim.vel[0].abs() < 1e-3, "stopped");
    assert_eq!(c.avoided, 0, "avoid never had to take over");
}

#[test]
fn hall_follow_out_of_a_door_turns_right_into_the_corridor() {
    // The corridor along x; the lab below it, its door in the corridor's wall at x 4.4..5.6.
    // The robot has just come through (go_through stops 0.8 m past the door line).
    let mut walls = vec![
        [0.0, 1.2, 16.0, 1.2],
        [0.0, -1.2, 4.4, -1.2],
        [5.6, -1.2, 16.0, -1.2],
        [0.0, -1.2, 0.0, 1.2],
        [16.0, -1.2, 16.0, 1.2],
    ];
    walls.extend([
        [2.0, -1.2, 2.0, -6.0],
        [2.0, -6.0, 8.0, -6.0],
        [8.0, -6.0, 8.0, -1.2],
    ]);
    let mut r = Robot::new(&world([5.0, -0.4, FRAC_PI_2], &walls, ""), 3);
    let mut c = Corridor::default();
    c.hall.set_param("turn=-1").unwrap();
    for _ in 0..5000 {
        c.cycle(&mut r);
    }
    let [x, y, th] = r.sim.pose;
    assert_eq!(r.sim.collisions, 0);
    assert!(
        r.closest > 0.4,
        "never nearer a wall than 0.4 m: {}",
        r.closest
    );
    assert!(
        x > 13.8 && x < 14.8,
        "along to the corridor's east end: {x}"
    );
    assert!(y.abs() < 0.25, "on its centre line: {y}");
    assert!(th.abs() < 0.1, "heading east: {th}");
    assert_eq!(
        c.junction.count, 1,
        "the door's exit was the one intersection"
    );
}

#[test]
fn hall_follow_turns_right_where_its_corridor_meets_a_crossing_one() {
    // A T from its stem: the stem along x up to x = 10, the bar along y at x 10..12.4.
    let walls = [
        [0.0, -1.2, 0.0, 1.2],
        [0.0, 1.2, 10.0, 1.2],
        [0.0, -1.2, 10.0, -1.2],
        [10.0, 1.2, 10.0, 10.0],
        [10.0, -1.2, 10.0, -10.0],
        [12.4, -10.0, 12.4, 10.0],
        [10.0, 10.0, 12.4, 10.0],
        [10.0, -10.0, 12.4, -10.0],
    ];
    let mut r = Robot::new(&world([1.5, 0.2, -0.05], &walls, ""), 12);
    let mut c = Corridor::default();
    c.hall.set_param("turn=-1").unwrap();
    for _ in 0..8000 {
        c.cycle(&mut r);
    }
    let [x, y, th] = r.sim.pose;
    assert_eq!(r.sim.collisions, 0);
    assert!(
        r.closest > 0.4,
        "never nearer a wall than 0.4 m: {}",
        r.closest
    );
    assert_eq!(c.junction.count, 1);
    assert!((x - 11.2).abs() < 0.25, "down the bar, centred: {x}");
    assert!(
        y < -7.5 && y > -9.0,
        "stopped before its end wall at -10: {y}"
    );
    assert!(wrap(th + FRAC_PI_2).abs() < 0.1, "{th}");
    assert_eq!(c.avoided, 0);
}

#[test]
fn hall_follow_goes_straight_through_a_crossing_and_stops_at_a_wall_ahead() {
    let walls = corridor(16.0, &[(7.0, 9.4, true)], &[(7.0, 9.4, true)]);
    let mut r = Robot::new(&world([1.5, -0.2, 0.0], &walls, ""), 4);
    let mut c = Corridor::default();
    for _ in 0..5000 {
        c.cycle(&mut r);
    }
    let [x, y, _] = r.sim.pose;
    assert_eq!(r.sim.collisions, 0);
    assert!(
        r.closest > 0.4,
        "never nearer a wall than 0.4 m: {}",
        r.closest
    );
    assert_eq!(c.junction.count, 1);
    let ahead = 16.0 - x - 0.36;
    assert!(
        ahead > 1.0 && ahead < 1.3,
        "stopped about 1.2 m before the wall: {ahead}"
    );
    assert!(y.abs() < 0.25, "{y}");
}

#[test]
fn door_detect_counts_the_side_doors_but_not_a_side_corridor() {
    // Doors: left at 5..6 and 14..15, right at 9..10; a side corridor on the right at 20..22.4.
    let walls = corridor(
        30.0,
        &[(5.0, 6.0, false), (14.0, 15.0, false)],
        &[(9.0, 10.0, false), (20.0, 22.4, true)],
    );
    let mut r = Robot::new(&world([1.5, 0.0, 0.0], &walls, ""), 5);
    let mut c = Corridor::default();
    let mut beside = Vec::new();
    for _ in 0..9000 {
        c.cycle(&mut r);
        if c.seen_doors.beside != 0 {
            beside.push((c.seen_doors.beside, r.sim.pose[0]));
        }
    }
    assert_eq!(r.sim.collisions, 0);
    assert!(
        r.closest > 0.4,
        "never nearer a wall than 0.4 m: {}",
        r.closest
    );
    assert!(
        r.sim.pose[0] > 27.0,
        "drove the whole corridor: {:?}",
        r.sim.pose
    );
    let d = c.seen_doors;
    assert_eq!((d.left, d.right), (2, 1), "{d:?}");
    assert_eq!(c.junction.count, 1, "the side corridor is an intersection");
    assert!(
        beside.iter().all(|&(side, x)| (side == 1
            && ((5.0..6.5).contains(&x) || (14.0..15.5).contains(&x)))
            || (side == -1 && ((9.0..10.5).contains(&x) || (20.0..22.9).contains(&x)))),
        "beside only at the openings: {beside:?}"
    );
}

#[test]
fn side_walls_give_the_corridors_axis_and_the_distance() {
    // Tilted 0.2 rad toward the left wall, 0.9 m from it: the wall runs 0.2 rad clockwise.
    let walls = [[-10.0, 0.9, 10.0, 0.9], [-10.0, -1.5, 10.0, -1.5]];
    let mut r = Robot::new(&world([0.0, 0.0, 0.2], &walls, ""), 6);
    // Fits of ten rings (3 s standing), averaged as hall_follow's axis averages them.
    let (mut left, mut right) = (Vec::new(), Vec::new());
    for _ in 0..300 {
        r.drive(Drive::default());
        left.push(side_wall(&r.sonar, 1.0).unwrap());
        right.push(side_wall(&r.sonar, -1.0).unwrap());
    }
    let mean = |w: &[SideWall], f: fn(&SideWall) -> f64| w.iter().map(f).sum::<f64>() / 300.0;
    let (lt, rt) = (mean(&left, |w| w.tilt), mean(&right, |w| w.tilt));
    assert!(
        (lt + 0.2).abs() < 0.04 && (rt + 0.2).abs() < 0.05,
        "{lt} {rt}"
    );
    let (ld, rd) = (mean(&left, |w| w.distance), mean(&right, |w| w.distance));
    assert!(
        (ld - 0.9).abs() < 0.05 && (rd - 1.5).abs() < 0.08,
        "{ld} {rd}"
    );
    // An open door beside: no wall on that side.
    let walls = [
        [-10.0, 1.2, -0.5, 1.2],
        [0.5, 1.2, 10.0, 1.2],
        [-10.0, -1.2, 10.0, -1.2],
    ];
    r.set_world(&world([0.0, 0.0, 0.0], &walls, ""));
    r.sim.pose = [0.0, 0.0, 0.0];
    for _ in 0..30 {
        r.drive(Drive::default());
    }
    assert_eq!(side_wall(&r.sonar, 1.0), None);
    assert!(side_wall(&r.sonar, -1.0).is_some());
}

#[test]
fn intersection_and_door_detect_count_afresh_when_reactivated() {
    let open_left = ring(|a| if (0.9..2.2).contains(&a) { 6.0 } else { 0.84 });
    let walls = ring(|_| 0.84);
    let mut j = Gapped::<Intersection>::new();
    // Driving on at 5 cm a cycle.
    let count = |j: &mut Gapped<Intersection>, s: Sonar, from: u64, to: u64| {
        (from..to)
            .map(|c| {
                let x = c as f64 * 0.05;
                j.input("sonar", s).input(
                    "odometry",
                    Odometry {
                        x,
                        ..Odometry::default()
                    },
                );
                j.step_at::<Junction>(c, "junction").unwrap()
            })
            .last()
            .unwrap()
    };
    assert_eq!(count(&mut j, open_left, 1, 20).count, 1);
    let k = count(&mut j, walls, 20, 40);
    assert_eq!((k.count, k.inside), (1, false));
    assert_eq!(count(&mut j, open_left, 40, 60).count, 2, "a second one");
    // Deactivated from cycle 60 to 100: the intersection it is in counts once again.
    let k = count(&mut j, open_left, 100, 105);
    assert_eq!(
        (k.count, k.inside),
        (0, false),
        "held for `hold` cycles first"
    );
    assert_eq!(count(&mut j, open_left, 105, 120).count, 1);

    // Walls on both sides while turning on the spot (no travel) do not end an intersection.
    let mut j = Gapped::<Intersection>::new();
    assert_eq!(count(&mut j, open_left, 1, 20).count, 1);
    j.input(
        "odometry",
        Odometry {
            x: 1.0,
            ..Odometry::default()
        },
    );
    j.input("sonar", walls);
    let k = (20..80)
        .map(|c| j.step_at::<Junction>(c, "junction").unwrap())
        .last()
        .unwrap();
    assert_eq!((k.count, k.inside), (1, true), "turning on the spot");
    let k = count(&mut j, walls, 80, 100);
    assert_eq!(
        (k.count, k.inside),
        (1, false),
        "moved on with walls beside"
    );

    let mut d = Gapped::<DoorDetect>::new();
    let at = |d: &mut Gapped<DoorDetect>, cycle: u64, x: f64, left: f64| {
        let mut s = walls;
        s.range[6] = left;
        s.age_ms = [0.0; SONARS];
        d.input("sonar", s).input(
            "odometry",
            Odometry {
                x,
                ..Odometry::default()
            },
        );
        // Each cycle's readings are new: the device's age falls to 0 and rises between.
        d.step_at::<Doors>(cycle, "doors").unwrap();
        s.age_ms = [5.0; SONARS];
        d.input("sonar", s);
        d.step_at::<Doors>(cycle + 1, "doors").unwrap()
    };
    at(&mut d, 1, 0.0, 0.84);
    assert_eq!(at(&mut d, 3, 0.1, 3.0).beside, 1, "an opening begins");
    let seen = at(&mut d, 5, 0.7, 0.84);
    assert_eq!((seen.left, seen.beside), (1, 0), "0.6 m + the cone: a door");
    at(&mut d, 7, 0.8, 3.0);
    assert_eq!(
        at(&mut d, 9, 3.0, 0.84).left,
        1,
        "2.2 m + the cone: no door"
    );
    assert_eq!(at(&mut d, 50, 3.0, 0.84).left, 0, "counted afresh");
}

// ---------------------------------------------------------------------------------------
// The elevator lobby.

/// The bank's wall along y = 0 (cars' doorways 1.1 m wide centred at x = −2.7, −0.9, 0.9,
/// 2.7), the lobby below it down to y = −6; car 3's cabin (1.7 m × 1.7 m inside) behind its
/// doorway; the hall call button (850) 0.05 m in front of the wall at x = 0; inside car 3 its
/// panel (864 on the back wall) and its floor indicator (901, above the doorway). `open`:
/// car 3's doors are open and its lantern (813, 0.05 m into the lobby) lit.
fn lobby(start: [f64; 3], open: bool) -> String {
    let (a, b) = (0.35, 1.45);
    let mut walls = vec![
        [-6.0, 0.0, a, 0.0],
        [b, 0.0, 6.0, 0.0],
        [-6.0, -6.0, 6.0, -6.0],
        [-6.0, -6.0, -6.0, 0.0],
        [6.0, -6.0, 6.0, 0.0],
        // The cabin.
        [0.05, 0.0, 0.05, 1.7],
        [1.75, 0.0, 1.75, 1.7],
        [0.05, 1.7, 1.75, 1.7],
    ];
    let mut extra = barcode(850, 0.0, -0.05) + &barcode(864, 1.5, 1.65) + &barcode(901, 0.9, 0.05);
    if open {
        extra += &barcode(813, 0.9, -0.05);
    } else {
        walls.push([a, 0.0, b, 0.0]);
    }
    world(start, &walls, &extra)
}

/// barcode_track on the call button and car_watch, as the plan runs them while waiting.
#[derive(Default)]
struct Watch {
    track: Harness<BarcodeTrack>,
    watch: Harness<CarWatch>,
    target: Target,
    car: Car,
}

impl Watch {
    fn new() -> Watch {
        let mut w = Watch::default();
        w.track.set_param("id=850").unwrap();
        w
    }

    fn cycle(&mut self, r: &Robot) {
        self.target = r.track(&mut self.track);
        self.watch
            .input("barcodes", r.barcodes)
            .input("odometry", r.odometry)
            .input("target", self.target);
        self.car = *self.watch.step().unwrap().output::<Car>("car").unwrap();
    }
}

#[test]
fn car_watch_names_the_open_car_and_the_way_in_until_its_doors_close() {
    let mut r = Robot::new(&lobby([-0.5, -4.5, FRAC_PI_2], true), 7);
    let mut w = Watch::new();
    for _ in 0..100 {
        w.cycle(&r);
        r.drive(Drive::default());
    }
    let car = w.car;
    assert_eq!(car.id, 3, "{car:?}");
    let (x, y) = r.to_odom(0.9, 0.0);
    assert!(
        (car.x - x).abs() < 0.08 && (car.y - y).abs() < 0.08,
        "its doorway: {car:?}"
    );
    assert!(
        wrap(car.heading - FRAC_PI_2).abs() < 0.08,
        "into the bank's wall: {car:?}"
    );
    // The doors close: the lantern goes out; the car is gone after 1.5 s without it.
    r.set_world(&lobby([-0.5, -4.5, FRAC_PI_2], false));
    let mut gone_after = None;
    for k in 0..300 {
        w.cycle(&r);
        r.drive(Drive::default());
        if w.car.id == 0 && gone_after.is_none() {
            gone_after = Some(k);
        }
    }
    let k = gone_after.expect("the car is gone");
    assert!(
        (140..=170).contains(&k),
        "1.5 s after its last sighting: {k}"
    );
}

#[test]
fn car_watch_keeps_the_open_car_then_names_the_lantern_seen_last() {
    let mut h = Harness::<CarWatch>::new();
    let mut age = 400.0;
    // Each frame a new report (younger than the one before), in view (under 500 ms old).
    let mut sighting = |ids: &[u32]| {
        age -= 1.0;
        let mut b = Barcodes {
            age_ms: age,
            ..Barcodes::default()
        };
        for (k, &id) in ids.iter().enumerate() {
            b.id[k] = id;
            b.range[k] = 4.0;
            b.count += 1;
        }
        b
    };
    h.input("odometry", Odometry::default())
        .input("target", Target::default());
    let car = |h: &mut Harness<CarWatch>, b| {
        h.input("barcodes", b);
        h.step().unwrap().output::<Car>("car").unwrap().id
    };
    assert_eq!(car(&mut h, sighting(&[850])), 0, "no lantern: no car");
    assert_eq!(car(&mut h, sighting(&[812])), 2);
    assert_eq!(car(&mut h, sighting(&[814])), 2, "car 2 is still open");
    assert_eq!(
        car(&mut h, sighting(&[815, 850])),
        2,
        "no car 5 in a bank of 4"
    );
    // Car 2's lantern out of view for 1.5 s while car 4's is seen: car 4.
    let mut ids = Vec::new();
    for _ in 0..152 {
        ids.push(car(&mut h, sighting(&[814])));
    }
    assert!(ids[..140].iter().all(|&id| id == 2), "{ids:?}");
    assert_eq!(ids.last(), Some(&4));
    h.set_param("cars=5").unwrap();
    assert_eq!(car(&mut h, sighting(&[815])), 4, "car 4 is still open");
}

#[test]
fn enter_car_drives_through_the_doorway_into_the_cabin_and_faces_the_back_wall() {
    // Waiting in front of the bank, in line with the car's doorway or off to either side.
    for (n, start) in [
        [-0.5, -4.5, FRAC_PI_2],
        [-1.2, -4.5, FRAC_PI_2],
        [2.0, -4.0, FRAC_PI_2 + 0.3],
    ]
    .into_iter()
    .enumerate()
    {
        let mut r = Robot::new(&lobby(start, true), 8 + n as u64);
        let mut w = Watch::new();
        let mut enter = Harness::<EnterCar>::new();
        let mut avoid = Harness::<Avoid>::new();
        // The plan lowers avoid for the tight doorway (as exit-lab does for go_through).
        avoid.set_param("safe_distance=0.15").unwrap();
        let mut progress = Progress::default();
        for _ in 0..4000 {
            w.cycle(&r);
            enter
                .input("car", w.car)
                .input("odometry", r.odometry)
                .input("sonar", r.sonar);
            let step = enter.step().unwrap();
            progress = *step.output::<Progress>("progress").unwrap();
            let d = step.output::<Drive>("drive").copied();
            avoid.input("sonar", r.sonar);
            let a = avoid.step().unwrap().output::<Drive>("drive").copied();
            r.drive(arbitrate(&[(8, a), (6, d)]));
            assert_ne!(progress.phase, enter_phase::LOST, "the doors stayed open");
        }
        let [x, y, th] = r.sim.pose;
        assert_eq!(r.sim.collisions, 0, "through the 1.1 m doorway untouched");
        assert!(
            r.closest > 0.1,
            "never nearer a wall than 0.1 m: {}",
            r.closest
        );
        assert!(progress.done, "{progress:?}");
        assert!((x - 0.9).abs() < 0.12, "centred in the cabin: {x}");
        assert!((y - 0.95).abs() < 0.1, "0.95 m past the doorway line: {y}");
        assert!(
            wrap(th - FRAC_PI_2).abs() < 0.06,
            "facing the back wall: {th}"
        );
        assert!((progress.value - 0.95).abs() < 0.12, "{progress:?}");
    }
}

#[test]
fn enter_car_stops_lost_when_the_doors_close_before_it_reaches_them() {
    let mut h = Harness::<EnterCar>::new();
    let car = Car {
        id: 2,
        x: 3.0,
        y: 0.0,
        heading: 0.0,
    };
    h.input("car", Car::default())
        .input("sonar", ring(|_| 3.0))
        .input("odometry", Odometry::default());
    let p = *h.step().unwrap().output::<Progress>("progress").unwrap();
    assert_eq!(
        p.phase,
        enter_phase::LINING_UP,
        "no car yet: waiting, not lost"
    );
    h.input("car", car);
    let step = h.step().unwrap();
    assert!(step.output::<Drive>("drive").unwrap().translate > 0.0);
    h.input("car", Car::default());
    let step = h.step().unwrap();
    assert_eq!(
        step.output::<Progress>("progress").unwrap().phase,
        enter_phase::LOST
    );
    assert_eq!(*step.output::<Drive>("drive").unwrap(), Drive::default());
    // It stays lost though the car opens again: the sequencer retries by reactivating it.
    h.input("car", car);
    let step = h.step().unwrap();
    assert_eq!(
        step.output::<Progress>("progress").unwrap().phase,
        enter_phase::LOST
    );
    assert_eq!(*step.output::<Drive>("drive").unwrap(), Drive::default());
}

#[test]
fn enter_car_backs_away_from_doors_that_close_in_front_of_it_then_is_lost() {
    let mut h = Harness::<EnterCar>::new();
    let car = Car {
        id: 2,
        x: 3.0,
        y: 0.0,
        heading: 0.0,
    };
    let at = |x: f64| Odometry {
        x,
        ..Odometry::default()
    };
    // On the doorway's axis 0.5 m before it, facing it: driving in.
    h.input("car", car)
        .input("sonar", ring(|_| 3.0))
        .input("odometry", at(2.5));
    let p = *h.step().unwrap().output::<Progress>("progress").unwrap();
    assert_eq!(p.phase, enter_phase::ENTERING);
    // Another car reported: this one's doors closed. Back away, not yet lost.
    h.input(
        "car",
        Car {
            id: 4,
            y: 5.0,
            ..car
        },
    );
    let step = h.step().unwrap();
    assert_eq!(
        step.output::<Progress>("progress").unwrap().phase,
        enter_phase::BACKING_OUT
    );
    assert!(step.output::<Drive>("drive").unwrap().translate < 0.0);
    // `approach` (1.2 m) before the doorway: lost, standing still.
    h.input("odometry", at(1.75));
    let step = h.step().unwrap();
    assert_eq!(
        step.output::<Progress>("progress").unwrap().phase,
        enter_phase::LOST
    );
    assert_eq!(*step.output::<Drive>("drive").unwrap(), Drive::default());
}

#[test]
fn leave_car_turns_to_the_doors_waits_for_go_and_for_them_to_open_then_drives_out() {
    let start = [0.9, 0.95, FRAC_PI_2];
    let mut r = Robot::new(&lobby(start, false), 9);
    let mut h = Harness::<LeaveCar>::new();
    let run = |h: &mut Harness<LeaveCar>, r: &mut Robot, cycles: u32| {
        let mut p = Progress::default();
        for _ in 0..cycles {
            h.input("odometry", r.odometry).input("sonar", r.sonar);
            let step = h.step().unwrap();
            p = *step.output::<Progress>("progress").unwrap();
            r.drive(*step.output::<Drive>("drive").unwrap());
        }
        p
    };
    let p = run(&mut h, &mut r, 900);
    assert_eq!(p.phase, leave_phase::WAITING, "{p:?}");
    assert!(
        wrap(r.sim.pose[2] + FRAC_PI_2).abs() < 0.08,
        "facing the doors: {:?}",
        r.sim.pose
    );
    h.set_param("go=1").unwrap();
    let p = run(&mut h, &mut r, 300);
    // (Squaring up to the cabin may turn it a little more meanwhile.)
    assert!(
        matches!(p.phase, leave_phase::WAITING | leave_phase::TURNING),
        "the doors are closed: {p:?}"
    );
    let held = r.sim.pose;
    assert!(
        (held[0] - 0.9).abs() < 0.02 && (held[1] - 0.95).abs() < 0.02,
        "still: {held:?}"
    );
    r.set_world(&lobby(start, true));
    let p = run(&mut h, &mut r, 1500);
    let [x, y, _] = r.sim.pose;
    assert!(p.done && p.phase == leave_phase::OUT, "{p:?}");
    assert_eq!(r.sim.collisions, 0);
    assert!(
        r.closest > 0.1,
        "never nearer a wall than 0.1 m: {}",
        r.closest
    );
    assert!((y - (0.95 - 1.8)).abs() < 0.1, "1.8 m out: {y}");
    assert!((x - 0.9).abs() < 0.1, "straight out: {x}");
    assert!(r.sim.vel[0].abs() < 1e-3, "stopped");
}

#[test]
fn leave_car_waits_again_when_the_doors_close_in_front_of_it() {
    let mut h = Harness::<LeaveCar>::new();
    h.set_param("go=1").unwrap();
    let od = |y: f64| Odometry {
        y,
        theta: -FRAC_PI_2,
        ..Odometry::default()
    };
    // Facing the back wall (+y); the way out is −y.
    h.input(
        "odometry",
        Odometry {
            theta: FRAC_PI_2,
            ..Odometry::default()
        },
    )
    .input("sonar", ring(|_| 3.0));
    h.step().unwrap();
    h.input("odometry", od(0.0));
    assert_eq!(
        h.step()
            .unwrap()
            .output::<Progress>("progress")
            .unwrap()
            .phase,
        leave_phase::LEAVING
    );
    h.input("odometry", od(-0.3)).input("sonar", ring(|_| 0.6));
    let step = h.step().unwrap();
    assert_eq!(
        step.output::<Progress>("progress").unwrap().phase,
        leave_phase::WAITING
    );
    assert_eq!(*step.output::<Drive>("drive").unwrap(), Drive::default());
}

/// Building A's route from the lab door to the elevator lobby (devices/denning-sim/buildings/
/// building-a.toml): out of the door left into the corridor, straight over the crossing,
/// right at the T, on until the call button is in view; the plan's corridor legs, turn set
/// before each junction as the junction count goes up.
#[test]
fn hall_follow_takes_building_a_from_the_lab_door_to_the_lobby() {
    for seed in 1..=4 {
        // Just through the lab door (go_through stops 0.8 m past it), facing east.
        let mut r = Robot::in_building("building-a.toml", seed, 0, [10.8, 4.0, 0.05]);
        let mut c = Corridor::default();
        c.hall.set_param("turn=1").unwrap();
        let mut track = Harness::<BarcodeTrack>::new();
        track.set_param("id=850").unwrap();
        let mut seen = None;
        for k in 0..40_000 {
            c.cycle(&mut r);
            let turn = match c.junction.count {
                0 => "turn=1",
                1 => "turn=0",
                2 => "turn=-1",
                _ => "turn=0",
            };
            c.hall.set_param(turn).unwrap();
            if r.track(&mut track).visible {
                seen = Some(k);
                break;
            }
        }
        let [x, y, _] = r.sim.pose;
        assert_eq!(r.sim.collisions, 0, "seed {seed}: {:?}", r.sim.pose);
        assert!(
            seen.is_some(),
            "seed {seed}: the call button never in view, at {x}, {y}"
        );
        assert!(c.junction.count >= 3, "seed {seed}: {:?}", c.junction);
    }
}

/// Out of a fourth-floor lobby: lined up on the call button and turned round, the robot is
/// only roughly on the corridor's centre line and square to the bank; hall_follow, with no
/// wall beside in the open lobby, must still find the corridor's mouth (in both shipped
/// buildings the corridor out of the lobby faces the call button) and go in without
/// stopping at the wall beside it.
#[test]
fn hall_follow_finds_the_corridor_out_of_an_open_lobby() {
    // Building, start on the corridor's centre line, and how far along it the robot is well
    // inside the corridor (m).
    let cases = [
        ("building-a.toml", [26.0, 18.2, PI], 10.0),
        ("building-b.toml", [19.2, -8.5, FRAC_PI_2], 7.0),
    ];
    for (file, [x0, y0, th0], inside) in cases {
        for (k, (off, tilt)) in [
            (0.5, 0.06),
            (-0.5, -0.06),
            (0.45, -0.05),
            (-0.3, 0.08),
            (0.7, -0.1),
            (-0.7, 0.1),
        ]
        .into_iter()
        .enumerate()
        {
            // Sideways from the axis by `off` (to the left of the heading).
            let pose = [x0 - off * th0.sin(), y0 + off * th0.cos(), wrap(th0 + tilt)];
            let mut r = Robot::in_building(file, k as u64 + 1, 4, pose);
            let mut c = Corridor::default();
            let mut reached = false;
            for _ in 0..6000 {
                c.cycle(&mut r);
                let [x, y, _] = r.sim.pose;
                if (x - x0) * th0.cos() + (y - y0) * th0.sin() > inside {
                    reached = true;
                    break;
                }
            }
            assert_eq!(r.sim.collisions, 0, "{file} {pose:?}: {:?}", r.sim.pose);
            assert!(
                reached,
                "{file} from {pose:?}: into the corridor, not stuck at {:?}",
                r.sim.pose
            );
        }
    }
}

/// Turned in a lobby toward the corridor out of its side (as in a plan: out of the car, turn
/// left): the line the robot turned on may pass beside the corridor's mouth, not into it.
/// The lobby is 12 m wide and 7 m deep in front of the bank's wall (y = 0); the corridor
/// leaves its east side between y = −4.6 and −2.2 (centre −3.4), 10 m long.
#[test]
fn hall_follow_turned_in_a_lobby_finds_the_corridor_out_of_its_side() {
    let walls = [
        [-6.0, 0.0, 6.0, 0.0],
        [-6.0, -7.0, 6.0, -7.0],
        [-6.0, -7.0, -6.0, 0.0],
        [6.0, -2.2, 6.0, 0.0],
        [6.0, -7.0, 6.0, -4.6],
        [6.0, -2.2, 16.0, -2.2],
        [6.0, -4.6, 16.0, -4.6],
        [16.0, -4.6, 16.0, -2.2],
    ];
    // Facing away from the bank; the robot turns some 0.8 m on, so on lines from 2 m above
    // the mouth's centre to 2.4 m below it (1.2 m past its edge). Mirrored (`m` = −1: the
    // corridor leaves the west side), it turns right.
    let cases = [-2.2, -2.8, -3.4, -4.0, -4.5, -5.0];
    for (k, (m, y0)) in [1.0, -1.0]
        .into_iter()
        .flat_map(|m| cases.map(|y0| (m, y0)))
        .enumerate()
    {
        let walls: Vec<[f64; 4]> = walls
            .iter()
            .map(|w| [m * w[0], w[1], m * w[2], w[3]])
            .collect();
        let start = [m * 0.3, y0, -FRAC_PI_2];
        let mut r = Robot::new(&world(start, &walls, ""), k as u64 + 1);
        let mut c = Corridor::default();
        c.hall
            .set_param(if m > 0.0 { "turn=1" } else { "turn=-1" })
            .unwrap();
        let mut reached = false;
        for _ in 0..8000 {
            c.cycle(&mut r);
            if m * r.sim.pose[0] > 10.0 {
                reached = true;
                break;
            }
        }
        assert_eq!(r.sim.collisions, 0, "from {start:?}: {:?}", r.sim.pose);
        assert!(
            reached,
            "from {start:?}: into the corridor, not stuck at {:?}",
            r.sim.pose
        );
    }
}

/// Out of the lab door askew (building B, seed 3 of the delivery runs: 15° to the left of the
/// corridor's axis), the front cones see the side wall within `stop`: hall_follow must turn
/// to the axis and go on, not stand there.
#[test]
fn hall_follow_out_of_a_door_askew_turns_to_the_axis_and_goes_on() {
    let mut r = Robot::in_building("building-b.toml", 3, 0, [11.05, 4.24, 0.256]);
    let mut c = Corridor::default();
    c.hall.set_param("turn=-1").unwrap();
    for _ in 0..3000 {
        c.cycle(&mut r);
    }
    assert_eq!(r.sim.collisions, 0);
    assert!(r.sim.pose[0] > 14.0, "along the corridor: {:?}", r.sim.pose);
}

/// After calling a car, back away from the call button to 5 m from the bank's wall, where
/// the camera sees all four lanterns (from 4.6 m the outer ones are at 30.3°, just outside).
const CALL_RETREAT: &str = "retreat=4.35";

/// The stages of an elevator ride, as the delivery plan sequences them.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Ride {
    /// Pressing the call button, then backing away to watch the lanterns.
    Call,
    /// Watching for a car to open.
    Wait,
    /// Driving into the open car.
    Enter,
    /// Pressing the panel's 4.
    Press,
    /// Riding: turned to the doors, waiting for the indicator to say 4.
    Up,
    /// Driving out.
    Leave,
    /// Out of the car.
    Out,
}

/// The elevator ride of the delivery plan (skills/plans/deliver.xml, RideToTheFourthFloor) in
/// the shipped building A's simulator (its cars come and go with other passengers): call a
/// car from the lobby of floor 0, board whichever opens, press 4, turn to the doors, leave
/// when the indicator says 4. A small sequencer of harnessed skills; a fresh harness is a
/// reactivated skill.
#[test]
fn a_ride_calls_a_car_boards_it_presses_four_and_leaves_on_the_fourth_floor() {
    for seed in 1..=6 {
        let mut r = Robot::in_building("building-a.toml", seed, 0, [24.5, 18.0, 0.1]);
        let mut stage = Ride::Call;
        let mut log = vec![(0.0, stage)];
        let fresh_push = |retreat: &str| {
            let mut h = Harness::<PushButton>::new();
            h.set_param(retreat).unwrap();
            h
        };
        let fresh_track = |id: &str| {
            let mut h = Harness::<BarcodeTrack>::new();
            h.set_param(id).unwrap();
            h
        };
        let mut track = fresh_track("id=850");
        let mut push = fresh_push(CALL_RETREAT);
        let mut watch = Harness::<CarWatch>::new();
        let mut enter = Harness::<EnterCar>::new();
        let mut leave = Harness::<LeaveCar>::new();
        let mut signs = Harness::<SignRead>::new();
        let mut avoid = Harness::<Avoid>::new();
        avoid.set_param("safe_distance=0.15").unwrap();
        let mut since = 0u64;
        for k in 0..60_000u64 {
            let target = r.track(&mut track);
            avoid.input("sonar", r.sonar);
            let a = avoid.step().unwrap().output::<Drive>("drive").copied();
            let (mut job, mut press) = (None, Push::default());
            let mut next = None;
            match stage {
                Ride::Call | Ride::Press => {
                    push.input("target", target)
                        .input("odometry", r.odometry)
                        .input("arm", r.arm)
                        .input("sonar", r.sonar);
                    let step = push.step().unwrap();
                    let p = *step.output::<Progress>("progress").unwrap();
                    job = step.output::<Drive>("drive").copied().map(|d| (5, d));
                    press = *step.output::<Push>("push").unwrap();
                    // Called: a car may open while the robot backs away (one that was
                    // here opens at once), so the lanterns are watched from the press on.
                    let called = p.done || p.phase == push_phase::RETREAT;
                    if stage == Ride::Call && called {
                        watch
                            .input("barcodes", r.barcodes)
                            .input("odometry", r.odometry)
                            .input("target", target);
                        let car = *watch.step().unwrap().output::<Car>("car").unwrap();
                        if car.id > 0 {
                            next = Some(Ride::Enter);
                        }
                    }
                    if next.is_some() {
                    } else if p.done {
                        next = Some(if stage == Ride::Call {
                            Ride::Wait
                        } else {
                            Ride::Up
                        });
                    } else if p.phase == push_phase::FAILED {
                        push = fresh_push("retreat=0.0");
                    }
                }
                Ride::Wait | Ride::Enter => {
                    watch
                        .input("barcodes", r.barcodes)
                        .input("odometry", r.odometry)
                        .input("target", target);
                    let car = *watch.step().unwrap().output::<Car>("car").unwrap();
                    if stage == Ride::Wait && car.id > 0 {
                        next = Some(Ride::Enter);
                    } else if stage == Ride::Wait && k - since > 9000 {
                        next = Some(Ride::Call);
                    }
                    if stage == Ride::Enter {
                        enter
                            .input("car", car)
                            .input("odometry", r.odometry)
                            .input("sonar", r.sonar);
                        let step = enter.step().unwrap();
                        let p = *step.output::<Progress>("progress").unwrap();
                        job = step.output::<Drive>("drive").copied().map(|d| (6, d));
                        if p.done {
                            next = Some(Ride::Press);
                        } else if p.phase == enter_phase::LOST {
                            next = Some(Ride::Call);
                        }
                    }
                }
                Ride::Up | Ride::Leave | Ride::Out => {
                    signs.input("barcodes", r.barcodes);
                    let sign = *signs.step().unwrap().output::<Signs>("signs").unwrap();
                    leave.input("odometry", r.odometry).input("sonar", r.sonar);
                    let step = leave.step().unwrap();
                    let p = *step.output::<Progress>("progress").unwrap();
                    job = step.output::<Drive>("drive").copied().map(|d| (6, d));
                    if stage == Ride::Up && sign.floor_known && sign.floor == 4 {
                        leave.set_param("go=1").unwrap();
                        next = Some(Ride::Leave);
                    } else if stage == Ride::Leave && p.done {
                        next = Some(Ride::Out);
                    }
                }
            }
            let (jp, jd) = job.map_or((0, None), |(p, d)| (p, Some(d)));
            r.cycle(arbitrate(&[(8, a), (jp, jd)]), press, silent());

            if let Some(n) = next {
                log.push((r.sim.time, n));
                since = k;
                stage = n;
                match n {
                    Ride::Call => {
                        track = fresh_track("id=850");
                        push = fresh_push(CALL_RETREAT);
                        watch = Harness::new();
                    }
                    Ride::Enter => enter = Harness::new(),
                    Ride::Press => {
                        track = fresh_track("id=864");
                        push = fresh_push("retreat=0.0");
                    }
                    Ride::Up => {
                        leave = Harness::new();
                        signs = Harness::new();
                    }
                    _ => {}
                }
            }
            if stage == Ride::Out {
                break;
            }
        }
        let [x, _, _] = r.sim.pose;
        assert_eq!(stage, Ride::Out, "seed {seed}: {log:?}");
        assert_eq!(r.sim.collisions, 0, "seed {seed}: {log:?}");
        assert_eq!(r.sim.floor(), 4, "seed {seed}");
        // Out of the doorway's light curtain (0.51 m): its doors may close behind it.
        assert!(x < 27.5 - 0.55, "out in the lobby: {:?}", r.sim.pose);
    }
}

// ---------------------------------------------------------------------------------------
// Buttons.

#[test]
fn push_button_presses_the_call_button_on_the_wall_coming_square_to_it() {
    // The wall along y = 0, the button 0.05 m in front of it. From 2.5 m off, turned away by
    // 0.5 rad; and from beside it along the wall (67° off its normal), where going straight
    // for it would bring the robot's flank against the wall.
    let walls = [[-5.0, 0.0, 5.0, 0.0], [-5.0, -6.0, 5.0, -6.0]];
    for (n, start) in [[0.6, -2.5, FRAC_PI_2 + 0.5], [2.0, -0.9, PI]]
        .into_iter()
        .enumerate()
    {
        let w = world(start, &walls, &barcode(850, 0.0, -0.05));
        let mut r = Robot::new(&w, 10 + n as u64);
        let mut track = Harness::<BarcodeTrack>::new();
        track.set_param("id=850").unwrap();
        let mut push = Harness::<PushButton>::new();
        let mut progress = Progress::default();
        for _ in 0..4000 {
            let t = r.track(&mut track);
            push.input("target", t)
                .input("odometry", r.odometry)
                .input("arm", r.arm)
                .input("sonar", r.sonar);
            let step = push.step().unwrap();
            progress = *step.output::<Progress>("progress").unwrap();
            // No proposal (no target yet): nobody drives, the safe command stops.
            let d = step.output::<Drive>("drive").copied().unwrap_or_default();
            r.cycle(d, *step.output::<Push>("push").unwrap(), silent());
        }
        assert!(progress.done, "{n}: {progress:?}");
        assert_eq!(progress.value, 1.0, "one stroke");
        assert_eq!((r.arm.strokes, r.arm.pressed), (1, 850));
        assert_eq!(r.sim.collisions, 0);
        assert!(
            r.closest > 0.12,
            "{n}: never nearer a wall than 0.12 m: {}",
            r.closest
        );
        let [x, y, th] = r.sim.pose;
        let reach = x.hypot(y + 0.05);
        assert!(
            reach > 0.5 && reach <= 0.75,
            "within the pusher's reach: {reach}"
        );
        let bearing = wrap((-0.05 - y).atan2(-x) - th);
        assert!(
            bearing.abs() < 12f64.to_radians(),
            "and its ±12°: {bearing}"
        );
    }
}

#[test]
fn push_button_backs_off_after_a_miss_and_gives_up_after_its_tries() {
    let mut h = Harness::<PushButton>::new();
    let target = Target {
        seen: true,
        visible: true,
        id: 864,
        range: 0.6,
        bearing: 0.0,
        ..Target::default()
    };
    let mut arm = Arm::default();
    h.input("target", target)
        .input("odometry", Odometry::default())
        .input("arm", arm)
        .input("sonar", ring(|_| 3.0));
    for attempt in 1..=3u32 {
        // Within reach and straight ahead: align, then the stroke.
        let mut step = h.step().unwrap();
        while !step.output::<Push>("push").unwrap().press {
            step = h.step().unwrap();
        }
        assert_eq!(
            step.output::<Progress>("progress").unwrap().phase,
            push_phase::STROKE
        );
        // The stroke missed (it pressed the button beside).
        arm.strokes += 1;
        arm.pressed = 863;
        h.input("arm", arm);
        let step = h.step().unwrap();
        let p = *step.output::<Progress>("progress").unwrap();
        assert!(!step.output::<Push>("push").unwrap().press, "released");
        assert_eq!(p.value, f64::from(attempt));
        if attempt == 3 {
            assert_eq!(p.phase, push_phase::FAILED);
            assert_eq!(*step.output::<Drive>("drive").unwrap(), Drive::default());
            break;
        }
        assert_eq!(p.phase, push_phase::BACKING);
        assert!(step.output::<Drive>("drive").unwrap().translate < 0.0);
        // Backed off 0.3 m: it approaches again.
        h.input(
            "odometry",
            Odometry {
                x: -0.3 * f64::from(attempt),
                ..Odometry::default()
            },
        );
        let p = *h.step().unwrap().output::<Progress>("progress").unwrap();
        assert_eq!(p.phase, push_phase::APPROACH);
    }
}

#[test]
fn push_button_starts_again_when_reactivated() {
    let mut g = Gapped::<PushButton>::new();
    let target = Target {
        seen: true,
        id: 850,
        range: 0.6,
        ..Target::default()
    };
    g.input("target", target)
        .input("odometry", Odometry::default())
        .input("arm", Arm::default())
        .input("sonar", ring(|_| 3.0));
    let progress = |g: &mut Gapped<PushButton>, c| g.step_at::<Progress>(c, "progress").unwrap();
    progress(&mut g, 1);
    progress(&mut g, 2);
    g.input(
        "arm",
        Arm {
            strokes: 1,
            pressed: 850,
            ..Arm::default()
        },
    );
    let p = progress(&mut g, 3);
    assert!(p.done && p.value == 1.0, "{p:?}");
    assert!(progress(&mut g, 4).done, "stays done while active");
    let p = progress(&mut g, 50);
    assert!(!p.done && p.value == 0.0, "a new job: {p:?}");
}

// ---------------------------------------------------------------------------------------
// Signs and the message.

fn frame(signs: &[(u32, f64, f64)], age_ms: f64) -> Barcodes {
    let mut b = Barcodes {
        age_ms,
        ..Barcodes::default()
    };
    for (k, &(id, range, bearing)) in signs.iter().enumerate() {
        b.id[k] = id;
        b.range[k] = range;
        b.bearing[k] = bearing;
        b.count += 1;
    }
    b
}

#[test]
fn sign_read_reads_the_floor_and_the_nearest_room_and_forgets_the_floor_when_reactivated() {
    let mut g = Gapped::<SignRead>::new();
    g.input("barcodes", frame(&[], f64::INFINITY));
    let s = g.step_at::<Signs>(1, "signs").unwrap();
    assert!(!s.floor_known && s.room == 0);
    g.input(
        "barcodes",
        frame(&[(403, 3.0, 0.2), (904, 1.0, 0.0), (405, 2.0, -0.1)], 20.0),
    );
    let s = g.step_at::<Signs>(2, "signs").unwrap();
    assert!(s.floor_known && s.floor == 4, "{s:?}");
    assert_eq!((s.room, s.room_range, s.room_bearing), (405, 2.0, -0.1));
    g.input("barcodes", frame(&[(403, 3.0, 0.2)], 700.0));
    let s = g.step_at::<Signs>(3, "signs").unwrap();
    assert!(s.floor_known && s.floor == 4, "the floor is kept");
    assert_eq!(s.room, 0, "no room sign in view");
    let s = g.step_at::<Signs>(30, "signs").unwrap();
    assert!(!s.floor_known, "reactivated: read it again");
}

#[test]
fn deliver_says_the_message_once_near_its_room() {
    // Along a corridor past room 403's sign, to room 405's.
    let walls = [[-1.0, 1.2, 20.0, 1.2], [-1.0, -1.2, 20.0, -1.2]];
    let signs = barcode(403, 5.0, 1.15) + &barcode(405, 10.0, 1.15);
    let mut r = Robot::new(&world([0.0, 0.0, 0.0], &walls, &signs), 11);
    let mut read = Harness::<SignRead>::new();
    let mut deliver = Harness::<Deliver>::new();
    let mut decided_at = None;
    let mut progress = Progress::default();
    while r.sim.pose[0] < 9.5 {
        read.input("barcodes", r.barcodes);
        let s = *read.step().unwrap().output::<Signs>("signs").unwrap();
        deliver.input("signs", s).input("voice", r.voice);
        let step = deliver.step().unwrap();
        progress = *step.output::<Progress>("progress").unwrap();
        let say = step.output::<Say>("say").copied().unwrap_or_else(silent);
        if say.seq != 0 && decided_at.is_none() {
            decided_at = Some((r.sim.pose[0], s));
            assert_eq!(say.text(), MESSAGE.as_bytes());
        }
        r.cycle(
            Drive {
                translate: 0.2,
                rotate: 0.0,
            },
            Push::default(),
            say,
        );
    }
    let (x, signs) = decided_at.expect("it spoke");
    assert!(x > 7.0, "at 405, not at 403: {x}");
    assert!(signs.room == 405 && signs.room_range <= 2.5, "{signs:?}");
    assert_eq!(r.voice.said, 1, "said once");
    assert!(progress.done, "{progress:?}");
}

#[test]
fn deliver_counts_only_what_is_said_after_activation() {
    let mut h = Harness::<Deliver>::new();
    let near = Signs {
        room: 405,
        room_range: 2.0,
        ..Signs::default()
    };
    h.input("signs", Signs::default())
        .input("voice", Voice { said: 3, seq: 9 });
    let step = h.step().unwrap();
    assert!(step.output::<Say>("say").is_none(), "nothing to say yet");
    h.input("signs", near);
    let step = h.step().unwrap();
    let say = *step.output::<Say>("say").unwrap();
    assert_ne!(say.seq, 0);
    assert!(!step.output::<Progress>("progress").unwrap().done);
    h.input(
        "voice",
        Voice {
            said: 4,
            seq: say.seq,
        },
    );
    let step = h.step().unwrap();
    assert_eq!(
        step.output::<Say>("say").unwrap().seq,
        say.seq,
        "the same message"
    );
    assert!(step.output::<Progress>("progress").unwrap().done);
}

// ---------------------------------------------------------------------------------------
// The changed navigation skills.

#[test]
fn barcode_track_forgets_its_target_when_the_id_changes_or_it_is_reactivated() {
    let seen = |id: u32, age_ms: f64| {
        let mut b = Barcodes {
            count: 1,
            age_ms,
            ..Barcodes::default()
        };
        b.id[0] = id;
        b.range[0] = 2.0;
        b
    };
    let mut h = Harness::<BarcodeTrack>::new();
    h.set_param("id=7").unwrap();
    h.input("barcodes", seen(7, 0.0))
        .input("odometry", Odometry::default());
    assert!(h.step().unwrap().output::<Target>("target").unwrap().seen);
    h.set_param("id=850").unwrap();
    h.input("barcodes", seen(7, 10.0));
    let t = *h.step().unwrap().output::<Target>("target").unwrap();
    assert!(
        !t.seen && t.id == 850,
        "the door's place is not the button's: {t:?}"
    );

    let mut g = Gapped::<BarcodeTrack>::new();
    g.input("barcodes", seen(7, 0.0))
        .input("odometry", Odometry::default());
    assert!(g.step_at::<Target>(1, "target").unwrap().seen);
    g.input("barcodes", seen(7, 900.0));
    assert!(g.step_at::<Target>(2, "target").unwrap().seen, "remembered");
    assert!(
        !g.step_at::<Target>(40, "target").unwrap().seen,
        "reactivated: forgotten"
    );
}

#[test]
fn go_through_reports_lining_up_passing_and_through() {
    let mut h = Harness::<crate::nav::GoThrough>::new();
    let door = skillfab_msgs::Door {
        found: true,
        x: 3.0,
        y: 0.0,
        heading: 0.0,
        width: 1.2,
    };
    h.input("sonar", ring(|_| 5.0));
    h.input("door", skillfab_msgs::Door::default())
        .input("odometry", Odometry::default());
    let p = *h.step().unwrap().output::<Progress>("progress").unwrap();
    assert_eq!((p.phase, p.done), (0, false), "no door yet");
    h.input("door", door);
    let at = |h: &mut Harness<crate::nav::GoThrough>, x: f64| {
        h.input(
            "odometry",
            Odometry {
                x,
                ..Odometry::default()
            },
        );
        h.step().unwrap();
        *h.step().unwrap().output::<Progress>("progress").unwrap()
    };
    let p = at(&mut h, 0.0);
    assert_eq!((p.phase, p.value), (0, -3.0));
    let p = at(&mut h, 2.0);
    assert_eq!(p.phase, 1, "lined up at the approach point: {p:?}");
    let p = at(&mut h, 3.5);
    assert!(p.phase == 1 && !p.done, "{p:?}");
    let p = at(&mut h, 3.85);
    assert!(
        p.phase == 2 && p.done && (p.value - 0.85).abs() < 1e-9,
        "{p:?}"
    );
}

// ---------------------------------------------------------------------------------------
// The search for the lab door's barcode.

/// Cycles until `explore` (`wander` with WANDER set in the environment; avoid beside it)
/// brings the lab door's barcode (7) into
/// barcode_track's view in a shipped lab world, or `None` within `limit` cycles; and the
/// robot's collisions.
fn search(file: &str, seed: u64, limit: u64) -> (Option<u64>, u64) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../devices/denning-sim/worlds")
        .join(file);
    let mut r = Robot::new(&std::fs::read_to_string(path).unwrap(), seed);
    let mut explore = Harness::<crate::nav::Explore>::new();
    let mut wander = Harness::<crate::nav::Wander>::new();
    wander.set_param(&format!("seed={seed}")).unwrap();
    let use_wander = std::env::var("WANDER").is_ok();
    let mut avoid = Harness::<Avoid>::new();
    let mut track = Harness::<BarcodeTrack>::new();
    track.set_param("id=7").unwrap();
    for k in 0..limit {
        explore
            .input("sonar", r.sonar)
            .input("odometry", r.odometry);
        let go = if use_wander {
            wander.input("sonar", r.sonar).input("odometry", r.odometry);
            wander.step().unwrap().output::<Drive>("drive").copied()
        } else {
            explore.step().unwrap().output::<Drive>("drive").copied()
        };
        avoid.input("sonar", r.sonar);
        let away = avoid.step().unwrap().output::<Drive>("drive").copied();
        r.drive(arbitrate(&[(8, away), (2, go)]));
        if r.track(&mut track).seen {
            return (Some(k), r.sim.collisions);
        }
    }
    (None, r.sim.collisions)
}

/// The systematic search: in each shipped lab, from seeded starts, explore (look round, go to
/// the nearest ground not covered, look round) sees the door's barcode within the exit-lab
/// mission's 300 s, without touching anything.
#[test]
fn explore_finds_the_lab_doors_barcode_in_every_shipped_lab() {
    for file in [
        "exit-lab.toml",
        "exit-lab-north.toml",
        "exit-lab-clutter.toml",
    ] {
        for seed in 1..=4 {
            let (seen, collisions) = search(file, seed, 30_000);
            eprintln!("{file} seed {seed}: {seen:?}");
            assert!(seen.is_some(), "{file} seed {seed}: never seen in 300 s");
            assert_eq!(collisions, 0, "{file} seed {seed}");
        }
    }
}

/// The search's figures (docs/deliver.md): explore against wander, seeds 1–20, in the shipped
/// labs and the held-out ones (never tuned against); every search must see the barcode in
/// 300 s without a collision. `cargo test -p skills --release measure_the_search --
/// --ignored --nocapture` (with `WANDER=1`: wander instead).
#[test]
#[ignore = "a measurement: run it by name"]
fn measure_the_search() {
    let worlds = [
        "exit-lab.toml",
        "exit-lab-north.toml",
        "exit-lab-clutter.toml",
        "heldout/west-long.toml",
        "heldout/south-tall.toml",
        "heldout/partition.toml",
    ];
    for file in worlds {
        let mut times: Vec<f64> = (1..=20)
            .map(|seed| {
                let (seen, collisions) = search(file, seed, 30_000);
                assert_eq!(collisions, 0, "{file} seed {seed}");
                seen.unwrap_or_else(|| panic!("{file} seed {seed}: not seen in 300 s")) as f64
                    / 100.0
            })
            .collect();
        times.sort_by(f64::total_cmp);
        eprintln!(
            "{file}: 20/20 seen, median {:.1} s, slowest {:.1} s",
            (times[9] + times[10]) / 2.0,
            times[19]
        );
    }
}
