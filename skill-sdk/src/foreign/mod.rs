//! Skills declared at run time, for other languages: the C ABI (`skill-sdk/capi`) and, through
//! it, Python build a [`ForeignSkill`] — ports by message type name, parameters from specs, a
//! boxed body over raw message bytes — and [`run`] runs it through the same runtime as a Rust
//! skill (registration, cycles, parameter updates, shutdown).
//!
//! Message types are looked up by type name in the registry the skill is declared with
//! (`skillfab_msgs::registry()` for the shared catalog): a foreign skill can use every type
//! listed there, and its bytes have exactly the Rust layout (the generated C header and Python
//! classes are checked against it).
//!
//! [`run`] builds the runtime's unit from the declaration by value and starts it through the
//! same start-up path as a Rust skill; a process runs one skill, so [`run`] may be called once
//! per process.

mod raw;
mod sanitize;

use sanitize::contains_bool;
pub use sanitize::{sanitize_bools, sanitize_message};

use crate::SdkError;
use crate::decl::{Mode, PortDecl, PortKind};
use crate::params::{ParamError, ParamSpec, ParamValue, Params, check_bounds};
use crate::ports::{ErasedInput, ErasedOutput, InputMeta, InputSource, PortMaker};
use crate::runtime::{Common, Io, Link, SkillArgs, Unit, guarded, start, step_skill};
use crate::schema::MessageSchema;
use crate::skill::{Ctx, SkillError, SkillResult};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// A boxed runtime input port.
pub type ErasedInputBox = Box<dyn ErasedInput>;

/// What the runtime needs to use a message type chosen by name at run time (a skill declared
/// in C or Python). Build one with [`MessageType::of`].
#[derive(Debug)]
pub struct MessageType {
    /// The type name.
    pub type_name: &'static str,
    /// Its layout.
    pub schema: fn() -> MessageSchema,
    /// Builds the runtime input port of input `idx`.
    pub input: fn(&PortMaker<'_>, usize) -> Result<ErasedInputBox, SdkError>,
    /// Builds the runtime output cell of output `idx`.
    pub output: fn(&PortMaker<'_>, usize) -> Result<ErasedOutput, SdkError>,
    /// The bytes of a value of this type held as `&dyn Any`.
    pub bytes: fn(&dyn std::any::Any) -> Option<&[u8]>,
}

impl MessageType {
    /// The entry of message type `T`.
    pub const fn of<T: crate::Message>() -> MessageType {
        MessageType {
            type_name: T::TYPE_NAME,
            schema: T::schema,
            input: <crate::ports::Input<'static, T> as crate::ports::InputField<'static>>::make,
            output: <crate::ports::Output<'static, T> as crate::ports::OutputField<'static>>::make,
            bytes: bytes_of::<T>,
        }
    }
}

/// The entry of every type known only by its schema (declared with
/// [`ForeignSkill::input_schema`] / [`ForeignSkill::output_schema`]): its ports take the schema
/// from their declaration.
static RAW: MessageType = MessageType {
    type_name: "",
    schema: no_schema,
    input: raw::make_input,
    output: raw::make_output,
    bytes: raw::view_bytes,
};

fn no_schema() -> MessageSchema {
    MessageSchema {
        type_name: String::new(),
        doc: String::new(),
        size: 0,
        align: 1,
        fields: Vec::new(),
    }
}

fn bytes_of<T: crate::Message>(any: &dyn std::any::Any) -> Option<&[u8]> {
    let value = any.downcast_ref::<T>()?;
    // SAFETY: a Message is plain old data; the slice covers exactly the borrowed value.
    Some(unsafe {
        std::slice::from_raw_parts((value as *const T).cast::<u8>(), std::mem::size_of::<T>())
    })
}

/// A skill body over raw message bytes.
pub type Body = Box<dyn FnMut(&mut ForeignRun<'_>) -> SkillResult + Send>;

/// Why a declaration was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DeclError {
    /// A message file on `SKILLFAB_MSG_PATH` is wrong.
    #[error("message file: {reason}")]
    MessageFile {
        /// Its path, line and what is wrong.
        reason: String,
    },
    /// No shared message type of that name.
    #[error(
        "unknown message type '{type_name}' (neither in the shared catalog nor in a message package on SKILLFAB_MSG_PATH)"
    )]
    UnknownType {
        /// The name given.
        type_name: String,
    },
    /// A port, channel or parameter name that is not allowed or used twice.
    #[error("bad {what} name '{name}': {reason}")]
    BadName {
        /// Port, channel or parameter.
        what: &'static str,
        /// The name given.
        name: String,
        /// Why.
        reason: String,
    },
    /// A parameter whose default lies outside its bounds, or whose bounds are reversed.
    #[error("parameter '{name}': {reason}")]
    BadParam {
        /// Parameter name.
        name: String,
        /// Why.
        reason: String,
    },
    /// More ports than the board can track (64 inputs, 64 outputs).
    #[error("too many {what} (at most 64)")]
    TooMany {
        /// Inputs or outputs.
        what: &'static str,
    },
}

/// A skill declared at run time.
pub struct ForeignSkill {
    /// What kind of skill this is (the default instance name).
    pub kind: String,
    mode: Mode,
    priority: i32,
    inputs: Vec<PortDecl>,
    outputs: Vec<PortDecl>,
    params: Vec<ParamSpec>,
    body: Option<Body>,
    /// The message types ports may be declared with, by type name.
    registry: &'static [MessageType],
    /// Handed out by [`ForeignSkill::waker`].
    waker: Option<crate::runtime::Waker>,
}

impl std::fmt::Debug for ForeignSkill {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ForeignSkill")
            .field("kind", &self.kind)
            .field("mode", &self.mode)
            .field("inputs", &self.inputs.len())
            .field("outputs", &self.outputs.len())
            .field("params", &self.params.len())
            .finish()
    }
}

fn message_type(
    registry: &'static [MessageType],
    type_name: &str,
) -> Result<&'static MessageType, DeclError> {
    registry
        .iter()
        .find(|t| t.type_name == type_name)
        .ok_or_else(|| DeclError::UnknownType {
            type_name: type_name.to_string(),
        })
}

fn check_port_name(what: &'static str, name: &str, taken: &[PortDecl]) -> Result<(), DeclError> {
    let bad = |reason: String| DeclError::BadName {
        what,
        name: name.to_string(),
        reason,
    };
    crate::names::check_name(what, name, false).map_err(|e| bad(e.to_string()))?;
    if taken.iter().any(|p| p.port == name) {
        return Err(bad("declared twice".into()));
    }
    Ok(())
}

impl ForeignSkill {
    /// A skill of `kind` with no ports, parameters or body yet, whose ports may have the
    /// message types of `registry` (e.g. `skillfab_msgs::registry()`).
    pub fn new(
        kind: &str,
        mode: Mode,
        registry: &'static [MessageType],
    ) -> Result<ForeignSkill, DeclError> {
        crate::names::check_name("skill", kind, false).map_err(|e| DeclError::BadName {
            what: "skill",
            name: kind.to_string(),
            reason: e.to_string(),
        })?;
        Ok(ForeignSkill {
            kind: kind.to_string(),
            mode,
            priority: 0,
            inputs: Vec::new(),
            outputs: Vec::new(),
            params: Vec::new(),
            body: None,
            registry,
            waker: None,
        })
    }

    /// Declares input `port` of message type `type_name`; returns its index.
    pub fn input(&mut self, port: &str, type_name: &str) -> Result<usize, DeclError> {
        let t = message_type(self.registry, type_name)?;
        self.input_schema(port, (t.schema)())
    }

    /// Declares input `port` of a message type known by its schema alone (a type of a
    /// message file that is not in the registry, e.g. from `SKILLFAB_MSG_PATH`); returns its
    /// index.
    pub fn input_schema(&mut self, port: &str, schema: MessageSchema) -> Result<usize, DeclError> {
        check_port_name("input", port, &self.inputs)?;
        if self.inputs.len() >= 64 {
            return Err(DeclError::TooMany { what: "inputs" });
        }
        self.inputs.push(PortDecl {
            port: port.to_string(),
            topic: port.to_string(),
            schema,
            kind: PortKind::Data,
        });
        Ok(self.inputs.len() - 1)
    }

    /// Declares output `port` of message type `type_name`; returns its index.
    pub fn output(&mut self, port: &str, type_name: &str) -> Result<usize, DeclError> {
        let t = message_type(self.registry, type_name)?;
        self.add_output(port, (t.schema)(), PortKind::Data)
    }

    /// Declares output `port` of a message type known by its schema alone (see
    /// [`ForeignSkill::input_schema`]); returns its index.
    pub fn output_schema(&mut self, port: &str, schema: MessageSchema) -> Result<usize, DeclError> {
        self.add_output(port, schema, PortKind::Data)
    }

    /// Declares a proposal on actuator channel `channel`; returns its output index.
    pub fn proposal(&mut self, channel: &str, type_name: &str) -> Result<usize, DeclError> {
        let t = message_type(self.registry, type_name)?;
        self.add_output(channel, (t.schema)(), PortKind::Proposal)
    }

    fn add_output(
        &mut self,
        port: &str,
        schema: MessageSchema,
        kind: PortKind,
    ) -> Result<usize, DeclError> {
        check_port_name("output", port, &self.outputs)?;
        if self.outputs.len() >= 64 {
            return Err(DeclError::TooMany { what: "outputs" });
        }
        let topic = match kind {
            PortKind::Data => port.to_string(),
            _ => crate::names::channel_topic(port),
        };
        self.outputs.push(PortDecl {
            port: port.to_string(),
            topic,
            schema,
            kind,
        });
        Ok(self.outputs.len() - 1)
    }

    /// Declares a parameter; returns its index. The default must lie within the bounds.
    pub fn param(&mut self, spec: ParamSpec) -> Result<usize, DeclError> {
        let bad = |reason: String| DeclError::BadParam {
            name: spec.name.clone(),
            reason,
        };
        crate::names::check_name("parameter", &spec.name, false).map_err(|e| bad(e.to_string()))?;
        if self.params.iter().any(|p| p.name == spec.name) {
            return Err(bad("declared twice".into()));
        }
        for v in std::iter::once(&spec.default)
            .chain(&spec.min)
            .chain(&spec.max)
        {
            if v.kind() != spec.kind {
                return Err(bad(format!("{v} is not a {}", spec.kind)));
            }
            if v.as_f64().is_nan() {
                return Err(bad("NaN is not a value".into()));
            }
        }
        if let (Some(lo), Some(hi)) = (spec.min, spec.max)
            && lo.as_f64() > hi.as_f64()
        {
            return Err(bad(format!("min {lo} > max {hi}")));
        }
        check_bounds(&spec, spec.default).map_err(|e| bad(e.to_string()))?;
        self.params.push(spec);
        Ok(self.params.len() - 1)
    }

    /// Sets the default arbitration priority (`--priority` overrides it).
    pub fn set_priority(&mut self, priority: i32) {
        self.priority = priority;
    }

    /// Sets the body.
    pub fn compute(&mut self, body: Body) {
        self.body = Some(body);
    }

    /// The declared outputs.
    pub fn outputs(&self) -> &[PortDecl] {
        &self.outputs
    }

    /// A handle with which other threads make this skill run at once. An async skill that
    /// asked for one runs when it is woken, and only then — not on fresh inputs nor once per
    /// cycle (a gateway that receives samples on its own threads publishes them as they come).
    pub fn waker(&mut self) -> crate::runtime::Waker {
        self.waker.get_or_insert_with(Default::default).clone()
    }
}

/// Why [`run`] could not start.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunError {
    /// The skill has no body.
    #[error("skill '{kind}' has no compute body")]
    NoBody {
        /// Its kind.
        kind: String,
    },
    /// A skill already ran in this process.
    #[error("a skill already ran in this process (one skill per process)")]
    AlreadyRan,
    /// Bad command-line arguments (the message is clap's, with usage).
    #[error("{0}")]
    Args(String),
    /// The runtime failed.
    #[error(transparent)]
    Sdk(#[from] SdkError),
}

/// Whether a foreign skill ran in this process: one skill per process (its tracing, log
/// stream and signal handling are the process's).
static RAN: AtomicBool = AtomicBool::new(false);

/// Runs `skill` as this process's skill with command-line `args` (the program name first,
/// then the usual skill options: `--name`, `--domain`, `--param`, …) until SIGINT/SIGTERM.
pub fn run(mut skill: ForeignSkill, args: Vec<String>) -> Result<(), RunError> {
    let body = skill.body.take().ok_or_else(|| RunError::NoBody {
        kind: skill.kind.clone(),
    })?;
    let args = <SkillArgs as clap::Parser>::try_parse_from(args)
        .map_err(|e| RunError::Args(e.render().to_string()))?;
    if RAN.swap(true, Ordering::AcqRel) {
        return Err(RunError::AlreadyRan);
    }
    let kind = skill.kind.clone();
    let unit = ForeignUnit::new(skill, body);
    start(unit, &args, &[], &kind).map_err(|(_, e)| RunError::Sdk(e))
}

/// Parameter values of a foreign skill, in declaration order, with their declaration.
#[derive(Debug, Clone)]
pub struct ForeignParams {
    specs: Arc<[ParamSpec]>,
    values: Vec<ParamValue>,
}

impl ForeignParams {
    /// The declared defaults of `specs`.
    fn defaults(specs: Arc<[ParamSpec]>) -> ForeignParams {
        let values = specs.iter().map(|s| s.default).collect();
        ForeignParams { specs, values }
    }

    /// The value of parameter `idx`.
    pub fn at(&self, idx: usize) -> Option<ParamValue> {
        self.values.get(idx).copied()
    }
}

impl Params for ForeignParams {
    fn specs(&self) -> Vec<ParamSpec> {
        self.specs.to_vec()
    }
    fn get(&self, name: &str) -> Option<ParamValue> {
        let i = self.specs.iter().position(|s| s.name == name)?;
        self.at(i)
    }
    fn set_unchecked(&mut self, name: &str, value: ParamValue) -> Result<(), ParamError> {
        let i = self
            .specs
            .iter()
            .position(|s| s.name == name)
            .ok_or_else(|| ParamError::Unknown {
                param: name.to_string(),
            })?;
        let kind = self.specs[i].kind;
        self.values[i] = value.coerce(kind).ok_or_else(|| ParamError::WrongType {
            param: name.to_string(),
            expected: kind,
            got: value,
        })?;
        Ok(())
    }
}

/// What a foreign body sees in one run.
pub struct ForeignRun<'a> {
    /// The cycle of this run.
    pub cycle: u64,
    /// The cycle's time, period and mode (read it instead of a clock: docs/replay.md).
    pub clock: crate::skill::Clock,
    /// The instance name.
    pub name: &'a str,
    params: &'a ForeignParams,
    /// The message type of each input, to view its samples as bytes.
    input_types: &'a [&'static MessageType],
    inputs: &'a dyn InputSource,
    outputs: &'a mut [ErasedOutput],
    error: Option<String>,
}

impl<'a> ForeignRun<'a> {
    /// The bytes and cycle bookkeeping of input `idx` (`None`: no sample yet, or no such input).
    pub fn input(&self, idx: usize) -> Option<(&'a [u8], InputMeta)> {
        let (any, meta) = self.inputs.get(idx)?;
        let bytes = (self.input_types.get(idx)?.bytes)(any)?;
        Some((bytes, meta))
    }

    /// The bytes of output `idx` to write, zeroed at the first access in a run (`clear` false:
    /// not cleared, see [`crate::ports::Output::fill_in_place`]); marks it written.
    pub fn output(&mut self, idx: usize, clear: bool) -> Option<&mut [u8]> {
        Some(self.outputs.get_mut(idx)?.bytes_mut(clear))
    }

    /// The value of parameter `idx` (declaration order).
    pub fn param(&self, idx: usize) -> Option<ParamValue> {
        self.params.at(idx)
    }

    /// Fails this run with `reason` (the body's return value decides as well).
    pub fn fail(&mut self, reason: &str) {
        self.error = Some(reason.to_string());
    }
}

/// The runtime's unit of a foreign skill: its declaration and body, by value.
struct ForeignUnit {
    mode: Mode,
    priority: i32,
    inputs: Vec<PortDecl>,
    outputs: Vec<PortDecl>,
    params: Arc<[ParamSpec]>,
    /// Which message type each input and output is.
    input_types: Vec<&'static MessageType>,
    output_types: Vec<&'static MessageType>,
    /// Which outputs' types have a bool anywhere (only those are normalised after a run).
    output_bools: Vec<bool>,
    body: Body,
    waker: Option<crate::runtime::Waker>,
}

impl ForeignUnit {
    fn new(skill: ForeignSkill, body: Body) -> ForeignUnit {
        // One type per port: `ForeignSkill::input`/`output` accepted only registered types.
        let types = |ports: &[PortDecl]| {
            ports
                .iter()
                .map(|p| message_type(skill.registry, &p.schema.type_name).unwrap_or(&RAW))
                .collect::<Vec<_>>()
        };
        ForeignUnit {
            mode: skill.mode,
            priority: skill.priority,
            input_types: types(&skill.inputs),
            output_types: types(&skill.outputs),
            output_bools: skill
                .outputs
                .iter()
                .map(|p| p.schema.fields.iter().any(|f| contains_bool(&f.ty)))
                .collect(),
            inputs: skill.inputs,
            outputs: skill.outputs,
            params: skill.params.into(),
            body,
            waker: skill.waker,
        }
    }
}

impl Unit for ForeignUnit {
    type Params = ForeignParams;
    fn waker(&self) -> Option<crate::runtime::Waker> {
        self.waker.clone()
    }
    fn mode(&self) -> Mode {
        self.mode
    }
    fn priority(&self) -> i32 {
        self.priority
    }
    fn default_params(&self) -> ForeignParams {
        ForeignParams::defaults(self.params.clone())
    }
    fn input_ports(&self) -> Vec<PortDecl> {
        self.inputs.clone()
    }
    fn output_ports(&self) -> Vec<PortDecl> {
        self.outputs.clone()
    }
    fn make_inputs(&self, m: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedInput>>, SdkError> {
        let inputs = self.input_types.iter().enumerate();
        inputs.map(|(i, t)| (t.input)(m, i)).collect()
    }
    fn make_outputs(&self, m: &PortMaker<'_>) -> Result<Vec<ErasedOutput>, SdkError> {
        let outputs = self.output_types.iter().enumerate();
        outputs.map(|(i, t)| (t.output)(m, i)).collect()
    }
    fn step(&mut self, link: &Link<'_>, io: &mut Io, common: &mut Common<ForeignParams>) {
        let ForeignUnit {
            mode,
            inputs,
            outputs: decls,
            input_types,
            output_bools,
            body,
            ..
        } = self;
        step_skill(
            link,
            io,
            common,
            *mode,
            // A foreign skill's memory is its own (C, C++, Python): nothing kept by the runtime.
            &mut (),
            |(), src, outputs, ctx: &Ctx<'_, ForeignParams>| {
                // As for a Rust skill, a run needs a sample on every input.
                if (0..inputs.len()).any(|i| src.get(i).is_none()) {
                    return crate::board::RunStatus::Skipped;
                }
                guarded(ctx.cycle, || {
                    let mut run = ForeignRun {
                        cycle: ctx.cycle,
                        clock: ctx.clock,
                        name: ctx.name,
                        params: ctx.params,
                        input_types,
                        inputs: src,
                        outputs: &mut *outputs,
                        error: None,
                    };
                    let result = body(&mut run);
                    let error = run.error.take();
                    result?;
                    if let Some(e) = error {
                        return Err(SkillError::msg(e));
                    }
                    for ((o, decl), bools) in outputs
                        .iter_mut()
                        .zip(decls.iter())
                        .zip(output_bools.iter())
                    {
                        if *bools && o.is_written() {
                            sanitize_message(&decl.schema, o.bytes_mut(false));
                        }
                    }
                    Ok(())
                })
            },
            |(), _, _, _| {},
        );
    }
}

#[cfg(test)]
mod tests;
