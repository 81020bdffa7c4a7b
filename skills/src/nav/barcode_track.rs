//! `barcode_track`: barcode tracking in the odometry frame.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`BarcodeTrack`].
#[derive(Params, Debug, Clone)]
pub struct TrackParams {
    /// The barcode id to track.
    #[param(default = 7, min = 0, max = 65535)]
    pub id: u32,
}

/// Inputs of [`BarcodeTrack`].
#[derive(Inputs)]
pub struct TrackIn<'a> {
    /// Camera sightings.
    pub barcodes: Input<'a, Barcodes>,
    /// Odometry.
    pub odometry: Input<'a, Odometry>,
}

/// Output of [`BarcodeTrack`].
#[derive(Outputs)]
pub struct TrackOut<'a> {
    /// The tracked barcode.
    pub target: Output<'a, Target>,
}

/// Barcode tracking: keeps the latest sighting of the wanted id, placed in the odometry
/// frame (a running average over sightings that forgets old ones, as odometry drifts), and
/// its range and bearing from the robot now. Each sighting is used once: the camera's report
/// stays in the input until the next one, and placing it again from a pose that moved on
/// would smear the estimate. A new `id`, or a new activation, starts from nothing: one
/// tracker serves a plan's successive targets (a door, a button, a sign), and the old
/// target's place must not leak into the new one's.
#[derive(Default, Serialize, Deserialize)]
pub struct BarcodeTrack {
    sum: (f64, f64, f64),
    /// Age of the report seen in the last cycle (a younger one is a new report).
    last_age_ms: Option<f64>,
    /// The id the estimate belongs to.
    tracking: Option<u32>,
    activation: Activation,
}

/// Weight kept by the older sightings when a new one arrives.
const TRACK_FORGET: f64 = 0.9;

impl Skill for BarcodeTrack {
    type Params = TrackParams;
    type Inputs<'a> = TrackIn<'a>;
    type Outputs<'a> = TrackOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(&mut self, ctx: &Ctx<TrackParams>, i: TrackIn, o: &mut TrackOut) -> SkillResult {
        let od = *i.odometry;
        let b = *i.barcodes;
        let begins = self.activation.begins(ctx);
        if begins || self.tracking != Some(ctx.params.id) {
            self.sum = (0.0, 0.0, 0.0);
            self.tracking = Some(ctx.params.id);
        }
        let new = self.last_age_ms.is_none_or(|last| b.age_ms < last);
        self.last_age_ms = Some(b.age_ms);
        let mut visible = false;
        for k in 0..(b.count as usize).min(8) {
            if b.id[k] == ctx.params.id && b.age_ms < 500.0 {
                visible = true;
                if !new {
                    continue;
                }
                let a = od.theta + b.bearing[k];
                let (x, y) = (od.x + b.range[k] * a.cos(), od.y + b.range[k] * a.sin());
                // Near sightings are better: weight by 1/range.
                let w = 1.0 / b.range[k].max(0.3);
                let f = TRACK_FORGET;
                self.sum = (
                    f * self.sum.0 + w * x,
                    f * self.sum.1 + w * y,
                    f * self.sum.2 + w,
                );
            }
        }
        let mut t = Target {
            id: ctx.params.id,
            visible,
            ..Target::default()
        };
        if self.sum.2 > 0.0 {
            t.seen = true;
            t.x = self.sum.0 / self.sum.2;
            t.y = self.sum.1 / self.sum.2;
            t.range = (t.x - od.x).hypot(t.y - od.y);
            t.bearing = wrap((t.y - od.y).atan2(t.x - od.x) - od.theta);
        }
        o.target.set(t);
        Ok(())
    }
}
