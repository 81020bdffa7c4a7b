//! The exit-lab experiment's sequencer written against the client library (the plan
//! `skills/plans/exit-lab.xml` is the same as a behaviour tree).

use skillfab_client::Client;
use skillfab_proto::control::MonitorMode;

/// Where the sequencer is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Phase {
    /// Wandering until the barcode is seen.
    Search,
    /// Homing on the barcode.
    Home,
    /// Following the wall from the barcode with the wall on this side (-1 left, 1 right).
    Follow(i32),
    /// Back to the barcode after following the wall on the left in vain.
    Return,
    /// Driving through the located door.
    Through,
}

/// The exit-lab sequencer: which skills run in each phase, and the monitor that ends it.
/// Barcode seen: explore -> home (and door_locate looks). Near the barcode: follow the wall
/// with it on the left; 4 m away without a door, home again and follow it on the right. Door
/// located (in any phase): lower `avoid.safe_distance` for the tight passage, go_through.
pub(super) struct Sequencer {
    pub(super) phase: Phase,
    pub(super) seen: u64,
    pub(super) near: Option<u64>,
    pub(super) far: Option<u64>,
    pub(super) found: Option<u64>,
}

impl Sequencer {
    /// Reacts to a monitor firing; returns the step to report.
    pub(super) fn on_monitor(&mut self, c: &Client, id: u64) -> anyhow::Result<Option<String>> {
        let near_code =
            |c: &Client| c.add_monitor("barcode_track.target.range < 1.7", MonitorMode::Once, 2);
        let step = match self.phase {
            _ if Some(id) == self.found && self.phase != Phase::Through => {
                self.phase = Phase::Through;
                c.set_param("avoid", "safe_distance", "0.2")?;
                c.deactivate(&["home", "wall_follow"])?;
                c.activate(&["go_through"])?;
                "door located: avoid.safe_distance = 0.2 for the passage; go_through drives"
                    .to_string()
            }
            Phase::Search if id == self.seen => {
                self.phase = Phase::Home;
                c.deactivate(&["explore"])?;
                c.activate(&["home", "door_locate"])?;
                self.near = Some(near_code(c)?);
                self.found =
                    Some(c.add_monitor("door_locate.door.found == 1", MonitorMode::Once, 0)?);
                "barcode seen: explore -> home; door_locate looks".to_string()
            }
            Phase::Home | Phase::Return if Some(id) == self.near => {
                let side = if self.phase == Phase::Home { -1 } else { 1 };
                self.phase = Phase::Follow(side);
                c.deactivate(&["home"])?;
                c.set_param("wall_follow", "side", &side.to_string())?;
                c.activate(&["wall_follow"])?;
                if side < 0 {
                    self.far = Some(c.add_monitor(
                        "barcode_track.target.range > 4.0",
                        MonitorMode::Once,
                        2,
                    )?);
                }
                format!(
                    "near the barcode: home -> wall_follow, wall on the {}",
                    if side < 0 { "left" } else { "right" }
                )
            }
            Phase::Follow(-1) if Some(id) == self.far => {
                self.phase = Phase::Return;
                c.deactivate(&["wall_follow"])?;
                c.activate(&["home"])?;
                self.near = Some(near_code(c)?);
                "no door within 4 m that way: wall_follow -> home, then the other way".to_string()
            }
            _ => return Ok(None),
        };
        Ok(Some(step))
    }
}
