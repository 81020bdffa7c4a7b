//! Runs a skill body in-process on scripted inputs: unit tests for skills, no processes.
//!
//! ```
//! use skill_sdk::harness::Harness;
//! # use skill_sdk::prelude::*;
//! # use skillfab_msgs::{Scaled, Tick};
//! # #[derive(Params, Debug, Clone)] struct P { #[param(default = 2.0)] gain: f64 }
//! # #[derive(Inputs)] struct In<'a> { tick: Input<'a, Tick> }
//! # #[derive(Outputs)] struct Out<'a> { scaled: Output<'a, Scaled> }
//! # #[derive(Default)] struct Scale;
//! # impl Skill for Scale {
//! #     type Params = P; type Inputs<'a> = In<'a>; type Outputs<'a> = Out<'a>;
//! #     fn compute(&mut self, c: &Ctx<P>, i: In, o: &mut Out) -> SkillResult {
//! #         o.scaled.set(Scaled { value: c.params.gain * i.tick.value as f64 }); Ok(()) }
//! # }
//! let mut h = Harness::<Scale>::new();
//! h.set(P::GAIN, 3.0).unwrap();
//! h.input(In::TICK, Tick { value: 5 });
//! let step = h.step().unwrap();
//! assert_eq!(step.output(Out::SCALED).unwrap().value, 15.0);
//! ```
//!
//! Ports and parameters are named by the references their derives generate (`In::TICK`, an
//! [`InputRef`]; see [`crate::refs`]): the compiler checks that the skill has the port and
//! that the value is of its message type, and `output` needs no type. A name works too
//! (`h.input("tick", ..)`, `step.output::<Scaled>("scaled")`, `h.set_param("gain=3")`),
//! checked when the test runs: a name the skill does not have stops the test.

use crate::Message;
use crate::params::{ParamError, ParamType, Params};
use crate::ports::{ErasedOutput, InputMeta, InputSet, InputSource, OutputSet, PortMaker};
use crate::refs::{InputRef, OutputRef, Param};
use crate::skill::{Ctx, Skill, SkillError};
use std::any::Any;
use std::marker::PhantomData;

/// A port of the skill under test as a test names it: a reference its derive made, of the
/// skill's input or output struct `Of` ([`InputRef`] for inputs, [`OutputRef`] for outputs:
/// the harness takes only its own skill's, so a test cannot feed an output or name another
/// skill's port), or the port's name (checked when the test runs).
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a port of the skill under test (its ports are of `{Of}`)",
    label = "a reference of `{Of}`, or a port name"
)]
pub trait Port<Of> {
    /// The port's name.
    fn name(&self) -> &str;
}

impl<Of> Port<Of> for &str {
    fn name(&self) -> &str {
        self
    }
}

impl<T, Of> Port<Of> for InputRef<T, Of> {
    fn name(&self) -> &str {
        InputRef::name(self)
    }
}

impl<T, Of> Port<Of> for OutputRef<T, Of> {
    fn name(&self) -> &str {
        OutputRef::name(self)
    }
}

/// A port that carries message type `T`: a reference of a port of that type, or any name
/// (its type is checked when the test runs).
#[diagnostic::on_unimplemented(
    message = "`{Self}` does not carry `{T}`",
    label = "the port carries another message type"
)]
pub trait Carries<T> {}

impl<T> Carries<T> for &str {}
impl<T, Of> Carries<T> for InputRef<T, Of> {}
impl<T, Of> Carries<T> for OutputRef<T, Of> {}

/// The input struct of skill `S` (what its input references are of).
type InputsOf<S> = <S as Skill>::Inputs<'static>;
/// The output struct of skill `S`.
type OutputsOf<S> = <S as Skill>::Outputs<'static>;

/// The period a harness steps at (its [`crate::skill::Clock`]).
pub const HARNESS_PERIOD: std::time::Duration = std::time::Duration::from_millis(10);

/// An in-process driver for one skill body.
pub struct Harness<S: Skill> {
    skill: S,
    params: S::Params,
    cycle: u64,
    input_names: Vec<String>,
    output_names: Vec<String>,
    inputs: Vec<Option<(Box<dyn Any>, u64)>>,
    outputs: Vec<ErasedOutput>,
    /// Restart the skill before every this many steps ([`Harness::restarting`]); 0: never.
    restart_every: u64,
    /// The activation number the steps run in ([`Harness::reactivate`]).
    activation: u32,
}

/// What one step of skill `S` produced.
pub struct Step<S> {
    names: Vec<String>,
    values: Vec<Option<Box<dyn Any>>>,
    /// The cycle number of the step.
    pub cycle: u64,
    /// True if the body did not run because an input was missing.
    pub skipped: bool,
    /// Whose outputs these are (what [`Step::output`] takes references of).
    skill: PhantomData<fn() -> S>,
}

impl<S: Skill> Step<S> {
    /// The value written to output `port`, `None` if the body did not write it. `port` is a
    /// reference of the skill's outputs (`Out::SCALED`: the type follows from it) or a name
    /// (`output::<Scaled>("scaled")`).
    ///
    /// # Panics
    /// If the skill has no output named `port`, or the value written is of another type than
    /// `T` (only possible with a name): a misspelt name must fail the test, not pass an
    /// `is_none()` that tests nothing.
    pub fn output<T: Message>(&self, port: impl Port<OutputsOf<S>> + Carries<T>) -> Option<&T> {
        let port = port.name();
        let Some(i) = self.names.iter().position(|n| n == port) else {
            panic!(
                "the skill has no output '{port}' (its outputs: {})",
                self.names.join(", ")
            );
        };
        let value = self.values.get(i)?.as_ref()?;
        match value.downcast_ref::<T>() {
            Some(v) => Some(v),
            None => panic!(
                "output '{port}' does not carry {}",
                std::any::type_name::<T>()
            ),
        }
    }
}

struct Scripted<'a> {
    inputs: &'a [Option<(Box<dyn Any>, u64)>],
    cycle: u64,
}

impl InputSource for Scripted<'_> {
    fn get(&self, idx: usize) -> Option<(&dyn Any, InputMeta)> {
        let (v, c) = self.inputs.get(idx)?.as_ref()?;
        Some((
            v.as_ref(),
            InputMeta {
                cycle: *c,
                age: self.cycle.saturating_sub(*c),
                source: None,
            },
        ))
    }
}

impl<S: Skill> Default for Harness<S> {
    fn default() -> Self {
        Self::new()
    }
}

impl<S: Skill> Harness<S> {
    /// The clock a harness step runs with: lock-step at [`HARNESS_PERIOD`], time = cycle ×
    /// period.
    fn clock(cycle: u64) -> crate::skill::Clock {
        crate::skill::Clock {
            time: HARNESS_PERIOD * u32::try_from(cycle).unwrap_or(u32::MAX),
            period: Some(HARNESS_PERIOD),
            lockstep: true,
        }
    }

    /// A fresh skill with default parameters, before cycle 1.
    pub fn new() -> Self {
        let input_names: Vec<String> = <S::Inputs<'static> as InputSet<'static>>::ports()
            .into_iter()
            .map(|p| p.port)
            .collect();
        let output_ports = <S::Outputs<'static> as OutputSet<'static>>::ports();
        let output_names: Vec<String> = output_ports.iter().map(|p| p.port.clone()).collect();
        let maker = PortMaker {
            node: None,
            ports: output_ports,
        };
        // Memory cells cannot fail to build.
        let outputs = <S::Outputs<'static> as OutputSet<'static>>::make(&maker).unwrap_or_default();
        Harness {
            skill: S::default(),
            params: S::Params::default(),
            cycle: 0,
            inputs: input_names.iter().map(|_| None).collect(),
            input_names,
            output_names,
            outputs,
            restart_every: 0,
            activation: 1,
        }
    }

    /// What a sequencer's deactivate + activate does: the next step belongs to a new
    /// activation ([`Ctx::activation`]).
    pub fn reactivate(&mut self) -> &mut Self {
        self.activation += 1;
        self
    }

    /// Restarts the skill ([`Harness::restart`]) before every `every`-th step: a closed-loop
    /// test run so shows whether the skill goes on as if its process had never died.
    pub fn restarting(&mut self, every: u64) -> &mut Self {
        self.restart_every = every;
        self
    }

    /// What a restart after `kill -9` does to the skill, here between two steps: the value is
    /// replaced by a new instance given the state of the last completed run, encoded and
    /// decoded as the runtime keeps it ([`Skill::STATE`]; a skill that keeps nothing starts
    /// from `Default`). Parameters and inputs stay, as the manager and the producers keep
    /// them.
    ///
    /// # Panics
    /// If the state does not survive its own encoding (the mistake a test is there to find).
    pub fn restart(&mut self) -> &mut Self {
        let mut bytes = Vec::new();
        #[allow(clippy::expect_used)]
        let kept = S::STATE
            .encode(&self.skill, &mut bytes)
            .expect("the state encodes");
        self.skill = if kept {
            #[allow(clippy::expect_used)]
            S::STATE.decode(&bytes).expect("the kept state decodes")
        } else {
            S::default()
        };
        self
    }

    /// Applies `name=value`, checked like `--param`.
    pub fn set_param(&mut self, assignment: &str) -> Result<&mut Self, ParamError> {
        self.params.assign(assignment)?;
        Ok(self)
    }

    /// Sets parameter `param` (a reference of the skill's parameters, `P::GAIN`) to `value`,
    /// checked against its bounds as at run time; on error nothing changes.
    pub fn set<T: ParamType>(
        &mut self,
        param: Param<T, S::Params>,
        value: T,
    ) -> Result<&mut Self, ParamError> {
        self.params.set(param.name(), value.to_value())?;
        Ok(self)
    }

    /// The current parameters.
    pub fn params(&self) -> &S::Params {
        &self.params
    }

    /// The skill state, to inspect between steps.
    pub fn skill(&self) -> &S {
        &self.skill
    }

    /// Sets input `port` (a reference of the skill's inputs, `In::TICK`, or a name) for the
    /// next step (produced in that step's cycle).
    ///
    /// # Panics
    /// If the skill has no input named `port` (a mistake in the test itself).
    pub fn input<T: Message>(
        &mut self,
        port: impl Port<InputsOf<S>> + Carries<T>,
        value: T,
    ) -> &mut Self {
        self.input_aged(port, value, 0)
    }

    /// Sets input `port`, produced `age` cycles before the next step.
    ///
    /// # Panics
    /// If the skill has no input named `port` (a mistake in the test itself).
    pub fn input_aged<T: Message>(
        &mut self,
        port: impl Port<InputsOf<S>> + Carries<T>,
        value: T,
        age: u64,
    ) -> &mut Self {
        let i = self.input_index(port.name());
        self.inputs[i] = Some((Box::new(value), (self.cycle + 1).saturating_sub(age)));
        self
    }

    /// Removes input `port`.
    ///
    /// # Panics
    /// If the skill has no input named `port`.
    pub fn clear_input(&mut self, port: impl Port<InputsOf<S>>) -> &mut Self {
        let i = self.input_index(port.name());
        self.inputs[i] = None;
        self
    }

    /// The index of input `port`; a test naming an input the skill lacks is wrong, and stops.
    fn input_index(&self, port: &str) -> usize {
        match self.input_names.iter().position(|n| n == port) {
            Some(i) => i,
            None => panic!(
                "the skill has no input '{port}' (its inputs: {})",
                self.input_names.join(", ")
            ),
        }
    }

    /// Runs one cycle: the body on the current inputs. An error from the body is returned.
    pub fn step(&mut self) -> Result<Step<S>, SkillError> {
        if self.restart_every > 0 && self.cycle > 0 && self.cycle.is_multiple_of(self.restart_every)
        {
            self.restart();
        }
        self.cycle += 1;
        let cycle = self.cycle;
        let src = Scripted {
            inputs: &self.inputs,
            cycle,
        };
        let Some(input) = <S::Inputs<'_> as InputSet<'_>>::fetch(&src) else {
            return Ok(Step {
                names: self.output_names.clone(),
                values: self.output_names.iter().map(|_| None).collect(),
                cycle,
                skipped: true,
                skill: PhantomData,
            });
        };
        let result = {
            let mut out = <S::Outputs<'_> as OutputSet<'_>>::bind(&mut self.outputs);
            let ctx = Ctx {
                params: &self.params,
                cycle,
                name: "harness",
                activation: self.activation,
                clock: Self::clock(cycle),
            };
            self.skill.compute(&ctx, input, &mut out)
        };
        let values = self.outputs.iter_mut().map(|o| o.take_memory()).collect();
        // Unlike the runtime, a failed step is not undone: the test sees the error and the
        // value as the body left it.
        result?;
        Ok(Step {
            names: self.output_names.clone(),
            values,
            cycle,
            skipped: false,
            skill: PhantomData,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::Harness;
    use crate::prelude::*;
    use skillfab_msgs::{Scaled, Tick};

    #[derive(Params, Debug, Clone)]
    struct P {
        /// Ticks above this are scaled; the others write nothing.
        #[param(default = 0, min = -100, max = 100)]
        above: i64,
    }
    #[derive(Inputs)]
    struct In<'a> {
        tick: Input<'a, Tick>,
    }
    #[derive(Outputs)]
    struct Out<'a> {
        scaled: Output<'a, Scaled>,
    }
    #[derive(Default)]
    struct Scale;
    impl Skill for Scale {
        type Params = P;
        type Inputs<'a> = In<'a>;
        type Outputs<'a> = Out<'a>;
        fn compute(&mut self, c: &Ctx<P>, i: In, o: &mut Out) -> SkillResult {
            if i.tick.value as i64 > c.params.above {
                o.scaled.set(Scaled {
                    value: i.tick.value as f64,
                });
            }
            Ok(())
        }
    }

    fn stepped(tick: u64) -> super::Step<Scale> {
        let mut h = Harness::<Scale>::new();
        h.set_param("above=3").unwrap();
        h.input("tick", Tick { value: tick });
        h.step().unwrap()
    }

    #[test]
    fn an_output_the_body_did_not_write_is_none() {
        assert!(stepped(2).output::<Scaled>("scaled").is_none());
        assert_eq!(stepped(5).output::<Scaled>("scaled").unwrap().value, 5.0);
    }

    #[test]
    #[should_panic(expected = "the skill has no output 'scald' (its outputs: scaled)")]
    fn a_misspelt_output_fails_the_test_instead_of_reading_none() {
        let _ = stepped(2).output::<Scaled>("scald");
    }

    #[test]
    #[should_panic(expected = "output 'scaled' does not carry")]
    fn an_output_read_as_another_type_fails_the_test() {
        let _ = stepped(5).output::<Tick>("scaled");
    }

    #[test]
    #[should_panic(expected = "the skill has no input 'tik' (its inputs: tick)")]
    fn a_misspelt_input_fails_the_test() {
        Harness::<Scale>::new().clear_input("tik");
    }

    #[test]
    fn references_name_ports_and_parameters_with_their_types() {
        let mut h = Harness::<Scale>::new();
        h.set(P::ABOVE, 3).unwrap();
        assert_eq!(h.params().above, 3);
        h.input(In::TICK, Tick { value: 5 });
        // No type to write: `Out::SCALED` carries `Scaled`.
        let step = h.step().unwrap();
        let scaled: Option<&Scaled> = step.output(Out::SCALED);
        assert_eq!(scaled.map(|s| s.value), Some(5.0));
        h.clear_input(In::TICK);
        assert!(h.step().unwrap().skipped);
        // Bounds are checked as for a name; a refused value changes nothing.
        assert!(h.set(P::ABOVE, 1000).is_err());
        assert_eq!(h.params().above, 3);
    }

    #[test]
    fn a_typed_input_ages_like_a_named_one() {
        let mut h = Harness::<Scale>::new();
        h.input_aged(In::TICK, Tick { value: 9 }, 2);
        assert_eq!(h.step().unwrap().output(Out::SCALED).unwrap().value, 9.0);
    }
}
