//! A skill's run, shared by Rust skills and skills declared at run time: whether one is due,
//! the body, the outputs sent, the run stamped on the board.

use super::serve::Link;
use super::{Common, Io, Unit};
use crate::SdkError;
use crate::board::RunStatus;
use crate::decl::{Mode, PortDecl};
use crate::header::{MaybeSlot, SampleHeader, now_ns};
use crate::params::Params;
use crate::ports::{
    ErasedInput, ErasedOutput, InputMeta, InputSet, InputSource, OutputSet, PortMaker,
};
use crate::skill::{Ctx, Skill, SkillResult};
use crate::state::StateError;
use std::any::Any;
use std::sync::atomic::Ordering;

/// The wrapper that runs a [`Skill`].
pub(crate) struct SkillUnit<S: Skill>(pub(crate) S);

pub(crate) struct RuntimeInputs<'a> {
    pub(crate) inputs: &'a [Box<dyn ErasedInput>],
    pub(crate) cycle: u64,
}

impl InputSource for RuntimeInputs<'_> {
    fn get(&self, idx: usize) -> Option<(&dyn Any, InputMeta)> {
        let port = self.inputs.get(idx)?;
        let h = port.latest_header()?;
        Some((
            port.latest_any()?,
            InputMeta {
                cycle: h.cycle,
                age: self.cycle.saturating_sub(h.cycle),
                source: h.slot.get(),
            },
        ))
    }
}

/// Outcome of running a body once (error or panic logged).
pub(crate) fn guarded(cycle: u64, body: impl FnOnce() -> SkillResult) -> RunStatus {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(body)) {
        Ok(Ok(())) => RunStatus::Ok,
        Ok(Err(e)) => {
            tracing::warn!(cycle, error = %e, "run failed");
            RunStatus::Failed
        }
        Err(_) => {
            tracing::error!(cycle, "run panicked");
            RunStatus::Failed
        }
    }
}

/// Sends the written outputs of a successful run (or drops them), ringing each sent output's
/// consumers; returns the sent mask. Readers outside the fabric are told afterwards, off the
/// critical path ([`announce`]).
pub(crate) fn commit_outputs(
    link: &Link<'_>,
    outputs: &mut [ErasedOutput],
    status: RunStatus,
    header: SampleHeader,
) -> u64 {
    let mut mask = 0u64;
    for (i, o) in outputs.iter_mut().enumerate() {
        if status != RunStatus::Ok {
            o.discard();
            continue;
        }
        match o.commit(header) {
            Ok(true) => {
                mask |= 1 << i;
                link.wake_consumers(i);
            }
            Ok(false) => {}
            Err(e) => tracing::warn!(cycle = header.cycle, error = %e, "publish failed"),
        }
    }
    mask
}

/// Notifies the iceoryx2 event services of the outputs in `mask` (readers outside the fabric).
pub(crate) fn announce(outputs: &[ErasedOutput], mask: u64) {
    for (i, o) in outputs.iter().enumerate() {
        if mask & (1 << i.min(63)) != 0 {
            o.announce();
        }
    }
}

/// One finished run, as stamped on the board.
pub(crate) struct RunRecord {
    pub(crate) k: u64,
    pub(crate) status: RunStatus,
    /// Outputs sent.
    pub(crate) mask: u64,
    /// Number of outputs.
    pub(crate) outputs: usize,
    pub(crate) start: u64,
    pub(crate) end: u64,
    /// Whether the cycle waits for this unit.
    pub(crate) sync: bool,
}

/// Stamps a finished run on the board and, for a sync unit, takes it off the cycle's counter
/// (waking the manager if that finished the cycle or the run passed nothing on).
pub(crate) fn finish_run(link: &Link<'_>, r: RunRecord) {
    let RunRecord {
        k,
        status,
        mask,
        outputs,
        start,
        end,
        sync,
    } = r;
    let slot = link.board.slot(link.idx);
    let counter = match status {
        RunStatus::Ok => &slot.runs,
        RunStatus::Skipped => &slot.skips,
        _ => &slot.failures,
    };
    counter.fetch_add(1, Ordering::Relaxed);
    slot.compute_ns_total
        .fetch_add(end - start, Ordering::Relaxed);
    slot.last_compute_ns.store(end - start, Ordering::Relaxed);
    slot.published_mask.store(mask, Ordering::Relaxed);
    slot.status.store(status as u32, Ordering::Relaxed);
    slot.last_end_ns.store(now_ns(), Ordering::Relaxed);
    slot.done_cycle.store(k, Ordering::Release);
    if sync {
        let all = if outputs >= 64 {
            u64::MAX
        } else {
            (1u64 << outputs) - 1
        };
        let finished = link.board.complete(k, 1);
        if finished || status != RunStatus::Ok || mask != all {
            link.board.ring_manager();
        }
    }
}

impl<S: Skill> Unit for SkillUnit<S> {
    type Params = S::Params;
    fn state_fingerprint(&self) -> Option<u64> {
        S::STATE.fingerprint()
    }
    fn restore_state(&mut self, bytes: &[u8]) -> Result<(), StateError> {
        self.0 = S::STATE.decode(bytes)?;
        Ok(())
    }
    fn mode(&self) -> Mode {
        S::MODE
    }
    fn priority(&self) -> i32 {
        S::PRIORITY
    }
    fn default_params(&self) -> S::Params {
        S::Params::default()
    }
    fn input_ports(&self) -> Vec<PortDecl> {
        <S::Inputs<'static> as InputSet<'static>>::ports()
    }
    fn output_ports(&self) -> Vec<PortDecl> {
        <S::Outputs<'static> as OutputSet<'static>>::ports()
    }
    fn make_inputs(&self, m: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedInput>>, SdkError> {
        <S::Inputs<'static> as InputSet<'static>>::make(m)
    }
    fn make_outputs(&self, m: &PortMaker<'_>) -> Result<Vec<ErasedOutput>, SdkError> {
        <S::Outputs<'static> as OutputSet<'static>>::make(m)
    }

    fn step(&mut self, link: &Link<'_>, io: &mut Io, common: &mut Common<S::Params>) {
        step_skill(
            link,
            io,
            common,
            S::MODE,
            &mut self.0,
            |skill, src, outputs, ctx| match <S::Inputs<'_> as InputSet<'_>>::fetch(src) {
                None => RunStatus::Skipped,
                Some(input) => {
                    let mut out = <S::Outputs<'_> as OutputSet<'_>>::bind(outputs);
                    guarded(ctx.cycle, || skill.compute(ctx, input, &mut out))
                }
            },
            keep_state,
        );
    }
}

/// After a run: the state of a completed run is kept (committed to the state object before
/// the run is stamped, so a run the manager counts as done is never lost); a failed run is
/// undone, the skill taken back to the state of the last completed one, as its outputs are
/// dropped (a panic half-way through a body leaves nothing half-changed).
fn keep_state<S: Skill>(skill: &mut S, status: RunStatus, common: &mut Common<S::Params>, k: u64) {
    let Some(kept) = common.kept.as_mut() else {
        return;
    };
    match status {
        RunStatus::Ok => {
            let error = match S::STATE.encode(skill, &mut common.state_buf) {
                Ok(_) => kept
                    .commit(&common.state_buf, k)
                    .err()
                    .map(|e| format!("{e:?}")),
                Err(e) => Some(format!("{e:?}")),
            };
            if let Some(error) = error
                && !common.state_warned
            {
                common.state_warned = true;
                tracing::warn!(cycle = k, %error, "the state of a run could not be kept (said once)");
            }
        }
        RunStatus::Failed => {
            *skill = kept
                .last()
                .and_then(|bytes| S::STATE.decode(&bytes).ok())
                .unwrap_or_default();
        }
        _ => {}
    }
}

/// One run of a skill, if one is due: a sync skill runs when the manager expects it in cycle
/// k and every same-cycle input carries cycle k; an async one when an input changed (or once
/// per cycle without inputs). `run` runs the body on the inputs and outputs; the outputs of a
/// successful run are sent, the run stamped, and proposals not made are announced.
pub(crate) fn step_skill<P: Params, B>(
    link: &Link<'_>,
    io: &mut Io,
    common: &mut Common<P>,
    mode: Mode,
    body: &mut B,
    run: impl FnOnce(&mut B, &dyn InputSource, &mut [ErasedOutput], &Ctx<'_, P>) -> RunStatus,
    keep: impl FnOnce(&mut B, RunStatus, &mut Common<P>, u64),
) {
    let board = link.board;
    let slot = board.slot(link.idx);
    let k = board.header().cycle.load(Ordering::Acquire);
    let inputs = &mut io.inputs;
    let due = match mode {
        Mode::Sync => {
            let fresh = slot.fresh_mask.load(Ordering::Acquire);
            k > common.last_cycle
                && slot.expected_cycle.load(Ordering::Acquire) == k
                && inputs.iter().enumerate().all(|(i, p)| {
                    fresh & (1 << i) == 0 || p.latest_header().is_some_and(|h| h.cycle == k)
                })
        }
        // A unit with a waker (a gateway's) runs when another thread woke it, and only then:
        // without inputs it would otherwise be due every cycle, for nothing.
        Mode::Async if common.waker.is_some() => {
            common.waker.as_ref().is_some_and(super::Waker::take)
        }
        Mode::Async if inputs.is_empty() => k > common.last_cycle,
        Mode::Async => inputs.iter().any(|p| p.is_fresh()),
    };
    if !due {
        return;
    }
    let start = now_ns();
    slot.last_start_ns.store(start, Ordering::Relaxed);
    let status = {
        let src = RuntimeInputs { inputs, cycle: k };
        let ctx = Ctx {
            params: &common.params,
            cycle: k,
            name: &common.name,
            activation: slot.active.load(Ordering::Acquire),
            clock: link.board.header().clock(),
        };
        run(body, &src, &mut io.outputs, &ctx)
    };
    let end = now_ns();
    let header = SampleHeader {
        cycle: k,
        stamp_ns: end,
        slot: MaybeSlot::some(link.idx as u32),
        reserved: 0,
    };
    let mask = commit_outputs(link, &mut io.outputs, status, header);
    keep(body, status, common, k);
    for i in io.inputs.iter_mut() {
        i.consume();
    }
    common.last_cycle = k;
    finish_run(
        link,
        RunRecord {
            k,
            status,
            mask,
            outputs: io.outputs.len(),
            start,
            end,
            sync: mode == Mode::Sync,
        },
    );
    // A proposal not made: the device waiting for it learns from the board, once woken.
    for &i in &io.proposals {
        if mask & (1 << i) == 0 {
            link.wake_consumers(i);
        }
    }
    announce(&io.outputs, mask);
}
