//! Signs and the message: sign_read reading the floor and room signs, deliver saying the
//! message near its room.

use super::*;

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
fn sign_read_says_whether_the_floor_read_is_the_one_its_parameter_names() {
    let mut g = Gapped::<SignRead>::new();
    g.input("barcodes", frame(&[(904, 1.0, 0.0)], 20.0));
    let s = g.step_at::<Signs>(1, "signs").unwrap();
    assert!(
        s.floor_known && s.floor == 4 && !s.at_floor,
        "no floor named: {s:?}"
    );
    g.params.floor = 4;
    let s = g.step_at::<Signs>(2, "signs").unwrap();
    assert!(s.at_floor, "{s:?}");
    g.params.floor = 0;
    let s = g.step_at::<Signs>(3, "signs").unwrap();
    assert!(!s.at_floor, "{s:?}");
    g.input("barcodes", frame(&[(900, 1.0, 0.0)], 20.0));
    let s = g.step_at::<Signs>(4, "signs").unwrap();
    assert!(s.at_floor && s.floor == 0, "{s:?}");
    // Reactivated: nothing read yet, so not at floor 0 even though `floor` reads 0.
    g.input("barcodes", frame(&[], f64::INFINITY));
    let s = g.step_at::<Signs>(30, "signs").unwrap();
    assert!(!s.floor_known && s.floor == 0 && !s.at_floor, "{s:?}");
}

/// Also with both skills restarted (as after `kill -9`) every 3 cycles: a restarted deliver
/// that forgot what it said would say it again.
#[test]
fn deliver_says_the_message_once_near_its_room() {
    for every in [0, 3] {
        deliver_once(every);
    }
}

fn deliver_once(every: u64) {
    // Along a corridor past room 403's sign, to room 405's.
    let walls = [[-1.0, 1.2, 20.0, 1.2], [-1.0, -1.2, 20.0, -1.2]];
    let signs = barcode(403, 5.0, 1.15) + &barcode(405, 10.0, 1.15);
    let mut r = Robot::new(&world([0.0, 0.0, 0.0], &walls, &signs), 11);
    let mut read = Harness::<SignRead>::new();
    let mut deliver = Harness::<Deliver>::new();
    read.restarting(every);
    deliver.restarting(every);
    let mut decided_at = None;
    let mut progress = Progress::default();
    while r.sim.pose[0] < 9.5 {
        read.input(SignIn::BARCODES, r.barcodes);
        let s = *read.step().unwrap().output(SignsOut::SIGNS).unwrap();
        deliver
            .input(DeliverIn::SIGNS, s)
            .input(DeliverIn::VOICE, r.voice);
        let step = deliver.step().unwrap();
        progress = *step.output(DeliverOut::PROGRESS).unwrap();
        let say = step.output(DeliverOut::SAY).copied().unwrap_or_else(silent);
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
    h.input(DeliverIn::SIGNS, Signs::default())
        .input(DeliverIn::VOICE, Voice { said: 3, seq: 9 });
    let step = h.step().unwrap();
    assert!(step.output(DeliverOut::SAY).is_none(), "nothing to say yet");
    h.input(DeliverIn::SIGNS, near);
    let step = h.step().unwrap();
    let say = *step.output(DeliverOut::SAY).unwrap();
    assert_ne!(say.seq, 0);
    assert!(!step.output(DeliverOut::PROGRESS).unwrap().done);
    h.input(
        DeliverIn::VOICE,
        Voice {
            said: 4,
            seq: say.seq,
        },
    );
    let step = h.step().unwrap();
    assert_eq!(
        step.output(DeliverOut::SAY).unwrap().seq,
        say.seq,
        "the same message"
    );
    assert!(step.output(DeliverOut::PROGRESS).unwrap().done);
}
