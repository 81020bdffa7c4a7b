//! The fabric log end to end: parameter changes and a skill's I/O samples in an MCAP file
//! (read back with the `mcap` crate, as Foxglove would), replayed into a fresh fabric; and the
//! default JSON-lines log in the log directory.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use serde_json::Value as Json;
use skillfab_client::Client;
use skillfab_proto::param::ParamValue;
use skillfab_tests::TestDomain;

/// Stops `skillfab up` with SIGINT, as Ctrl-C would.
fn stop(t: &mut TestDomain, up: usize) {
    t.signal(up, nix::sys::signal::Signal::SIGINT);
    assert!(t.wait_exit(up).success());
}

#[test]
fn an_mcap_log_holds_changes_and_samples_and_replays() {
    let mut t = TestDomain::new("mcaplog");
    let file = t.dir.join("run.mcap");
    let up = t.hello(&["--param-log", file.to_str().unwrap()]);
    let client = Client::connect(&t.domain).unwrap();
    t.ctl(&["set", "scale.gain=4"]);
    t.ctl(&["iolog", "scale", "on"]);
    assert!(t.ctl(&["logging"]).contains("run.mcap"));
    let from = client.stats().unwrap().cycles;
    t.wait_until("50 logged cycles", || {
        client.stats().unwrap().cycles > from + 50
    });
    t.ctl(&["iolog", "scale", "off"]);
    drop(client);
    stop(&mut t, up);

    let bytes = std::fs::read(&file).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a fabric stopped cleanly writes the MCAP summary");
    let topics: Vec<&str> = summary
        .channels
        .values()
        .map(|c| c.topic.as_str())
        .collect();
    for want in [
        "/skillfab/param",
        "/skillfab/iolog",
        "/scale/in/tick",
        "/scale/out/scaled",
    ] {
        assert!(topics.contains(&want), "{want} missing from {topics:?}");
    }
    // Samples are CDR with ROS 2 schemas, the other records JSON.
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == "/scale/out/scaled" {
            let schema = m.channel.schema.as_ref().unwrap();
            assert_eq!(schema.name, "skillfab/msg/Scaled");
            assert_eq!(schema.encoding, "ros2msg");
            assert_eq!(m.channel.message_encoding, "cdr");
        } else if m.channel.topic == "/skillfab/param" {
            assert_eq!(m.channel.message_encoding, "json");
        }
    }
    let mut samples = 0;
    let mut last_cycle = 0;
    let mut params = Vec::new();
    skillfab_manager::recorder::read_file(&file, |r| {
        use skillfab_manager::recorder::ReadRecord;
        let (topic, j) = match r {
            ReadRecord::Json(j) => (format!("/skillfab/{}", j["kind"].as_str().unwrap()), j),
            ReadRecord::Sample(s) => {
                let c = &s.channel;
                (format!("/{}/{}/{}", c.skill, c.dir, c.port), s.to_json())
            }
        };
        match topic.as_str() {
            "/scale/out/scaled" => {
                // scaled = gain × tick, and the ticker's tick is the cycle number.
                let cycle = j["cycle"].as_u64().unwrap();
                assert_eq!(
                    j["value"]["value"].as_f64().unwrap(),
                    4.0 * cycle as f64,
                    "{j}"
                );
                assert!(cycle > last_cycle, "each sample once, in order: {j}");
                last_cycle = cycle;
                samples += 1;
            }
            "/scale/in/tick" => assert_eq!(j["value"]["value"], j["cycle"], "{j}"),
            "/skillfab/param" => params.push(j),
            _ => {}
        }
    })
    .unwrap();
    assert!(samples >= 45, "{samples} output samples over 50 cycles");
    assert_eq!(params.len(), 1);
    assert_eq!(params[0]["skill"], "scale");
    assert_eq!(params[0]["new"], 4.0);

    // A fresh fabric gets the recorded change back through the same validated requests.
    let mut t2 = TestDomain::new("mcapreplay");
    let up2 = t2.hello(&[]);
    let client = Client::connect(&t2.domain).unwrap();
    assert_eq!(
        client.get_param("scale", "gain").unwrap(),
        ParamValue::Float(2.0)
    );
    t2.ctl(&["reapply", file.to_str().unwrap()]);
    assert_eq!(
        client.get_param("scale", "gain").unwrap(),
        ParamValue::Float(4.0)
    );
    drop(client);
    stop(&mut t2, up2);
    // The replayed change is in t2's own (default, JSON-lines) log.
    let logs: Vec<_> = std::fs::read_dir(&t2.dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "jsonl"))
        .collect();
    assert_eq!(logs.len(), 1, "{logs:?}");
    let name = logs[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(name.starts_with(t2.domain.name()), "{name}");
    let text = std::fs::read_to_string(&logs[0]).unwrap();
    assert!(
        text.lines()
            .map(|l| serde_json::from_str::<Json>(l).unwrap())
            .any(|j| j["kind"] == "param" && j["new"] == 4.0),
        "{text}"
    );
}

#[test]
fn a_fabric_nobody_changed_leaves_no_log_file() {
    let mut t = TestDomain::new("nolog");
    let up = t.hello(&[]);
    stop(&mut t, up);
    let logs: Vec<_> = std::fs::read_dir(&t.dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "jsonl" || e == "mcap"))
        .collect();
    assert!(logs.is_empty(), "{logs:?}");
}
