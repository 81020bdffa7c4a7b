//! `sign_read`: floor and room signs from the camera.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`SignRead`].
#[derive(Params, Debug, Clone)]
pub struct SignReadParams {
    /// The floor a ride is for (the route's tree sets it before the ride): `signs.at_floor`
    /// says whether the floor last read is this one. −1: none (`at_floor` is never true).
    #[param(default = -1, min = -1, max = 99)]
    pub floor: i64,
}

/// Input of [`SignRead`].
#[derive(Inputs)]
pub struct SignIn<'a> {
    /// Camera sightings.
    pub barcodes: Input<'a, Barcodes>,
}

/// Output of [`SignRead`].
#[derive(Outputs)]
pub struct SignsOut<'a> {
    /// The floor last read and the nearest room sign in view.
    pub signs: Output<'a, Signs>,
}

/// Floor signs (and a car's floor indicator) carry 900 + the floor.
const FLOORS: std::ops::RangeInclusive<u32> = 900..=999;
/// Room signs carry the room number, floor × 100 + n (floors 1 to 7).
const ROOMS: std::ops::RangeInclusive<u32> = 100..=799;

/// Reads the building's signs, by its barcode convention. A floor sign in view (id 900 + f)
/// sets the floor, which is kept until another is read; the nearest room sign in view (ids
/// 100..=799) is reported with its range and bearing, or room 0 when none is in view. "In
/// view": in a camera report younger than 500 ms.
///
/// For a sequencer: `signs.floor_known == 1 && signs.floor == 4` (the car's indicator says
/// floor 4; `floor_known` is false again after a reactivation, so an indicator read on another
/// ride does not count), or with `floor` set to the ride's floor, `signs.at_floor == 1` (the
/// same test, the floor a parameter: a plan's subtree cannot take a number);
/// `signs.room == 405 && signs.room_range < 2.0`.
#[derive(Default, Serialize, Deserialize)]
pub struct SignRead {
    activation: Activation,
    /// The floor last read, if one was read since activation.
    floor: Option<i32>,
}

impl Skill for SignRead {
    type Params = SignReadParams;
    type Inputs<'a> = SignIn<'a>;
    type Outputs<'a> = SignsOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(&mut self, ctx: &Ctx<SignReadParams>, i: SignIn, o: &mut SignsOut) -> SkillResult {
        let b = &*i.barcodes;
        if self.activation.begins(ctx) {
            self.floor = None;
        }
        let mut signs = Signs::default();
        if b.age_ms < IN_VIEW_MS {
            for k in 0..(b.count as usize).min(b.id.len()) {
                let id = b.id[k];
                if FLOORS.contains(&id) {
                    // In 0..=99: fits an i32.
                    self.floor = Some((id - 900) as i32);
                } else if ROOMS.contains(&id) && (signs.room == 0 || b.range[k] < signs.room_range)
                {
                    signs.room = id;
                    signs.room_range = b.range[k];
                    signs.room_bearing = b.bearing[k];
                }
            }
        }
        signs.floor_known = self.floor.is_some();
        signs.floor = self.floor.unwrap_or(0);
        signs.at_floor = self.floor.is_some_and(|f| i64::from(f) == ctx.params.floor);
        o.signs.set(signs);
        Ok(())
    }
}
