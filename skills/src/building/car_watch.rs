//! `car_watch`: which elevator car is open on this floor, from the hall lanterns.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`CarWatch`].
#[derive(Params, Debug, Clone)]
pub struct CarWatchParams {
    /// Cars in the bank: lanterns 811 ..= 810 + cars.
    #[param(default = 4, min = 1, max = 89)]
    pub cars: u32,
    /// No lantern seen for this long: no car is open (ms of fabric time: cycles × period).
    #[param(default = 1500.0, min = 0.0, max = 60000.0)]
    pub lost_ms: f64,
    /// A lantern out of the camera's view (the robot turned away, or too near the bank to
    /// see it) is taken to be still lit for this long after it was last seen (ms of fabric
    /// time): a car's doors stay open 8 s after they finish opening, longer for a call or
    /// a robot in the doorway.
    #[param(default = 8000.0, min = 0.0, max = 60000.0)]
    pub unseen_ms: f64,
}

/// Inputs of [`CarWatch`].
#[derive(Inputs)]
pub struct CarWatchIn<'a> {
    /// Camera sightings.
    pub barcodes: Input<'a, Barcodes>,
    /// Odometry.
    pub odometry: Input<'a, Odometry>,
    /// The hall call button (barcode_track on it): it hangs on the bank's wall.
    pub target: Input<'a, Target>,
}

/// Output of [`CarWatch`].
#[derive(Outputs)]
pub struct CarOut<'a> {
    /// The open car.
    pub car: Output<'a, Car>,
}

/// Car k's hall lantern carries 810 + k.
const LANTERN_BASE: u32 = 810;
/// Weight kept by the older sightings of a lantern when a new one arrives (as barcode_track).
const FORGET: f64 = 0.9;
/// Closer than this (m), the button and the lantern do not give the wall's direction.
const WALL_BASE: f64 = 0.5;
/// The lantern hangs at the doorway's centre this far into the lobby, and the call button
/// this far in front of the bank's wall (m; the building's convention).
const INSET: f64 = 0.05;
/// A lantern is in the camera's view within this of its axis (rad; the camera sees ±30°) ...
const VIEW_HALF: f64 = 27.0 * PI / 180.0;
/// ... and this near (m; it sees 6 m).
const VIEW_RANGE: f64 = 5.6;

/// One car's lantern in the odometry frame.
#[derive(Debug, Default, Clone, Copy, Serialize, Deserialize)]
struct Lantern {
    /// Weighted sums of x, y and the weights (a running average that forgets).
    sum: (f64, f64, f64),
    /// Cycle of the last sighting, and its range then (ties between lanterns seen in one
    /// frame go to the nearest).
    seen: Option<(u64, f64)>,
}

/// Which car is open on this floor. A car's hall lantern (barcode 810 + k, at the centre of
/// its doorway, 5 cm into the lobby) shows only while car k is here with its doors open. Each
/// lantern in view is placed in the odometry frame (a running average over new sightings,
/// nearer ones weighing more, as barcode_track does). A car is open until its lantern has
/// not been seen for `lost_ms` while it should have been (where it was seen is within the
/// camera's view), or for `unseen_ms` while it could not be. The car reported stays the same while it is open (with two
/// open, the robot may be on its way into the first); otherwise it is the lantern seen most
/// recently. The way in is the bank wall's normal
/// away from the robot, the wall running along the line through the lantern and the call
/// button (both 5 cm in front of it; with the button unknown or within 0.5 m of the lantern,
/// the direction from the robot to the lantern); the doorway's centre is 5 cm beyond the
/// lantern that way.
///
/// For a sequencer: `car.id > 0` (car `id`, 1.., is open: its doorway at `car.x`, `car.y`, the way
/// in `car.heading`, odometry frame), `car.id == 0` (none, or its doors closed). Everything is
/// forgotten when reactivated: a lantern must be seen again.
#[derive(Default, Serialize, Deserialize)]
pub struct CarWatch {
    activation: Activation,
    lanterns: Vec<Lantern>,
    /// Age of the camera report seen in the last cycle (a younger one is a new report).
    last_age_ms: Option<f64>,
    /// The car reported (its index).
    current: Option<usize>,
}

impl Skill for CarWatch {
    type Params = CarWatchParams;
    type Inputs<'a> = CarWatchIn<'a>;
    type Outputs<'a> = CarOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(&mut self, ctx: &Ctx<CarWatchParams>, i: CarWatchIn, o: &mut CarOut) -> SkillResult {
        let (b, od, t, p) = (&*i.barcodes, &*i.odometry, &*i.target, ctx.params);
        if self.activation.begins(ctx) {
            self.lanterns.clear();
            self.last_age_ms = None;
            self.current = None;
        }
        self.lanterns.resize(p.cars as usize, Lantern::default());
        let new = self.last_age_ms.is_none_or(|last| b.age_ms < last);
        self.last_age_ms = Some(b.age_ms);
        if b.age_ms < IN_VIEW_MS {
            for k in 0..(b.count as usize).min(b.id.len()) {
                let Some(l) = b.id[k]
                    .checked_sub(LANTERN_BASE + 1)
                    .and_then(|n| self.lanterns.get_mut(n as usize))
                else {
                    continue;
                };
                l.seen = Some((ctx.cycle, b.range[k]));
                if new {
                    let a = od.theta + b.bearing[k];
                    let (x, y) = (od.x + b.range[k] * a.cos(), od.y + b.range[k] * a.sin());
                    let w = 1.0 / b.range[k].max(0.3);
                    l.sum = (
                        FORGET * l.sum.0 + w * x,
                        FORGET * l.sum.1 + w * y,
                        FORGET * l.sum.2 + w,
                    );
                }
            }
        }
        let period_ms = period_ms(ctx);
        // Open: seen within `lost_ms`; or, while where it was seen is out of the camera's
        // view, within `unseen_ms`.
        let open = |l: &Lantern| {
            let Some((cycle, _)) = l.seen.filter(|_| l.sum.2 > 0.0) else {
                return false;
            };
            let (x, y) = (l.sum.0 / l.sum.2, l.sum.1 / l.sum.2);
            let bearing = wrap((y - od.y).atan2(x - od.x) - od.theta);
            let in_view = bearing.abs() < VIEW_HALF && (x - od.x).hypot(y - od.y) < VIEW_RANGE;
            let unseen = ctx.cycle.saturating_sub(cycle) as f64 * period_ms;
            unseen <= p.lost_ms || (!in_view && unseen <= p.unseen_ms)
        };
        // The car reported last while it stays open (with two open, the camera sees one
        // lantern, then the other: the robot may be on its way to the first); else the
        // lantern seen most recently, the nearest among those of one frame.
        let keep = self
            .current
            .filter(|&n| self.lanterns.get(n).is_some_and(&open));
        let latest = || {
            self.lanterns
                .iter()
                .enumerate()
                .filter(|(_, l)| open(l))
                .filter_map(|(n, l)| l.seen.map(|(cycle, r)| (n, cycle, r)))
                .max_by(|a, b| a.1.cmp(&b.1).then(b.2.total_cmp(&a.2)))
                .map(|(n, ..)| n)
        };
        self.current = keep.or_else(latest);
        let mut car = Car::default();
        if let Some(n) = self.current
            && let Some(sum) = self.lanterns.get(n).map(|l| l.sum)
        {
            let (x, y) = (sum.0 / sum.2, sum.1 / sum.2);
            let (dx, dy) = (x - t.x, y - t.y);
            let base = dx.hypot(dy);
            let heading = if t.seen && base >= WALL_BASE {
                // The wall's normal away from the robot: the button and the lantern stand
                // the same INSET in front of the wall, so the line through them runs with it.
                let (nx, ny) = (-dy / base, dx / base);
                let away = nx * (x - od.x) + ny * (y - od.y);
                if away >= 0.0 {
                    ny.atan2(nx)
                } else {
                    (-ny).atan2(-nx)
                }
            } else {
                (y - od.y).atan2(x - od.x)
            };
            // The doorway's centre: INSET beyond the lantern, in the wall's line.
            let (x, y) = (x + INSET * heading.cos(), y + INSET * heading.sin());
            // `n` < cars ≤ 89: fits a u32.
            car = Car {
                id: 1 + n as u32,
                x,
                y,
                heading,
            };
        }
        o.car.set(car);
        Ok(())
    }
}
