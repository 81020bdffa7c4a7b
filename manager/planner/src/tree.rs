//! A [`Route`] as a plan: a BehaviorTree.CPP v4 tree of the delivery library's subtrees
//! (`skills/plans/deliver.xml`), with the route's own steps — the turn `hall_follow` takes
//! at each junction and the junction count `intersection` must reach — written between them.
//! The plan language has no blackboard, so a subtree cannot take a count or a room number:
//! those are written into the route's tree, the rest is the library's.
//!
//! How the steps are written (the rules the hand-written routes followed, kept so the same
//! route gives the same run):
//! - `hall_follow.turn` is set before a junction to what the robot does there, only when it
//!   is not that already, and set back to straight on once the last junction of a floor is
//!   passed (before the lobby, before the office's sign is looked for).
//! - `intersection` counts the junctions since it was activated: out of a lab door in a
//!   corridor's side the turn into the corridor is the first; a lobby entered through its
//!   side, or left through it, counts as one. Leaving a lobby the counter is started again
//!   once the robot is between a corridor's walls (`InTheCorridor`), when there are junctions
//!   to count on that floor.
//! - The corridor skills are activated with the first junction (or the lobby) after the lab,
//!   with `sign_read` on the room's floor on the way there.
//! - A ride: `BoardACar`, then `barcode_track.id` set to the floor's panel button (860 + f)
//!   and `sign_read.floor` to the floor, then `RideToTheFloor`. Its tries all failed, the
//!   robot is believed in the car (`From::Car`); a route from a car starts with `InACar`
//!   and rides, with no boarding.
//! - The way back: out of the room's door turned along the corridor on the spot, square to
//!   its walls (`OutOfTheOfficeLeft`/`Right`), junctions counted once the robot is between
//!   the corridor's walls; at the lab's leg, doors counted again from the corridor
//!   (`DoorsCountedFromHere`) and `door_detect.doors.<side>` waited for to pass the lab's
//!   door, then `AtTheLabsDoor`; a lab's door at the corridor's end is `ToTheLabAhead`.
//! - A missed turn: after a junction where the route turns and the leg straight on ends in
//!   a dead end, the waits up to the next junction (the lobby's call button, the room's
//!   door, the lab's door count) and the junction's own count are each in a `Parallel`
//!   beside `NotAtADeadEnd` — a junction's own count only when the junction before says no
//!   dead end (else the robot could be at either) —; the route says
//!   the robot is at that dead end when one fails ([`Route::believed`]). From a dead end
//!   (`From::DeadEnd`) the route starts with `AtADeadEnd`: turned round, the corridor
//!   skills straight on.
//! - A room's door not found, or the lab's not counted on the way back: where the way
//!   straight on past the door comes to a dead end (the leg's, or past junctions crossed
//!   straight), the wait for the door is guarded the same way and says that dead end
//!   (unless a missed turn before it says its own); from there the route comes back and
//!   finds the door on the other side.

use crate::map::{Side, Turn};
use crate::replan::Believed;
use crate::route::{From, Route, Step, Trip};
use std::collections::BTreeSet;
use std::fmt::Write;

/// Out of a car the robot stands this far in front of the bank wall (m): `leave_car` stops
/// 1.8 m from the cabin's centre, which is 0.85 m inside the doorway.
const OUT_OF_A_CAR_M: f64 = 0.95;
/// A corridor's width (m, the buildings' convention).
const CORRIDOR_M: f64 = 2.4;

/// Why a route could not be written as a plan.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TreeError {
    /// The library is not a plan file.
    #[error("{file}: {reason}")]
    Library {
        /// The library file.
        file: String,
        /// What is wrong.
        reason: String,
    },
    /// A subtree the route needs is not in the library.
    #[error("{file} has no tree '{id}', which the plan needs")]
    Missing {
        /// The library file.
        file: String,
        /// The tree.
        id: String,
    },
    /// The library already has a tree with the plan's ID.
    #[error("{file} already has a tree '{id}': the route's tree is called so")]
    Taken {
        /// The library file.
        file: String,
        /// The tree.
        id: String,
    },
    /// No button in a car for that floor: the panel's are 860 + f, floors 0 to 9.
    #[error(
        "the route rides from floor {from} to floor {to}: a car's buttons are for floors 0 to 9 (barcodes 860 + f)"
    )]
    NoRide {
        /// From.
        from: i32,
        /// To.
        to: i32,
    },
}

/// The library of subtrees a route's tree is built from: a plan file's `<BehaviorTree>`s.
#[derive(Debug, Clone)]
pub struct Library {
    file: String,
    /// The file's `<root>`'s content, as written (trees and comments).
    body: String,
    /// Its trees' IDs.
    trees: BTreeSet<String>,
}

impl Library {
    /// Reads a library (`file` names it in errors). Its trees are read as the sequencer reads
    /// them when the plan runs; here only their IDs matter.
    pub fn parse(text: &str, file: &str) -> Result<Library, TreeError> {
        let bad = |reason: String| TreeError::Library {
            file: file.to_string(),
            reason,
        };
        let doc = roxmltree::Document::parse(text).map_err(|e| bad(format!("not XML: {e}")))?;
        let root = doc.root_element();
        if root.tag_name().name() != "root" {
            return Err(bad(
                "the document element must be <root BTCPP_format=\"4\">".into(),
            ));
        }
        let trees = root
            .children()
            .filter(|c| c.has_tag_name("BehaviorTree"))
            .filter_map(|c| c.attribute("ID").map(str::to_string))
            .collect();
        let body = match (root.first_child(), root.last_child()) {
            (Some(first), Some(last)) => text[first.range().start..last.range().end]
                .trim()
                .to_string(),
            _ => String::new(),
        };
        Ok(Library {
            file: file.to_string(),
            body,
            trees,
        })
    }
}

/// A node of the route's tree.
#[derive(Debug, Clone, PartialEq)]
enum X {
    SubTree(&'static str),
    SetParam {
        skill: &'static str,
        param: &'static str,
        value: String,
    },
    Activate(Vec<&'static str>),
    WaitFor {
        name: String,
        condition: String,
    },
    WithParam {
        skill: &'static str,
        param: &'static str,
        value: String,
        children: Vec<X>,
    },
    /// A wait that fails when the robot stops at a dead end (`NotAtADeadEnd` beside it).
    UnlessAtADeadEnd(Box<X>),
}

/// Writes the steps, keeping what the plan has set so far.
struct Writer {
    out: Vec<X>,
    /// Steps inside a `WithParam` being written.
    group: Option<(&'static str, &'static str, String, Vec<X>)>,
    /// The corridor skills are active (since the last activation, or the lobby's deactivation).
    active: bool,
    /// `hall_follow.turn` as the plan last set it (`None`: not yet).
    turn: Option<Turn>,
    /// The junction count `intersection` is at.
    count: u32,
    /// The floor the robot is on, and the room's while the robot is on its way there
    /// (`sign_read` is on with the corridor skills there).
    floor: i32,
    sign_floor: Option<i32>,
    /// Where the robot is if a node of `out` fails, by its index (the nodes a plan goes on
    /// from; the others fail the plan).
    believed: Vec<(usize, Believed)>,
    /// The step being written, and the step each node of `out` was written for.
    step: usize,
    step_of: Vec<usize>,
    /// Where a missed turn at the last junction leaves the robot (the leg straight on, a
    /// dead end), until the next junction: the waits up to there fail when it stops there.
    dead_end: Option<usize>,
    /// On the way back to the lab (the message said).
    back: bool,
}

impl Writer {
    fn push(&mut self, x: X) {
        match &mut self.group {
            Some((.., children)) => children.push(x),
            None => {
                self.out.push(x);
                self.step_of.push(self.step);
            }
        }
    }

    fn set_turn(&mut self, turn: Turn) {
        if self.turn != Some(turn) {
            self.push(X::SetParam {
                skill: "hall_follow",
                param: "turn",
                value: turn.hall_follow().to_string(),
            });
            self.turn = Some(turn);
        }
    }

    /// The corridor skills; on the room's floor `sign_read` too (the office's sign).
    fn corridor_skills(&self) -> Vec<&'static str> {
        let mut s = vec!["intersection", "door_detect", "hall_follow"];
        if Some(self.floor) == self.sign_floor {
            s.push("sign_read");
        }
        s
    }

    /// A wait a missed turn could leave waiting at a dead end: failing there, with the dead
    /// end believed, when the last junction says where it is (and not inside a group).
    fn wait(&mut self, x: X) {
        match self.dead_end {
            Some(leg) if self.group.is_none() => {
                self.push(X::UnlessAtADeadEnd(Box::new(x)));
                let at = From::DeadEnd { leg };
                let back = self.back;
                self.believed
                    .push((self.out.len() - 1, Believed { at, back }));
            }
            _ => self.push(x),
        }
    }

    /// A junction (or a lobby's side) where the robot does `turn`: counted.
    fn junction(&mut self, name: &str, turn: Turn) {
        self.set_turn(turn);
        if !self.active {
            self.push(X::Activate(self.corridor_skills()));
            (self.active, self.count) = (true, 0);
        }
        self.count += 1;
        self.wait(X::WaitFor {
            name: format!("{name}: {turn}"),
            condition: format!("intersection.junction.count >= {}", self.count),
        });
    }
}

impl Route {
    /// The ID of the route's tree in its plan.
    pub fn tree_id(&self) -> String {
        match self.trip {
            Trip::ToTheRoom => format!("deliver-to-{}", self.room),
            Trip::BackToTheLab => format!("back-from-{}", self.room),
            Trip::RoundTrip => format!("deliver-to-{}-and-back", self.room),
        }
    }

    /// The plan: the route's tree, then the library's trees; a whole BehaviorTree.CPP v4
    /// file that runs as it is. `source` names the map in the file's comment.
    pub fn plan_xml(&self, library: &Library, source: &str) -> Result<String, TreeError> {
        let id = self.tree_id();
        if library.trees.contains(&id) {
            return Err(TreeError::Taken {
                file: library.file.clone(),
                id,
            });
        }
        let body = self.nodes()?;
        let mut used = BTreeSet::new();
        subtrees(&body, &mut used);
        for t in used {
            if !library.trees.contains(t) {
                return Err(TreeError::Missing {
                    file: library.file.clone(),
                    id: t.to_string(),
                });
            }
        }
        let mut xml = String::from("<?xml version=\"1.0\"?>\n<!-- ");
        // (A comment may not hold "--".)
        let words = format!(
            "Planned by `skillfab plan` from {source}, with the subtrees of {} (after the \
             route's tree).\n     The route in words:\n     {}",
            library.file,
            self.to_string().replace('\n', "\n     ")
        )
        .replace("--", "- -");
        xml.push_str(&words);
        let _ = write!(
            xml,
            " -->\n<root BTCPP_format=\"4\" main_tree_to_execute=\"{id}\">\n\n  <BehaviorTree ID=\"{id}\">\n    <Sequence>\n"
        );
        for x in &body {
            write_node(&mut xml, x, 3);
        }
        xml.push_str("    </Sequence>\n  </BehaviorTree>\n\n  ");
        xml.push_str(&library.body);
        xml.push_str("\n</root>\n");
        Ok(xml)
    }

    /// Where the robot is believed to be when a child of the route's tree's `Sequence` fails,
    /// one entry per child: `Some` for the steps the plan can go on from (a car that did not
    /// come: the robot is in that floor's lobby; a ride that failed: in the car; a missed turn
    /// or door: at a dead end), `None` for the others. The sequencer's
    /// runner reads which child failed; [`Route::replanned`] plans from there.
    pub fn believed(&self) -> Result<Vec<Option<Believed>>, TreeError> {
        let w = self.written()?;
        let mut out = vec![None; w.out.len()];
        for (i, b) in w.believed {
            out[i] = Some(b);
        }
        Ok(out)
    }

    /// The step of the route (an index into `steps`) each child of the route's tree's
    /// `Sequence` was written for (a plan from a lobby or a car: its first node, too, the first
    /// step's).
    pub fn node_steps(&self) -> Result<Vec<usize>, TreeError> {
        Ok(self.written()?.step_of)
    }

    /// The route's tree: the children of its `Sequence`.
    fn nodes(&self) -> Result<Vec<X>, TreeError> {
        Ok(self.written()?.out)
    }

    /// The route's tree written, with where each node leaves the robot if it fails.
    fn written(&self) -> Result<Writer, TreeError> {
        let mut w = Writer {
            out: Vec::new(),
            group: None,
            active: false,
            turn: None,
            count: 0,
            // The way back starts on the room's floor, the way there on the first ride's.
            floor: match (self.from, self.trip) {
                (From::Lobby { floor } | From::Car { floor }, _) => Some(floor),
                (_, Trip::BackToTheLab) => None,
                _ => self.steps.iter().find_map(|s| match s {
                    Step::Ride { from, .. } => Some(*from),
                    _ => None,
                }),
            }
            .unwrap_or(self.floor),
            sign_floor: (self.trip != Trip::BackToTheLab).then_some(self.floor),
            believed: Vec::new(),
            step: 0,
            step_of: Vec::new(),
            dead_end: None,
            back: self.trip == Trip::BackToTheLab,
        };
        // From a lobby, whatever ran before: the corridor skills off, `avoid` on.
        // From a car: what ran before the ride off, `avoid` on.
        match self.from {
            From::Lobby { .. } => w.push(X::SubTree("InALobby")),
            From::Car { .. } => w.push(X::SubTree("InACar")),
            _ => {}
        }
        for (i, step) in self.steps.iter().enumerate() {
            w.step = i;
            // Junctions still to count on this floor after this step, on this way.
            let junctions_follow = self.steps[i + 1..]
                .iter()
                .take_while(|s| !matches!(s, Step::Ride { .. } | Step::AtTheRoom { .. }))
                .any(|s| matches!(s, Step::Junction { .. }));
            match step {
                Step::LeaveTheLab => w.push(X::SubTree("LeaveTheLab")),
                Step::IntoTheCorridor { turn } => {
                    w.push(X::SubTree(match turn {
                        Turn::Right => "IntoTheCorridorRight",
                        _ => "IntoTheCorridorLeft",
                    }));
                    (w.active, w.turn, w.count) = (true, Some(*turn), 1);
                    if Some(w.floor) == w.sign_floor {
                        w.push(X::Activate(vec!["sign_read"]));
                    }
                }
                // Facing the room's sign beside its door, not square to it: turned along the
                // corridor on the spot, squared to its walls; the corridor skills start,
                // hall_follow straight on, and junctions are counted from 0 once the robot is
                // between the corridor's walls (were the door's exit counted as the first, as
                // out of the lab's, a junction just beside the door would merge with it).
                Step::OutOfTheRoom { turn, .. } => {
                    w.push(X::SubTree(match turn {
                        Turn::Right => "OutOfTheOfficeRight",
                        _ => "OutOfTheOfficeLeft",
                    }));
                    (w.active, w.turn, w.count) = (true, Some(Turn::Straight), 0);
                }
                Step::Along { .. } => {}
                Step::Junction {
                    name,
                    turn,
                    overshoot,
                } => {
                    // Missed here (not counted, or counted at a door before), the robot goes
                    // straight on: to a dead end, or somewhere the route cannot say.
                    let own = (*turn != Turn::Straight).then_some(*overshoot).flatten();
                    // Its own count, failing at a dead end: this junction missed, or the one
                    // before counted early and missed. Guarded only when both say the same
                    // place (or the one before says none).
                    w.dead_end = match w.dead_end {
                        None => own,
                        before if before == own => own,
                        _ => None,
                    };
                    w.junction(name, *turn);
                    w.dead_end = own;
                }
                // Stopped facing the dead end: turned round along the corridor on the spot,
                // square to it; the corridor skills start, hall_follow straight on, and
                // junctions are counted from 0 once the robot is between the walls.
                Step::TurnRound { .. } => {
                    w.push(X::SubTree("AtADeadEnd"));
                    (w.active, w.turn, w.count) = (true, Some(Turn::Straight), 0);
                    if Some(w.floor) == w.sign_floor {
                        w.push(X::Activate(vec!["sign_read"]));
                    }
                }
                Step::IntoTheLobby { turn, .. } => {
                    if *turn != Turn::Straight {
                        w.junction("the lobby", *turn);
                    } else if !w.active {
                        w.set_turn(Turn::Straight);
                        w.push(X::Activate(w.corridor_skills()));
                        w.active = true;
                    }
                    w.set_turn(Turn::Straight);
                    w.wait(X::SubTree("IntoTheLobby"));
                    (w.active, w.dead_end) = (false, None);
                }
                Step::Ride { from, to } => {
                    if !(0..=9).contains(to) {
                        return Err(TreeError::NoRide {
                            from: *from,
                            to: *to,
                        });
                    }
                    // The ride's floor, which its subtree cannot be told: the button
                    // barcode_track finds, the floor sign_read waits for. No car boarded:
                    // the robot is still in this floor's lobby. (A plan from a car starts
                    // boarded.)
                    let back = w.back;
                    if !(i == 0 && matches!(self.from, From::Car { .. })) {
                        w.push(X::SubTree("BoardACar"));
                        let at = From::Lobby { floor: *from };
                        w.believed.push((w.out.len() - 1, Believed { at, back }));
                    }
                    w.push(X::SetParam {
                        skill: "barcode_track",
                        param: "id",
                        value: (860 + to).to_string(),
                    });
                    w.push(X::SetParam {
                        skill: "sign_read",
                        param: "floor",
                        value: to.to_string(),
                    });
                    // The ride failed, try after try: the robot is still in the car.
                    w.push(X::SubTree("RideToTheFloor"));
                    let at = From::Car { floor: *from };
                    w.believed.push((w.out.len() - 1, Believed { at, back }));
                    w.floor = *to;
                }
                Step::OutOfTheLobby {
                    turn, beside_bank, ..
                } => {
                    if *turn == Turn::Straight {
                        // Lined up on the call button, away from the bank: turn 0, the
                        // corridor skills active.
                        w.push(X::SubTree("OutOfTheLobby"));
                        (w.active, w.turn, w.count) = (true, Some(Turn::Straight), 0);
                    } else {
                        if *beside_bank {
                            // Turned where the car left it, on the corridor's centre line.
                            let after = CORRIDOR_M / 2.0 - OUT_OF_A_CAR_M;
                            w.group =
                                Some(("hall_follow", "after", format!("{after:.2}"), Vec::new()));
                        } else {
                            w.push(X::SubTree("LineUpOnTheCallButton"));
                        }
                        w.junction("the lobby's side", *turn);
                        w.set_turn(Turn::Straight);
                    }
                    if junctions_follow {
                        w.set_turn(Turn::Straight);
                        w.push(X::SubTree("InTheCorridor"));
                        w.count = 0;
                    }
                    if let Some((skill, param, value, children)) = w.group.take() {
                        w.push(X::WithParam {
                            skill,
                            param,
                            value,
                            children,
                        });
                    }
                }
                Step::AtTheRoom {
                    room,
                    side,
                    faced,
                    missed,
                } => {
                    w.set_turn(Turn::Straight);
                    // Not found, the door is passed and the robot, straight on, stops at the
                    // dead end past it (the leg's, or past junctions crossed straight): the
                    // wait for it fails there. A missed turn before says its own dead end, as
                    // it did (a robot that missed it never came this way).
                    w.dead_end = w.dead_end.or(*missed);
                    for skill in ["barcode_track", "deliver"] {
                        w.push(X::SetParam {
                            skill,
                            param: if skill == "deliver" { "room" } else { "id" },
                            value: room.to_string(),
                        });
                    }
                    // `door_detect` says left when both sides open at once: a door on the
                    // right with one facing it is waited for on either side.
                    // (At the corridor's end the room's door is where hall_follow stops.)
                    match (side, faced) {
                        (Some(Side::Left), _) => w.wait(X::SubTree("ToTheOfficeOnTheLeft")),
                        (Some(Side::Right), false) => w.wait(X::SubTree("ToTheOfficeOnTheRight")),
                        (Some(Side::Right), true) => {
                            w.wait(X::SubTree("ToTheOfficeOnTheRightFacingADoor"));
                        }
                        (None, _) => w.push(X::SubTree("ToTheOfficeAhead")),
                    }
                    w.push(X::SubTree("DeliverTheMessage"));
                    w.sign_floor = None;
                    (w.back, w.dead_end) = (true, None);
                }
                Step::AtTheLab {
                    side,
                    doors_before,
                    missed,
                } => {
                    w.set_turn(Turn::Straight);
                    // As a room's door: not counted, the lab's door is passed and the robot
                    // stops at the dead end straight on past it.
                    w.dead_end = w.dead_end.or(*missed);
                    match side {
                        // Doors are counted from the corridor after the last junction: the
                        // lab's is the one after `doors_before` others on its side.
                        Some(s) => {
                            w.push(X::SubTree("DoorsCountedFromHere"));
                            let field = match s {
                                Side::Left => "left",
                                Side::Right => "right",
                            };
                            w.wait(X::WaitFor {
                                name: format!("past the lab's door on the {s}"),
                                condition: format!(
                                    "door_detect.doors.{field} >= {}",
                                    doors_before + 1
                                ),
                            });
                            w.push(X::SubTree("AtTheLabsDoor"));
                        }
                        None => w.push(X::SubTree("ToTheLabAhead")),
                    }
                }
            }
        }
        Ok(w)
    }
}

/// The subtrees `nodes` use.
fn subtrees(nodes: &[X], out: &mut BTreeSet<&'static str>) {
    for x in nodes {
        match x {
            X::SubTree(id) => {
                out.insert(id);
            }
            X::WithParam { children, .. } => subtrees(children, out),
            X::UnlessAtADeadEnd(x) => {
                out.insert("NotAtADeadEnd");
                subtrees(std::slice::from_ref(x), out);
            }
            _ => {}
        }
    }
}

/// XML's escapes for an attribute's value.
fn attr(v: &str) -> String {
    v.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn write_node(xml: &mut String, x: &X, depth: usize) {
    let pad = "  ".repeat(depth);
    let _ = match x {
        X::SubTree(id) => writeln!(xml, "{pad}<SubTree ID=\"{id}\"/>"),
        X::SetParam {
            skill,
            param,
            value,
        } => writeln!(
            xml,
            "{pad}<SetParam skill=\"{skill}\" param=\"{param}\" value=\"{}\"/>",
            attr(value)
        ),
        X::Activate(skills) => writeln!(xml, "{pad}<Activate skills=\"{}\"/>", skills.join(", ")),
        X::WaitFor { name, condition } => writeln!(
            xml,
            "{pad}<WaitFor name=\"{}\" condition=\"{}\"/>",
            attr(name),
            attr(condition)
        ),
        X::WithParam {
            skill,
            param,
            value,
            children,
        } => {
            let _ = writeln!(
                xml,
                "{pad}<WithParam skill=\"{skill}\" param=\"{param}\" value=\"{}\">\n{pad}  <Sequence>",
                attr(value)
            );
            for c in children {
                write_node(xml, c, depth + 2);
            }
            writeln!(xml, "{pad}  </Sequence>\n{pad}</WithParam>")
        }
        X::UnlessAtADeadEnd(x) => {
            let _ = writeln!(
                xml,
                "{pad}<Parallel name=\"unless stopped at a dead end\" success_count=\"1\" failure_count=\"1\">"
            );
            write_node(xml, x, depth + 1);
            let _ = writeln!(xml, "{pad}  <SubTree ID=\"NotAtADeadEnd\"/>");
            writeln!(xml, "{pad}</Parallel>")
        }
    };
}
