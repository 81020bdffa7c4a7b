//! @NAME@: slows down and turns away from what is near ahead (reads the sonar ring, proposes
//! on the `drive` channel; arbitrated with wander and avoid by priority).
use skill_sdk::prelude::*;
use skillfab_msgs::{Drive, Sonar};

#[derive(Params, Debug, Clone)]
pub struct P {
    /// Closer than this ahead (m), it slows and turns.
    #[param(default = 1.2, min = 0.1, max = 5.0)]
    pub near: f64,
}
#[derive(Inputs)]
pub struct In<'a> {
    pub sonar: Input<'a, Sonar>,
}
#[derive(Outputs)]
pub struct Out<'a> {
    pub drive: Proposal<'a, Drive>,
}

#[derive(Default)]
pub struct MySkill;
impl Skill for MySkill {
    type Params = P;
    type Inputs<'a> = In<'a>;
    type Outputs<'a> = Out<'a>;
    /// Above wander (0), below avoid (8).
    const PRIORITY: i32 = 5;
    fn compute(&mut self, ctx: &Ctx<P>, i: In, o: &mut Out) -> SkillResult {
        // Sonars 0, 1 and 23 look ahead; no echo is far, a sonar never read says nothing.
        let ahead = [0, 1, 23]
            .into_iter()
            .filter_map(|k| i.sonar.echo(k))
            .map(|e| e.range_or(f64::INFINITY))
            .fold(f64::INFINITY, f64::min);
        if ahead < ctx.params.near {
            o.drive.set(Drive {
                translate: 0.1 * ahead / ctx.params.near,
                rotate: 0.5,
            });
        }
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    skill_sdk::main::<MySkill>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use skill_sdk::harness::Harness;

    fn sonar(ahead: f64) -> Sonar {
        let mut s = Sonar {
            range: [f64::INFINITY; 24],
            age_ms: [0.0; 24],
        };
        s.range[0] = ahead;
        s
    }

    #[test]
    fn it_turns_away_only_when_something_is_near() {
        let mut h = Harness::<MySkill>::new();
        h.input(In::SONAR, sonar(0.6));
        let d = *h.step().unwrap().output(Out::DRIVE).unwrap();
        assert!((d.translate - 0.05).abs() < 1e-9 && d.rotate > 0.0, "{d:?}");
        h.input(In::SONAR, sonar(3.0));
        assert!(
            h.step().unwrap().output(Out::DRIVE).is_none(),
            "nothing near: no proposal"
        );
    }
}
