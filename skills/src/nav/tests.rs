//! The navigation skills through the SDK's harness, on scripted sonar rings.

use super::*;
use skill_sdk::harness::Harness;
use skill_sdk::refs::OutputRef;
use skillfab_msgs::Echo;

fn ring(f: impl Fn(f64) -> f64) -> Sonar {
    let mut s = Sonar {
        range: [0.0; SONARS],
        age_ms: [10.0; SONARS],
    };
    for i in 0..SONARS {
        s.range[i] = f(sonar_angle(i));
    }
    s
}

#[test]
fn avoid_turns_away_from_the_near_side_and_is_quiet_in_the_open() {
    let mut h = Harness::<Avoid>::new();
    h.input(SonarIn::SONAR, ring(|_| 5.0));
    assert!(
        h.step().unwrap().output(DriveOut::DRIVE).is_none(),
        "nothing near: no proposal"
    );
    // An obstacle ahead and to the right: turn left (positive rotate).
    let mut h = Harness::<Avoid>::new();
    h.input(
        SonarIn::SONAR,
        ring(|a| if (-1.0..0.3).contains(&a) { 0.3 } else { 4.0 }),
    );
    let d = *h.step().unwrap().output(DriveOut::DRIVE).unwrap();
    assert!(d.rotate > 0.0, "{d:?}");
    let mut h = Harness::<Avoid>::new();
    h.input(
        SonarIn::SONAR,
        ring(|a| if (-0.3..1.0).contains(&a) { 0.3 } else { 4.0 }),
    );
    assert!(h.step().unwrap().output(DriveOut::DRIVE).unwrap().rotate < 0.0);
    // A lowered safe distance lets it pass close obstacles.
    let mut h = Harness::<Avoid>::new();
    h.set(AvoidParams::SAFE_DISTANCE, 0.2).unwrap();
    h.input(SonarIn::SONAR, ring(|_| 0.3));
    assert!(h.step().unwrap().output(DriveOut::DRIVE).is_none());
}

/// The ring in a passage `wide` (m) with the robot on its centre line, facing along it, and
/// a wall across it `ahead` (m from the centre): each sonar reads the nearest of its cone's
/// seven rays (every 5°, as the simulator casts them), from the ring.
fn passage(wide: f64, ahead: f64) -> Sonar {
    ring(|a| {
        let (ox, oy) = (RING * a.cos(), RING * a.sin());
        (-3..=3)
            .map(|k| {
                let ray = a + f64::from(k) * CONE / 3.0;
                let (c, s) = (ray.cos(), ray.sin());
                let side = if s.abs() > 1e-9 {
                    (wide / 2.0 * s.signum() - oy) / s
                } else {
                    f64::INFINITY
                };
                let front = if c > 1e-9 {
                    (ahead - ox) / c
                } else {
                    f64::INFINITY
                };
                side.min(front)
            })
            .fold(f64::INFINITY, f64::min)
            .min(9.0)
    })
}

/// In a passage 1.4 m wide (0.34 m each side of the robot), the sonars 45°–75° off the
/// front read the side walls under the safe distance: with every echo counted avoid takes
/// over; with `beside` at 0.15 those echoes can only come from beside the way ahead, and it
/// is quiet — until a wall across the passage comes within the safe distance.
#[test]
fn avoid_with_beside_lowered_lets_the_robot_down_a_passage_and_turns_at_its_end() {
    let open = passage(1.4, 9.0);
    let mut h = Harness::<Avoid>::new();
    h.input(SonarIn::SONAR, open);
    assert!(
        h.step().unwrap().output(DriveOut::DRIVE).is_some(),
        "every echo counted: the side walls hold it"
    );
    let mut h = Harness::<Avoid>::new();
    h.set(AvoidParams::BESIDE, 0.15).unwrap();
    h.input(SonarIn::SONAR, open);
    assert!(h.step().unwrap().output(DriveOut::DRIVE).is_none());
    // A wall across it 0.9 m ahead (0.54 m from the ring): it takes over.
    h.input(SonarIn::SONAR, passage(1.4, 0.9));
    assert!(h.step().unwrap().output(DriveOut::DRIVE).is_some());
    // Narrower than 0.15 m beyond each side of the robot (1.0 m): it takes over.
    let mut h = Harness::<Avoid>::new();
    h.set(AvoidParams::BESIDE, 0.15).unwrap();
    h.input(SonarIn::SONAR, passage(1.0, 9.0));
    assert!(h.step().unwrap().output(DriveOut::DRIVE).is_some());
}

#[test]
fn home_converges_on_its_goal() {
    // Integrate the proposals with a unicycle: the robot ends near the goal.
    let mut h = Harness::<Home>::new();
    h.input(HomeIn::SONAR, ring(|_| 5.0));
    let (mut x, mut y, mut th) = (0.0f64, 0.0f64, 2.0f64);
    let goal = (4.0, 3.0);
    for _ in 0..2000 {
        let range = (goal.0 - x).hypot(goal.1 - y);
        let bearing = wrap((goal.1 - y).atan2(goal.0 - x) - th);
        h.input(
            HomeIn::TARGET,
            Target {
                seen: true,
                visible: true,
                id: 7,
                x: goal.0,
                y: goal.1,
                range,
                bearing,
            },
        );
        let d = *h.step().unwrap().output(DriveOut::DRIVE).unwrap();
        th += d.rotate * 0.05;
        x += d.translate * 0.05 * th.cos();
        y += d.translate * 0.05 * th.sin();
    }
    let left = (goal.0 - x).hypot(goal.1 - y);
    assert!(
        left < 1.5 && left > 1.2,
        "stops at its stop distance: {left}"
    );
}

/// North-maze seed 6 (lock-step, the tried lab search): the barcode behind the robot, `home`
/// turning the short way round toward it, and `avoid` turning it back each time a box's
/// corner comes into its front arc on that side: the two took turns for 250 s. Here the
/// box is a sector of headings in which `avoid`'s turn (0.9 rad/s, counter-clockwise)
/// replaces `home`'s: `home` turns the other way round after `TURN_HELD_S` and faces the
/// target without entering it.
#[test]
fn home_turns_the_other_way_round_when_its_turn_on_the_spot_is_held() {
    let mut h = Harness::<Home>::new();
    h.input(HomeIn::SONAR, ring(|_| 5.0));
    let target = -2.9;
    let blocked = -1.2..-0.6;
    let mut th = 0.0f64;
    let mut faced = None;
    let mut held = 0;
    for k in 0..3000 {
        let bearing = wrap(target - th);
        if bearing.abs() < 0.1 {
            faced = Some(k);
            break;
        }
        h.input(
            HomeIn::TARGET,
            Target {
                seen: true,
                visible: true,
                range: 4.0,
                bearing,
                ..Target::default()
            },
        );
        let d = *h.step().unwrap().output(DriveOut::DRIVE).unwrap();
        let rotate = if blocked.contains(&wrap(th)) {
            held += 1;
            0.9
        } else {
            d.rotate
        };
        th += rotate * 0.01;
    }
    let faced = faced.expect("it faces the target");
    assert!(held > 0, "its first turn was the short way, into the box");
    // Into the box (0.6 rad), 4 s held, then round the other way (4 rad at up to 1 rad/s).
    assert!(faced < 1000, "{faced} cycles");
}

#[test]
fn barcode_track_places_the_sighting_in_the_odometry_frame() {
    let mut h = Harness::<BarcodeTrack>::new();
    let mut b = Barcodes {
        count: 1,
        ..Barcodes::default()
    };
    b.id[0] = 7;
    b.bearing[0] = PI / 2.0;
    b.range[0] = 2.0;
    h.input(TrackIn::BARCODES, b);
    h.input(
        TrackIn::ODOMETRY,
        Odometry {
            x: 1.0,
            y: 1.0,
            theta: 0.0,
            v: 0.0,
            w: 0.0,
        },
    );
    let t = *h.step().unwrap().output(TrackOut::TARGET).unwrap();
    assert!(t.seen && t.visible);
    assert!(
        (t.x - 1.0).abs() < 1e-9 && (t.y - 3.0).abs() < 1e-9,
        "{t:?}"
    );
    // Out of view, it is remembered and re-aimed from the new pose.
    h.input(TrackIn::BARCODES, Barcodes::default());
    h.input(
        TrackIn::ODOMETRY,
        Odometry {
            x: 1.0,
            y: 1.0,
            theta: PI / 2.0,
            v: 0.0,
            w: 0.0,
        },
    );
    let t = *h.step().unwrap().output(TrackOut::TARGET).unwrap();
    assert!(t.seen && !t.visible && t.bearing.abs() < 1e-9 && (t.range - 2.0).abs() < 1e-9);
}

/// A pass of the robot along `path` (x, y, heading per cycle) in `world`, with the
/// simulator's sonar model read group by group as the device reports it; `each` gets
/// the pose as odometry.
pub(crate) fn pass<S: Skill>(
    h: &mut Harness<S>,
    world: &str,
    path: impl Iterator<Item = (f64, f64, f64)>,
    mut each: impl FnMut(&mut Harness<S>, &Odometry),
) {
    use denning_sim::sim::Sim;
    use denning_sim::world::World;
    let mut sim = Sim::new(World::parse(world, "test").unwrap(), 3);
    let mut s = Sonar {
        range: [f64::NAN; SONARS],
        age_ms: [f64::INFINITY; SONARS],
    };
    for (k, (x, y, th)) in path.enumerate() {
        sim.pose = [x, y, th];
        for i in 0..SONARS {
            s.age_ms[i] += 10.0;
            if i % 3 == k % 3 {
                s.set_reading(i, sim.sonar(i).map_or(Echo::Silent, Echo::Range), 0.0);
            }
        }
        let od = Odometry {
            x,
            y,
            theta: th,
            v: 0.3,
            w: 0.0,
        };
        h.input("sonar", s);
        each(h, &od);
    }
}

/// A wall along x = 2 with a 1.2 m opening from y = 0.4 to 1.6, the barcode south of it.
const DOOR_WORLD: &str = "name = 'door'\nstart = [0.0, 0.0, 0.0]\n\
    [[wall]]\nfrom = [2.0, -3.0]\nto = [2.0, 0.4]\n\
    [[wall]]\nfrom = [2.0, 1.6]\nto = [2.0, 4.0]\n\
    [[barcode]]\nid = 7\nat = [1.95, -0.4]\n";

/// The door's barcode at `code`, seen before and out of view now, from pose `od`.
pub(crate) fn remembered(code: (f64, f64), od: &Odometry) -> Target {
    let (dx, dy) = (code.0 - od.x, code.1 - od.y);
    Target {
        seen: true,
        visible: false,
        id: 7,
        x: code.0,
        y: code.1,
        range: dx.hypot(dy),
        bearing: wrap(dy.atan2(dx) - od.theta),
    }
}

#[test]
fn door_locate_finds_the_opening_from_a_pass_along_the_wall() {
    let mut h = Harness::<DoorLocate>::new();
    let code = (1.95, -0.4);
    // Drive north 1 m from the wall, past the barcode and the opening.
    let path = (0..140).map(|k| (1.0, -1.5 + 0.03 * f64::from(k), PI / 2.0));
    let mut last = Door::default();
    pass(&mut h, DOOR_WORLD, path, |h, od| {
        h.input(DoorIn::ODOMETRY, *od);
        h.input(DoorIn::TARGET, remembered(code, od));
        last = *h.step().unwrap().output(DoorOut::DOOR).unwrap();
    });
    assert!(last.found, "{last:?}");
    assert!(
        (last.x - 2.0).abs() < 0.1 && (last.y - 1.0).abs() < 0.15,
        "the opening's centre: {last:?}"
    );
    assert!(last.heading.abs() < 0.05, "through the wall: {last:?}");
    assert!((last.width - 1.2).abs() < 0.3, "its width: {last:?}");
}

#[test]
fn door_locate_sees_no_door_in_a_plain_wall() {
    let mut h = Harness::<DoorLocate>::new();
    let world = "name = 'wall'\nstart = [0.0, 0.0, 0.0]\n\
        [[wall]]\nfrom = [2.0, -3.0]\nto = [2.0, 4.0]\n";
    let path = (0..140).map(|k| (1.0, -1.5 + 0.03 * f64::from(k), PI / 2.0));
    pass(&mut h, world, path, |h, od| {
        h.input(DoorIn::ODOMETRY, *od);
        h.input(DoorIn::TARGET, remembered((1.95, -0.4), od));
        let d = *h.step().unwrap().output(DoorOut::DOOR).unwrap();
        assert!(!d.found, "no opening, no door: {d:?}");
    });
}

#[test]
fn wall_follow_keeps_its_distance_and_turns_away_from_a_wall_ahead() {
    // Parallel to a wall 1 m away on the right: turn right toward 0.5 m.
    let mut h = Harness::<WallFollow>::new();
    let world = "name = 'wall'\nstart = [0.0, 0.0, 0.0]\n\
        [[wall]]\nfrom = [-5.0, -1.36]\nto = [5.0, -1.36]\n\
        [[wall]]\nfrom = [3.0, -5.0]\nto = [3.0, 5.0]\n";
    let mut d = Drive::default();
    pass(&mut h, world, (0..3).map(|_| (0.0, 0.0, 0.0)), |h, _| {
        d = *h.step().unwrap().output(DriveOut::DRIVE).unwrap();
    });
    assert!(
        d.translate > 0.0 && d.rotate < 0.0,
        "toward the wall: {d:?}"
    );
    // Heading into the wall at 40°: turn away (left).
    pass(&mut h, world, (0..3).map(|_| (0.0, -0.5, -0.7)), |h, _| {
        d = *h.step().unwrap().output(DriveOut::DRIVE).unwrap();
    });
    assert!(d.rotate > 0.0, "away from the wall: {d:?}");
    // The wall ahead (x = 3) close: turn left on the spot.
    pass(&mut h, world, (0..3).map(|_| (2.2, -0.5, 0.0)), |h, _| {
        d = *h.step().unwrap().output(DriveOut::DRIVE).unwrap();
    });
    assert!(d.translate == 0.0 && d.rotate > 0.0, "{d:?}");
    // The same on the left side, mirrored.
    h.set(WallFollowParams::SIDE, -1).unwrap();
    let mirrored = "name = 'wall'\nstart = [0.0, 0.0, 0.0]\n\
        [[wall]]\nfrom = [-5.0, 1.36]\nto = [5.0, 1.36]\n";
    pass(&mut h, mirrored, (0..3).map(|_| (0.0, 0.0, 0.0)), |h, _| {
        d = *h.step().unwrap().output(DriveOut::DRIVE).unwrap();
    });
    assert!(d.rotate > 0.0, "toward the wall on the left: {d:?}");
}

#[test]
fn wander_drives_on_and_bounces_off_what_is_ahead() {
    let mut h = Harness::<Wander>::new();
    h.input(WanderIn::SONAR, ring(|_| 5.0));
    h.input(WanderIn::ODOMETRY, Odometry::default());
    let d = *h.step().unwrap().output(DriveOut::DRIVE).unwrap();
    assert!(d.translate >= 0.0);
    // Something close ahead: the next heading is the open side (here: behind).
    let mut h = Harness::<Wander>::new();
    h.set(WanderParams::LOOK, 0.0).unwrap();
    h.input(
        WanderIn::SONAR,
        ring(|a| if a.abs() < 2.0 { 0.5 } else { 5.0 }),
    );
    h.input(WanderIn::ODOMETRY, Odometry::default());
    let d = *h.step().unwrap().output(DriveOut::DRIVE).unwrap();
    assert!(
        d.translate == 0.0 && d.rotate.abs() > 0.5,
        "turns around: {d:?}"
    );
}

/// The outputs of a skill driven by `feed` for `steps` steps, restarted before every `every`-th
/// step (0: never) as a `kill -9` and a new process given the kept state would restart it.
fn outputs_restarted_every<S: Skill, T: Message + std::fmt::Debug>(
    every: u64,
    steps: u64,
    port: OutputRef<T, S::Outputs<'static>>,
    mut feed: impl FnMut(&mut Harness<S>, u64),
) -> Vec<String> {
    let mut h = Harness::<S>::new();
    h.restarting(every);
    (0..steps)
        .map(|k| {
            feed(&mut h, k);
            format!("{:?}", h.step().unwrap().output(port))
        })
        .collect()
}

/// Sonar readings that change from cycle to cycle (each new, ranges of a room 2–6 m across).
fn varying_ring(k: u64) -> Sonar {
    let mut s = ring(|a| 4.0 + 2.0 * (a * 3.0 + k as f64 * 0.01).sin());
    s.age_ms = [(k % 3) as f64 * 5.0; SONARS];
    s
}

/// Odometry of a robot driving a slow circle.
fn circling(k: u64) -> Odometry {
    let t = k as f64 * 0.004;
    Odometry {
        x: 2.0 * t.cos(),
        y: 2.0 * t.sin(),
        theta: wrap(t + PI / 2.0),
        v: 0.2,
        w: 0.1,
    }
}

#[test]
fn a_restarted_wander_draws_on_as_if_never_killed() {
    let feed = |h: &mut Harness<Wander>, k| {
        h.input(WanderIn::SONAR, varying_ring(k))
            .input(WanderIn::ODOMETRY, circling(k));
    };
    let once = outputs_restarted_every(0, 1500, DriveOut::DRIVE, feed);
    assert_eq!(
        outputs_restarted_every(7, 1500, DriveOut::DRIVE, feed),
        once,
        "the same map and generator after every restart"
    );
    // A fresh process would not draw the same (the test has teeth).
    let mut fresh = Harness::<Wander>::new();
    let forgetful: Vec<String> = (0..1500)
        .map(|k| {
            if k % 7 == 0 {
                fresh = Harness::new();
            }
            feed(&mut fresh, k);
            format!("{:?}", fresh.step().unwrap().output(DriveOut::DRIVE))
        })
        .collect();
    assert_ne!(forgetful, once);
}

#[test]
fn a_restarted_explore_goes_on_covering_as_if_never_killed() {
    let feed = |h: &mut Harness<Explore>, k| {
        h.input(ExploreIn::SONAR, varying_ring(k))
            .input(ExploreIn::ODOMETRY, circling(k));
    };
    assert_eq!(
        outputs_restarted_every(13, 3000, DriveOut::DRIVE, feed),
        outputs_restarted_every(0, 3000, DriveOut::DRIVE, feed),
    );
}

#[test]
fn a_restarted_door_locate_keeps_its_readings_and_its_door() {
    let run = |every| {
        let mut h = Harness::<DoorLocate>::new();
        h.restarting(every);
        let path = (0..140).map(|k| (1.0, -1.5 + 0.03 * f64::from(k), PI / 2.0));
        let mut doors = Vec::new();
        pass(&mut h, DOOR_WORLD, path, |h, od| {
            h.input(DoorIn::ODOMETRY, *od);
            h.input(DoorIn::TARGET, remembered((1.95, -0.4), od));
            doors.push(*h.step().unwrap().output(DoorOut::DOOR).unwrap());
        });
        doors
    };
    let restarted = run(3);
    assert!(restarted.last().unwrap().found);
    assert_eq!(format!("{restarted:?}"), format!("{:?}", run(0)));
}

#[test]
fn restarted_go_through_wall_follow_avoid_and_home_go_on_as_if_never_killed() {
    let door = Door {
        found: true,
        x: 3.0,
        y: 0.0,
        heading: 0.0,
        width: 1.2,
    };
    // A robot that closes on the door from the side, with walls near and far.
    let od = |k: u64| Odometry {
        x: k as f64 * 0.004,
        y: 1.0 - k as f64 * 0.002,
        theta: 0.0,
        v: 0.3,
        w: 0.0,
    };
    let through = |h: &mut Harness<GoThrough>, k| {
        h.input(GoIn::DOOR, door)
            .input(GoIn::SONAR, varying_ring(k))
            .input(GoIn::ODOMETRY, od(k));
    };
    assert_eq!(
        outputs_restarted_every(5, 800, GoOut::DRIVE, through),
        outputs_restarted_every(0, 800, GoOut::DRIVE, through),
    );
    let near = |k: u64| {
        let mut s = ring(|a| 0.4 + 0.3 * (a + k as f64 * 0.05).cos().abs());
        s.age_ms = [0.0; SONARS];
        s
    };
    let follow = |h: &mut Harness<WallFollow>, k| {
        h.input(SonarIn::SONAR, near(k));
    };
    assert_eq!(
        outputs_restarted_every(5, 800, DriveOut::DRIVE, follow),
        outputs_restarted_every(0, 800, DriveOut::DRIVE, follow),
    );
    let avoid = |h: &mut Harness<Avoid>, k| {
        h.input(SonarIn::SONAR, near(k));
    };
    assert_eq!(
        outputs_restarted_every(5, 800, DriveOut::DRIVE, avoid),
        outputs_restarted_every(0, 800, DriveOut::DRIVE, avoid),
    );
    // home held at a box on the line to its target: going round starts after 8 s (800
    // cycles) counted across the restarts.
    let held = |h: &mut Harness<Home>, _| {
        h.input(
            HomeIn::TARGET,
            Target {
                seen: true,
                range: 4.0,
                ..Target::default()
            },
        )
        .input(
            HomeIn::SONAR,
            ring(|a| if a.abs() < 0.7 { 0.3 } else { 5.0 }),
        );
    };
    let home = outputs_restarted_every(5, 1000, DriveOut::DRIVE, held);
    assert_eq!(
        home,
        outputs_restarted_every(0, 1000, DriveOut::DRIVE, held)
    );
    assert_ne!(home[0], home[999], "it went round");
}

#[test]
fn stop_proposes_standing_still() {
    let mut h = Harness::<Stop>::new();
    assert_eq!(
        *h.step().unwrap().output(DriveOut::DRIVE).unwrap(),
        Drive::default()
    );
}

#[test]
fn go_through_heads_for_the_axis_then_through() {
    let mut h = Harness::<GoThrough>::new();
    let door = Door {
        found: true,
        x: 3.0,
        y: 0.0,
        heading: 0.0,
        width: 1.2,
    };
    h.input(GoIn::DOOR, door);
    h.input(GoIn::SONAR, ring(|_| 5.0));
    h.input(
        GoIn::ODOMETRY,
        Odometry {
            x: 0.0,
            y: 1.0,
            theta: 0.0,
            v: 0.0,
            w: 0.0,
        },
    );
    let d = *h.step().unwrap().output(GoOut::DRIVE).unwrap();
    assert!(
        d.rotate < 0.0,
        "turns toward the approach point below: {d:?}"
    );
}

/// The robot's way in exit-lab-clutter seed 8 (lock-step), every 0.5 s from the barcode seen
/// (92.6 s) to the door reported (128.2 s): home on the barcode, near it along the wall on
/// the left past the door, then away west between the boxes. World frame, (x, y, heading).
const CLUTTER_SEED_8: &[(f64, f64, f64)] = &[
    (4.77, 3.17, 0.13),
    (4.92, 3.21, 0.27),
    (5.09, 3.26, 0.33),
    (5.25, 3.32, 0.36),
    (5.41, 3.38, 0.37),
    (5.58, 3.44, 0.37),
    (5.74, 3.51, 0.38),
    (5.90, 3.57, 0.38),
    (6.07, 3.64, 0.38),
    (6.23, 3.70, 0.38),
    (6.39, 3.77, 0.38),
    (6.55, 3.83, 0.38),
    (6.71, 3.90, 0.38),
    (6.88, 3.96, 0.38),
    (7.04, 4.03, 0.38),
    (7.20, 4.10, 0.38),
    (7.36, 4.16, 0.38),
    (7.53, 4.23, 0.38),
    (7.69, 4.29, 0.38),
    (7.85, 4.36, 0.38),
    (8.01, 4.42, 0.38),
    (8.18, 4.49, 0.38),
    (8.34, 4.55, 0.38),
    (8.48, 4.62, 0.51),
    (8.59, 4.72, 0.96),
    (8.67, 4.85, 1.10),
    (8.75, 4.97, 0.81),
    (8.87, 5.06, 0.54),
    (8.98, 5.13, 0.53),
    (8.99, 5.14, 0.16),
    (8.99, 5.14, -0.44),
    (8.99, 5.14, -1.04),
    (9.00, 5.11, -1.56),
    (8.99, 4.99, -1.68),
    (8.99, 4.84, -1.38),
    (9.03, 4.69, -1.24),
    (9.07, 4.55, -1.46),
    (9.08, 4.40, -1.38),
    (9.14, 4.26, -0.92),
    (9.26, 4.17, -0.45),
    (9.40, 4.12, -0.34),
    (9.51, 4.06, -0.65),
    (9.53, 4.04, -1.10),
    (9.54, 4.01, -1.55),
    (9.54, 3.99, -2.00),
    (9.50, 3.95, -2.48),
    (9.38, 3.90, -2.94),
    (9.23, 3.88, -3.09),
    (9.08, 3.86, -2.81),
    (8.96, 3.78, -2.27),
    (8.94, 3.75, -2.09),
    (8.94, 3.75, -2.34),
    (8.94, 3.75, -2.93),
    (8.92, 3.76, 2.84),
    (8.81, 3.82, 2.50),
    (8.70, 3.92, 2.29),
    (8.59, 4.03, 2.50),
    (8.46, 4.09, 2.87),
    (8.31, 4.13, 2.81),
    (8.18, 4.20, 2.57),
    (8.05, 4.27, 2.71),
    (7.91, 4.30, -3.05),
    (7.76, 4.26, -2.67),
    (7.63, 4.19, -2.73),
    (7.49, 4.14, -2.99),
    (7.34, 4.12, -2.95),
    (7.20, 4.07, -2.49),
    (7.11, 3.95, -2.03),
    (7.05, 3.81, -2.01),
    (6.99, 3.73, -2.36),
    (6.87, 3.64, -2.65),
];

/// exit-lab-clutter seed 8, from its sonar geometry: door_locate on the run's way (the simulator's
/// sonar, exact odometry). Before the fix the wall's refit followed the few readings that met
/// it while the robot was beside the door and walking away, and the door came out 1.3 m wide,
/// 0.2 m off its centre and askew, so go_through pushed a post for 172 s. Any door reported
/// now is the real one (x = 10, y 3.4–4.6): its centre and heading, and no wider than it is.
#[test]
#[ignore = "a known flaw: with the refit on the newest 1200 readings the door first reported on \
            this way is 0.16 m off and 6° askew, as before (the refit on every reading kept \
            passes it, and failed seeds 18 and 19 in closed loop: docs/deliver.md)"]
fn door_locate_keeps_to_the_real_door_on_clutter_seed_8s_way() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../devices/denning-sim/worlds/exit-lab-clutter.toml");
    let world = std::fs::read_to_string(path).unwrap();
    let poses = CLUTTER_SEED_8.windows(2).flat_map(|w| {
        let ((x0, y0, t0), (x1, y1, t1)) = (w[0], w[1]);
        (0..50).map(move |k| {
            let f = f64::from(k) / 50.0;
            (
                x0 + f * (x1 - x0),
                y0 + f * (y1 - y0),
                wrap(t0 + f * wrap(t1 - t0)),
            )
        })
    });
    let mut h = Harness::<DoorLocate>::new();
    let mut doors = Vec::new();
    pass(&mut h, &world, poses, |h, od| {
        h.input(DoorIn::ODOMETRY, *od);
        h.input(DoorIn::TARGET, remembered((9.95, 5.2), od));
        doors.push(*h.step().unwrap().output(DoorOut::DOOR).unwrap());
    });
    for (k, d) in doors.iter().enumerate().filter(|(_, d)| d.found) {
        assert!(
            (d.x - 10.0).abs() < 0.15 && (d.y - 4.0).abs() < 0.12,
            "cycle {k}: the centre is off: {d:?}"
        );
        assert!(d.heading.abs() < 0.07, "cycle {k}: askew: {d:?}");
        assert!(d.width < 1.4, "cycle {k}: wider than it is: {d:?}");
    }
    eprintln!("last: {:?}", doors.last());
}

/// Building C seed 17: between the posts the door's estimate jumped 1.5 m along the wall and
/// 20° round, and go_through, steering for a point ahead on the new axis, turned the robot
/// 70° into the corridor. Once in the doorway it holds the door it is passing: a far estimate
/// is ignored, a near one (a refinement) is taken, and the robot goes straight through.
#[test]
fn go_through_holds_the_door_it_is_passing_and_only_refines_it() {
    let door = Door {
        found: true,
        x: 3.0,
        y: 0.0,
        heading: 0.0,
        width: 1.2,
    };
    let moved = Door {
        x: 2.9,
        y: 1.5,
        heading: 0.35,
        ..door
    };
    let refined = Door {
        x: 3.1,
        y: 0.05,
        heading: 0.03,
        ..door
    };
    let mut h = Harness::<GoThrough>::new();
    h.input(GoIn::SONAR, ring(|_| 5.0));
    // A unicycle from the approach point, heading along the axis.
    let (mut x, mut y, mut th) = (2.0f64, 0.0f64, 0.0f64);
    let mut through = false;
    for k in 0..1000 {
        // Into the doorway the estimate moves far, then a little.
        let along = x - 3.0;
        let estimate = if along < -0.3 {
            door
        } else if k % 2 == 0 {
            moved
        } else {
            refined
        };
        h.input(GoIn::DOOR, estimate);
        h.input(
            GoIn::ODOMETRY,
            Odometry {
                x,
                y,
                theta: th,
                v: 0.3,
                w: 0.0,
            },
        );
        let step = h.step().unwrap();
        let (d, p) = (
            *step.output(GoOut::DRIVE).unwrap(),
            *step.output(GoOut::PROGRESS).unwrap(),
        );
        if p.done {
            through = true;
            break;
        }
        th += d.rotate * 0.01;
        x += d.translate * 0.01 * th.cos();
        y += d.translate * 0.01 * th.sin();
        assert!(
            th.abs() < 0.15 && y.abs() < 0.1,
            "step {k}: off the door's axis at ({x:.2}, {y:.2}, {th:.2}): {p:?}"
        );
    }
    assert!(through, "never through: at ({x:.2}, {y:.2}, {th:.2})");
    // The refinement was taken: through is 0.8 m past the refined door line (x = 3.1).
    assert!(x > 3.1 + 0.75, "through at x = {x:.2}");
}

/// The door located from a pass along its wall stays where it is while the robot turns and
/// walks away (few readings then meet the wall near the barcode, and those aslant): the wall
/// is refitted only on clearly more agreeing readings.
#[test]
#[ignore = "a known flaw: with the refit on the newest 1200 readings the door turns 5.6° as the \
            robot walks away (the refit on every reading kept passes it: docs/deliver.md)"]
fn door_locate_holds_the_door_while_the_robot_walks_away() {
    let along = (0..140).map(|k| (1.0, -1.5 + 0.03 * f64::from(k), PI / 2.0));
    let turn = (0..160).map(|k| (1.0, 2.7, PI / 2.0 + PI * f64::from(k) / 160.0));
    let away = (0..500).map(|k| (1.0 - 0.006 * f64::from(k), 2.7 - 0.004 * f64::from(k), PI));
    let mut h = Harness::<DoorLocate>::new();
    let mut doors = Vec::new();
    pass(
        &mut h,
        DOOR_WORLD,
        along.chain(turn).chain(away),
        |h, od| {
            h.input(DoorIn::ODOMETRY, *od);
            h.input(DoorIn::TARGET, remembered((1.95, -0.4), od));
            doors.push(*h.step().unwrap().output(DoorOut::DOOR).unwrap());
        },
    );
    assert!(doors[139].found, "found on the pass: {:?}", doors[139]);
    for (k, d) in doors.iter().enumerate().filter(|(_, d)| d.found) {
        assert!(
            (d.x - 2.0).abs() < 0.15 && (d.y - 1.0).abs() < 0.15 && d.heading.abs() < 0.07,
            "cycle {k}: the door moved: {d:?}"
        );
    }
}

/// Pushing a post in front of the door line (the robot does not move; the left front sonars
/// read near), go_through backs off and aims 0.15 m to the right of the estimate.
#[test]
fn go_through_aims_away_from_a_post_it_cannot_pass() {
    let door = Door {
        found: true,
        x: 3.0,
        y: 0.0,
        heading: 0.0,
        width: 1.2,
    };
    let mut h = Harness::<GoThrough>::new();
    h.input(GoIn::DOOR, door);
    // Lined up at the approach point, then against a post ahead on the left 0.5 m before the
    // line (in front of the side sonars, which would turn it away from the post instead).
    let at = |x: f64, v: f64| Odometry {
        x,
        y: 0.0,
        theta: 0.0,
        v,
        w: 0.0,
    };
    h.input(GoIn::SONAR, ring(|_| 5.0))
        .input(GoIn::ODOMETRY, at(2.0, 0.3));
    h.step().unwrap();
    h.input(
        GoIn::SONAR,
        ring(|a| if (0.0..0.45).contains(&a) { 0.2 } else { 5.0 }),
    )
    .input(GoIn::ODOMETRY, at(2.5, 0.0));
    let mut backing = 0;
    for _ in 0..400 {
        let d = *h.step().unwrap().output(GoOut::DRIVE).unwrap();
        if d.translate < 0.0 {
            backing += 1;
        }
    }
    assert!(backing > 0, "never backed off");
    // Backed off: it lines up on an axis 0.15 m to the right (y = -0.15).
    h.input(GoIn::SONAR, ring(|_| 5.0))
        .input(GoIn::ODOMETRY, at(1.0, 0.0));
    let p = *h.step().unwrap().output(GoOut::PROGRESS).unwrap();
    assert!((p.value + 2.0).abs() < 1e-9, "{p:?}");
    let d = *h.step().unwrap().output(GoOut::DRIVE).unwrap();
    assert!(
        d.rotate < 0.0,
        "turns right toward the moved approach point: {d:?}"
    );
}

#[test]
fn a_detour_leaves_an_approach_alone_until_it_is_held_with_something_on_the_line() {
    // 10 ms cycles: HELD_S is 800 of them, ROUND_S 3000.
    let open = ring(|_| 5.0);
    // A box ahead, 0.3 m from the ring over the front ±40°, clear elsewhere.
    let boxed = ring(|a| if a.abs() < 0.7 { 0.3 } else { 5.0 });
    let mut d = Detour::default();
    for _ in 0..2000 {
        assert_eq!(
            d.steer(&open, 0.2, 4.0, 10.0, Watch::Line),
            0.2,
            "held, the line clear"
        );
    }
    let mut d = Detour::default();
    for k in 0..800 {
        assert_eq!(
            d.steer(&boxed, 0.0, 4.0, 10.0, Watch::Line),
            0.0,
            "cycle {k}: not held 8 s yet"
        );
    }
    let first = d.steer(&boxed, 0.0, 4.0, 10.0, Watch::Line);
    assert!(first.abs() > 0.7, "round the box: {first}");
    for _ in 0..3000 {
        assert_eq!(
            d.steer(&boxed, 0.0, 4.0, 10.0, Watch::Line).signum(),
            first.signum()
        );
    }
    // Given up after 30 s: straight again, then held 8 s more, round the other side.
    assert_eq!(d.steer(&boxed, 0.0, 4.0, 10.0, Watch::Line), 0.0);
    for _ in 0..800 {
        d.steer(&boxed, 0.0, 4.0, 10.0, Watch::Line);
    }
    let second = d.steer(&boxed, 0.0, 4.0, 10.0, Watch::Line);
    assert!(
        second.signum() == -first.signum() && second.abs() > 0.7,
        "{second}"
    );
    // The line clear (round the box): straight at once.
    assert_eq!(d.steer(&open, 0.3, 3.5, 10.0, Watch::Line), 0.3);
    // Getting nearer resets the count: a slow approach with the box ahead is left alone.
    let mut d = Detour::default();
    for k in 0..5000 {
        let far = 4.0 - 0.3 * f64::from(k / 700);
        assert_eq!(
            d.steer(&boxed, 0.0, far.max(1.5), 10.0, Watch::Line),
            0.0,
            "cycle {k}"
        );
    }
}

#[test]
fn a_detour_goes_round_a_corner_its_body_clips_that_no_sonar_facing_the_goal_hears() {
    // A box's corner at the right front, 0.1 m from the ring, for the sonars facing 45–90°
    // right; none facing within 15° of the goal (straight ahead) hears it, but the body's
    // corridor toward the goal clips it (building F seed 5's lining up above a box).
    let corner = ring(|a| if (-1.6..-0.7).contains(&a) { 0.1 } else { 5.0 });
    let mut d = Detour::default();
    for k in 0..800 {
        assert_eq!(
            d.steer(&corner, 0.0, 2.0, 10.0, Watch::LineAndBody),
            0.0,
            "cycle {k}: not held 8 s yet"
        );
    }
    let round = d.steer(&corner, 0.0, 2.0, 10.0, Watch::LineAndBody);
    assert!(
        round > 0.3,
        "round on the left, away from the corner: {round}"
    );
    for _ in 0..100 {
        assert!(
            d.steer(&corner, 0.0, 2.0, 10.0, Watch::LineAndBody) > 0.3,
            "still round"
        );
    }
    // Past the corner (the ring clear): straight again.
    assert_eq!(
        d.steer(&ring(|_| 5.0), 0.0, 1.8, 10.0, Watch::LineAndBody),
        0.0
    );
    // Watching the line only (`home`'s), the corner beside it holds nothing.
    let mut d = Detour::default();
    for _ in 0..2000 {
        assert_eq!(d.steer(&corner, 0.0, 2.0, 10.0, Watch::Line), 0.0);
    }
}
