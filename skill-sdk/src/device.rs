//! The device trait: the paper's dskill. A device process hides hardware behind buffers and
//! never blocks the cycle: at the start of every cycle it publishes its latest buffered sample
//! at once; once the cycle's proposals are in it receives one arbitrated command per channel.

use crate::actuation::ChannelSet;
use crate::params::Params;
use crate::ports::OutputSet;
use crate::skill::{Ctx, SkillResult};

/// Where a device's hardware is (`--port`, `--baud`).
#[derive(Debug, Clone, Default)]
pub struct DeviceOptions {
    /// Serial port path (a tty, or a simulator's pty link).
    pub port: Option<String>,
    /// Baud rate.
    pub baud: Option<u32>,
    /// A directory of this device instance (by domain and name) for state that must outlive
    /// its process — a restarted or hot-swapped instance finds it there (e.g. the odometry
    /// frame). It lies in the domain's private root and goes with the domain's files.
    pub state_dir: Option<std::path::PathBuf>,
}

/// A device: sensor outputs published at cycle start, actuator channels served at cycle end.
///
/// `Commands` is a struct of `Command<'a, T>` fields (derive `Channels`): the field name is the
/// channel (`--remap drive=drive2` renames it, `--policy drive=blend` blends it), `T` an
/// [`Actuation`](crate::actuation::Actuation) whose `safe()` is sent when nobody proposes.
pub trait Device: Default + 'static {
    /// Parameters (derive `Params`), or [`crate::params::NoParams`].
    type Params: Params + Default;
    /// Sensor outputs (derive `Outputs`), or `()`.
    type Outputs<'a>: OutputSet<'a>;
    /// Channels served (derive `Channels` over `Command<'a, T>` fields), or `()`.
    type Commands<'a>: ChannelSet<'a>;

    /// Called once before registration: open the hardware (start its I/O thread).
    fn init(&mut self, _options: &DeviceOptions) -> SkillResult {
        Ok(())
    }

    /// Cycle start: write the latest buffered sample. Must not block on the hardware.
    fn sample(&mut self, ctx: &Ctx<'_, Self::Params>, out: &mut Self::Outputs<'_>) -> SkillResult;

    /// The cycle's arbitrated commands, one per channel (the safe command when nobody
    /// proposed). Hand them to the hardware's buffer; must not block.
    fn command(&mut self, ctx: &Ctx<'_, Self::Params>, commands: Self::Commands<'_>)
    -> SkillResult;
}
