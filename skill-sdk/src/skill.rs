//! The skill trait: what a skill author implements.

use crate::decl::Mode;
use crate::params::Params;
use crate::ports::{InputSet, OutputSet};
pub use crate::state::State;
pub use skillfab_proto::board::Clock;
use std::fmt;

/// A skill: typed inputs, outputs and parameters, and a compute body.
///
/// ```
/// use skill_sdk::prelude::*;
/// use skillfab_msgs::{Scaled, Tick};
///
/// #[derive(Params, Debug, Clone)]
/// pub struct ScaleParams {
///     /// Factor applied to the tick.
///     #[param(default = 2.0, min = -1e6, max = 1e6)]
///     pub gain: f64,
/// }
/// #[derive(Inputs)]
/// pub struct In<'a> { pub tick: Input<'a, Tick> }
/// #[derive(Outputs)]
/// pub struct Out<'a> { pub scaled: Output<'a, Scaled> }
///
/// #[derive(Default)]
/// pub struct Scale;
/// impl Skill for Scale {
///     type Params = ScaleParams;
///     type Inputs<'a> = In<'a>;
///     type Outputs<'a> = Out<'a>;
///     fn compute(&mut self, ctx: &Ctx<ScaleParams>, i: In, o: &mut Out) -> SkillResult {
///         o.scaled.set(Scaled { value: ctx.params.gain * i.tick.value as f64 });
///         Ok(())
///     }
/// }
/// ```
pub trait Skill: Default + 'static {
    /// Parameters (derive `Params`), or [`crate::params::NoParams`].
    type Params: Params + Default;
    /// Inputs (derive `Inputs`), or `()`.
    type Inputs<'a>: InputSet<'a>;
    /// Outputs (derive `Outputs`), or `()`.
    type Outputs<'a>: OutputSet<'a>;
    /// Scheduling mode.
    const MODE: Mode = Mode::Sync;
    /// Default priority for actuator arbitration (higher wins); `--priority` overrides it.
    const PRIORITY: i32 = 0;

    /// One run: read the inputs, write the outputs. Written outputs are published only if
    /// this returns `Ok`.
    fn compute(
        &mut self,
        ctx: &Ctx<'_, Self::Params>,
        input: Self::Inputs<'_>,
        output: &mut Self::Outputs<'_>,
    ) -> SkillResult;

    /// What this instance must not lose if its process dies — its memory: a map of where the
    /// robot has been, an estimate built over many cycles, the phase of a manoeuvre.
    /// [`State::kept`] (the skill derives serde's `Serialize` and `Deserialize`): the runtime
    /// keeps the whole value as of its last completed run in the domain's shared memory and
    /// gives it to the next process of the same name before its first run; a failed run is
    /// undone. [`State::NONE`] (the default): nothing kept. See [`crate::state`].
    const STATE: State<Self> = State::NONE;
}

/// What a run knows besides its inputs.
#[derive(Debug)]
pub struct Ctx<'a, P> {
    /// Current parameter values.
    pub params: &'a P,
    /// The cycle this run belongs to.
    pub cycle: u64,
    /// The instance name.
    pub name: &'a str,
    /// Which activation of this skill the run belongs to: a number the manager raises each
    /// time a client (a sequencer) activates the skill, and gives unchanged to a restarted
    /// process of it. A skill that starts afresh when activated compares it with the last
    /// run's; a gap in cycles is not a new activation (a restart, a missing input).
    pub activation: u32,
    /// The cycle's time, period and mode. A skill that needs the time reads `clock.time`, never
    /// the wall clock, and draws random numbers from [`Ctx::rng`]: then a recorded run replays
    /// identically (docs/replay.md, "Determinism rules").
    pub clock: Clock,
}

impl<P> Ctx<'_, P> {
    /// A random generator for this run, seeded by the instance name and the cycle: the same
    /// numbers in a replay, after a restart, and from any cycle on. (A skill that wants one
    /// stream over many cycles keeps its own generator, seeded by a parameter, in its
    /// [`Skill::STATE`].)
    pub fn rng(&self) -> CycleRng {
        // FNV-1a of the name, mixed with the cycle.
        let h = self.name.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        });
        CycleRng(h ^ self.cycle.wrapping_mul(0x9E37_79B9_7F4A_7C15))
    }
}

/// A small seeded generator (splitmix64), from [`Ctx::rng`]; a skill may keep one in its
/// [`Skill::STATE`].
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct CycleRng(u64);

impl CycleRng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The result of a run.
pub type SkillResult = Result<(), SkillError>;

/// Why a run failed: any error, boxed (like `anyhow::Error`).
pub struct SkillError(Box<dyn std::error::Error + Send + Sync + 'static>);

impl SkillError {
    /// An error with just a message.
    pub fn msg(text: impl Into<String>) -> SkillError {
        SkillError(text.into().into())
    }
}

impl<E: std::error::Error + Send + Sync + 'static> From<E> for SkillError {
    fn from(e: E) -> Self {
        SkillError(Box::new(e))
    }
}

impl fmt::Debug for SkillError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&self.0, f)
    }
}

impl fmt::Display for SkillError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0, f)
    }
}
