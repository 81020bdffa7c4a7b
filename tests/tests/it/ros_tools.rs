//! A recording read by the ROS tools: every message of a recorded lock-step exit-lab run
//! decodes with the PyPI packages `mcap` and `mcap-ros2-support` (samples as CDR through their
//! ros2msg schemas, the fabric's own records as JSON), and the robot's sensors read as sensors.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use skillfab_tests::{TestDomain, python_deps, repo_root};

#[test]
fn the_ros_tools_decode_every_message_of_a_recording() {
    let t = TestDomain::new("rostools");
    let rec = t.dir.join("run.mcap");
    let world = t.doorway();
    let plan = repo_root().join("skills/plans/exit-lab.xml");
    let out = t.run(
        "skillfab",
        &[
            "demo",
            "exit-lab",
            "--world",
            world.to_str().unwrap(),
            "--plan",
            plan.to_str().unwrap(),
            "--lockstep",
            "--seed",
            "1",
            "--runs",
            "1",
            "--limit-s",
            "150",
            "--record",
            rec.to_str().unwrap(),
            "--json",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let read = std::process::Command::new("python3")
        .arg(repo_root().join("tests/scripts/ros_decode.py"))
        .arg(&rec)
        .env("PYTHONPATH", python_deps())
        .output()
        .unwrap();
    assert!(
        read.status.success(),
        "{}",
        String::from_utf8_lossy(&read.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&read.stdout).unwrap();
    assert_eq!(r["messages"], r["summary_messages"], "{r}");
    assert!(r["cdr"].as_u64().unwrap() > 1000, "samples: {r}");
    assert!(r["json"].as_u64().unwrap() > 100, "records: {r}");
    // The doorway room is a few metres across; the robot drove out through the door.
    let (near, far) = (
        r["sonar_min"].as_f64().unwrap(),
        r["sonar_max"].as_f64().unwrap(),
    );
    assert!(near > 0.0 && far < 20.0 && near < far, "{r}");
    assert!(r["moved_m"].as_f64().unwrap() > 0.5, "{r}");
}
