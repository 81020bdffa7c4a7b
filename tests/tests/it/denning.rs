//! The Denning robot end to end: simulator on a real pty, the device process on the same code
//! path as a real serial port, a real manager.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use nix::sys::signal::Signal;
use skillfab_client::Client;
use skillfab_proto::control::EventKind;
use skillfab_proto::value::Value;
use skillfab_tests::{TestDomain, bin};
use std::path::{Path, PathBuf};
use std::time::Duration;

struct Robot {
    t: TestDomain,
    sim: usize,
    dev: usize,
    link: PathBuf,
    world: PathBuf,
    trajectory: PathBuf,
    client: Client,
}

fn field(v: &Value, name: &str) -> Value {
    match v {
        Value::Struct(f) => f.iter().find(|(n, _)| n == name).unwrap().1.clone(),
        other => panic!("not a struct: {other}"),
    }
}

fn num(c: &Client, path: &str) -> Option<f64> {
    c.query(path).ok().and_then(|(v, _)| v.as_f64())
}

impl Robot {
    fn start(tag: &str, sim_args: &[&str]) -> Robot {
        let mut t = TestDomain::new(tag);
        let world = t.dir.join("room.toml");
        std::fs::write(&world, skillfab_tests::BOX_ROOM).unwrap();
        let link = t.dir.join("robot");
        let trajectory = t.dir.join("trajectory.csv");
        t.spawn(
            "skillfab",
            &["manager", "--period-ms", "20", "--deadline-ms", "2000"],
        );
        let sim = Self::spawn_sim(&mut t, &world, &link, &trajectory, sim_args);
        let dev = t.spawn("denning", &["--port", link.to_str().unwrap()]);
        let board = t.board();
        t.wait_until("the device to register", || {
            skillfab_tests::registered(&board, "denning").is_some()
        });
        let client = Client::connect(&t.domain).unwrap();
        let r = Robot {
            t,
            sim,
            dev,
            link,
            world,
            trajectory,
            client,
        };
        r.wait_connected(1);
        r
    }

    fn spawn_sim(
        t: &mut TestDomain,
        world: &Path,
        link: &Path,
        traj: &Path,
        extra: &[&str],
    ) -> usize {
        let mut args = vec![
            "--world",
            world.to_str().unwrap(),
            "--link",
            link.to_str().unwrap(),
            "--trajectory",
            traj.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let i = t.spawn("denning-sim", &args);
        t.wait_until("the simulator's link", || link.exists());
        i
    }

    fn wait_connected(&self, connects: u64) {
        self.t.wait_until("the robot link", || {
            self.client.query("denning.link").is_ok_and(|(v, _)| {
                field(&v, "connected") == Value::Bool(true)
                    && field(&v, "connects").as_f64().unwrap_or(0.0) >= connects as f64
                    && field(&v, "frames").as_f64().unwrap_or(0.0) > 3.0
            })
        });
    }

    /// Collision steps so far (ground truth: steps in which the robot pushed into a wall).
    fn collisions(&self) -> f64 {
        let text = std::fs::read_to_string(&self.trajectory).unwrap_or_default();
        let last = text.lines().last().unwrap_or("");
        last.split(',')
            .nth(7)
            .and_then(|c| c.parse().ok())
            .unwrap_or(f64::NAN)
    }

    /// Last ground-truth row: (x, y, v).
    fn truth(&self) -> (f64, f64, f64) {
        let text = std::fs::read_to_string(&self.trajectory).unwrap_or_default();
        let last = text.lines().last().unwrap_or("");
        let f: Vec<f64> = last.split(',').filter_map(|x| x.parse().ok()).collect();
        if f.len() < 5 {
            (f64::NAN, f64::NAN, f64::NAN)
        } else {
            (f[1], f[2], f[4])
        }
    }
}

#[test]
fn sonar_readings_match_the_world_geometry() {
    let r = Robot::start("sonar", &[]);
    // Sonar 0 faces the east wall: 6 − 2 − 0.36 = 3.64 m; sonar 6 faces north: 4 − 2 − 0.36.
    r.t.wait_until("sonar 0 and 6", || {
        let s0 = num(&r.client, "denning.sonar.range[0]").unwrap_or(f64::NAN);
        let s6 = num(&r.client, "denning.sonar.range[6]").unwrap_or(f64::NAN);
        (s0 - 3.64).abs() < 0.15 && (s6 - 1.64).abs() < 0.1
    });
    // The barcode on the east wall, straight ahead, 3.95 m away.
    r.t.wait_until("the barcode", || {
        num(&r.client, "denning.barcodes.count") == Some(1.0)
            && num(&r.client, "denning.barcodes.id[0]") == Some(9.0)
            && num(&r.client, "denning.barcodes.range[0]").is_some_and(|d| (d - 3.95).abs() < 0.1)
    });
}

#[test]
fn a_drive_proposal_moves_the_robot_and_the_robot_watchdog_stops_it() {
    let mut r = Robot::start("drive", &[]);
    let go =
        r.t.spawn("proposer", &["--name", "go", "--param", "translate=0.3"]);
    r.t.wait_until("odometry to advance", || {
        num(&r.client, "denning.odometry.x").is_some_and(|x| x > 0.2)
    });
    r.t.wait_until("the simulated robot to move", || r.truth().0 > 2.2);
    // Kill the device mid-motion: nobody feeds the robot's watchdog, which stops it (2 s).
    let _ = go;
    r.t.signal(r.dev, Signal::SIGKILL);
    r.t.wait_exit(r.dev);
    r.t.wait_until("the robot's watchdog to stop the drive", || {
        r.truth().2 == 0.0
    });
}

#[test]
fn the_safety_layer_stops_the_robot_short_of_a_wall_a_proposer_drives_at() {
    let mut r = Robot::start("safety", &[]);
    // Full speed at the east wall, 3.64 m ahead: nothing in the skills stops it.
    r.t.spawn("proposer", &["--name", "go", "--param", "translate=0.5"]);
    r.t.wait_until("the robot to move", || r.truth().2 > 0.1);
    r.t.wait_until("the device to stop it", || {
        num(&r.client, "denning.safety.stopped").is_some_and(|n| n > 20.0) && r.truth().2 == 0.0
    });
    let (x, _, _) = r.truth();
    assert!(x < 6.0 - 0.36, "short of the wall: {x}");
    assert!(x > 6.0 - 0.36 - 0.4, "close to it, not far: {x}");
    assert_eq!(r.collisions(), 0.0);
    // It still turns, and backs away, on the same proposer's word.
    r.client.set_param("go", "translate", "-0.2").unwrap();
    r.t.wait_until("the robot to back away", || r.truth().2 < -0.1);

    // With the layer off, the same proposer drives it into the wall.
    r.client.set_param("denning", "safety", "false").unwrap();
    r.client.set_param("go", "translate", "0.5").unwrap();
    r.t.wait_until("a collision", || r.collisions() > 0.0);
}

#[test]
fn a_lost_manager_stops_the_robot_and_the_next_manager_drives_it_again() {
    let mut r = Robot::start("mgrlost", &[]);
    let manager = 0; // Robot::start spawns the manager first.
    r.t.spawn("proposer", &["--name", "go", "--param", "translate=0.3"]);
    r.t.wait_until("the simulated robot to move", || r.truth().2 > 0.1);
    // No manager, no cycles: the device's command goes stale and it sends stop (500 ms)
    // while it keeps the link and the robot's watchdog fed.
    r.t.signal(manager, Signal::SIGKILL);
    r.t.wait_exit(manager);
    r.t.wait_until("the device to stop the drive", || r.truth().2 == 0.0);
    assert!(
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(r.t.pid(r.dev) as i32), None).is_ok(),
        "the device process outlives its manager"
    );
    // A new manager: device and proposer register with it and the robot drives on.
    r.t.spawn(
        "skillfab",
        &["manager", "--period-ms", "20", "--deadline-ms", "2000"],
    );
    r.t.wait_until("the robot to move again", || r.truth().2 > 0.1);
}

#[test]
fn corrupted_bytes_are_counted_and_data_keeps_flowing() {
    let r = Robot::start("corrupt", &["--corrupt-rate", "0.01", "--seed", "3"]);
    let link = |c: &Client| c.query("denning.link").unwrap().0;
    let first = field(&link(&r.client), "frames").as_f64().unwrap();
    r.t.wait_until("bad frames counted while good ones keep coming", || {
        let l = link(&r.client);
        field(&l, "bad_frames").as_f64().unwrap() > 0.0
            && field(&l, "frames").as_f64().unwrap() > first + 20.0
    });
    assert!(num(&r.client, "denning.sonar.range[0]").is_some());
}

#[test]
fn the_device_survives_the_simulator_restarting() {
    let mut r = Robot::start("simrestart", &[]);
    r.t.signal(r.sim, Signal::SIGKILL);
    r.t.wait_exit(r.sim);
    let _ = std::fs::remove_file(&r.link);
    r.t.wait_until("the device to notice", || {
        r.client
            .query("denning.link")
            .is_ok_and(|(v, _)| field(&v, "connected") == Value::Bool(false))
    });
    let (world, link, traj) = (r.world.clone(), r.link.clone(), r.trajectory.clone());
    r.sim = Robot::spawn_sim(&mut r.t, &world, &link, &traj, &["--seed", "2"]);
    r.wait_connected(2);
}

#[test]
fn a_restarted_simulator_resumes_the_robot_where_it_was() {
    let mut r = Robot::start("simresume", &[]);
    // Restart the first simulator with a state file (Robot::start's has none).
    let state = r.t.dir.join("robot.state");
    let (world, link, traj) = (r.world.clone(), r.link.clone(), r.trajectory.clone());
    let state_arg = state.to_str().unwrap().to_string();
    r.t.signal(r.sim, Signal::SIGKILL);
    r.t.wait_exit(r.sim);
    let _ = std::fs::remove_file(&link);
    r.sim = Robot::spawn_sim(&mut r.t, &world, &link, &traj, &["--state", &state_arg]);
    r.wait_connected(2);
    r.t.spawn("proposer", &["--name", "go", "--param", "translate=0.3"]);
    r.t.wait_until("the robot to drive 0.3 m", || r.truth().0 > 2.3);

    // Killed mid-motion and started again with the same state: the same robot, where it was.
    r.t.signal(r.sim, Signal::SIGKILL);
    r.t.wait_exit(r.sim);
    let before = r.truth();
    let rows_before = std::fs::read_to_string(&traj).unwrap().lines().count();
    let _ = std::fs::remove_file(&link);
    r.sim = Robot::spawn_sim(&mut r.t, &world, &link, &traj, &["--state", &state_arg]);
    r.wait_connected(3);
    r.t.wait_until("the resumed robot's first rows", || {
        std::fs::read_to_string(&traj).unwrap().lines().count() > rows_before + 2
    });
    let text = std::fs::read_to_string(&traj).unwrap();
    let first_after: Vec<f64> = text
        .lines()
        .nth(rows_before)
        .unwrap()
        .split(',')
        .filter_map(|x| x.parse().ok())
        .collect();
    // The state is saved with every ground-truth row: at most one row of motion apart.
    assert!(
        (first_after[1] - before.0).abs() < 0.1,
        "x {} -> {}",
        before.0,
        first_after[1]
    );
    assert!(
        (first_after[2] - before.1).abs() < 0.1,
        "y {} -> {}",
        before.1,
        first_after[2]
    );
    // One trajectory, one clock: the header is not written again and time goes on.
    assert_eq!(text.lines().filter(|l| l.starts_with('t')).count(), 1);
    // And it drives on from there.
    r.t.wait_until("the robot to drive on", || r.truth().0 > before.0 + 0.2);
}

#[test]
fn hot_swap_of_the_device_under_a_running_manager() {
    let mut r = Robot::start("hotswap", &[]);
    r.client.subscribe().unwrap();
    let before = r.client.stats().unwrap().cycles;
    r.t.signal(r.dev, Signal::SIGKILL);
    r.t.wait_exit(r.dev);
    r.dev = r.t.spawn("denning", &["--port", r.link.to_str().unwrap()]);
    let (mut lost, mut back) = (false, false);
    while !(lost && back) {
        match r
            .client
            .next_event(Duration::from_secs(30))
            .unwrap()
            .expect("events")
            .kind
        {
            EventKind::DeviceLost { device } if device == "denning" => lost = true,
            EventKind::DeviceBack { device } if device == "denning" => back = true,
            _ => {}
        }
    }
    r.wait_connected(1);
    r.t.wait_until("fresh sonar again", || {
        r.client
            .query("denning.sonar.age_ms[0]")
            .is_ok_and(|(v, _)| v.as_f64().is_some_and(|a| a < 1000.0))
    });
    assert!(
        r.client.stats().unwrap().cycles > before,
        "the manager kept cycling"
    );
    let _ = bin("denning");
}

#[test]
fn odometry_keeps_its_frame_across_a_hot_swap() {
    let mut r = Robot::start("odomframe", &[]);
    let go =
        r.t.spawn("proposer", &["--name", "go", "--param", "translate=0.3"]);
    r.t.wait_until("odometry to pass 0.6 m", || {
        num(&r.client, "denning.odometry.x").is_some_and(|x| x > 0.6)
    });
    r.t.signal(go, Signal::SIGKILL);
    r.t.wait_exit(go);
    // Nobody proposes: the device sends the safe command (stop).
    r.t.wait_until("the robot to stop", || r.truth().2 == 0.0);
    r.t.wait_until("odometry to report the stop", || {
        num(&r.client, "denning.odometry.v") == Some(0.0)
    });
    let x = num(&r.client, "denning.odometry.x").unwrap();
    let y = num(&r.client, "denning.odometry.y").unwrap();
    let board = r.t.board();
    let old = skillfab_tests::registered(&board, "denning")
        .unwrap()
        .decl
        .pid;
    r.t.signal(r.dev, Signal::SIGKILL);
    r.t.wait_exit(r.dev);
    r.dev = r.t.spawn("denning", &["--port", r.link.to_str().unwrap()]);
    let new = r.t.pid(r.dev);
    assert_ne!(old, new);
    r.t.wait_until("the new device process to register", || {
        skillfab_tests::registered(&board, "denning")
            .is_some_and(|s| s.decl.pid == new && s.runs > 0)
    });
    let k = skillfab_tests::cycle(&board);
    // A sample the new process took from the robot after connecting (its own counters).
    let mut odom = (f64::NAN, f64::NAN);
    r.t.wait_until("odometry from the new device process", || {
        let link = r.client.query("denning.link");
        let fresh = link.is_ok_and(|(v, c)| {
            c > k
                && field(&v, "connected") == Value::Bool(true)
                && field(&v, "frames").as_f64().is_some_and(|f| f > 3.0)
        });
        if let (true, Ok((v, c))) = (fresh, r.client.query("denning.odometry")) {
            odom = (
                field(&v, "x").as_f64().unwrap_or(f64::NAN),
                field(&v, "y").as_f64().unwrap_or(f64::NAN),
            );
            return c > k;
        }
        false
    });
    // The new process continues the frame: where the robot stands is where it stood.
    let (x2, y2) = odom;
    assert!(
        (x2 - x).abs() < 0.01 && (y2 - y).abs() < 0.01,
        "odometry ({x:.3}, {y:.3}) before the swap, ({x2:.3}, {y2:.3}) after"
    );
}
