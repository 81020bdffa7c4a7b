//! The checker's refusals, one per way a map can contradict itself, and the planner's routes
//! on a small map and on the shipped ones.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use skillfab_planner::map::{Heading, Side, Turn};
use skillfab_planner::{
    Believed, From, Library, Map, PlanError, Step, Trip, map_beside, plan, plan_back,
    plan_back_from, plan_round_trip, plan_round_trip_from,
};
use std::path::Path;

/// A small building: the lab's door on the left of a corridor running north to a T; right at
/// the T the lobby (bank ahead); left at the T, room 9 at the corridor's end. Floor 1: out of
/// the lobby's left side beside the bank, north to a crossing; rooms on both sides after it.
const SMALL: &str = r#"
building = "small"
office = 105
floors = [0, 1]

[[lobby]]
floor = 0
openings = [{ leg = "to the lobby", wall = "opposite" }]

[[lobby]]
floor = 1
openings = [{ leg = "up", wall = "left", beside_bank = true }]

[[leg]]
name = "the lab's corridor"
floor = 0
from = "end"
to = "the T"
heading = "north"
left = ["door", "lab", 2]
right = [1]

[[junction]]
name = "the T"
floor = 0
arriving = "the lab's corridor"
left = "west"
right = "to the lobby"

[[leg]]
name = "west"
floor = 0
from = "the T"
to = "room 9"
heading = "west"

[[leg]]
name = "to the lobby"
floor = 0
from = "the T"
to = "lobby"
heading = "east"

[[leg]]
name = "up"
floor = 1
from = "lobby"
to = "the crossing"
heading = "north"

[[junction]]
name = "the crossing"
floor = 1
arriving = "up"
straight = "on"
left = "west arm"
right = "east arm"

[[leg]]
name = "on"
floor = 1
from = "the crossing"
to = "end"
heading = "north"
left = [101, 103]
right = [105]

[[leg]]
name = "west arm"
floor = 1
from = "the crossing"
to = "end"
heading = "west"

[[leg]]
name = "east arm"
floor = 1
from = "end"
to = "the crossing"
heading = "west"
right = [102]
"#;

/// The problems of SMALL with `from` replaced by `to` (which must occur in it).
fn problems(from: &str, to: &str) -> Vec<String> {
    problems_of(&[(from, to)])
}

/// The problems of SMALL with each (from, to) replaced, in turn.
fn problems_of(edits: &[(&str, &str)]) -> Vec<String> {
    let mut text = SMALL.to_string();
    for (from, to) in edits {
        assert!(text.contains(from), "{from}");
        text = text.replacen(from, to, 1);
    }
    match Map::parse(&text, "small.map.toml") {
        Ok(_) => Vec::new(),
        Err(e) => e.problems.iter().map(ToString::to_string).collect(),
    }
}

fn refused(from: &str, to: &str, expected: &str) {
    let p = problems(from, to);
    assert!(
        p.iter().any(|s| s == expected),
        "expected «{expected}», got {p:#?}"
    );
}

#[test]
fn the_small_map_is_sound() {
    let map = Map::parse(SMALL, "small.map.toml").unwrap();
    assert_eq!(map.rooms(), vec![2, 1, 101, 103, 105, 102, 9]);
}

#[test]
fn a_junction_whose_sides_disagree_with_its_legs_is_refused() {
    refused(
        "left = \"west\"\nright = \"to the lobby\"",
        "left = \"to the lobby\"\nright = \"west\"",
        "junction 'the T': its left, seen arriving along 'the lab's corridor' (heading north), \
         is west, but leg 'to the lobby' leaves it heading east",
    );
    // An arm that leaves the way the robot came is no side at all.
    refused(
        "heading = \"west\"\nright = [102]",
        "heading = \"east\"\nright = [102]",
        "junction 'the crossing': its right, seen arriving along 'up' (heading north), is east, \
         but leg 'east arm' leaves it heading west",
    );
}

#[test]
fn a_junction_must_name_every_leg_that_ends_there_and_only_those() {
    refused(
        "straight = \"on\"\n",
        "",
        "junction 'the crossing': leg 'on' ends there but the junction does not say on which side",
    );
    refused(
        "left = \"west arm\"",
        "left = \"up\"",
        "junction 'the crossing' lists leg 'up' twice",
    );
    refused(
        "right = \"to the lobby\"",
        "right = \"west arm\"",
        "junction 'the T' (floor 0): there is no leg 'west arm' on its floor",
    );
    // A bend: the T's west arm starts elsewhere.
    let p = problems_of(&[
        ("left = \"west\"\n", ""),
        (
            "from = \"the T\"\nto = \"room 9\"",
            "from = \"end\"\nto = \"room 9\"",
        ),
    ]);
    let bend = "junction 'the T' joins 2 legs: a junction joins 3 or 4 (a bend is part of a leg)";
    assert!(p.iter().any(|s| s == bend), "{p:#?}");
}

#[test]
fn a_room_on_two_doors_or_on_the_wrong_floor_is_refused() {
    refused(
        "right = [105]",
        "right = [105, 103]",
        "room 103 is listed on two doors: the left of leg 'on' (door 2) and the right of leg 'on' (door 2)",
    );
    refused(
        "right = [105]",
        "right = [205]",
        "room 205 is on the right of leg 'on' (door 1) (floor 1), but its number says floor 2",
    );
    refused(
        "right = [105]",
        "right = [\"office\"]",
        "leg 'on': 'office' on its right is not a door (a room number, \"door\" or \"lab\")",
    );
    refused(
        "right = [105]",
        "right = [105]\nfacing = [[101, 103]]",
        "leg 'on': rooms 101 and 103 face each other, so each must be on one of its sides",
    );
    refused(
        "office = 105",
        "office = 107",
        "the office, room 107, is on no door of the map",
    );
}

#[test]
fn a_leg_that_leads_nowhere_is_refused() {
    refused(
        "to = \"room 9\"",
        "to = \"the west wing\"",
        "leg 'west' leads to 'the west wing', which is no place of the map (a junction's name, \
         lab, lobby, room N or end)",
    );
    refused(
        "to = \"room 9\"",
        "to = \"the crossing\"",
        "leg 'west' (floor 0) leads to junction 'the crossing' on floor 1",
    );
}

#[test]
fn unreachable_places_floors_without_a_lobby_and_a_missing_lab_are_refused() {
    // The crossing's legs cut off from the lobby: everything past it is out of reach.
    let p = problems_of(&[
        (
            "from = \"lobby\"\nto = \"the crossing\"",
            "from = \"end\"\nto = \"the crossing\"",
        ),
        (
            "openings = [{ leg = \"up\", wall = \"left\", beside_bank = true }]",
            "",
        ),
    ]);
    for expected in [
        "junction 'the crossing' cannot be reached from the lab",
        "leg 'on' cannot be reached from the lab",
    ] {
        assert!(p.iter().any(|s| s == expected), "{expected}: {p:#?}");
    }
    refused(
        "floors = [0, 1]",
        "floors = [0, 1, 2]",
        "floor 2 has no lobby: the elevator bank serves every floor the map lists",
    );
    refused(
        "left = [\"door\", \"lab\", 2]",
        "left = [\"door\", 2]",
        "the map has no lab: name it on a leg's side (\"lab\") or at a leg's end (lab)",
    );
    refused(
        "from = \"lobby\"\nto = \"the crossing\"",
        "from = \"end\"\nto = \"the crossing\"",
        "the lobby of floor 1: leg 'up' does not lead to the lobby",
    );
    refused(
        "openings = [{ leg = \"to the lobby\", wall = \"opposite\" }]",
        "",
        "leg 'to the lobby' leads to the lobby of floor 0, but the lobby does not say in which wall it opens",
    );
    refused(
        "wall = \"left\", beside_bank = true",
        "wall = \"opposite\", beside_bank = true",
        "the lobby of floor 1: the opening of 'up' is in the opposite wall, so it cannot be beside the bank wall",
    );
    // A key the format does not have is refused, not ignored.
    let p = problems("heading = \"west\"\n", "heading = \"west\"\nlenght = 4\n");
    assert!(p[0].contains("unknown field `lenght`"), "{p:?}");
}

fn junctions(steps: &[Step]) -> Vec<(String, Turn)> {
    steps
        .iter()
        .filter_map(|s| match s {
            Step::Junction { name, turn, .. } => Some((name.clone(), *turn)),
            _ => None,
        })
        .collect()
}

#[test]
fn routes_turn_the_way_the_map_says_on_each_floor() {
    let map = Map::parse(SMALL, "small.map.toml").unwrap();
    // The office: out of the lab left (north), right at the T, straight in; out of the lobby's
    // left side (turning right with the bank wall behind), straight over the crossing.
    let r = plan(&map, None, From::Lab).unwrap();
    assert_eq!(r.steps[1], Step::IntoTheCorridor { turn: Turn::Left });
    assert!(r.steps.contains(&Step::OutOfTheLobby {
        floor: 1,
        turn: Turn::Right,
        beside_bank: true
    }));
    assert_eq!(
        junctions(&r.steps),
        [
            ("the T".into(), Turn::Right),
            ("the crossing".into(), Turn::Straight)
        ]
    );
    assert_eq!(
        r.steps.last(),
        Some(&Step::AtTheRoom {
            room: 105,
            side: Some(Side::Right),
            faced: false,
            // 'on' ends in a dead end past the door.
            missed: map.legs.iter().position(|l| l.name == "on"),
        })
    );
    // A room on a leg walked against its way: its side is the other one.
    let r = plan(&map, Some(102), From::Lab).unwrap();
    assert_eq!(junctions(&r.steps)[1], ("the crossing".into(), Turn::Right));
    assert!(r.steps.contains(&Step::Along {
        leg: "east arm".into(),
        heading: Heading::East
    }));
    assert_eq!(
        r.steps.last(),
        Some(&Step::AtTheRoom {
            room: 102,
            side: Some(Side::Left),
            faced: false,
            missed: map.legs.iter().position(|l| l.name == "east arm"),
        })
    );
    // On the lab's floor: no elevator. Room 2 is after the lab's door on its side (north):
    // left out of the door, on the left. Room 9 is at the end of the T's west arm.
    let r = plan(&map, Some(2), From::Lab).unwrap();
    assert_eq!(
        r.steps[1..],
        [
            Step::IntoTheCorridor { turn: Turn::Left },
            Step::Along {
                leg: "the lab's corridor".into(),
                heading: Heading::North
            },
            Step::AtTheRoom {
                room: 2,
                side: Some(Side::Left),
                faced: false,
                missed: None,
            },
        ]
    );
    let r = plan(&map, Some(9), From::Lab).unwrap();
    assert!(!r.steps.iter().any(|s| matches!(s, Step::Ride { .. })));
    assert_eq!(
        r.steps.last(),
        Some(&Step::AtTheRoom {
            room: 9,
            side: None,
            faced: false,
            missed: None,
        })
    );
    // Room 1 is across the corridor from the lab's door: whether it is north or south of it
    // the map cannot say (each side's doors are in order, not the two sides together).
    assert!(matches!(
        plan(&map, Some(1), From::Lab),
        Err(PlanError::NoWay { .. })
    ));
    assert!(matches!(
        plan(&map, Some(404), From::Lab),
        Err(PlanError::UnknownRoom { .. })
    ));
    assert!("room 405".parse::<From>().is_err());
}

/// SMALL's rooms as plans: each reads as the sequencer reads it; on the lab's floor no car
/// and `sign_read` on with the corridor skills; a door at a corridor's end is approached ahead.
#[test]
fn plans_on_the_labs_floor_and_to_a_corridors_end_read_and_say_so() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let library = std::fs::read_to_string(root.join("skills/plans/deliver.xml")).unwrap();
    let library = Library::parse(&library, "deliver.xml").unwrap();
    // On floor 4, the floor the library's ride goes to.
    let small = SMALL
        .replace("floors = [0, 1]", "floors = [0, 4]")
        .replace("floor = 1\n", "floor = 4\n")
        .replace("10", "40");
    let map = Map::parse(&small, "small.map.toml").unwrap();
    let xml = |room| {
        let xml = plan(&map, Some(room), From::Lab)
            .unwrap()
            .plan_xml(&library, "small")
            .unwrap();
        skillfab_sequence::Plan::parse(&xml, "planned").unwrap();
        // The route's own tree: up to the library's first.
        xml[..xml.find("<BehaviorTree ID=\"LeaveTheLab\"").unwrap()].to_string()
    };
    let to_9 = xml(9);
    assert!(!to_9.contains("RideToTheFloor"), "{to_9}");
    assert!(
        to_9.contains("<SubTree ID=\"ToTheOfficeAhead\"/>"),
        "{to_9}"
    );
    assert!(
        to_9.contains("skills=\"intersection, door_detect, hall_follow, sign_read\"")
            || to_9.contains("<Activate skills=\"sign_read\"/>"),
        "{to_9}"
    );
    // Out of the lobby beside the bank wall, with a crossing to count: the turn from where
    // the car left it, on the corridor's centre line, and counting started again after it.
    let to_405 = xml(405);
    for expected in [
        "<WithParam skill=\"hall_follow\" param=\"after\" value=\"0.25\">",
        "<SubTree ID=\"InTheCorridor\"/>",
        "condition=\"intersection.junction.count &gt;= 1\"/>",
        "<SubTree ID=\"ToTheOfficeOnTheRight\"/>",
    ] {
        assert!(to_405.contains(expected), "{expected}: {to_405}");
    }
    // A door on the right with one facing it: waited for on either side (door_detect says
    // left when both open at once).
    let faced = small.replace("right = [405]", "right = [405]\nfacing = [[403, 405]]");
    let faced = Map::parse(&faced, "small.map.toml").unwrap();
    let xml = plan(&faced, Some(405), From::Lab)
        .unwrap()
        .plan_xml(&library, "small")
        .unwrap();
    assert!(xml.contains("<SubTree ID=\"ToTheOfficeOnTheRightFacingADoor\"/>"));
    // The ride's floor is set before the ride: floor 4's button and indicator here.
    let ride = "<SubTree ID=\"BoardACar\"/>\n      \
                <SetParam skill=\"barcode_track\" param=\"id\" value=\"864\"/>\n      \
                <SetParam skill=\"sign_read\" param=\"floor\" value=\"4\"/>\n      \
                <SubTree ID=\"RideToTheFloor\"/>";
    assert!(to_405.contains(ride), "{to_405}");
    // A room on the fifth floor: its button is 865. A tenth floor has no button (860 + f
    // stays in its decade).
    let mut steps = plan(&map, Some(405), From::Lab).unwrap();
    for s in &mut steps.steps {
        if let Step::Ride { to, .. } = s {
            *to = 5;
        }
    }
    let xml = steps.plan_xml(&library, "small").unwrap();
    assert!(xml.contains("param=\"id\" value=\"865\""), "{xml}");
    assert!(xml.contains("param=\"floor\" value=\"5\""), "{xml}");
    for s in &mut steps.steps {
        if let Step::Ride { to, .. } = s {
            *to = 10;
        }
    }
    assert!(steps.plan_xml(&library, "small").is_err());
}

/// The way back from a room's door (the robot facing it): into the corridor toward the
/// lobby, the junctions the other way round, a car down, and the lab's door counted among
/// the doors on its side.
#[test]
fn the_way_back_turns_out_of_the_door_and_counts_the_labs_door_on_its_side() {
    let map = Map::parse(SMALL, "small.map.toml").unwrap();
    // 105 is on the right going north from the crossing: facing it, the lobby is to the
    // right. Straight over the crossing, into the lobby through its left side (turning left
    // to face the bank), down, straight out, left at the T (south), and the lab's door on
    // the right after door 2 (the lab's corridor lists ["door", "lab", 2] on its left going
    // north).
    let r = plan_back(&map, None).unwrap();
    assert_eq!((r.room, r.trip), (105, Trip::BackToTheLab));
    assert_eq!(
        r.steps[0],
        Step::OutOfTheRoom {
            room: 105,
            turn: Turn::Right
        }
    );
    assert!(r.steps.contains(&Step::IntoTheLobby {
        floor: 1,
        turn: Turn::Left
    }));
    assert!(r.steps.contains(&Step::Ride { from: 1, to: 0 }));
    assert_eq!(
        junctions(&r.steps),
        [
            ("the crossing".into(), Turn::Straight),
            ("the T".into(), Turn::Left)
        ]
    );
    assert_eq!(
        r.steps.last(),
        Some(&Step::AtTheLab {
            side: Some(Side::Right),
            doors_before: 1,
            // The lab's corridor ends south of the lab's door.
            missed: Some(0),
        })
    );
    // 102: on the right of the east arm, which runs west to the crossing, so on its north
    // side; facing it, the crossing (west) is to the left, and there the way south is left.
    let r = plan_back(&map, Some(102)).unwrap();
    assert_eq!(
        r.steps[0],
        Step::OutOfTheRoom {
            room: 102,
            turn: Turn::Left
        }
    );
    assert_eq!(junctions(&r.steps)[0], ("the crossing".into(), Turn::Left));
    // On the lab's own corridor: room 2 is north of the lab's door on its side; facing it,
    // the lab is to the left, and no door between.
    let r = plan_back(&map, Some(2)).unwrap();
    assert_eq!(
        r.steps,
        [
            Step::OutOfTheRoom {
                room: 2,
                turn: Turn::Left
            },
            Step::Along {
                leg: "the lab's corridor".into(),
                heading: Heading::South
            },
            Step::AtTheLab {
                side: Some(Side::Right),
                doors_before: 0,
                missed: Some(0),
            },
        ]
    );
    // Refused: a door at a corridor's end (the way back is a turn round), a room across the
    // lab's corridor (which way the lab is the map cannot say), a room not on the map.
    assert_eq!(plan_back(&map, Some(9)), Err(PlanError::NoWayBack(9)));
    assert!(matches!(
        plan_back(&map, Some(1)),
        Err(PlanError::NoWay { .. })
    ));
    assert!(matches!(
        plan_back(&map, Some(404)),
        Err(PlanError::UnknownRoom { .. })
    ));
}

/// The round trip is the way there, then the way back from the room's door, in one tree:
/// the second ride's floor is the lab's, the corridor skills on the way back go without
/// `sign_read`, and the lab's door is counted on its side.
#[test]
fn a_round_trip_is_one_tree_with_both_ways() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let library = std::fs::read_to_string(root.join("skills/plans/deliver.xml")).unwrap();
    let library = Library::parse(&library, "deliver.xml").unwrap();
    let map = Map::parse(SMALL, "small.map.toml").unwrap();
    let there = plan(&map, None, From::Lab).unwrap();
    let back = plan_back(&map, None).unwrap();
    let both = plan_round_trip(&map, None).unwrap();
    assert_eq!(both.trip, Trip::RoundTrip);
    assert_eq!(
        both.steps,
        [there.steps.clone(), back.steps.clone()].concat()
    );
    let xml = both.plan_xml(&library, "small").unwrap();
    let parsed = skillfab_sequence::Plan::parse(&xml, "planned").unwrap();
    assert_eq!(parsed.main, "deliver-to-105-and-back");
    let own = &xml[..xml.find("<BehaviorTree ID=\"LeaveTheLab\"").unwrap()];
    // The way there's tree is the round trip's first part, node for node.
    let there_xml = there.plan_xml(&library, "small").unwrap();
    let there_own = &there_xml[..there_xml.find("<BehaviorTree ID=\"LeaveTheLab\"").unwrap()];
    let body = |t: &str| {
        let from = t.find("<Sequence>").unwrap();
        t[from..t.rfind("</Sequence>").unwrap()].to_string()
    };
    assert!(body(own).starts_with(&body(there_own)), "{own}");
    let rest = &body(own)[body(there_own).len()..];
    for expected in [
        "<SubTree ID=\"OutOfTheOfficeRight\"/>",
        "<SetParam skill=\"barcode_track\" param=\"id\" value=\"860\"/>",
        "<SetParam skill=\"sign_read\" param=\"floor\" value=\"0\"/>",
        "<SubTree ID=\"DoorsCountedFromHere\"/>",
        "condition=\"door_detect.doors.right &gt;= 2\"",
        "<SubTree ID=\"AtTheLabsDoor\"/>",
    ] {
        assert!(rest.contains(expected), "{expected}: {rest}");
    }
    assert!(
        !rest.contains("sign_read\"/>") && !rest.contains(", sign_read"),
        "{rest}"
    );
    // The way back alone is the round trip's second part, node for node.
    let back_xml = back.plan_xml(&library, "small").unwrap();
    let back_own = &back_xml[..back_xml.find("<BehaviorTree ID=\"LeaveTheLab\"").unwrap()];
    assert_eq!(
        rest.trim(),
        body(back_own).trim_start_matches("<Sequence>").trim()
    );
}

#[test]
fn every_numbered_room_of_the_shipped_maps_has_a_plan_that_reads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let library = std::fs::read_to_string(root.join("skills/plans/deliver.xml")).unwrap();
    let library = Library::parse(&library, "deliver.xml").unwrap();
    for building in [
        "devices/denning-sim/buildings/building-a.toml",
        "devices/denning-sim/buildings/building-b.toml",
        "devices/denning-sim/buildings/heldout/building-c.toml",
        "devices/denning-sim/buildings/heldout/building-d.toml",
        "devices/denning-sim/buildings/heldout/building-e.toml",
        "devices/denning-sim/buildings/heldout/building-f.toml",
        "devices/denning-sim/buildings/heldout/building-g.toml",
    ] {
        let map = Map::load(&map_beside(&root.join(building))).unwrap();
        assert!(!map.rooms().is_empty(), "{building}");
        for room in map.rooms() {
            let route = plan(&map, Some(room), From::Lab);
            // Building E's, F's and G's room 1 are on the lab's own corridor, on the side
            // across from the lab's door: a map lists each side's doors in order, not how the
            // two sides interleave, so the planner cannot tell the door is ahead, and says so.
            if ["building-e.toml", "building-f.toml", "building-g.toml"]
                .iter()
                .any(|b| building.ends_with(b))
                && room == 1
            {
                assert!(matches!(route, Err(PlanError::NoWay { .. })));
                continue;
            }
            let route = route.unwrap();
            let xml = route.plan_xml(&library, building).unwrap();
            let plan = skillfab_sequence::Plan::parse(&xml, "planned").unwrap();
            assert_eq!(plan.main, format!("deliver-to-{room}"), "{building}");
            assert!(
                xml.contains(&format!("value=\"{room}\"")),
                "{building} {room}"
            );
            // And back: every room's door is in a corridor's side on these maps.
            let both = plan_round_trip(&map, Some(room)).unwrap();
            let xml = both.plan_xml(&library, building).unwrap();
            let plan = skillfab_sequence::Plan::parse(&xml, "planned").unwrap();
            assert_eq!(plan.main, format!("deliver-to-{room}-and-back"));
            assert!(
                matches!(both.steps.last(), Some(Step::AtTheLab { .. })),
                "{building} {room}"
            );
        }
    }
}

/// From a lobby (where a car that did not come left the robot): a car to the room's floor
/// and the same way out of its lobby as from the lab, or straight out on the room's floor; back
/// to the lab from the room's floor's lobby. The route's tree says which of its nodes leave
/// the robot in a lobby when they fail: the boardings, each on its floor and way.
#[test]
fn from_a_lobby_the_route_goes_on_as_from_the_lab_and_says_where_a_boarding_leaves_the_robot() {
    let map = Map::parse(SMALL, "small.map.toml").unwrap();
    let there = plan(&map, None, From::Lab).unwrap();
    let ride = there
        .steps
        .iter()
        .position(|s| matches!(s, Step::Ride { .. }))
        .unwrap();
    let lobby0 = plan(&map, None, From::Lobby { floor: 0 }).unwrap();
    assert_eq!(lobby0.from, From::Lobby { floor: 0 });
    assert_eq!(lobby0.steps, there.steps[ride..]);
    let lobby1 = plan(&map, None, From::Lobby { floor: 1 }).unwrap();
    assert_eq!(lobby1.steps, there.steps[ride + 1..]);
    assert_eq!(
        plan(&map, None, From::Lobby { floor: 7 }),
        Err(PlanError::NoLobby {
            building: "small".into(),
            floor: 7
        })
    );
    let both = plan_round_trip_from(&map, None, From::Lobby { floor: 0 }).unwrap();
    let back = plan_back(&map, None).unwrap();
    assert_eq!(
        both.steps,
        [lobby0.steps.clone(), back.steps.clone()].concat()
    );
    let back_ride = back
        .steps
        .iter()
        .position(|s| matches!(s, Step::Ride { .. }))
        .unwrap();
    let home = plan_back_from(&map, 105, From::Lobby { floor: 1 }).unwrap();
    assert_eq!(home.trip, Trip::BackToTheLab);
    assert_eq!(home.steps, back.steps[back_ride..]);
    // Where each node leaves the robot if it fails: the boardings and the rides, the wait for
    // 105's door (not found, the robot stops at the end of 'on', its leg, past it) and the
    // count to the lab's door on the way back (the lab's corridor ends past it).
    let believed = plan_round_trip(&map, None).unwrap().believed().unwrap();
    let said: Vec<Believed> = believed.iter().flatten().copied().collect();
    let on = map.legs.iter().position(|l| l.name == "on").unwrap();
    assert_eq!(
        said,
        [
            Believed {
                at: From::Lobby { floor: 0 },
                back: false
            },
            Believed {
                at: From::Car { floor: 0 },
                back: false
            },
            Believed {
                at: From::DeadEnd { leg: on },
                back: false
            },
            Believed {
                at: From::Lobby { floor: 1 },
                back: true
            },
            Believed {
                at: From::Car { floor: 1 },
                back: true
            },
            Believed {
                at: From::DeadEnd { leg: 0 },
                back: true
            }
        ]
    );
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let library = std::fs::read_to_string(root.join("skills/plans/deliver.xml")).unwrap();
    let library = Library::parse(&library, "deliver.xml").unwrap();
    let xml = lobby0.plan_xml(&library, "small").unwrap();
    let parsed = skillfab_sequence::Plan::parse(&xml, "planned").unwrap();
    // One entry per child of the route's tree, the lobby's own first.
    let seq = skillfab_sequence::Sequencer::new(&parsed, None).unwrap();
    let children = seq
        .live()
        .shape()
        .iter()
        .filter(|n| n.parent == Some(0))
        .count();
    assert_eq!(children, lobby0.believed().unwrap().len());
    assert!(xml.contains(
        "<Sequence>\n      <SubTree ID=\"InALobby\"/>\n      <SubTree ID=\"BoardACar\"/>"
    ));
    assert_eq!("lobby:3".parse(), Ok(From::Lobby { floor: 3 }));
    assert_eq!("lab".parse(), Ok(From::Lab));
    assert!("lobby".parse::<From>().is_err());
}

/// A missed turn: where the leg straight on ends in a dead end, the waits from that junction
/// to the next are guarded by `NotAtADeadEnd` and say the robot is at that dead end when they
/// fail (building E: at 'the crossing' a turn left, straight on 'the east arm', a dead end;
/// 407's door counted as the crossing once). From a dead end the route turns round and goes
/// back along the leg.
#[test]
fn a_missed_turn_into_a_dead_end_is_planned_on_from_that_dead_end() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let building = root.join("devices/denning-sim/buildings/heldout/building-e.toml");
    let map = Map::load(&map_beside(&building)).unwrap();
    let leg = |name: &str| map.legs.iter().position(|l| l.name == name).unwrap();
    let (south, east) = (leg("the dead end south"), leg("the east arm"));
    let route = plan(&map, None, From::Lab).unwrap();
    let at = |leg| Believed {
        at: From::DeadEnd { leg },
        back: false,
    };
    let said: Vec<Believed> = route.believed().unwrap().into_iter().flatten().collect();
    assert_eq!(
        said,
        [
            // 'the first intersection': right, or straight on to the dead end south; then
            // the lobby's call button in view.
            at(south),
            at(south),
            // A car that does not come, a ride that fails.
            Believed {
                at: From::Lobby { floor: 0 },
                back: false
            },
            Believed {
                at: From::Car { floor: 0 },
                back: false
            },
            // 'the crossing': left, then 407's door on the left.
            at(east),
            at(east),
        ]
    );
    let again = route.replanned(&map, at(east)).unwrap();
    assert_eq!(
        again,
        plan(&map, None, From::DeadEnd { leg: east }).unwrap()
    );
    assert_eq!(
        again.steps,
        [
            Step::TurnRound {
                leg: "the east arm".into()
            },
            Step::Along {
                leg: "the east arm".into(),
                heading: Heading::West
            },
            Step::Junction {
                name: "the crossing".into(),
                turn: Turn::Right,
                overshoot: None,
            },
            Step::Along {
                leg: "the north arm".into(),
                heading: Heading::North
            },
            Step::AtTheRoom {
                room: 407,
                side: Some(Side::Left),
                faced: false,
                missed: Some(leg("the north arm")),
            },
        ]
    );
    // From floor 0's dead end: back to the junction, left there, and on as from the lab.
    let south_again = plan(&map, None, From::DeadEnd { leg: south }).unwrap();
    let ride = |r: &skillfab_planner::Route| {
        r.steps
            .iter()
            .position(|s| matches!(s, Step::Ride { .. }))
            .unwrap()
    };
    assert_eq!(
        south_again.steps[ride(&south_again)..],
        route.steps[ride(&route)..]
    );
    let library = std::fs::read_to_string(root.join("skills/plans/deliver.xml")).unwrap();
    let library = Library::parse(&library, "deliver.xml").unwrap();
    let xml = again.plan_xml(&library, "building-e").unwrap();
    assert!(
        xml.contains(
            "<Sequence>\n      <SubTree ID=\"AtADeadEnd\"/>\n      <Activate skills=\"sign_read\"/>"
        ),
        "{xml}"
    );
    let planned = route.plan_xml(&library, "building-e").unwrap();
    assert!(planned.contains(
        "<Parallel name=\"unless stopped at a dead end\" success_count=\"1\" failure_count=\"1\">\n        <WaitFor name=\"the crossing: left\""
    ));
    // The text form, and the legs with no dead end.
    assert_eq!(
        format!("end:{}", east + 1).parse(),
        Ok(From::DeadEnd { leg: east })
    );
    assert!("end:0".parse::<From>().is_err());
    let corridor = leg("to the crossing");
    assert!(matches!(
        plan(&map, None, From::DeadEnd { leg: corridor }),
        Err(PlanError::NoDeadEnd { what, .. }) if what.contains("'to the crossing' has no dead end")
    ));
    assert!(matches!(
        plan(&map, None, From::DeadEnd { leg: 99 }),
        Err(PlanError::NoDeadEnd { n: 100, .. })
    ));
}

/// The nodes of `route`'s tree that say where the robot is when they fail, a place `kept`
/// keeps, with their route step in words.
fn places_said(
    route: &skillfab_planner::Route,
    kept: fn(&From) -> bool,
) -> Vec<(String, Believed)> {
    route
        .node_steps()
        .unwrap()
        .into_iter()
        .zip(route.believed().unwrap())
        .filter_map(|(step, b)| Some((route.steps[step].to_string(), b?)))
        .filter(|(_, b)| kept(&b.at))
        .collect()
}

/// The nodes of `route`'s tree that say the robot is at a dead end when they fail.
fn dead_ends_said(route: &skillfab_planner::Route) -> Vec<(String, Believed)> {
    places_said(route, |at| matches!(at, From::DeadEnd { .. }))
}

/// A door not found: building A's office, 405, is on 'the offices', which ends in a dead end
/// past it. The wait for its door says that dead end when it fails (the robot went on past
/// the door and stands at the corridor's end); from there the route turns round and the door
/// is on the left, with no dead end past it that way. The same for the lab's door on the way
/// back: the lab's corridor ends south of it.
#[test]
fn a_door_not_found_is_looked_for_again_from_its_legs_dead_end() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let building = root.join("devices/denning-sim/buildings/building-a.toml");
    let map = Map::load(&map_beside(&building)).unwrap();
    let offices = map
        .legs
        .iter()
        .position(|l| l.name == "the offices")
        .unwrap();
    let route = plan(&map, None, From::Lab).unwrap();
    assert_eq!(
        route.steps.last(),
        Some(&Step::AtTheRoom {
            room: 405,
            side: Some(Side::Right),
            faced: false,
            missed: Some(offices),
        })
    );
    let at_the_end = Believed {
        at: From::DeadEnd { leg: offices },
        back: false,
    };
    // The only wait that says a dead end: the door's.
    assert_eq!(
        dead_ends_said(&route),
        [("room 405: its door on the right".to_string(), at_the_end)]
    );
    let again = route.replanned(&map, at_the_end).unwrap();
    assert_eq!(
        again.steps,
        [
            Step::TurnRound {
                leg: "the offices".into()
            },
            Step::Along {
                leg: "the offices".into(),
                heading: Heading::East
            },
            Step::AtTheRoom {
                room: 405,
                side: Some(Side::Left),
                faced: false,
                missed: None,
            },
        ]
    );
    let library = std::fs::read_to_string(root.join("skills/plans/deliver.xml")).unwrap();
    let library = Library::parse(&library, "deliver.xml").unwrap();
    let planned = route.plan_xml(&library, "building-a").unwrap();
    assert!(planned.contains(
        "<Parallel name=\"unless stopped at a dead end\" success_count=\"1\" failure_count=\"1\">\n        <SubTree ID=\"ToTheOfficeOnTheRight\"/>"
    ), "{planned}");
    // The way back: the lab's corridor ends south of the lab's door, so the count of doors to
    // it says that dead end when it fails; from there the lab's door is the first on the left.
    let lab_corridor = map
        .legs
        .iter()
        .position(|l| l.name == "the lab's corridor")
        .unwrap();
    let back = plan_back(&map, None).unwrap();
    assert_eq!(
        back.steps.last(),
        Some(&Step::AtTheLab {
            side: Some(Side::Right),
            doors_before: 0,
            missed: Some(lab_corridor),
        })
    );
    let at_the_south_end = Believed {
        at: From::DeadEnd { leg: lab_corridor },
        back: true,
    };
    assert_eq!(
        back.believed().unwrap().into_iter().flatten().last(),
        Some(at_the_south_end)
    );
    assert_eq!(
        back.replanned(&map, at_the_south_end).unwrap().steps,
        [
            Step::TurnRound {
                leg: "the lab's corridor".into()
            },
            Step::Along {
                leg: "the lab's corridor".into(),
                heading: Heading::North
            },
            Step::AtTheLab {
                side: Some(Side::Left),
                doors_before: 0,
                missed: None,
            },
        ]
    );
}

/// Two turns in a row, each with a dead end straight on: failing at a dead end while the
/// second junction's count is awaited, the robot may have missed either turn (the first
/// counted early at a door, or the second missed), so that wait is not guarded; the waits
/// after the second junction say its dead end.
#[test]
fn a_junctions_count_after_another_dead_end_is_not_guarded() {
    let text = SMALL.replacen(
        r#"[[leg]]
name = "west arm"
floor = 1
from = "the crossing"
to = "end"
heading = "west"
"#,
        r#"[[leg]]
name = "west arm"
floor = 1
from = "the crossing"
to = "the corner"
heading = "west"

[[junction]]
name = "the corner"
floor = 1
arriving = "west arm"
straight = "far west"
left = "south lane"

[[leg]]
name = "far west"
floor = 1
from = "the corner"
to = "end"
heading = "west"

[[leg]]
name = "south lane"
floor = 1
from = "the corner"
to = "end"
heading = "south"
left = [107]
"#,
        1,
    );
    assert_ne!(text, SMALL);
    let map = Map::parse(&text, "small.map.toml").unwrap();
    let leg = |name: &str| map.legs.iter().position(|l| l.name == name).unwrap();
    let route = plan(&map, Some(107), From::Lab).unwrap();
    let guarded = dead_ends_said(&route);
    let at = |name| Believed {
        at: From::DeadEnd { leg: leg(name) },
        back: false,
    };
    assert_eq!(
        guarded,
        [
            ("at 'the crossing': left".to_string(), at("on")),
            ("room 107: its door on the left".to_string(), at("far west")),
        ]
    );
}

/// A door not found on a leg that goes on: building E's 401 is on 'to the crossing', which
/// ends at the crossing, and straight across it the east arm ends in a dead end. A robot that
/// passes 401's door without finding it crosses straight on (nothing counts junctions then,
/// `hall_follow` straight on) and stands at the east arm's end: the wait for the door says
/// that dead end. From there the route turns round, crosses straight back, and the door is
/// on the left. Where the way straight on ends at a T's bar (the small map's room 2, before
/// the T), the wait says nothing: the robot stops there with the sides open.
#[test]
fn a_door_not_found_on_a_leg_that_goes_on_is_looked_for_again_from_the_dead_end_straight_on() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let building = root.join("devices/denning-sim/buildings/heldout/building-e.toml");
    let map = Map::load(&map_beside(&building)).unwrap();
    let leg = |name: &str| map.legs.iter().position(|l| l.name == name).unwrap();
    let route = plan(&map, Some(401), From::Lab).unwrap();
    assert_eq!(
        route.steps.last(),
        Some(&Step::AtTheRoom {
            room: 401,
            side: Some(Side::Right),
            faced: false,
            missed: Some(leg("the east arm")),
        })
    );
    let at_the_east_end = Believed {
        at: From::DeadEnd {
            leg: leg("the east arm"),
        },
        back: false,
    };
    // (On floor 0 the first intersection's waits say its own dead end, as on every route.)
    assert_eq!(
        dead_ends_said(&route).last(),
        Some(&(
            "room 401: its door on the right".to_string(),
            at_the_east_end
        ))
    );
    assert_eq!(
        route.replanned(&map, at_the_east_end).unwrap().steps,
        [
            Step::TurnRound {
                leg: "the east arm".into()
            },
            Step::Along {
                leg: "the east arm".into(),
                heading: Heading::West
            },
            Step::Junction {
                name: "the crossing".into(),
                turn: Turn::Straight,
                overshoot: None,
            },
            Step::Along {
                leg: "to the crossing".into(),
                heading: Heading::West
            },
            Step::AtTheRoom {
                room: 401,
                side: Some(Side::Left),
                faced: false,
                missed: None,
            },
        ]
    );
    // The office, 407, on the north arm, which ends in a dead end past it: the step says
    // that end, as before (the wait keeps the crossing's dead end, the east arm: a robot
    // that missed the turn never came to the north arm).
    let office = plan(&map, None, From::Lab).unwrap();
    assert_eq!(
        office.steps.last(),
        Some(&Step::AtTheRoom {
            room: 407,
            side: Some(Side::Left),
            faced: false,
            missed: Some(leg("the north arm")),
        })
    );

    let small = Map::parse(SMALL, "small.map.toml").unwrap();
    let to_2 = plan(&small, Some(2), From::Lab).unwrap();
    assert_eq!(
        to_2.steps.last(),
        Some(&Step::AtTheRoom {
            room: 2,
            side: Some(Side::Left),
            faced: false,
            missed: None,
        })
    );
    assert_eq!(dead_ends_said(&to_2), []);
}

/// A ride that fails: `RideToTheFloor`'s tries all failed (a car stopped between floors), the
/// robot is still in the car. The route from there starts in the car (`InACar`, no boarding)
/// and rides to the room's floor, pressing its button again; on the way back, to the lab's.
#[test]
fn a_ride_that_fails_is_ridden_again_from_the_car() {
    let map = Map::parse(SMALL, "small.map.toml").unwrap();
    let both = plan_round_trip(&map, None).unwrap();
    let in_the_car = |floor, back| Believed {
        at: From::Car { floor },
        back,
    };
    let rides = places_said(&both, |at| matches!(at, From::Car { .. }));
    assert_eq!(
        rides,
        [
            (
                "a car from floor 0 to floor 1".to_string(),
                in_the_car(0, false)
            ),
            (
                "a car from floor 1 to floor 0".to_string(),
                in_the_car(1, true)
            ),
        ]
    );
    let lobby0 = plan(&map, None, From::Lobby { floor: 0 }).unwrap();
    let again = both.replanned(&map, in_the_car(0, false)).unwrap();
    let back = plan_back(&map, None).unwrap();
    assert_eq!(again.from, From::Car { floor: 0 });
    assert_eq!(again.steps, [lobby0.steps, back.steps.clone()].concat());
    let back_ride = back
        .steps
        .iter()
        .position(|s| matches!(s, Step::Ride { .. }))
        .unwrap();
    assert_eq!(
        both.replanned(&map, in_the_car(1, true)).unwrap().steps,
        back.steps[back_ride..]
    );
    // From a car on the room's floor itself: a ride all the same (its button reopens the
    // doors there).
    assert_eq!(
        plan(&map, None, From::Car { floor: 1 }).unwrap().steps[0],
        Step::Ride { from: 1, to: 1 }
    );
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let library = std::fs::read_to_string(root.join("skills/plans/deliver.xml")).unwrap();
    let library = Library::parse(&library, "deliver.xml").unwrap();
    let xml = again.plan_xml(&library, "small").unwrap();
    assert!(
        xml.contains(
            "<Sequence>\n      <SubTree ID=\"InACar\"/>\n      \
             <SetParam skill=\"barcode_track\" param=\"id\" value=\"861\"/>\n      \
             <SetParam skill=\"sign_read\" param=\"floor\" value=\"1\"/>\n      \
             <SubTree ID=\"RideToTheFloor\"/>"
        ),
        "{xml}"
    );
    // No boarding before the ride from the car; the way back boards a car again.
    let route_tree = &xml[..xml.find("</BehaviorTree>").unwrap()];
    assert_eq!(route_tree.matches("<SubTree ID=\"BoardACar\"/>").count(), 1);
    let parsed = skillfab_sequence::Plan::parse(&xml, "planned").unwrap();
    let seq = skillfab_sequence::Sequencer::new(&parsed, None).unwrap();
    let children = seq
        .live()
        .shape()
        .iter()
        .filter(|n| n.parent == Some(0))
        .count();
    assert_eq!(children, again.believed().unwrap().len());
    assert_eq!("car:4".parse(), Ok(From::Car { floor: 4 }));
    assert_eq!(From::Car { floor: 4 }.to_string(), "car:4");
    assert!("car:".parse::<From>().is_err());
}
