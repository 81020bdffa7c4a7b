//! Priority-based actuator arbitration across skill processes: a device serving `drive`,
//! skills proposing on it.

// Helpers of this test crate fail the test right where a step goes wrong.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use skillfab_client::Client;
use skillfab_proto::control::EventKind;
use skillfab_proto::value::Value;
use skillfab_tests::{TestDomain, registered};
use std::time::Duration;

/// `skillfab up` with a mock device and the given proposer entries, cycling every 5 ms.
fn network(
    tag: &str,
    device_args: &str,
    proposers: &[(&str, i32, f64, f64)],
) -> (TestDomain, Client) {
    network_at(tag, 5.0, device_args, proposers)
}

/// [`network`] with the given cycle period (0: back to back).
fn network_at(
    tag: &str,
    period_ms: f64,
    device_args: &str,
    proposers: &[(&str, i32, f64, f64)],
) -> (TestDomain, Client) {
    let mut t = TestDomain::new(tag);
    let mut launch = format!(
        "[manager]\nperiod_ms = {period_ms}\ndeadline_ms = 2000\n[[process]]\nname = \"dev\"\nbin = \"{{bin:mock-device}}\"\nargs = [{device_args}]\n"
    );
    for (name, prio, v, w) in proposers {
        launch.push_str(&format!(
            "[[process]]\nname = \"{name}\"\nbin = \"{{bin:proposer}}\"\npriority = {prio}\nparams = {{ translate = {v:?}, rotate = {w:?} }}\n"
        ));
    }
    let path = t.launch_file(&launch);
    t.spawn("skillfab", &["up", path.to_str().unwrap()]);
    let board = t.board();
    t.wait_until("the network to run", || {
        registered(&board, "dev").is_some_and(|s| s.runs > 3)
            && proposers
                .iter()
                .all(|(n, ..)| registered(&board, n).is_some_and(|s| s.runs > 3))
    });
    let c = Client::connect(&t.domain).unwrap();
    (t, c)
}

fn field<'a>(v: &'a Value, name: &str) -> &'a Value {
    match v {
        Value::Struct(f) => &f.iter().find(|(n, _)| n == name).unwrap().1,
        other => panic!("not a struct: {other}"),
    }
}

/// The channel's winner and command once the condition holds.
fn wait_channel(t: &TestDomain, c: &Client, what: &str, ok: impl Fn(&Value) -> bool) -> Value {
    let mut last = Value::Null;
    t.wait_until(what, || {
        last = match c.query("channel.drive") {
            Ok((v, cycle)) => {
                CYCLE.with(|k| k.set(cycle));
                v
            }
            Err(_) => Value::Null,
        };
        last != Value::Null && ok(&last)
    });
    last
}

/// Whether the command in a channel query is from the cycle of the arbitration record.
fn same_cycle(v: &Value) -> bool {
    match (field(v, "command_cycle"), v) {
        (Value::UInt(c), Value::Struct(_)) => CYCLE.with(|k| k.get() == *c),
        _ => false,
    }
}

thread_local! {
    /// The record's cycle of the last query (set by `wait_channel`).
    static CYCLE: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

fn winner(v: &Value) -> Option<String> {
    match field(v, "winner") {
        Value::Text(s) => Some(s.clone()),
        _ => None,
    }
}

fn translate(v: &Value) -> f64 {
    field(field(v, "command"), "translate").as_f64().unwrap()
}

#[test]
fn the_higher_priority_wins_and_a_runtime_priority_change_flips_it_next_cycle() {
    let (t, mut c) = network("prio", "", &[("lo", 1, 1.0, 0.0), ("hi", 2, 2.0, 0.0)]);
    let v = wait_channel(&t, &c, "hi to win", |v| winner(v).as_deref() == Some("hi"));
    assert_eq!(
        translate(&v),
        2.0,
        "the winner's proposal reaches the device: {v}"
    );
    assert_eq!(field(&v, "policy"), &Value::Text("priority".into()));
    // Both publish on the channel's topic; each skill's query shows its own proposal.
    for (skill, want) in [("lo", 1.0), ("hi", 2.0)] {
        for _ in 0..20 {
            let (got, _) = c.query(&format!("{skill}.drive.translate")).unwrap();
            assert_eq!(got.as_f64(), Some(want), "{skill}.drive");
        }
    }

    c.subscribe().unwrap();
    c.set_priority("lo", 5).unwrap();
    let mut changed_at = None;
    let mut flipped_at = None;
    while flipped_at.is_none() {
        let ev = c
            .next_event(Duration::from_secs(20))
            .unwrap()
            .expect("events");
        match ev.kind {
            EventKind::PriorityChanged {
                ref skill, new: 5, ..
            } if skill == "lo" => changed_at = Some(ev.cycle),
            EventKind::ChannelWinner {
                winner: Some(ref w),
                ..
            } if w == "lo" => flipped_at = Some(ev.cycle),
            _ => {}
        }
    }
    let (changed, flipped) = (changed_at.unwrap(), flipped_at.unwrap());
    // Asked between cycles `changed` and `changed + 1` (which may already be running): the
    // first cycle that starts afterwards has the new winner. One cycle of slack: the event's
    // cycle is the manager's count when it published it, read after the loop iteration.
    assert!(
        flipped <= changed + 3,
        "priority changed after cycle {changed}, winner flipped in {flipped}"
    );
    let v = c.query("channel.drive").unwrap().0;
    assert_eq!(translate(&v), 1.0);
    let stats = c.stats().unwrap();
    assert_eq!(stats.channels[0].channel, "drive");
    assert_eq!(stats.channels[0].winner, "lo");
}

#[test]
fn deactivating_or_killing_the_winner_hands_the_channel_over() {
    let (t, c) = network("handover", "", &[("lo", 1, 1.0, 0.0), ("hi", 2, 2.0, 0.0)]);
    wait_channel(&t, &c, "hi to win", |v| winner(v).as_deref() == Some("hi"));
    c.deactivate(&["hi"]).unwrap();
    wait_channel(&t, &c, "lo to take over", |v| {
        winner(v).as_deref() == Some("lo") && translate(v) == 1.0
    });
    c.activate(&["hi"]).unwrap();
    wait_channel(&t, &c, "hi back", |v| winner(v).as_deref() == Some("hi"));
    let board = t.board();
    let pid = registered(&board, "hi").unwrap().decl.pid;
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(pid as i32),
        nix::sys::signal::Signal::SIGKILL,
    )
    .unwrap();
    wait_channel(&t, &c, "lo after hi died", |v| {
        winner(v).as_deref() == Some("lo")
    });
    // The device got exactly one command per cycle throughout.
    let dev = c
        .list()
        .unwrap()
        .into_iter()
        .find(|s| s.name == "dev")
        .unwrap();
    assert_eq!(dev.figures.failures, 0);
}

#[test]
fn blend_is_the_exact_priority_weighted_mean() {
    let (t, c) = network(
        "blend",
        "\"--policy\", \"drive=blend\"",
        &[("a", 1, 1.0, -1.0), ("b", 3, 5.0, 3.0)],
    );
    // Both proposals in, and the command read from the same cycle as the record.
    let v = wait_channel(&t, &c, "a blend of both", |v| match field(v, "weights") {
        Value::Struct(w) => w.len() == 2 && same_cycle(v),
        _ => false,
    });
    assert_eq!(field(&v, "policy"), &Value::Text("blend".into()));
    assert_eq!(winner(&v), None);
    // (1·1 + 3·5) / 4 = 4 and (1·-1 + 3·3) / 4 = 2, exactly.
    assert_eq!(
        field(&v, "command").to_string(),
        r#"{"translate": 4, "rotate": 2}"#
    );
    assert_eq!(
        field(&v, "weights").to_string(),
        r#"{"a": 0.25, "b": 0.75}"#
    );
}

#[test]
fn nobody_proposing_yields_the_safe_command() {
    let (t, c) = network("safe", "", &[("quiet", 1, 3.0, 1.0)]);
    wait_channel(&t, &c, "quiet to win", |v| {
        winner(v).as_deref() == Some("quiet")
    });
    c.set_param("quiet", "propose", "false").unwrap();
    let v = wait_channel(&t, &c, "the safe command", |v| winner(v).is_none());
    assert_eq!(
        field(&v, "command").to_string(),
        r#"{"translate": 0, "rotate": 0}"#
    );
    assert_eq!(c.stats().unwrap().channels[0].winner, "safe");
    // Cycles go on: a proposer that does not propose does not stall the device.
    let k = c.stats().unwrap().cycles;
    t.wait_until("cycles without proposals", || {
        c.stats().unwrap().cycles > k + 20
    });
}

/// Watches `cycles` cycles of channel events: `winner` must win every one of them.
fn assert_never_loses(c: &mut Client, winner: &str, cycles: u64) {
    c.subscribe().unwrap();
    let from = c.stats().unwrap().cycles;
    let mut lost = Vec::new();
    // A fabric that stops cycling fails the test instead of hanging it.
    let deadline = std::time::Instant::now() + skillfab_tests::WAIT;
    while c.stats().unwrap().cycles < from + cycles {
        assert!(
            std::time::Instant::now() < deadline,
            "{cycles} cycles did not run within {:?}",
            skillfab_tests::WAIT
        );
        while let Some(ev) = c.next_event(Duration::from_millis(10)).unwrap() {
            if let EventKind::ChannelWinner { winner: w, .. } = ev.kind
                && w.as_deref() != Some(winner)
            {
                lost.push(ev.cycle);
            }
        }
    }
    assert!(
        lost.is_empty(),
        "cycles where the proposal was missed: {lost:?}"
    );
}

#[test]
fn a_proposal_made_in_every_cycle_is_never_missed() {
    // Back to back, a proposer's proposal and its "done" reach the device in either order;
    // the device must arbitrate on the proposal, never on "done, nothing proposed". A quiet
    // proposer finishing first must not cancel the device's cycle either; and the device
    // keeps more proposals than a subscriber may borrow samples.
    let (t, mut c) = network_at(
        "steady",
        0.0,
        "",
        &[
            ("only", 5, 1.0, 0.0),
            ("b", 1, 2.0, 0.0),
            ("c", 2, 3.0, 0.0),
            ("quiet", 9, 4.0, 0.0),
        ],
    );
    c.set_param("quiet", "propose", "false").unwrap();
    wait_channel(&t, &c, "only to win", |v| {
        winner(v).as_deref() == Some("only")
    });
    assert_never_loses(&mut c, "only", 3000);
}

#[test]
fn a_quiet_proposer_downstream_of_the_device_does_not_cancel_the_others() {
    // Proposers that read the device's state, as real controllers do. The quiet one finishes
    // first without proposing; that is no reason to cancel the device's cycle, nor the other
    // proposer's run with it.
    let mut t = TestDomain::new("reactors");
    let launch = t.launch_file(
        "[manager]\nperiod_ms = 0\ndeadline_ms = 2000\n\
         [[process]]\nname = \"dev\"\nbin = \"{bin:mock-device}\"\n\
         [[process]]\nname = \"steady\"\nbin = \"{bin:reactor}\"\npriority = 5\nparams = { translate = 1.0 }\n\
         [[process]]\nname = \"quiet\"\nbin = \"{bin:reactor}\"\npriority = 9\nparams = { propose = false }\n",
    );
    t.spawn("skillfab", &["up", launch.to_str().unwrap()]);
    let board = t.board();
    t.wait_until("the network to run", || {
        ["dev", "steady", "quiet"]
            .iter()
            .all(|n| registered(&board, n).is_some_and(|s| s.runs > 3))
    });
    let mut c = Client::connect(&t.domain).unwrap();
    wait_channel(&t, &c, "steady to win", |v| {
        winner(v).as_deref() == Some("steady")
    });
    assert_never_loses(&mut c, "steady", 3000);
    let s = c.stats().unwrap();
    let steady = s.skills.iter().find(|k| k.name == "steady").unwrap();
    assert_eq!(steady.figures.failures, 0, "no failed runs: {steady:?}");
}

#[test]
fn ties_go_to_the_name_that_sorts_first_in_every_run() {
    for order in [["beta", "alpha"], ["alpha", "beta"]] {
        let (t, c) = network(
            "tie",
            "",
            &[(order[0], 4, 1.0, 0.0), (order[1], 4, 2.0, 0.0)],
        );
        let v = wait_channel(&t, &c, "a winner", |v| winner(v).is_some());
        assert_eq!(winner(&v).as_deref(), Some("alpha"), "order {order:?}: {v}");
    }
}

#[test]
fn a_second_device_for_a_channel_is_refused() {
    let (t, _c) = network("twodev", "", &[]);
    // Its own state topic: only the channel is in conflict.
    let out = t.run(
        "mock-device",
        &["--name", "dev2", "--remap", "state=dev2_state"],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("channel 'drive' is already served by device 'dev'"),
        "{err}"
    );
}
