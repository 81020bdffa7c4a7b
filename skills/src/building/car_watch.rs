//! `car_watch`: which elevator car is open on this floor, from the hall lanterns.

use super::*;

/// Parameters of [`CarWatch`].
#[derive(Params, Debug, Clone)]
pub struct CarWatchParams {
    /// Cars in the bank: lanterns 811 ..= 810 + cars.
    #[param(default = 4, min = 1, max = 89)]
    pub cars: u32,
    /// No lantern seen for this long: no car is open (ms of fabric time: cycles × period).
    #[param(default = 1500.0, min = 0.0, max = 60000.0)]
    pub lost_ms: f64,
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
/// The call button stands this far in front of the bank's wall (m; the building's convention).
const BUTTON_OFF: f64 = 0.05;
/// The period assumed when the manager free-runs (no nominal period): its default.
const FREE_RUN_PERIOD_MS: f64 = 10.0;

/// One car's lantern in the odometry frame.
#[derive(Debug, Default, Clone, Copy)]
struct Lantern {
    /// Weighted sums of x, y and the weights (a running average that forgets).
    sum: (f64, f64, f64),
    /// Cycle of the last sighting, and its range then (ties between lanterns seen in one
    /// frame go to the nearest).
    seen: Option<(u64, f64)>,
}

/// Which car is open on this floor. A car's hall lantern (barcode 810 + k, at the centre of
/// its doorway on the bank's wall) shows only while car k is here with its doors open. Each
/// lantern in view is placed in the odometry frame (a running average over new sightings,
/// nearer ones weighing more, as barcode_track does). The car is the lantern seen most
/// recently, until none has been seen for `lost_ms`. Its doorway is the lantern's place; the
/// way in is the bank wall's normal away from the robot, the wall being the line through the
/// lantern and the call button's foot on the wall (or, with the button unknown or within
/// 0.5 m of the lantern, the direction from the robot to the lantern).
///
/// For a sequencer: `car.id > 0` (car `id`, 1.., is open: its doorway at `car.x`, `car.y`, the way
/// in `car.heading`, odometry frame), `car.id == 0` (none, or its doors closed). Everything is
/// forgotten when reactivated: a lantern must be seen again.
#[derive(Default)]
pub struct CarWatch {
    activation: Activation,
    lanterns: Vec<Lantern>,
    /// Age of the camera report seen in the last cycle (a younger one is a new report).
    last_age_ms: Option<f64>,
}

impl Skill for CarWatch {
    type Params = CarWatchParams;
    type Inputs<'a> = CarWatchIn<'a>;
    type Outputs<'a> = CarOut<'a>;
    fn compute(&mut self, ctx: &Ctx<CarWatchParams>, i: CarWatchIn, o: &mut CarOut) -> SkillResult {
        let (b, od, t, p) = (&*i.barcodes, &*i.odometry, &*i.target, ctx.params);
        if self.activation.begins(ctx.cycle) {
            self.lanterns.clear();
            self.last_age_ms = None;
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
        let period_ms = ctx
            .clock
            .period
            .map_or(FREE_RUN_PERIOD_MS, |d| d.as_secs_f64() * 1000.0);
        // The most recent sighting, the nearest among those of one frame.
        let latest = self
            .lanterns
            .iter()
            .enumerate()
            .filter_map(|(n, l)| l.seen.map(|(cycle, r)| (n, cycle, r, l.sum)))
            .filter(|&(.., sum)| sum.2 > 0.0)
            .max_by(|a, b| a.1.cmp(&b.1).then(b.2.total_cmp(&a.2)));
        let mut car = Car::default();
        if let Some((n, cycle, _, sum)) = latest
            && ctx.cycle.saturating_sub(cycle) as f64 * period_ms <= p.lost_ms
        {
            let (x, y) = (sum.0 / sum.2, sum.1 / sum.2);
            let heading = if t.seen && (x - t.x).hypot(y - t.y) >= WALL_BASE {
                // The wall's normal away from the robot, from the line through the button and
                // the lantern; then again from the button's foot on the wall (it stands
                // BUTTON_OFF in front of it: 3° off over a car's 0.9 m, 5 cm at the cabin).
                let normal = |bx: f64, by: f64| {
                    let (dx, dy) = (x - bx, y - by);
                    let base = dx.hypot(dy).max(f64::EPSILON);
                    let (nx, ny) = (-dy / base, dx / base);
                    let away = nx * (x - od.x) + ny * (y - od.y);
                    if away >= 0.0 { (nx, ny) } else { (-nx, -ny) }
                };
                let (nx, ny) = normal(t.x, t.y);
                let (nx, ny) = normal(t.x + BUTTON_OFF * nx, t.y + BUTTON_OFF * ny);
                ny.atan2(nx)
            } else {
                (y - od.y).atan2(x - od.x)
            };
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
