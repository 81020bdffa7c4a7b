//! The typed references the derives generate, seen from a skill crate: their names and types
//! for fields of several types, their docs (this crate denies missing docs, so an undocumented
//! generated item stops it compiling), and the harness taking them.

#![deny(missing_docs)]

use skill::{Go, GoIn, GoOut, GoParams, Pose};
use skill_sdk::harness::Harness;
use skill_sdk::refs::{Field, InputRef, OutputRef, Param, ValuePath};

/// A skill declared as a skill crate would, in a public module: the generated references are
/// public and must be documented.
pub mod skill {
    use skill_sdk::prelude::*;

    /// A pose with a covariance, a flag and a name.
    #[derive(Message, Debug, Default, Clone, Copy, PartialEq)]
    #[repr(C)]
    pub struct Pose {
        /// East (m).
        pub x: f64,
        /// North (m).
        pub y: f32,
        /// Diagonal covariance (no doc on its reference: the derive writes one).
        pub cov: [f64; 3],
        /// Whether the pose is known.
        pub known: bool,
        /// Short name, UTF-8.
        pub name: [u8; 7],
        /// A level, signed.
        pub level: i16,
    }

    /// Parameters, one of them called `name` (the reference's own `name()` is a method).
    #[derive(Params, Debug, Clone)]
    pub struct GoParams {
        /// Speed (m/s).
        #[param(default = 0.3, min = 0.0, max = 1.0)]
        pub speed: f64,
        /// How often to try.
        #[param(default = 2, min = 1, max = 9)]
        pub tries: u32,
        /// Whether to announce itself.
        #[param(default = false)]
        pub name: bool,
        /// Offset, signed.
        #[param(default = 0)]
        pub offset: i8,
    }

    /// Inputs.
    #[derive(Inputs)]
    pub struct GoIn<'a> {
        /// Where it is.
        pub pose: Input<'a, Pose>,
    }

    /// Outputs.
    #[derive(Outputs)]
    pub struct GoOut<'a> {
        /// Where it will be.
        pub next: Output<'a, Pose>,
    }

    /// Moves `x` by `speed` × `tries` + `offset` and passes the rest on.
    #[derive(Default)]
    pub struct Go;

    impl Skill for Go {
        type Params = GoParams;
        type Inputs<'a> = GoIn<'a>;
        type Outputs<'a> = GoOut<'a>;
        fn compute(&mut self, c: &Ctx<GoParams>, i: GoIn, o: &mut GoOut) -> SkillResult {
            let p = c.params;
            o.next.set(Pose {
                x: i.pose.x + p.speed * f64::from(p.tries) + f64::from(p.offset),
                known: p.name,
                ..*i.pose
            });
            Ok(())
        }
    }
}

#[test]
fn each_field_has_a_reference_of_its_type() {
    let fields: [(&str, &str); 6] = [
        (Field::<f64, Pose>::name(&Pose::X), "x"),
        (Field::<f32, Pose>::name(&Pose::Y), "y"),
        (Field::<[f64; 3], Pose>::name(&Pose::COV), "cov"),
        (Field::<bool, Pose>::name(&Pose::KNOWN), "known"),
        (Field::<[u8; 7], Pose>::name(&Pose::NAME), "name"),
        (Field::<i16, Pose>::name(&Pose::LEVEL), "level"),
    ];
    for (got, want) in fields {
        assert_eq!(got, want);
    }
    let params: [(&str, &str); 4] = [
        (Param::<f64, GoParams>::name(&GoParams::SPEED), "speed"),
        (Param::<u32, GoParams>::name(&GoParams::TRIES), "tries"),
        (Param::<bool, GoParams>::name(&GoParams::NAME), "name"),
        (Param::<i8, GoParams>::name(&GoParams::OFFSET), "offset"),
    ];
    for (got, want) in params {
        assert_eq!(got, want);
    }
    let input: InputRef<Pose, GoIn<'static>> = GoIn::POSE;
    let output: OutputRef<Pose, GoOut<'static>> = GoOut::NEXT;
    assert_eq!((input.name(), output.name()), ("pose", "next"));
}

#[test]
fn value_paths_are_built_from_an_output_and_its_fields() {
    let whole: ValuePath<Pose> = GoOut::NEXT.into();
    assert_eq!(whole.to_string(), "next");
    let cov: ValuePath<f64> = GoOut::NEXT.field(Pose::COV).at(2);
    assert_eq!(cov.to_string(), "next.cov[2]");
}

#[test]
fn the_harness_takes_the_skills_references() {
    let mut h = Harness::<Go>::new();
    h.set(GoParams::SPEED, 0.5)
        .unwrap()
        .set(GoParams::TRIES, 3)
        .unwrap()
        .set(GoParams::NAME, true)
        .unwrap()
        .set(GoParams::OFFSET, -1)
        .unwrap();
    assert!(h.set(GoParams::TRIES, 10).is_err(), "out of range");
    h.input(
        GoIn::POSE,
        Pose {
            x: 1.0,
            level: -4,
            ..Pose::default()
        },
    );
    let step = h.step().unwrap();
    let next = step.output(GoOut::NEXT).unwrap();
    assert_eq!((next.x, next.known, next.level), (1.5, true, -4));
}
