//! Answers, from the manager to a client: replies and the errors that refuse a request.

use crate::decl::Mode;
use crate::param::{ParamError, ParamSpec, ParamValue};
use crate::value::{PathError, Value};
use serde::{Deserialize, Serialize};

use super::MonitorMode;

/// One skill's run figures, as the board counts them: the one shape they take from the
/// manager's engine to the wire, the console and the run report.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SkillFigures {
    /// Completed runs.
    pub runs: u64,
    /// Cycles it could not run in (an input missing).
    pub skips: u64,
    /// Failed runs (error or panic).
    pub failures: u64,
    /// Mean compute time of a run (µs).
    pub compute_us_mean: f64,
    /// Compute time of the last run (µs).
    pub compute_us_last: f64,
    /// Cycle of the last run (0: none).
    pub last_cycle: u64,
    /// Monotonic clock (ns) at the start of the last run.
    pub last_start_ns: u64,
    /// Monotonic clock (ns) at the end of the last run.
    pub last_end_ns: u64,
    /// Runs that missed their cycle's deadline: ended after it, or were still in progress when
    /// the deadline closed the cycle (see docs/realtime.md).
    #[serde(default)]
    pub deadline_misses: u64,
    /// Allocations its thread made on the cycle's path after its warm-up runs (`None`: its
    /// runtime does not count them; see docs/realtime.md).
    #[serde(default)]
    pub cycle_allocs: Option<u64>,
}

/// Where a registered skill stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum SkillState {
    /// Registered; its ports are not open yet, so cycles do not plan with it.
    Starting,
    /// Run in every cycle its inputs allow.
    Active,
    /// Registered and ready, not run.
    Inactive,
}

impl SkillState {
    /// Its name in text and JSON: `starting`, `active`, `inactive`.
    pub fn as_str(&self) -> &'static str {
        match self {
            SkillState::Starting => "starting",
            SkillState::Active => "active",
            SkillState::Inactive => "inactive",
        }
    }
}

impl std::fmt::Display for SkillState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.as_str())
    }
}

/// A declared port, as listed.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PortInfo {
    /// The port's name in the skill.
    pub port: String,
    /// The topic it reads or writes.
    pub topic: String,
    /// The message type name.
    pub type_name: String,
}

/// A skill as listed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkillInfo {
    /// Instance name.
    pub name: String,
    /// Kind (program).
    pub kind: String,
    /// Scheduling mode.
    pub mode: Mode,
    /// Where it stands.
    pub state: SkillState,
    /// Arbitration priority.
    pub priority: i32,
    /// Process id.
    pub pid: u32,
    /// Declared parameters.
    pub params: Vec<ParamSpec>,
    /// Their current values.
    pub values: Vec<(String, ParamValue)>,
    /// Input ports.
    pub inputs: Vec<PortInfo>,
    /// Output ports.
    pub outputs: Vec<PortInfo>,
    /// Its run figures.
    pub figures: SkillFigures,
}

/// An installed monitor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MonitorInfo {
    /// Its id.
    pub id: u64,
    /// The condition.
    pub expr: String,
    /// Mode.
    pub mode: MonitorMode,
    /// Hold cycles.
    pub hold: u32,
    /// The client that owns it.
    pub client: String,
    /// Times it fired.
    pub fired: u64,
}

/// Percentiles in microseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Percentiles {
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest seen.
    pub max: f64,
}

/// One skill's line in [`Stats`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkillStat {
    /// Instance name.
    pub name: String,
    /// Its run figures.
    pub figures: SkillFigures,
}

/// One actuator channel's line in [`Stats`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelStat {
    /// The channel.
    pub channel: String,
    /// The winner of its last command, or `blend` / `safe`.
    pub winner: String,
    /// The cycle of its last command.
    pub cycle: u64,
}

/// Cycle statistics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    /// Cycles completed.
    pub cycles: u64,
    /// Whether the manager is cycling.
    pub running: bool,
    /// Overruns.
    pub overruns: u64,
    /// Cycle latency (start → last expected run done).
    pub latency_us: Percentiles,
    /// Per skill, in registration order.
    pub skills: Vec<SkillStat>,
    /// Skills that died.
    pub deaths: u64,
    /// Events published so far.
    pub events: u64,
    /// Per actuator channel.
    pub channels: Vec<ChannelStat>,
    /// The domain's bridges (their last report, if fresh).
    pub bridges: Vec<crate::bridge::BridgeStats>,
    /// Paced cycles that started more than a period after their scheduled start (a cycle's
    /// slot lost: the manager's thread woke that late).
    #[serde(default)]
    pub late_starts: u64,
}

/// What the manager answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Reply {
    /// The request was carried out.
    Done,
    /// Skills.
    Skills(Vec<SkillInfo>),
    /// A parameter's value.
    Param(ParamValue),
    /// A queried value and the cycle it was produced in.
    Value {
        /// The value.
        value: Value,
        /// Its cycle.
        cycle: u64,
    },
    /// The new monitor's id.
    MonitorAdded(u64),
    /// Monitors.
    Monitors(Vec<MonitorInfo>),
    /// Statistics.
    Stats(Stats),
    /// Stepping finished at this cycle.
    Stepped(u64),
    /// Recent cycle latencies, oldest first, in µs.
    Latencies {
        /// The last cycle completed.
        cycle: u64,
        /// Cycle start → last expected run done, one per cycle, ending with `cycle`'s.
        latency_us: Vec<f32>,
        /// Cycle start → the manager handling the completion (one more wake-up: the round
        /// trip back to the manager), one per cycle, aligned with `latency_us`.
        round_trip_us: Vec<f32>,
    },
    /// The fabric log.
    Logging {
        /// Its file (`None`: the manager could not open one).
        file: Option<String>,
        /// Skills whose input and output samples are logged.
        io_skills: Vec<String>,
    },
    /// The message schema of a topic.
    Schema(crate::schema::MessageSchema),
    /// What became of the monitors a client asked to take over, in the order asked.
    Adopted(Vec<MonitorFate>),
    /// The processes `skillfab up` gave up restarting ([`crate::control::Request::GaveUp`]).
    GaveUp(Vec<GaveUpInfo>),
    /// A skill's declaration ([`crate::control::Request::Declaration`]).
    Declaration(Box<crate::decl::SkillDecl>),
    /// The plan running now, if one is ([`crate::control::Request::CurrentPlan`]).
    Plan(Option<crate::control::PlanTree>),
}

/// A process `skillfab up` gave up restarting, as it told the manager.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct GaveUpInfo {
    /// The launch file's name of the process.
    pub process: String,
    /// Restarts in a row before `up` gave up.
    pub restarts: u32,
    /// How it last exited.
    pub status: String,
    /// The manager's cycle when it was told.
    pub cycle: u64,
}

/// What became of a monitor ([`crate::control::Request::AdoptMonitors`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MonitorFate {
    /// Still installed: now the asking client's.
    Live,
    /// A `Once` monitor that fired in this cycle and was removed (the manager remembers the
    /// last few thousand).
    Fired(u64),
    /// Not installed and not known to have fired: removed, or fired too long ago, or lost
    /// with a manager that restarted without it.
    Gone,
}

/// Why a request was refused. Every variant names what was wrong and is a value a client can
/// match; the text is made from it where it is shown.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize, Deserialize)]
#[non_exhaustive]
pub enum ControlError {
    /// No such skill.
    #[error("unknown skill '{0}'")]
    UnknownSkill(String),
    /// A parameter was refused.
    #[error("{skill}: {error}")]
    Param {
        /// Skill instance.
        skill: String,
        /// Why (in the message: a client in C or Python shows the message alone).
        error: ParamError,
    },
    /// A value path that does not resolve.
    #[error("bad path '{path}': {error}")]
    BadPath {
        /// As given.
        path: String,
        /// Why (in the message).
        error: PathError,
    },
    /// Nothing has been published at that path yet.
    #[error("no value yet at '{0}'")]
    NoValue(String),
    /// No registered skill declares the topic.
    #[error("no skill declares topic '{0}'")]
    UnknownTopic(String),
    /// A monitor expression that does not parse or type-check.
    #[error("bad expression '{expr}' {error}")]
    BadExpression {
        /// As given.
        expr: String,
        /// Where and why (in the message).
        error: ExprError,
    },
    /// No monitor with that id.
    #[error("unknown monitor {0}")]
    UnknownMonitor(u64),
    /// The client speaks another protocol version.
    #[error("protocol version mismatch: client {client}, manager {manager}")]
    Version {
        /// Client's version.
        client: u16,
        /// Manager's version.
        manager: u16,
    },
    /// The request bytes do not decode.
    #[error("malformed request: {0}")]
    Malformed(postcard::Error),
    /// A request larger than the manager reads.
    #[error("a request of {bytes} bytes (at most {max})")]
    RequestTooLarge {
        /// Its encoded size.
        bytes: usize,
        /// [`MAX_REQUEST_BYTES`].
        max: usize,
    },
    /// An answer larger than an answer may be (a query of a whole large message).
    #[error(
        "the answer is {bytes} bytes, more than the {max} an answer may have: ask for a field \
         or a range of it"
    )]
    AnswerTooLarge {
        /// Its encoded size.
        bytes: usize,
        /// [`MAX_ANSWER_BYTES`].
        max: usize,
    },
    /// A recording asked of a file not named `*.mcap`.
    #[error("a recording is an MCAP file: {file} does not end in .mcap")]
    NotMcap {
        /// The file asked for.
        file: String,
    },
    /// The recording's file cannot be created or written.
    #[error("cannot record to {file}{}", os_error.map(|e| format!(": {}", std::io::Error::from_raw_os_error(e))).unwrap_or_default())]
    CannotRecord {
        /// The file asked for.
        file: String,
        /// The operating system's error number, if there is one.
        os_error: Option<i32>,
    },
    /// `record stop` with no recording running.
    #[error("no recording in progress")]
    NotRecording,
    /// I/O logging asked of a manager whose fabric log file could not be opened.
    #[error("the manager has no fabric log file (see its start-up warning)")]
    NoFabricLog,
    /// A proposer's proposals asked for while it restarts.
    #[error("'{skill}' is restarting: its proposals can be read once it is back")]
    SkillAway {
        /// The skill.
        skill: String,
    },
    /// The manager could not open or poll a reader of the topic (iceoryx2 refused; the
    /// manager's log says why).
    #[error("the manager cannot read topic '{topic}' (see its log)")]
    CannotRead {
        /// The topic.
        topic: String,
    },
    /// The manager could not hand the skill its new parameters (the manager's log says why).
    #[error("the manager cannot write the parameters of '{skill}' (see its log)")]
    CannotWriteParams {
        /// The skill.
        skill: String,
    },
    /// A plan's shape that cannot be taken in.
    #[error("the tree of plan '{plan}': {problem}")]
    BadPlanTree {
        /// The plan, as named (shortened).
        plan: String,
        /// What is wrong.
        problem: crate::control::PlanTreeProblem,
    },
    /// A plan report about a plan that is not the running one of this client: the manager
    /// has none (it restarted, or never had its shape: send it), or another runner's plan
    /// replaced it.
    #[error("plan '{plan}' is not running here ({})", match current { Some(c) => format!("'{c}' is"), None => "no plan is".to_string() })]
    PlanNotCurrent {
        /// The plan reported on.
        plan: String,
        /// The plan the manager has, if any.
        current: Option<String>,
    },
    /// A status change of a node the plan's tree does not have.
    #[error("plan '{plan}' has no node {id} (it has {nodes})")]
    UnknownPlanNode {
        /// The plan.
        plan: String,
        /// The node id sent.
        id: u32,
        /// Nodes in the tree.
        nodes: u32,
    },
    /// A skill wanted (or needed by one) reads a topic nobody produces: it could never run.
    #[error(
        "'{skill}' reads '{topic}' (its input '{port}'), which no skill or device produces{}",
        wanted_by.as_ref().map(|w| format!(" ('{skill}' is needed by '{w}')")).unwrap_or_default()
    )]
    NoProducer {
        /// The skill whose input has no producer.
        skill: String,
        /// The input.
        port: String,
        /// Its topic.
        topic: String,
        /// The wanted skill that needs it, when it is not itself the one asked for.
        wanted_by: Option<String>,
    },
    /// The skills wanted read each other's outputs in a loop: none could run first.
    #[error("a loop of producers: {}", loop_.join(" reads "))]
    DemandLoop {
        /// The skills around the loop, each reading the next, the first again at the end.
        loop_: Vec<String>,
    },
}

/// `text` cut to at most `max` characters for an error message (a client's 1 MB string is
/// not echoed back): the start, then how much was left out.
pub fn shorten(text: &str, max: usize) -> String {
    match text.char_indices().nth(max) {
        None => text.to_string(),
        Some((cut, _)) => format!("{}… ({} bytes in all)", &text[..cut], text.len()),
    }
}

/// Largest request the manager reads (bytes); a bigger one is refused unread (the client
/// refuses to send it, with the same error).
pub const MAX_REQUEST_BYTES: usize = 64 * 1024;
/// Largest answer (bytes): a bigger one (a query of a whole large message) is answered with
/// an error that says so. The control plane's samples have fixed sizes: iceoryx2 keeps
/// bookkeeping per client connection for every segment a growing sender may ever allocate
/// (255), which made each connection cost seconds with 100 clients.
pub const MAX_ANSWER_BYTES: usize = 256 * 1024;

/// The manager's answer.
pub type Response = Result<Reply, ControlError>;

/// A syntax or type error in a monitor expression, with the byte position it was found at.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize, Deserialize)]
#[error("at {position}: {problem}")]
pub struct ExprError {
    /// Byte offset into the expression.
    pub position: usize,
    /// What is wrong.
    pub problem: ExprProblem,
}

/// What is wrong in a monitor expression.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize, Deserialize)]
#[non_exhaustive]
pub enum ExprProblem {
    /// More than [`ExprProblem::MAX_LEN`] bytes.
    #[error("expression longer than {max} bytes")]
    TooLong {
        /// The longest accepted.
        max: usize,
    },
    /// Deeper than the parser goes.
    #[error("more than {max} {what}")]
    TooDeep {
        /// What nests: "parentheses", "'not'/'-' operators".
        what: String,
        /// The most accepted.
        max: usize,
    },
    /// A number that does not parse.
    #[error("bad number '{text}'")]
    BadNumber {
        /// As written.
        text: String,
    },
    /// A `[` with no `]`.
    #[error("missing ']'")]
    UnclosedIndex,
    /// A character the language does not use.
    #[error("unexpected character '{ch}'")]
    UnexpectedChar {
        /// The character.
        ch: char,
    },
    /// A token where none may be.
    #[error("unexpected '{token}'")]
    UnexpectedToken {
        /// The token.
        token: String,
    },
    /// The expression stops in the middle.
    #[error("expression ends too early")]
    EndsEarly,
    /// Text after a complete expression.
    #[error("unexpected text after the expression")]
    TrailingText,
    /// A `(` with no `)`.
    #[error("expected ')'")]
    UnclosedParen,
    /// `min`/`max` without its parenthesis.
    #[error("expected '(' after {function}")]
    CallWithoutParen {
        /// `min` or `max`.
        function: String,
    },
    /// `min(…)`/`max(…)` of something other than one path.
    #[error("{function}() takes one path, e.g. {function}(skill.output.field[0..3])")]
    CallWithoutPath {
        /// `min` or `max`.
        function: String,
    },
    /// A word that is not a value.
    #[error("'{word}' is not a value: write skill.output[.field]")]
    NotAValue {
        /// The word.
        word: String,
    },
    /// A path that does not parse.
    #[error(transparent)]
    Path(#[from] PathError),
    /// An operand of the wrong type.
    #[error("{operator} needs a {}", if *number { "number" } else { "condition" })]
    WrongOperand {
        /// The operator: "'-'", "arithmetic", "a comparison", "'and'/'or'", "'not'".
        operator: String,
        /// A number was needed (else a condition).
        number: bool,
    },
    /// The whole expression is a number, not a condition.
    #[error("a monitor needs a condition, e.g. 'x.y.z < 3'")]
    NotACondition,
}

impl ExprProblem {
    /// The longest expression accepted (bytes).
    pub const MAX_LEN: usize = 4096;
}

/// Encodes the response to the client's request number `seq` (0: a request the manager could
/// not read, whose number it does not know — a client takes it as its answer); one over [`MAX_ANSWER_BYTES`] becomes an error answer saying so. The number lets a
/// client tell its answer from a stale one: under a crowd of clients connecting at once,
/// iceoryx2 0.10 has handed a client's new request the answer to its previous one.
pub fn encode_response(seq: u64, response: &Response) -> Vec<u8> {
    // Encoding into a Vec of plain data cannot fail; an empty answer would not decode and
    // the client would say so.
    match postcard::to_allocvec(&(seq, response)) {
        Ok(b) if b.len() <= MAX_ANSWER_BYTES => b,
        Ok(b) => postcard::to_allocvec(&(
            seq,
            Response::Err(ControlError::AnswerTooLarge {
                bytes: b.len(),
                max: MAX_ANSWER_BYTES,
            }),
        ))
        .unwrap_or_default(),
        Err(_) => Vec::new(),
    }
}

/// Decodes a response: the request number it answers, and the response.
pub fn decode_response(bytes: &[u8]) -> Result<(u64, Response), postcard::Error> {
    postcard::from_bytes(bytes)
}
