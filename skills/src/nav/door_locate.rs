//! `door_locate`: door location from the sonar ring.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`DoorLocate`].
#[derive(Params, Debug, Clone)]
pub struct DoorParams {
    /// Start looking when the barcode is closer than this (m).
    #[param(default = 3.0, min = 0.5, max = 10.0)]
    pub near: f64,
    /// A reading this much longer than the wall along its whole cone looks through it (m).
    #[param(default = 1.0, min = 0.2, max = 5.0)]
    pub margin: f64,
    /// Narrowest opening that counts as the door (m).
    #[param(default = 0.6, min = 0.2, max = 3.0)]
    pub min_width: f64,
    /// How far along the wall, either side of the barcode, the door may be (m).
    #[param(default = 3.0, min = 0.5, max = 10.0)]
    pub span: f64,
}

/// Inputs of [`DoorLocate`].
#[derive(Inputs)]
pub struct DoorIn<'a> {
    /// The ring.
    pub sonar: Input<'a, Sonar>,
    /// Odometry.
    pub odometry: Input<'a, Odometry>,
    /// The door's barcode.
    pub target: Input<'a, Target>,
}

/// Output of [`DoorLocate`].
#[derive(Outputs)]
pub struct DoorOut<'a> {
    /// The opening.
    pub door: Output<'a, Door>,
}

/// Incidence beyond which a ping reflects away from a wall instead of echoing (rad).
const GRAZING: f64 = 65.0 * PI / 180.0;
/// Width of an evidence bin along the wall (m).
const BIN: f64 = 0.05;

/// A cone faces the wall when its axis is within this of the wall's normal (rad).
const FACING: f64 = 60f64.to_radians();
/// Readings taken closer to the wall than this (m) tell nothing about it.
const MIN_GAP: f64 = 0.05;
/// A ray this close to parallel to the wall (cosine) never crosses it usefully.
const MIN_COSINE: f64 = 0.1;
/// The wall is searched from this far in front of the barcode (m) ...
const FIT_BEFORE: f64 = 0.05;
/// ... to this far behind it (the barcode hangs on the wall or just in front).
const FIT_BEYOND: f64 = 0.3;
/// Half the depth an echo is spread over when fitting the wall (m): the range's noise.
const ECHO_SPREAD: f64 = 0.08;
/// A reading adds evidence only when its cone meets the wall within this of the normal (rad).
const EVIDENCE_INCIDENCE: f64 = 55f64.to_radians();
/// Cone edges are clipped this far inside the grazing angle (rad): edges near it may not echo.
const GRAZING_MARGIN: f64 = 0.05;
/// An echo counts as the wall when it is within this of the range the wall explains (m).
const ECHO_TOLERANCE: f64 = 0.15;
/// Wall evidence within this distance on both sides of an open run brackets a door (m).
const BRACKET: f64 = 0.5;
/// A refit tries the wall's angle in steps of this (rad) ...
const REFIT_STEP: f64 = 0.25f64.to_radians();
/// ... this many steps to either side of the current fit (±6°).
const REFIT_STEPS: i32 = 24;
/// A wall needs this many readings that agree with it: a line through the barcode fitted on
/// fewer can be any line (the first fit is tried again each cycle until it has them).
const MIN_SUPPORT: usize = 20;
/// A refit replaces the wall when this many more readings (or a tenth more) agree with it.
const REFIT_MARGIN: usize = 4;
/// The first fit tries normals this far either side of the way to the barcode (degrees) ...
const FIT_RANGE: i32 = 70;
/// ... and each refit a fifth of them besides the near ones (one in five, in turn): in a
/// second, every one the first fit tried. A line among them replaces the wall only when half
/// as many again agree with it (and more than with the best near one).
const REFIT_PARTS: i32 = 5;

/// The normals the first fit tries, one a degree within [`FIT_RANGE`] of the way from the
/// robot at `od` to the barcode at `code`; with `part`, only that one of every
/// [`REFIT_PARTS`] (a refit's share of them).
fn first_fit_normals(
    od: &Odometry,
    code: (f64, f64),
    part: Option<i32>,
) -> impl Iterator<Item = f64> {
    let beta = (code.1 - od.y).atan2(code.0 - od.x);
    (-FIT_RANGE..=FIT_RANGE)
        .filter(move |d| part.is_none_or(|p| (d + FIT_RANGE) % REFIT_PARTS == p))
        .map(move |d| wrap(beta + f64::from(d).to_radians()))
}

/// One sonar reading placed in the odometry frame: ring point, direction, range (∞: no echo).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Ray {
    o: (f64, f64),
    a: f64,
    r: f64,
}

/// A wall line `x cos φ + y sin φ = ρ`, its normal pointing from the robot's side into it;
/// positions along it are measured from the barcode's foot on it.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Wall {
    phi: f64,
    rho: f64,
    anchor: (f64, f64),
}

impl Wall {
    fn n(&self) -> (f64, f64) {
        (self.phi.cos(), self.phi.sin())
    }
    /// Distance from `o` to the wall along the normal (positive: the wall is ahead).
    fn gap(&self, o: (f64, f64)) -> f64 {
        let (nx, ny) = self.n();
        self.rho - (o.0 * nx + o.1 * ny)
    }
    /// Coordinate along the wall of a point.
    fn along(&self, p: (f64, f64)) -> f64 {
        let (nx, ny) = self.n();
        -(p.0 - self.anchor.0) * ny + (p.1 - self.anchor.1) * nx
    }
    /// The point on the wall at coordinate `s`.
    fn at(&self, s: f64) -> (f64, f64) {
        let (nx, ny) = self.n();
        let g = self.gap(self.anchor);
        (
            self.anchor.0 + g * nx - s * ny,
            self.anchor.1 + g * ny + s * nx,
        )
    }
    /// The range a sonar cone sees when the whole cone meets the wall: its ray nearest to the
    /// normal hits first. `None` when the cone does not face the wall.
    fn expected(&self, ray: &Ray) -> Option<f64> {
        let inc = wrap(ray.a - self.phi).abs();
        let gap = self.gap(ray.o);
        (inc < FACING && gap > MIN_GAP).then(|| gap / (inc - CONE).max(0.0).cos())
    }
    /// Where the ray at angle `a` from `o` crosses the wall (coordinate along it).
    fn crossing(&self, o: (f64, f64), a: f64) -> Option<f64> {
        let c = wrap(a - self.phi).cos();
        let gap = self.gap(o);
        (c > MIN_COSINE && gap > MIN_GAP).then(|| {
            let t = gap / c;
            self.along((o.0 + t * a.cos(), o.1 + t * a.sin()))
        })
    }
}

/// Door location, the paper's example of a perception skill. Near the door's barcode it fits
/// the barcode's wall: the line through the barcode that best explains the ring's echoes
/// (a cone's range is the distance along its ray nearest to the wall's normal). Then every
/// new sonar reading is evidence along that wall: a cone that sees well past the wall shows
/// its whole footprint open; an echo at the wall's distance shows wall where the cone meets it
/// first. The door is the widest open run next to the barcode with wall on both sides, its
/// edges halfway between the last open and the first wall evidence; the way through is the
/// wall's normal. Each reading is used once, placed from the pose it was taken at.
#[derive(Default, Serialize, Deserialize)]
pub struct DoorLocate {
    /// Age of each sonar's reading in the last cycle (a younger one is a new reading).
    ages: Vec<f64>,
    /// Every reading since the search began, oldest first (bounded).
    history: std::collections::VecDeque<Ray>,
    wall: Option<Wall>,
    /// Along-wall evidence around the barcode, from `-span`: (open, wall) counts per bin.
    bins: Vec<(u32, u32)>,
    /// Cycle of the last refit of the wall.
    fitted: u64,
    /// Refits so far: which part of the first fit's range of normals the next one tries.
    #[serde(default)]
    refits: u32,
    /// The newest estimate.
    #[serde(with = "DoorState")]
    found: Door,
}

/// How the door estimate is kept (the message type itself has no serde).
#[derive(Serialize, Deserialize)]
#[serde(remote = "Door")]
struct DoorState {
    found: bool,
    x: f64,
    y: f64,
    heading: f64,
    width: f64,
}

/// Readings kept for refitting the wall and rebuilding the evidence.
const HISTORY: usize = 6000;
/// Readings the wall is first fitted on (the newest).
const FIT_RAYS: usize = 400;
/// Readings the wall is refitted on (the newest, some 15 s): enough that a few readings
/// meeting the wall do not move it, few enough that it follows the odometry's drift.
const REFIT_RAYS: usize = 1200;
/// The wall is fitted on readings that meet it this close to the barcode (m).
const FIT_WINDOW: f64 = 1.2;
/// ... and meet it this close to square (rad).
const FIT_INCIDENCE: f64 = 40.0 * PI / 180.0;

impl DoorLocate {
    /// The wall that explains most readings, among normals `phis` and offsets that put the
    /// barcode on the wall or a little in front of it. A reading agrees with a wall when its
    /// range is what the cone sees of it (within 8 cm); for one normal, the readings that
    /// agree at each offset are found in one sweep over the offsets each reading allows.
    /// Only readings that meet the wall near the barcode count: it hangs on that wall, while
    /// other surfaces (a box's face) may line up with it farther away. Returns the wall and
    /// how many readings agree with it; `None` when no wall has [`MIN_SUPPORT`].
    fn fit(
        rays: &[Ray],
        anchor: (f64, f64),
        phis: impl Iterator<Item = f64>,
    ) -> Option<(usize, Wall)> {
        let mut best: Option<(usize, Wall)> = None;
        let mut ends: Vec<(f64, i32)> = Vec::with_capacity(2 * rays.len());
        for phi in phis {
            let (nx, ny) = (phi.cos(), phi.sin());
            let at_code = anchor.0 * nx + anchor.1 * ny;
            let (lo, hi) = (at_code - FIT_BEFORE, at_code + FIT_BEYOND);
            let probe = Wall {
                phi,
                rho: at_code,
                anchor,
            };
            ends.clear();
            for ray in rays.iter().filter(|r| r.r.is_finite()) {
                let inc = wrap(ray.a - phi).abs();
                if inc > FIT_INCIDENCE
                    || probe
                        .crossing(ray.o, ray.a)
                        .is_none_or(|s| s.abs() > FIT_WINDOW)
                {
                    continue;
                }
                let c = (inc - CONE).max(0.0).cos();
                let base = ray.o.0 * nx + ray.o.1 * ny;
                let (a, b) = (
                    base + (ray.r - ECHO_SPREAD) * c,
                    base + (ray.r + ECHO_SPREAD) * c,
                );
                if b >= lo && a <= hi {
                    ends.push((a.max(lo), 1));
                    ends.push((b.min(hi), -1));
                }
            }
            ends.sort_by(|x, y| x.0.total_cmp(&y.0).then(y.1.cmp(&x.1)));
            let (mut n, mut top, mut at) = (0i32, 0i32, at_code);
            for (k, &(rho, step)) in ends.iter().enumerate() {
                n += step;
                if n > top {
                    top = n;
                    // The middle of the stretch where this many agree.
                    let next = ends.get(k + 1).map_or(rho, |e| e.0);
                    at = (rho + next) / 2.0;
                }
            }
            let count = top.max(0) as usize;
            if best.as_ref().is_none_or(|b| count > b.0) {
                best = Some((
                    count,
                    Wall {
                        phi,
                        rho: at,
                        anchor,
                    },
                ));
            }
        }
        best.filter(|b| b.0 >= MIN_SUPPORT)
    }

    /// How many of `rays` agree with `wall` as [`fit`](Self::fit) counts them.
    fn support(rays: &[Ray], wall: &Wall) -> usize {
        let (nx, ny) = wall.n();
        let probe = Wall {
            rho: wall.anchor.0 * nx + wall.anchor.1 * ny,
            ..*wall
        };
        rays.iter()
            .filter(|ray| ray.r.is_finite())
            .filter(|ray| {
                let inc = wrap(ray.a - wall.phi).abs();
                if inc > FIT_INCIDENCE
                    || probe
                        .crossing(ray.o, ray.a)
                        .is_none_or(|s| s.abs() > FIT_WINDOW)
                {
                    return false;
                }
                let depth = ray.o.0 * nx + ray.o.1 * ny + ray.r * (inc - CONE).max(0.0).cos();
                (depth - wall.rho).abs() <= ECHO_SPREAD
            })
            .count()
    }

    /// Evidence from every reading kept, along the current wall.
    fn rebuild(&mut self, span: f64, margin: f64) {
        let Some(wall) = self.wall else { return };
        self.bins = vec![(0, 0); (2.0 * span / BIN).ceil() as usize];
        let rays: Vec<Ray> = self.history.iter().copied().collect();
        for ray in rays {
            self.observe(wall, ray, margin, span);
        }
    }

    fn mark(&mut self, from: f64, to: f64, open: bool, span: f64) {
        let n = self.bins.len() as f64;
        let lo = ((from + span) / BIN).floor().max(0.0);
        let hi = ((to + span) / BIN).ceil().min(n);
        let (lo, hi) = (lo as usize, hi as usize);
        for b in self.bins.iter_mut().take(hi).skip(lo) {
            if open {
                b.0 += 1;
            } else {
                b.1 += 1;
            }
        }
    }

    /// Evidence from one new reading.
    fn observe(&mut self, wall: Wall, ray: Ray, margin: f64, span: f64) {
        let inc = wrap(ray.a - wall.phi);
        if inc.abs() > EVIDENCE_INCIDENCE {
            return;
        }
        // The cone's edges, clipped to the rays that would echo off a wall: steeper ones
        // reflect away and tell nothing.
        let steep = GRAZING - GRAZING_MARGIN;
        let clip = |a: f64| wall.phi + wrap(a - wall.phi).clamp(-steep, steep);
        let edges = [clip(ray.a - CONE), clip(ray.a + CONE)];
        let [Some(s1), Some(s2)] = edges.map(|a| wall.crossing(ray.o, a)) else {
            return;
        };
        let far = edges
            .iter()
            .map(|a| wall.gap(ray.o) / wrap(a - wall.phi).cos())
            .fold(0.0, f64::max);
        if ray.r > far + margin {
            self.mark(s1.min(s2), s1.max(s2), true, span);
        } else if let Some(e) = wall.expected(&ray)
            && (ray.r - e).abs() < ECHO_TOLERANCE
        {
            // The first echo: where the ray nearest to the normal meets the wall.
            let a = if inc.abs() <= CONE {
                wall.phi
            } else {
                ray.a - CONE * inc.signum()
            };
            if let Some(s) = wall.crossing(ray.o, a) {
                self.mark(s - BIN / 2.0, s + BIN / 2.0, false, span);
            }
        }
    }

    /// The door from the evidence: (centre along the wall, width).
    fn door(&self, min_width: f64, span: f64) -> Option<(f64, f64)> {
        let open = |b: &(u32, u32)| b.0 >= 2 && b.0 > 2 * b.1;
        let wall = |b: &(u32, u32)| b.1 >= 2 && b.1 > b.0;
        let mut best: Option<(f64, f64)> = None;
        let mut i = 0;
        while i < self.bins.len() {
            if !open(&self.bins[i]) {
                i += 1;
                continue;
            }
            let mut j = i;
            while j + 1 < self.bins.len()
                && (open(&self.bins[j + 1])
                    || (j + 2 < self.bins.len()
                        && !wall(&self.bins[j + 1])
                        && open(&self.bins[j + 2])))
            {
                j += 1;
            }
            // Wall evidence within BRACKET on both sides brackets the opening.
            let reach = (BRACKET / BIN) as usize;
            let left = (i.saturating_sub(reach)..i)
                .rev()
                .find(|&k| wall(&self.bins[k]));
            let right =
                (j + 1..(j + 1 + reach).min(self.bins.len())).find(|&k| wall(&self.bins[k]));
            if let (Some(l), Some(r)) = (left, right) {
                let lo = BIN * (i as f64 + l as f64 + 1.0) / 2.0 - span;
                let hi = BIN * (j as f64 + 1.0 + r as f64) / 2.0 - span;
                if hi - lo >= min_width && best.is_none_or(|b| hi - lo > b.1) {
                    best = Some(((lo + hi) / 2.0, hi - lo));
                }
            }
            i = j + 1;
        }
        best
    }
}

impl Skill for DoorLocate {
    type Params = DoorParams;
    type Inputs<'a> = DoorIn<'a>;
    type Outputs<'a> = DoorOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(&mut self, ctx: &Ctx<DoorParams>, i: DoorIn, o: &mut DoorOut) -> SkillResult {
        let (od, t, s, p) = (*i.odometry, *i.target, *i.sonar, ctx.params);
        if self.ages.is_empty() {
            self.ages = vec![f64::INFINITY; SONARS];
        }
        let mut fresh = Vec::new();
        for k in 0..SONARS {
            let new = s.age_ms[k] < self.ages[k];
            self.ages[k] = s.age_ms[k];
            if new && let Some(echo) = s.echo(k) {
                let a = wrap(od.theta + sonar_angle(k));
                let ray = Ray {
                    o: (od.x + RING * a.cos(), od.y + RING * a.sin()),
                    a,
                    r: echo.range_or(f64::INFINITY),
                };
                fresh.push(ray);
                if self.history.len() == HISTORY {
                    self.history.pop_front();
                }
                self.history.push_back(ray);
            }
        }
        let newest = |h: &std::collections::VecDeque<Ray>| -> Vec<Ray> {
            h.iter().rev().take(FIT_RAYS).copied().collect()
        };
        if self.wall.is_none() && t.seen && t.range < p.near {
            // First fit: any normal within 70° of the way to the barcode, through it.
            let phis = first_fit_normals(&od, (t.x, t.y), None);
            self.wall = Self::fit(&newest(&self.history), (t.x, t.y), phis).map(|f| f.1);
            self.fitted = ctx.cycle;
            self.rebuild(p.span, p.margin);
        } else if let Some(w) = self.wall
            && ctx.cycle >= self.fitted + 20
            && !fresh.is_empty()
        {
            // Refit on every reading kept, near the current line, from the barcode's newest
            // estimate: the evidence is rebuilt along the refined wall. A new line is taken
            // only when clearly more readings agree with it than with the current one. Refit
            // on the newest 400 readings and taken whenever best, the line followed the few
            // that met the wall while the robot was beside the door or walking away, and
            // walked 20° and more off in steps of up to 6° (exit-lab-clutter seed 8, building
            // C seed 17: doors reported 0.2 m and 2.5 m from the real one).
            let anchor = if t.seen { (t.x, t.y) } else { w.anchor };
            let current = Wall { anchor, ..w };
            let rays: Vec<Ray> = self
                .history
                .iter()
                .rev()
                .take(REFIT_RAYS)
                .copied()
                .collect();
            let cands =
                (-REFIT_STEPS..=REFIT_STEPS).map(|d| wrap(w.phi + f64::from(d) * REFIT_STEP));
            let held = Self::support(&rays, &current);
            // A first fit on few readings can take the wrong wall — a barcode 0.6 m from a
            // corner, the line along the corner's other wall (held-out building G's lab,
            // seeds 1 and 8) — which the near normals never leave: a part of the first fit's
            // range is tried too, in turn.
            let part = (self.refits % REFIT_PARTS as u32) as i32;
            self.refits = self.refits.wrapping_add(1);
            let wide = first_fit_normals(&od, anchor, Some(part));
            let near = Self::fit(&rays, anchor, cands);
            let far = Self::fit(&rays, anchor, wide);
            let beats = |n: usize, by: usize| n >= held + by;
            self.wall = Some(match (near, far) {
                (near, Some((n, other)))
                    if beats(n, held / 2 + REFIT_MARGIN)
                        && near.as_ref().is_none_or(|b| n > b.0) =>
                {
                    other
                }
                (Some((n, better)), _) if beats(n, (held / 10).max(REFIT_MARGIN)) => better,
                _ => current,
            });
            self.fitted = ctx.cycle;
            self.rebuild(p.span, p.margin);
        } else if let Some(wall) = self.wall {
            for ray in fresh {
                self.observe(wall, ray, p.margin, p.span);
            }
        }
        if let Some(wall) = self.wall {
            // Once found, the door stays found; new evidence only moves it.
            if let Some((s, width)) = self.door(p.min_width, p.span) {
                let (x, y) = wall.at(s);
                self.found = Door {
                    found: true,
                    x,
                    y,
                    heading: wall.phi,
                    width,
                };
            }
        }
        o.door.set(self.found);
        Ok(())
    }
}
