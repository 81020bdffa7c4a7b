//! The paper's whole mission end to end, in lock-step: `skillfab demo deliver` starts the
//! building simulator on a pty, the Denning device process (drive, pusher, speaker), every
//! skill of the mission and a manager in a private domain, and the plan takes the robot out of
//! the basement lab, up in an elevator and to the office, where the simulator's ground truth
//! must say the message was delivered. Lock-step makes the run a function of the seed, so
//! this run is the one measured in docs/deliver.md.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use skillfab_tests::{TestDomain, repo_root};

/// The demo's one run (`--json`), which must have delivered the message with no collision.
fn the_delivered_run(out: &std::process::Output) -> serde_json::Value {
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "demo failed: {stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value = serde_json::from_str(stdout.lines().next().unwrap()).unwrap();
    let run = summary["runs_detail"][0].clone();
    assert_eq!(summary["successes"], 1, "{run}");
    assert_eq!(run["collisions"], 0, "{run}");
    run
}

#[test]
fn the_plan_takes_the_robot_from_the_lab_to_the_office_and_the_message_is_delivered() {
    let t = TestDomain::new("deliver");
    let root = repo_root();
    let building = root.join("devices/denning-sim/buildings/building-a.toml");
    let plan = root.join("skills/plans/deliver.xml");
    let picture = t.dir.join("deliver.svg");
    let rec = t.dir.join("deliver.mcap");
    let out = t
        .command("skillfab")
        .current_dir(&root)
        .args(["demo", "deliver", "--lockstep", "--seed", "1", "--json"])
        .arg("--building")
        .arg(&building)
        .arg("--plan")
        .arg(&plan)
        .arg("--plot")
        .arg(&picture)
        .arg("--record")
        .arg(&rec)
        .output()
        .unwrap();
    let run = &the_delivered_run(&out);
    // It ended on the fourth floor, at the office door (goal: (9.5, 18.2), radius 2 m).
    let end = &run["end"];
    assert_eq!(end[0], 4, "{run}");
    let (x, y) = (end[1].as_f64().unwrap(), end[2].as_f64().unwrap());
    assert!((x - 9.5).hypot(y - 18.2) < 2.0, "{run}");
    // The mission's steps, in order, at increasing cycles.
    let order = skillfab_tests::steps_at(
        run,
        &[
            "the lab door's barcode seen",
            "through the door",
            "the call button in view",
            "the call button pressed",
            "a car is open",
            "inside the car",
            "the floor's button pressed",
            "the indicator says the floor",
            "out of the car",
            "its door on the right",
            "the message said",
            "the message is delivered",
        ],
    );
    assert!(order.windows(2).all(|w| w[0].0 < w[1].0), "{run}");
    assert!(
        order.windows(2).all(|w| w[0].1 <= w[1].1),
        "cycles increase: {run}"
    );
    // The picture has a map of each floor the robot was on: the basement and the fourth.
    let svg = std::fs::read_to_string(&picture).unwrap();
    assert!(svg.contains(">floor 0<") && svg.contains(">floor 4 (the office: room 405)<"));

    // Each skill of the building killed (SIGKILL) in the middle of its part of the mission
    // and started again, in a replay of the recorded run: every output from there on is the
    // uninterrupted run's (the skills of the lab are killed so in replay.rs).
    let building = [
        "hall_follow",
        "intersection",
        "door_detect",
        "sign_read",
        "car_watch",
        "enter_car",
        "leave_car",
        "push_button",
        "deliver",
    ];
    let (kills, kill_list) = crate::replay::mid_mission_kills(&rec, &building, &[]);
    let (r, out) = crate::replay::replay(
        &t,
        &rec,
        &[
            "--skills",
            &building.join(","),
            "--kill",
            &kill_list,
            "--to",
            &crate::replay::through_last_kill(&kills),
        ],
    );
    assert!(out.status.success(), "{r}");
    crate::replay::assert_identical_through(&r, &kills);
}

/// A car that does not come: every car stays where it is and no hall call is answered for
/// the first 600 simulated seconds, so `BoardACar` fails after its six calls. The plan's
/// runner says the robot is in floor 0's lobby, plans again from there
/// (`skillfab sequence --replan`) and runs that plan: a car is called again, and the message
/// is delivered. With `--no-replan` the same run fails where the boarding failed
/// (docs/deliver.md measures both).
#[test]
fn a_car_that_does_not_come_is_planned_around_from_the_lobby() {
    let t = TestDomain::new("replan");
    let root = repo_root();
    let out = t
        .command("skillfab")
        .current_dir(&root)
        .args(["demo", "deliver", "--lockstep", "--seed", "1", "--json"])
        .args(["--cars-out-until", "600"])
        .output()
        .unwrap();
    let run = &the_delivered_run(&out);
    let order = skillfab_tests::steps_at(
        run,
        &[
            "the call button pressed",
            "board a car: attempt 5 failed",
            "a step failed with the robot believed to be in the lobby of floor 0: planned again",
            "a car is open",
            "out of the car",
            "the message said",
        ],
    );
    assert!(order.windows(2).all(|w| w[0].0 < w[1].0), "{run}");
    // No car came before the plan was made again, and the first plan failed only there.
    let replanned = order[2].0;
    let steps = run["steps"].as_array().unwrap();
    assert!(
        steps[..replanned]
            .iter()
            .all(|s| !s[0].as_str().unwrap().starts_with("a car is open")),
        "{run}"
    );
    assert!(
        steps
            .iter()
            .all(|s| !s[0].as_str().unwrap().contains("the plan ended: Failure")),
        "{run}"
    );
}

/// A room's door not found: building B's 406 faces 405 across the corridor, and with a map
/// that leaves that out the plan waits for a door on the right alone, which `door_detect`
/// does not say where both sides open at once. The robot goes on past it to the corridor's
/// end; the wait for the door says that dead end, the runner plans again from there, and
/// turned round the robot finds the door on its left. (Seed 2 passes the door; on the build
/// before the guard the run waited there until its limit: docs/deliver.md.)
#[test]
fn a_rooms_door_not_found_is_looked_for_again_from_the_corridors_end() {
    let t = TestDomain::new("doorend");
    let root = repo_root();
    let building = root.join("devices/denning-sim/buildings/building-b.toml");
    let shipped =
        std::fs::read_to_string(root.join("devices/denning-sim/buildings/building-b.map.toml"))
            .unwrap();
    let map = shipped.replace("facing = [[405, 406]]\n", "");
    assert_ne!(map, shipped);
    let map_file = t.dir.join("building-b-no-facing.map.toml");
    std::fs::write(&map_file, map).unwrap();
    let out = t
        .command("skillfab")
        .current_dir(&root)
        .args([
            "demo",
            "deliver",
            "--lockstep",
            "--seed",
            "2",
            "--json",
            "--to",
            "406",
        ])
        .arg("--building")
        .arg(&building)
        .arg("--map")
        .arg(&map_file)
        .output()
        .unwrap();
    let run = &the_delivered_run(&out);
    let order = skillfab_tests::steps_at(
        run,
        &[
            "the office's sign in view",
            "stopped at a dead end",
            "a step failed with the robot believed to be at the dead end of the map's leg 7: planned again",
            "its door on the left",
            "the message said",
        ],
    );
    assert!(order.windows(2).all(|w| w[0].0 < w[1].0), "{run}");
}
