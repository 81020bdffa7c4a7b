//! The navigation skills as the building skills changed them: barcode_track and go_through.

use super::*;
use crate::nav::{GoIn, GoOut, TrackIn, TrackOut, TrackParams};

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
    h.set(TrackParams::ID, 7).unwrap();
    h.input(TrackIn::BARCODES, seen(7, 0.0))
        .input(TrackIn::ODOMETRY, Odometry::default());
    assert!(h.step().unwrap().output(TrackOut::TARGET).unwrap().seen);
    h.set(TrackParams::ID, 850).unwrap();
    h.input(TrackIn::BARCODES, seen(7, 10.0));
    let t = *h.step().unwrap().output(TrackOut::TARGET).unwrap();
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
    h.input(GoIn::SONAR, ring(|_| 5.0));
    h.input(GoIn::DOOR, skillfab_msgs::Door::default())
        .input(GoIn::ODOMETRY, Odometry::default());
    let p = *h.step().unwrap().output(GoOut::PROGRESS).unwrap();
    assert_eq!((p.phase, p.done), (0, false), "no door yet");
    h.input(GoIn::DOOR, door);
    let at = |h: &mut Harness<crate::nav::GoThrough>, x: f64| {
        h.input(
            GoIn::ODOMETRY,
            Odometry {
                x,
                ..Odometry::default()
            },
        );
        h.step().unwrap();
        *h.step().unwrap().output(GoOut::PROGRESS).unwrap()
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
