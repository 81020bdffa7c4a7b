//! Skills made for tests.

use skill_sdk::prelude::*;
use skillfab_msgs::{Scalar, Scaled, Sonar, Tick};
use skillfab_proto::header::now_ns;

/// Parameters of [`Work`] and [`WorkAsync`].
#[derive(Params, Debug, Clone)]
pub struct WorkParams {
    /// How long a run sleeps (ms): a body that takes time.
    #[param(default = 0.0, min = 0.0, max = 10000.0)]
    pub sleep_ms: f64,
    /// out.value = factor × input.
    #[param(default = 1.0)]
    pub factor: f64,
    /// Fail (return an error) in every cycle divisible by this; 0: never.
    #[param(default = 0, min = 0)]
    pub fail_every: u64,
    /// Panic in every cycle divisible by this; 0: never.
    #[param(default = 0, min = 0)]
    pub panic_every: u64,
    /// Allocate a buffer of this many bytes in every run (0: none): a body that allocates
    /// on the cycle's path (the allocation count's test).
    #[param(default = 0, min = 0, max = 1048576)]
    pub allocate_bytes: u64,
}

/// Input of the work skills.
#[derive(Inputs)]
pub struct WorkIn<'a> {
    /// Any tick.
    pub tick: Input<'a, Tick>,
}

/// Output of the work skills.
#[derive(Outputs)]
pub struct WorkOut<'a> {
    /// factor × tick, with the run's start and end instants.
    pub out: Output<'a, Scalar>,
}

fn work(ctx: &Ctx<WorkParams>, i: &WorkIn, o: &mut WorkOut) -> SkillResult {
    let p = ctx.params;
    let start_ns = now_ns();
    if p.sleep_ms > 0.0 {
        std::thread::sleep(std::time::Duration::from_secs_f64(p.sleep_ms / 1000.0));
    }
    if p.fail_every > 0 && ctx.cycle.is_multiple_of(p.fail_every) {
        return Err(SkillError::msg(format!(
            "failing on purpose in cycle {}",
            ctx.cycle
        )));
    }
    if p.panic_every > 0 && ctx.cycle.is_multiple_of(p.panic_every) {
        panic!("panicking on purpose in cycle {}", ctx.cycle);
    }
    if p.allocate_bytes > 0 {
        let buffer: Vec<u8> = Vec::with_capacity(p.allocate_bytes as usize);
        std::hint::black_box(buffer);
    }
    o.out.set(Scalar {
        value: p.factor * i.tick.value as f64,
        start_ns,
        end_ns: now_ns(),
    });
    Ok(())
}

/// Sync: takes `sleep_ms`, outputs factor × tick; fails or panics on demand.
#[derive(Default)]
pub struct Work;

impl Skill for Work {
    type Params = WorkParams;
    type Inputs<'a> = WorkIn<'a>;
    type Outputs<'a> = WorkOut<'a>;
    fn compute(&mut self, ctx: &Ctx<WorkParams>, i: WorkIn, o: &mut WorkOut) -> SkillResult {
        work(ctx, &i, o)
    }
}

/// Async twin of [`Work`].
#[derive(Default)]
pub struct WorkAsync;

impl Skill for WorkAsync {
    type Params = WorkParams;
    type Inputs<'a> = WorkIn<'a>;
    type Outputs<'a> = WorkOut<'a>;
    const MODE: Mode = Mode::Async;
    fn compute(&mut self, ctx: &Ctx<WorkParams>, i: WorkIn, o: &mut WorkOut) -> SkillResult {
        work(ctx, &i, o)
    }
}

/// Parameters of [`Check`].
#[derive(Params, Debug, Clone)]
pub struct CheckParams {
    /// The gain `scale` is expected to apply.
    #[param(default = 2.0)]
    pub gain: f64,
}

/// Inputs of [`Check`].
#[derive(Inputs)]
pub struct CheckIn<'a> {
    /// The tick of this cycle.
    pub tick: Input<'a, Tick>,
    /// scale's output in this cycle.
    pub scaled: Input<'a, Scaled>,
}

/// Sync: fails the run unless `tick == cycle` and `scaled == gain × tick`, both from this
/// cycle. A chain ticker → scale → check that finishes N cycles with N runs and no failure
/// produced exactly the expected values in every cycle.
#[derive(Default)]
pub struct Check;

impl Skill for Check {
    type Params = CheckParams;
    type Inputs<'a> = CheckIn<'a>;
    type Outputs<'a> = ();
    fn compute(&mut self, ctx: &Ctx<CheckParams>, i: CheckIn, _: &mut ()) -> SkillResult {
        let expected = ctx.params.gain * ctx.cycle as f64;
        if i.tick.value != ctx.cycle || i.tick.cycle() != ctx.cycle || i.scaled.cycle() != ctx.cycle
        {
            return Err(SkillError::msg(format!(
                "cycle {}: tick {} (from cycle {}), scaled from cycle {}",
                ctx.cycle,
                i.tick.value,
                i.tick.cycle(),
                i.scaled.cycle()
            )));
        }
        if i.scaled.value != expected {
            return Err(SkillError::msg(format!(
                "cycle {}: scaled {} != {expected}",
                ctx.cycle, i.scaled.value
            )));
        }
        Ok(())
    }
}

/// Input of [`Sink`].
#[derive(Inputs)]
pub struct SinkIn<'a> {
    /// Any scalar.
    pub input: Input<'a, Scalar>,
}

/// Sync: consumes a scalar of this cycle, fails if it is from another cycle.
#[derive(Default)]
pub struct Sink;

impl Skill for Sink {
    type Params = NoParams;
    type Inputs<'a> = SinkIn<'a>;
    type Outputs<'a> = ();
    fn compute(&mut self, ctx: &Ctx<NoParams>, i: SinkIn, _: &mut ()) -> SkillResult {
        if i.input.cycle() != ctx.cycle {
            return Err(SkillError::msg("stale input"));
        }
        Ok(())
    }
}

/// Input of [`Nearest`].
#[derive(Inputs)]
pub struct NearestIn<'a> {
    /// The sonar ring.
    pub sonar: Input<'a, Sonar>,
}

/// Output of [`Nearest`].
#[derive(Outputs)]
pub struct NearestOut<'a> {
    /// The shortest finite range (m).
    pub nearest: Output<'a, Scalar>,
}

/// Async: the shortest range of the sonar ring (the remote skill of the bridge tests).
#[derive(Default)]
pub struct Nearest;

impl Skill for Nearest {
    type Params = NoParams;
    type Inputs<'a> = NearestIn<'a>;
    type Outputs<'a> = NearestOut<'a>;
    const MODE: Mode = Mode::Async;
    fn compute(&mut self, _: &Ctx<NoParams>, i: NearestIn, o: &mut NearestOut) -> SkillResult {
        let nearest = i
            .sonar
            .range
            .iter()
            .copied()
            .filter(|r| r.is_finite())
            .fold(f64::INFINITY, f64::min);
        o.nearest.set(Scalar {
            value: nearest,
            ..Scalar::default()
        });
        Ok(())
    }
}

/// Parameters of [`Guard`].
#[derive(Params, Debug, Clone)]
pub struct GuardParams {
    /// guard = gain × nearest.
    #[param(default = 1.0, min = -1e6, max = 1e6)]
    pub gain: f64,
}

/// Input of [`Guard`].
#[derive(Inputs)]
pub struct GuardIn<'a> {
    /// The latest shortest range.
    pub nearest: Input<'a, Scalar>,
}

/// Output of [`Guard`].
#[derive(Outputs)]
pub struct GuardOut<'a> {
    /// gain × nearest.
    pub guard: Output<'a, Scalar>,
}

/// Sync: uses the latest `nearest` (from an async producer, here or remote) every cycle.
#[derive(Default)]
pub struct Guard;

impl Skill for Guard {
    type Params = GuardParams;
    type Inputs<'a> = GuardIn<'a>;
    type Outputs<'a> = GuardOut<'a>;
    fn compute(&mut self, ctx: &Ctx<GuardParams>, i: GuardIn, o: &mut GuardOut) -> SkillResult {
        o.guard.set(Scalar {
            value: ctx.params.gain * i.nearest.value,
            ..Scalar::default()
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skill_sdk::harness::Harness;

    #[test]
    fn work_scales_and_fails_on_demand() {
        let mut h = Harness::<Work>::new();
        h.set(WorkParams::FACTOR, 3.0)
            .unwrap()
            .set(WorkParams::FAIL_EVERY, 2)
            .unwrap();
        h.input(WorkIn::TICK, Tick { value: 4 });
        assert_eq!(h.step().unwrap().output(WorkOut::OUT).unwrap().value, 12.0);
        h.input(WorkIn::TICK, Tick { value: 5 });
        assert!(h.step().is_err(), "cycle 2 fails");
    }

    #[test]
    fn check_accepts_only_exact_values() {
        let mut h = Harness::<Check>::new();
        h.input(CheckIn::TICK, Tick { value: 1 })
            .input(CheckIn::SCALED, Scaled { value: 2.0 });
        assert!(h.step().is_ok());
        h.input(CheckIn::TICK, Tick { value: 2 })
            .input(CheckIn::SCALED, Scaled { value: 4.5 });
        assert!(h.step().is_err());
    }
}

/// Parameters of [`Proposer`].
#[derive(Params, Debug, Clone)]
pub struct ProposerParams {
    /// Proposed translate velocity.
    #[param(default = 0.0)]
    pub translate: f64,
    /// Proposed rotate velocity.
    #[param(default = 0.0)]
    pub rotate: f64,
    /// Whether to propose at all.
    #[param(default = true)]
    pub propose: bool,
}

/// Output of [`Proposer`].
#[derive(Outputs)]
pub struct ProposerOut<'a> {
    /// The proposal on the `drive` channel.
    pub drive: Proposal<'a, skillfab_msgs::Drive>,
}

/// Sync, no inputs: proposes a fixed drive command every cycle (unless `propose=false`).
#[derive(Default)]
pub struct Proposer;

impl Skill for Proposer {
    type Params = ProposerParams;
    type Inputs<'a> = ();
    type Outputs<'a> = ProposerOut<'a>;
    fn compute(&mut self, ctx: &Ctx<ProposerParams>, _: (), o: &mut ProposerOut) -> SkillResult {
        if ctx.params.propose {
            o.drive.set(skillfab_msgs::Drive {
                translate: ctx.params.translate,
                rotate: ctx.params.rotate,
            });
        }
        Ok(())
    }
}

/// Input of [`Reactor`].
#[derive(Inputs)]
pub struct ReactorIn<'a> {
    /// The mock device's state.
    pub state: Input<'a, skillfab_msgs::Tick>,
}

/// Sync, downstream of the mock device like a real controller of a real device: proposes a
/// fixed drive command every cycle once the device's state is in (unless `propose=false`).
#[derive(Default)]
pub struct Reactor;

impl Skill for Reactor {
    type Params = ProposerParams;
    type Inputs<'a> = ReactorIn<'a>;
    type Outputs<'a> = ProposerOut<'a>;
    fn compute(
        &mut self,
        ctx: &Ctx<ProposerParams>,
        _: ReactorIn,
        o: &mut ProposerOut,
    ) -> SkillResult {
        Proposer.compute(ctx, (), o)
    }
}

/// Output of [`MockDevice`].
#[derive(Outputs)]
pub struct MockOut<'a> {
    /// The cycle of the sample.
    pub state: Output<'a, skillfab_msgs::Tick>,
}

/// Channels of [`MockDevice`].
#[derive(Channels)]
pub struct MockCommands<'a> {
    /// The drive channel.
    pub drive: Command<'a, skillfab_msgs::Drive>,
}

/// A device with one channel, `drive`, publishing its `state` each cycle; fails a cycle if it ever gets a command of another
/// cycle (so "exactly one command per channel per cycle" shows as runs == cycles, failures == 0).
#[derive(Default)]
pub struct MockDevice {
    last: u64,
}

impl Device for MockDevice {
    type Params = NoParams;
    type Outputs<'a> = MockOut<'a>;
    type Commands<'a> = MockCommands<'a>;
    fn sample(&mut self, ctx: &Ctx<NoParams>, o: &mut MockOut) -> SkillResult {
        o.state.set(skillfab_msgs::Tick { value: ctx.cycle });
        Ok(())
    }
    fn command(&mut self, ctx: &Ctx<NoParams>, c: MockCommands) -> SkillResult {
        if c.drive.cycle() != ctx.cycle || ctx.cycle <= self.last {
            return Err(SkillError::msg(format!(
                "command of cycle {} in cycle {}",
                c.drive.cycle(),
                ctx.cycle
            )));
        }
        self.last = ctx.cycle;
        Ok(())
    }
}

/// Inputs of [`Relay`].
#[derive(Inputs)]
pub struct RelayIn<'a> {
    /// The previous link's tick.
    pub prev: Input<'a, Tick>,
}

/// Outputs of [`Relay`].
#[derive(Outputs)]
pub struct RelayOut<'a> {
    /// The same tick, passed on.
    pub tick: Output<'a, Tick>,
}

/// Sync: passes its input tick on (a link of the benchmarks' chains: remap `prev` and `tick`
/// to chain them).
#[derive(Default)]
pub struct Relay;

impl Skill for Relay {
    type Params = NoParams;
    type Inputs<'a> = RelayIn<'a>;
    type Outputs<'a> = RelayOut<'a>;
    fn compute(&mut self, _: &Ctx<NoParams>, i: RelayIn, o: &mut RelayOut) -> SkillResult {
        o.tick.set(*i.prev.value());
        Ok(())
    }
}

/// Payload messages of the benchmarks, a source writing one per cycle and a sink reading it.
/// The source writes only `seq` in place ([`Output::fill_in_place`]): a zero-copy fabric's
/// latency must not depend on the size.
macro_rules! blob {
    ($msg:ident, $type_name:literal, $bytes:expr, $src:ident, $src_out:ident, $sink:ident, $sink_in:ident) => {
        #[doc = concat!("A ", $type_name, " payload: a sequence number and bytes.")]
        #[derive(Message, Debug, Clone, Copy)]
        #[message(type_name = $type_name)]
        #[repr(C)]
        pub struct $msg {
            /// The cycle it was written in.
            pub seq: u64,
            /// The payload.
            pub data: [u8; $bytes - 8],
        }

        #[doc = concat!("Outputs of [`", stringify!($src), "`].")]
        #[derive(Outputs)]
        pub struct $src_out<'a> {
            /// The payload of this cycle.
            pub blob: Output<'a, $msg>,
        }

        #[doc = concat!("Sync, no inputs: writes `seq` of a ", $type_name, " in place.")]
        #[derive(Default)]
        pub struct $src;

        impl Skill for $src {
            type Params = NoParams;
            type Inputs<'a> = ();
            type Outputs<'a> = $src_out<'a>;
            fn compute(&mut self, ctx: &Ctx<NoParams>, _: (), o: &mut $src_out) -> SkillResult {
                o.blob.fill_in_place().seq = ctx.cycle;
                Ok(())
            }
        }

        #[doc = concat!("Inputs of [`", stringify!($sink), "`].")]
        #[derive(Inputs)]
        pub struct $sink_in<'a> {
            /// The source's payload.
            pub blob: Input<'a, $msg>,
        }

        #[doc = concat!("Sync: checks the ", $type_name, " of this cycle arrived.")]
        #[derive(Default)]
        pub struct $sink;

        impl Skill for $sink {
            type Params = NoParams;
            type Inputs<'a> = $sink_in<'a>;
            type Outputs<'a> = ();
            fn compute(&mut self, ctx: &Ctx<NoParams>, i: $sink_in, _: &mut ()) -> SkillResult {
                if i.blob.value().seq != ctx.cycle {
                    return Err(SkillError::msg(format!(
                        "cycle {}: payload of cycle {}",
                        ctx.cycle,
                        i.blob.value().seq
                    )));
                }
                Ok(())
            }
        }
    };
}

blob!(
    Blob64,
    "bench.Blob64",
    64,
    BlobSrc64,
    BlobSrc64Out,
    BlobSink64,
    BlobSink64In
);
blob!(
    Blob64K,
    "bench.Blob64K",
    64 << 10,
    BlobSrc64K,
    BlobSrc64KOut,
    BlobSink64K,
    BlobSink64KIn
);
blob!(
    Blob1M,
    "bench.Blob1M",
    1 << 20,
    BlobSrc1M,
    BlobSrc1MOut,
    BlobSink1M,
    BlobSink1MIn
);
blob!(
    Blob4M,
    "bench.Blob4M",
    4 << 20,
    BlobSrc4M,
    BlobSrc4MOut,
    BlobSink4M,
    BlobSink4MIn
);

/// Output of [`Counter`].
#[derive(Outputs)]
pub struct CounterOut<'a> {
    /// Runs so far, over every instance of this name.
    pub count: Output<'a, skillfab_msgs::Tick>,
}

/// Sync, no inputs: counts its runs, and keeps the count across restarts of its process
/// ([`Skill::STATE`]). Its `dwell_ms` holds each run inside its body that long (a process to
/// kill in the middle of a run); `panic_every` makes runs fail after counting.
#[derive(Default, serde::Serialize, serde::Deserialize)]
pub struct Counter {
    runs: u64,
}

/// Parameters of [`Counter`].
#[derive(Params, Debug, Clone)]
pub struct CounterParams {
    /// Time each run spends in its body after counting (ms).
    #[param(default = 0, min = 0, max = 10_000)]
    pub dwell_ms: u64,
    /// Panic, after counting, in every cycle divisible by this; 0: never (the count of a run
    /// that fails is undone by the runtime).
    #[param(default = 0, min = 0)]
    pub panic_every: u64,
}

impl Skill for Counter {
    type Params = CounterParams;
    type Inputs<'a> = ();
    type Outputs<'a> = CounterOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(&mut self, c: &Ctx<CounterParams>, _: (), o: &mut CounterOut) -> SkillResult {
        self.runs += 1;
        o.count.set(skillfab_msgs::Tick { value: self.runs });
        // A test's way to be inside a run when it kills the process (never in a real skill).
        std::thread::sleep(std::time::Duration::from_millis(c.params.dwell_ms));
        let every = c.params.panic_every;
        assert!(
            every == 0 || !c.cycle.is_multiple_of(every),
            "counter: panic_every"
        );
        Ok(())
    }
}

#[cfg(test)]
mod blob_tests {
    use skill_sdk::Message;
    use skillfab_proto::schema::FieldKind;

    #[test]
    fn a_blob_declares_its_full_length() {
        // The length is written `$bytes - 8` inside `blob!`: the derive must keep its grouping.
        let s = super::Blob64K::schema();
        assert_eq!(s.size, 64 << 10);
        assert!(
            matches!(&s.fields[1].ty, FieldKind::Array { len, .. } if *len == (64 << 10) - 8),
            "{:?}",
            s.fields[1].ty
        );
    }
}
