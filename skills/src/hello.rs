//! The hello network: `ticker` → `scale` → `smooth` (see `skills/launch/hello.toml`).

use skill_sdk::prelude::*;
use skillfab_msgs::{Scalar, Scaled, Smoothed, Tick};

/// Outputs of [`Ticker`].
#[derive(Outputs)]
pub struct TickOut<'a> {
    /// The cycle number.
    pub tick: Output<'a, Tick>,
}

/// Sync, no inputs: publishes the cycle number.
#[derive(Default)]
pub struct Ticker;

impl Skill for Ticker {
    type Params = NoParams;
    type Inputs<'a> = ();
    type Outputs<'a> = TickOut<'a>;
    fn compute(&mut self, ctx: &Ctx<NoParams>, _: (), o: &mut TickOut) -> SkillResult {
        o.tick.set(Tick { value: ctx.cycle });
        Ok(())
    }
}

/// Parameters of [`Scale`].
#[derive(Params, Debug, Clone)]
pub struct ScaleParams {
    /// Factor applied to the tick.
    #[param(default = 2.0, min = -1e6, max = 1e6)]
    pub gain: f64,
}
/// Inputs of [`Scale`].
#[derive(Inputs)]
pub struct ScaleIn<'a> {
    /// The tick of this cycle.
    pub tick: Input<'a, Tick>,
}
/// Outputs of [`Scale`].
#[derive(Outputs)]
pub struct ScaleOut<'a> {
    /// gain × tick.
    pub scaled: Output<'a, Scaled>,
}

/// Sync: `scaled = gain × tick`.
#[derive(Default)]
pub struct Scale;

impl Skill for Scale {
    type Params = ScaleParams;
    type Inputs<'a> = ScaleIn<'a>;
    type Outputs<'a> = ScaleOut<'a>;
    fn compute(&mut self, ctx: &Ctx<ScaleParams>, i: ScaleIn, o: &mut ScaleOut) -> SkillResult {
        o.scaled.set(Scaled {
            value: ctx.params.gain * i.tick.value as f64,
        });
        Ok(())
    }
}

/// Parameters of [`Smooth`].
#[derive(Params, Debug, Clone)]
pub struct SmoothParams {
    /// Weight of the newest sample in the moving average.
    #[param(default = 0.1, min = 0.0, max = 1.0)]
    pub alpha: f64,
}
/// Inputs of [`Smooth`].
#[derive(Inputs)]
pub struct SmoothIn<'a> {
    /// The latest scaled value.
    pub scaled: Input<'a, Scaled>,
}
/// Outputs of [`Smooth`].
#[derive(Outputs)]
pub struct SmoothOut<'a> {
    /// The moving average.
    pub smoothed: Output<'a, Smoothed>,
}

/// Async: exponential moving average of the latest `scaled`.
#[derive(Default)]
pub struct Smooth {
    state: Option<Smoothed>,
}

impl Skill for Smooth {
    type Params = SmoothParams;
    type Inputs<'a> = SmoothIn<'a>;
    type Outputs<'a> = SmoothOut<'a>;
    const MODE: Mode = Mode::Async;
    fn compute(&mut self, ctx: &Ctx<SmoothParams>, i: SmoothIn, o: &mut SmoothOut) -> SkillResult {
        let next = fold(self.state, i.scaled.value, ctx.params.alpha);
        self.state = Some(next);
        o.smoothed.set(next);
        Ok(())
    }
}

/// The moving average after folding in `x` with weight `alpha` (the first sample is the
/// average).
pub fn fold(state: Option<Smoothed>, x: f64, alpha: f64) -> Smoothed {
    match state {
        None => Smoothed {
            value: x,
            samples: 1,
        },
        Some(s) => Smoothed {
            value: alpha * x + (1.0 - alpha) * s.value,
            samples: s.samples + 1,
        },
    }
}

/// Parameters of [`CheckChain`].
#[derive(Params, Debug, Clone)]
pub struct CheckParams {
    /// The gain the scale stages use.
    #[param(default = 2.0, min = -1e6, max = 1e6)]
    pub gain: f64,
    /// The alpha the smooth stages use.
    #[param(default = 0.1, min = 0.0, max = 1.0)]
    pub alpha: f64,
    /// Largest difference from the reference that still passes.
    #[param(default = 1e-9, min = 0.0, max = 1e6)]
    pub tolerance: f64,
}
/// Inputs of [`CheckChain`].
#[derive(Inputs)]
pub struct CheckIn<'a> {
    /// The tick of this cycle.
    pub tick: Input<'a, Tick>,
    /// One implementation's smoothed value of this cycle.
    pub a: Input<'a, Smoothed>,
    /// Another implementation's smoothed value of this cycle.
    pub b: Input<'a, Smoothed>,
}
/// Outputs of [`CheckChain`].
#[derive(Outputs)]
pub struct CheckOut<'a> {
    /// The larger difference of `a` and `b` from the reference (0 when both agree).
    pub error: Output<'a, Scalar>,
}

/// Sync: a reference model of scale → smooth (`gain` × tick, moving average, one sample per
/// cycle) that fails every run in which `a` or `b` differs from it. Two implementations of
/// the chain — in other languages, say — run side by side; `failures` counts the cycles they
/// were wrong in.
#[derive(Default)]
pub struct CheckChain {
    reference: Option<Smoothed>,
}

impl Skill for CheckChain {
    type Params = CheckParams;
    type Inputs<'a> = CheckIn<'a>;
    type Outputs<'a> = CheckOut<'a>;
    fn compute(&mut self, ctx: &Ctx<CheckParams>, i: CheckIn, o: &mut CheckOut) -> SkillResult {
        let p = ctx.params;
        let r = fold(self.reference, p.gain * i.tick.value as f64, p.alpha);
        self.reference = Some(r);
        let error = (i.a.value - r.value).abs().max((i.b.value - r.value).abs());
        o.error.set(Scalar {
            value: error,
            ..Scalar::default()
        });
        if error > p.tolerance || i.a.samples != r.samples || i.b.samples != r.samples {
            return Err(SkillError::msg(format!(
                "cycle {}: reference {:?}, a {:?}, b {:?}",
                ctx.cycle,
                r,
                i.a.value(),
                i.b.value()
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skill_sdk::harness::Harness;

    #[test]
    fn check_chain_passes_the_reference_and_fails_a_difference() {
        let mut h = Harness::<CheckChain>::new();
        let mut ema = Smoothed::default();
        for k in 1..=3u64 {
            let x = 2.0 * k as f64;
            ema = if k == 1 {
                Smoothed {
                    value: x,
                    samples: 1,
                }
            } else {
                Smoothed {
                    value: 0.1 * x + 0.9 * ema.value,
                    samples: k,
                }
            };
            h.input(CheckIn::TICK, Tick { value: k });
            h.input(CheckIn::A, ema);
            h.input(CheckIn::B, ema);
            let step = h.step().unwrap();
            assert_eq!(step.output(CheckOut::ERROR).unwrap().value, 0.0);
        }
        h.input(CheckIn::TICK, Tick { value: 4 });
        h.input(
            CheckIn::A,
            Smoothed {
                value: 1.0,
                samples: 4,
            },
        );
        let e = h.step().err().expect("a wrong value fails the run");
        assert!(e.to_string().contains("cycle 4"), "{e}");
    }

    #[test]
    fn ticker_publishes_the_cycle() {
        let mut h = Harness::<Ticker>::new();
        for k in 1..=3 {
            assert_eq!(h.step().unwrap().output(TickOut::TICK).unwrap().value, k);
        }
    }

    #[test]
    fn scale_multiplies_and_checks_its_gain() {
        let mut h = Harness::<Scale>::new();
        h.input(ScaleIn::TICK, Tick { value: 7 });
        let scaled =
            |h: &mut Harness<Scale>| h.step().unwrap().output(ScaleOut::SCALED).unwrap().value;
        assert_eq!(scaled(&mut h), 14.0);
        h.set(ScaleParams::GAIN, -0.5).unwrap();
        assert_eq!(scaled(&mut h), -3.5);
        assert!(h.set(ScaleParams::GAIN, 1e9).is_err());
        // As text (`--param`, `skillfab ctl param`): parsed by the declared type.
        assert!(h.set_param("gain=abc").is_err());
        assert!(h.set_param("nope=1").is_err());
        assert_eq!(h.params().gain, -0.5, "a refused value changes nothing");
    }

    #[test]
    fn scale_skips_without_its_input() {
        let mut h = Harness::<Scale>::new();
        assert!(h.step().unwrap().skipped);
    }

    #[test]
    fn smooth_is_an_exponential_moving_average() {
        let mut h = Harness::<Smooth>::new();
        h.set(SmoothParams::ALPHA, 0.5).unwrap();
        h.input(SmoothIn::SCALED, Scaled { value: 10.0 });
        assert_eq!(
            h.step().unwrap().output(SmoothOut::SMOOTHED).unwrap().value,
            10.0
        );
        h.input(SmoothIn::SCALED, Scaled { value: 20.0 });
        let s = *h.step().unwrap().output(SmoothOut::SMOOTHED).unwrap();
        assert_eq!(
            s,
            Smoothed {
                value: 15.0,
                samples: 2
            }
        );
    }
}
