//! The building skills through the SDK's harness, most of them in closed loop with the
//! simulated robot in small buildings: corridors with doors and side corridors, an elevator
//! lobby with a bank of cars.
//!
//! This file is the fixture the tests share: the simulated `Robot` as the device reports it,
//! world text (`world`, `barcode`), `arbitrate` for a cycle's winning drive command, `Gapped`
//! for a skill the sequencer deactivates and activates again, and `ring` for a sonar ring
//! drawn by angle. The tests, a file per group of skills:
//!
//! - `corridors`: intersection, door_detect and hall_follow, in made-up corridors and in the
//!   shipped buildings;
//! - `lobby`: car_watch, enter_car, leave_car and push_button at a bank of cars, and a whole
//!   elevator ride with them;
//! - `signs`: sign_read and deliver;
//! - `nav`: the navigation skills as the building skills changed them (barcode_track,
//!   go_through);
//! - `search`: explore's search for the lab door's barcode.

mod corridors;
mod lobby;
mod nav;
mod search;
mod signs;

use super::*;
use crate::nav::{BarcodeTrack, TrackIn, TrackOut};
use denning_sim::sim::Sim;
use denning_sim::world::{World, point_segment};
use skill_sdk::harness::{HARNESS_PERIOD, Harness};
use skill_sdk::ports::{InputMeta, InputSet, InputSource, OutputSet, PortMaker};
use skillfab_msgs::Echo;
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
            let echo = self.sim.sonar(i).map_or(Echo::Silent, Echo::Range);
            self.sonar.set_reading(i, echo, 0.0);
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
        h.input(TrackIn::BARCODES, self.barcodes)
            .input(TrackIn::ODOMETRY, self.odometry);
        *h.step().unwrap().output(TrackOut::TARGET).unwrap()
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

// ---------------------------------------------------------------------------------------
// A driver that can leave cycles out: the harness steps cycle after cycle, but a skill the
// sequencer deactivated and activates again sees a gap in the cycles.

struct Gapped<S: Skill> {
    skill: S,
    params: S::Params,
    inputs: Vec<(String, Option<Box<dyn Any>>)>,
    names: Vec<String>,
    outputs: Vec<skill_sdk::ports::ErasedOutput>,
    /// The cycle of the last step and the activation number: a gap in the cycles stands for
    /// a deactivation and activation, as the manager would number it.
    last: Option<u64>,
    activation: u32,
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
            last: None,
            activation: 0,
        }
    }

    fn input<T: Message>(&mut self, port: &str, value: T) -> &mut Self {
        let slot = self.inputs.iter_mut().find(|i| i.0 == port).unwrap();
        slot.1 = Some(Box::new(value));
        self
    }

    /// Runs the body in `cycle`; returns output `port` if it was written.
    fn step_at<T: Message + Copy>(&mut self, cycle: u64, port: &str) -> Option<T> {
        if self.last.is_none_or(|l| cycle > l + 1 || cycle <= l) {
            self.activation += 1;
        }
        self.last = Some(cycle);
        let src = Given(&self.inputs, cycle);
        let input = <S::Inputs<'_> as InputSet<'_>>::fetch(&src).unwrap();
        {
            let mut out = <S::Outputs<'_> as OutputSet<'_>>::bind(&mut self.outputs);
            let ctx = Ctx {
                params: &self.params,
                cycle,
                name: "gapped",
                activation: self.activation,
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
