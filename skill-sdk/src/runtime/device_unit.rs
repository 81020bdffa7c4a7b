//! A device's cycle (the paper's dskill): at cycle start the latest buffered sample is
//! published at once; once every proposer the manager expects has settled, each channel is
//! arbitrated, the commands go to the device's body and out on the command topics, and the
//! run is finished.

use super::arbiter::Arbiter;
use super::serve::Link;
use super::skill_unit::{RunRecord, announce, commit_outputs, finish_run, guarded};
use super::{Common, Io, Unit};
use crate::SdkError;
use crate::actuation::{ChannelSet, ErasedChannel};
use crate::board::RunStatus;
use crate::decl::{Mode, PortDecl};
use crate::device::{Device, DeviceOptions};
use crate::header::{MaybeSlot, SampleHeader, now_ns};
use crate::ports::{ErasedInput, ErasedOutput, OutputSet, PortMaker};
use crate::skill::Ctx;
use std::sync::atomic::Ordering;

/// The wrapper that runs a [`Device`].
pub(crate) struct DeviceUnit<D: Device> {
    device: D,
    /// Where its hardware is (`--port`, `--baud`), for [`Device::init`].
    options: DeviceOptions,
    /// Last cycle whose sample phase ran.
    sampled: u64,
    /// Picks each channel's command from the cycle's proposals.
    arbiter: Arbiter,
}

impl<D: Device> DeviceUnit<D> {
    pub(crate) fn new(device: D, options: DeviceOptions) -> DeviceUnit<D> {
        DeviceUnit {
            device,
            options,
            sampled: 0,
            arbiter: Arbiter::default(),
        }
    }

    /// Cycle start: the body writes its latest buffered sample, which is sent at once.
    fn sample(&mut self, link: &Link<'_>, io: &mut Io, common: &Common<D::Params>, k: u64) {
        let me = link.board.slot(link.idx);
        self.sampled = k;
        me.last_start_ns.store(now_ns(), Ordering::Relaxed);
        let status = {
            let mut out = <D::Outputs<'_> as OutputSet<'_>>::bind(&mut io.outputs);
            let ctx = Ctx {
                params: &common.params,
                cycle: k,
                name: &common.name,
                activation: me.active.load(Ordering::Acquire),
                clock: link.board.header().clock(),
            };
            let device = &mut self.device;
            guarded(k, || device.sample(&ctx, &mut out))
        };
        let mask = commit_outputs(link, &mut io.outputs, status, header(link, k));
        me.published_mask.store(mask, Ordering::Relaxed);
        announce(&io.outputs, mask);
    }

    /// Hands the cycle's commands to the body and publishes them on the command topics.
    fn command(
        &mut self,
        link: &Link<'_>,
        io: &mut Io,
        common: &Common<D::Params>,
        k: u64,
    ) -> RunStatus {
        let status = match <D::Commands<'_> as ChannelSet<'_>>::fetch(&io.channels) {
            None => RunStatus::Skipped,
            Some(cmds) => {
                let ctx = Ctx {
                    params: &common.params,
                    cycle: k,
                    name: &common.name,
                    activation: link.board.slot(link.idx).active.load(Ordering::Acquire),
                    clock: link.board.header().clock(),
                };
                let device = &mut self.device;
                guarded(k, || device.command(&ctx, cmds))
            }
        };
        let header = header(link, k);
        for ch in io.channels.iter_mut() {
            if let Err(e) = ch.publish(header) {
                tracing::warn!(cycle = k, error = %e, "command not published");
            }
        }
        status
    }
}

/// The sample header of this unit's samples in cycle `k`, stamped now.
fn header(link: &Link<'_>, k: u64) -> SampleHeader {
    SampleHeader {
        cycle: k,
        stamp_ns: now_ns(),
        slot: MaybeSlot::some(link.idx as u32),
        reserved: 0,
    }
}

impl<D: Device> Unit for DeviceUnit<D> {
    type Params = D::Params;
    fn mode(&self) -> Mode {
        Mode::Sync
    }
    fn priority(&self) -> i32 {
        0
    }
    fn default_params(&self) -> D::Params {
        D::Params::default()
    }
    fn init(&mut self) -> Result<(), SdkError> {
        self.device
            .init(&self.options)
            .map_err(|e| SdkError::DeviceInit {
                reason: e.to_string(),
            })
    }
    /// The channels: a device reads no inputs.
    fn input_ports(&self) -> Vec<PortDecl> {
        <D::Commands<'static> as ChannelSet<'static>>::ports()
    }
    fn output_ports(&self) -> Vec<PortDecl> {
        <D::Outputs<'static> as OutputSet<'static>>::ports()
    }
    fn make_inputs(&self, _m: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedInput>>, SdkError> {
        Ok(Vec::new())
    }
    fn make_channels(&self, m: &PortMaker<'_>) -> Result<Vec<Box<dyn ErasedChannel>>, SdkError> {
        <D::Commands<'static> as ChannelSet<'static>>::make(m)
    }
    fn make_outputs(&self, m: &PortMaker<'_>) -> Result<Vec<ErasedOutput>, SdkError> {
        <D::Outputs<'static> as OutputSet<'static>>::make(m)
    }

    /// Cycle k: at the start, publish the latest sample at once; then, when every proposer
    /// the manager expects in k has finished (or was cancelled), arbitrate each channel, hand
    /// the commands to the body, publish them, and finish the cycle's run.
    fn step(&mut self, link: &Link<'_>, io: &mut Io, common: &mut Common<D::Params>) {
        let board = link.board;
        let me = board.slot(link.idx);
        let k = board.header().cycle.load(Ordering::Acquire);
        if k <= common.last_cycle || me.expected_cycle.load(Ordering::Acquire) != k {
            return;
        }
        if self.sampled < k {
            self.sample(link, io, common, k);
        }
        let Some(channels) = self.arbiter.settled(board, me, io, k) else {
            return;
        };
        // A proposer publishes its proposal before it marks its run done, but the proposal
        // may have landed after the poll of this wake-up: receive again now that everyone has
        // settled, or a proposal made in time would count as none.
        for ch in io.channels.iter_mut() {
            if let Err(e) = ch.poll() {
                tracing::warn!(cycle = k, error = %e, "proposals not received");
            }
        }
        let start = now_ns();
        Arbiter::arbitrate(me, io, channels, k);
        let status = self.command(link, io, common, k);
        let end = now_ns();
        common.last_cycle = k;
        finish_run(
            link,
            RunRecord {
                k,
                status,
                mask: me.published_mask.load(Ordering::Relaxed),
                outputs: io.outputs.len(),
                start,
                end,
                sync: true,
            },
        );
    }
}
