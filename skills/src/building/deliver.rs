//! `deliver`: saying the message at the office.

use super::*;
use serde::{Deserialize, Serialize};

/// Parameters of [`Deliver`].
#[derive(Params, Debug, Clone)]
pub struct DeliverParams {
    /// The room to deliver to (its number, as on its sign).
    #[param(default = 405, min = 100, max = 799)]
    pub room: u32,
    /// Say the message once the room's sign is in view this near (m).
    #[param(default = 2.5, min = 0.3, max = 6.0)]
    pub near: f64,
}

/// Inputs of [`Deliver`].
#[derive(Inputs)]
pub struct DeliverIn<'a> {
    /// The signs in view (sign_read).
    pub signs: Input<'a, Signs>,
    /// The speaker's report.
    pub voice: Input<'a, Voice>,
}

/// Outputs of [`Deliver`].
#[derive(Outputs)]
pub struct DeliverOut<'a> {
    /// The message proposal.
    pub say: Proposal<'a, Say>,
    /// How far the job is.
    pub progress: Output<'a, Progress>,
}

/// What the robot says at the office.
pub const MESSAGE: &str = "A message for the department head, from the basement lab.";

/// Phases of [`Deliver`] (its `progress.phase`).
pub mod deliver_phase {
    /// Looking for the room's sign within `near`.
    pub const LOOKING: u32 = 0;
    /// Proposing the message until the speaker reports it said.
    pub const SAYING: u32 = 1;
    /// Said.
    pub const SAID: u32 = 2;
}
use deliver_phase::*;

/// Says [`MESSAGE`] at the room. Once the room's sign is in view within `near`, it proposes
/// the message with a number of its own (the cycle it decided, never 0) and keeps proposing
/// it: the speaker says each number once, so the message is said once however long it is
/// proposed. Done when the speaker reports a message said since activation, and the last one
/// sent to be said is this one. A reactivation picks a new number (it says it again).
///
/// For a sequencer: `deliver.progress.done == 1` (said); `progress.value` is the range of the
/// room's sign when last in view (m; 0 before).
#[derive(Default, Serialize, Deserialize)]
pub struct Deliver {
    activation: Activation,
    /// Messages said when activated.
    said_before: u32,
    /// The message's number, once decided.
    seq: Option<u32>,
    range: f64,
}

impl Skill for Deliver {
    type Params = DeliverParams;
    type Inputs<'a> = DeliverIn<'a>;
    type Outputs<'a> = DeliverOut<'a>;
    const STATE: State<Self> = State::kept(1);
    fn compute(
        &mut self,
        ctx: &Ctx<DeliverParams>,
        i: DeliverIn,
        o: &mut DeliverOut,
    ) -> SkillResult {
        let (signs, voice, p) = (&*i.signs, &*i.voice, ctx.params);
        if self.activation.begins(ctx) {
            self.said_before = voice.said;
            self.seq = None;
            self.range = 0.0;
        }
        if signs.room == p.room {
            self.range = signs.room_range;
            if self.seq.is_none() && signs.room_range <= p.near {
                // The low 32 bits of the cycle; 0 means "say nothing".
                self.seq = Some((ctx.cycle as u32).max(1));
            }
        }
        let mut phase = LOOKING;
        if let Some(seq) = self.seq {
            o.say.set(Say::new(seq, MESSAGE));
            phase = if voice.said > self.said_before && voice.seq == seq {
                SAID
            } else {
                SAYING
            };
        }
        o.progress.set(Progress {
            done: phase == SAID,
            phase,
            value: self.range,
        });
        Ok(())
    }
}
