use super::*;
use crate::prelude::Message;

#[derive(Message, Debug, Default, Clone, Copy)]
#[message(type_name = "skillfab.Tick")]
#[repr(C)]
struct Tick {
    value: u64,
}
#[derive(Message, Debug, Default, Clone, Copy)]
#[message(type_name = "skillfab.Scaled")]
#[repr(C)]
struct Scaled {
    value: f64,
}
#[derive(Message, Debug, Default, Clone, Copy)]
#[message(type_name = "skillfab.Drive")]
#[repr(C)]
struct Drive {
    translate: f64,
    rotate: f64,
}
#[derive(Message, Debug, Default, Clone, Copy)]
#[message(type_name = "skillfab.Bumpers")]
#[repr(C)]
struct Bumpers {
    hit: u32,
    stall: bool,
}
static REGISTRY: [MessageType; 3] = [
    MessageType::of::<Tick>(),
    MessageType::of::<Scaled>(),
    MessageType::of::<Drive>(),
];

fn float(name: &str, default: f64, min: f64, max: f64) -> ParamSpec {
    ParamSpec {
        name: name.into(),
        kind: crate::params::ParamKind::Float,
        default: ParamValue::Float(default),
        min: Some(ParamValue::Float(min)),
        max: Some(ParamValue::Float(max)),
        doc: String::new(),
    }
}

#[test]
fn declarations_are_checked() {
    let mut s = ForeignSkill::new("c_scale", Mode::Sync, &REGISTRY).unwrap();
    assert_eq!(s.input("tick", "skillfab.Tick"), Ok(0));
    assert_eq!(s.output("scaled", "skillfab.Scaled"), Ok(0));
    assert_eq!(s.proposal("drive", "skillfab.Drive"), Ok(1));
    assert_eq!(s.outputs()[1].topic, "channel/drive");
    assert!(matches!(
        s.input("x", "skillfab.Nope"),
        Err(DeclError::UnknownType { .. })
    ));
    assert!(matches!(
        s.input("tick", "skillfab.Tick"),
        Err(DeclError::BadName { .. })
    ));
    assert!(matches!(
        s.output("bad name", "skillfab.Tick"),
        Err(DeclError::BadName { .. })
    ));
    assert_eq!(s.param(float("gain", 2.0, -10.0, 10.0)), Ok(0));
    assert!(matches!(
        s.param(float("gain", 2.0, -10.0, 10.0)),
        Err(DeclError::BadParam { .. })
    ));
    assert!(matches!(
        s.param(float("g2", 20.0, -10.0, 10.0)),
        Err(DeclError::BadParam { .. })
    ));
    assert!(matches!(
        s.param(float("g3", 0.0, 10.0, -10.0)),
        Err(DeclError::BadParam { .. })
    ));
    let mut wrong = float("g4", 0.0, -1.0, 1.0);
    wrong.default = ParamValue::Int(0);
    assert!(matches!(s.param(wrong), Err(DeclError::BadParam { .. })));
    assert!(ForeignSkill::new("", Mode::Sync, &REGISTRY).is_err());
}

#[test]
fn bools_written_by_c_are_made_valid() {
    let schema = <Bumpers as crate::Message>::schema();
    let mut bytes = vec![0u8; schema.size as usize];
    let stall = schema.fields[1].offset as usize;
    bytes[stall] = 7;
    bytes[0] = 9; // the u32 `hit` is left alone
    sanitize_message(&schema, &mut bytes);
    assert_eq!(bytes[stall], 1);
    assert_eq!(bytes[0], 9);
}
