//! `stop`: standing still.

use super::*;

/// Stop: proposes standing still, with the highest default priority.
#[derive(Default)]
pub struct Stop;

impl Skill for Stop {
    type Params = NoParams;
    type Inputs<'a> = ();
    type Outputs<'a> = DriveOut<'a>;
    const PRIORITY: i32 = 10;
    fn compute(&mut self, _: &Ctx<NoParams>, _: (), o: &mut DriveOut) -> SkillResult {
        o.drive.set(Drive::default());
        Ok(())
    }
}
