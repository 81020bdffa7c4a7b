//! The shipped message types as the ROS tools see them: each type's ros2msg definition says
//! what its `.msg` file says, and any sample survives CDR and back (but its padding).

// A failed check stops the test right there, with its message.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use proptest::prelude::*;
use skillfab_msggen::{Base, MsgType, Prim};
use skillfab_proto::schema::{FieldKind, MessageSchema};
use skillfab_proto::{cdr, ros2msg};
use std::collections::BTreeMap;
use std::path::Path;

/// The shipped `.msg` files, by type name.
fn msg_files() -> BTreeMap<String, MsgType> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("msg/skillfab");
    let package = skillfab_msggen::load_package(&dir).unwrap();
    package
        .types
        .into_iter()
        .map(|t| (t.type_name(), t))
        .collect()
}

fn schema_of(type_name: &str) -> MessageSchema {
    let t = skillfab_msgs::registry()
        .iter()
        .find(|t| t.type_name == type_name)
        .unwrap_or_else(|| panic!("{type_name} is not in the registry"));
    (t.schema)()
}

/// A field line as the `.msg` file declares it, in ROS 2's words.
fn ros_line(f: &skillfab_msggen::Field) -> String {
    let base = match &f.ty.base {
        Base::Prim(p) => match p {
            Prim::Bool => "bool".to_string(),
            Prim::F32 => "float32".into(),
            Prim::F64 => "float64".into(),
            // u8 → uint8, i16 → int16, …
            p => {
                let n = p.name();
                let bits = &n[1..];
                if n.starts_with('u') {
                    format!("uint{bits}")
                } else {
                    format!("int{bits}")
                }
            }
        },
        Base::Named(n) => n.replacen('.', "/", 1),
    };
    let len: Option<u32> = (!f.ty.dims.is_empty()).then(|| f.ty.dims.iter().product());
    match len {
        Some(n) => format!("{base}[{n}] {}", f.name),
        None => format!("{base} {}", f.name),
    }
}

#[test]
fn every_shipped_type_reads_in_ros2msg_as_its_msg_file_declares_it() {
    let files = msg_files();
    assert!(files.len() > 20, "the catalog: {}", files.len());
    let separator = format!("{}\n", "=".repeat(80));
    for (name, t) in &files {
        let schema = schema_of(name);
        assert_eq!(
            ros2msg::schema_name(name),
            format!("skillfab/msg/{}", t.name)
        );
        let text = ros2msg::schema_text(&schema);
        let mut sections = text.split(&separator);
        let own: Vec<&str> = sections.next().unwrap().lines().collect();
        let want: Vec<String> = t.fields.iter().map(ros_line).collect();
        assert_eq!(own, want, "{name}");
        // Each nested type's definition, as its own file declares it.
        for section in sections {
            let mut lines = section.lines();
            let head = lines.next().unwrap();
            let nested = head
                .strip_prefix("MSG: ")
                .unwrap_or_else(|| panic!("{name}: a nested definition starts '{head}'"))
                .replacen('/', ".", 1);
            let nt = &files[&nested];
            let want: Vec<String> = nt.fields.iter().map(ros_line).collect();
            assert_eq!(lines.collect::<Vec<_>>(), want, "{name} > {nested}");
        }
    }
}

/// Which bytes of a layout no field covers.
fn padding(m: &MessageSchema) -> Vec<bool> {
    fn size(k: &FieldKind) -> usize {
        match k {
            FieldKind::Prim(p) => p.size(),
            FieldKind::Array { elem, len } => size(elem) * *len as usize,
            FieldKind::Struct(m) => m.size as usize,
        }
    }
    fn mark(k: &FieldKind, at: usize, used: &mut [bool]) {
        match k {
            FieldKind::Prim(p) => used[at..at + p.size()].fill(true),
            FieldKind::Array { elem, len } => {
                (0..*len as usize).for_each(|i| mark(elem, at + i * size(elem), used));
            }
            FieldKind::Struct(m) => {
                for f in &m.fields {
                    mark(&f.ty, at + f.offset as usize, used);
                }
            }
        }
    }
    let mut used = vec![false; m.size as usize];
    mark(&FieldKind::Struct(m.clone()), 0, &mut used);
    used.iter().map(|u| !u).collect()
}

/// The shipped types (but the large blobs: their bytes are one array, and a proptest case of
/// 64 KB costs more than it tells).
fn shipped() -> Vec<MessageSchema> {
    skillfab_msgs::registry()
        .iter()
        .map(|t| (t.schema)())
        .filter(|s| s.size <= 4096)
        .collect()
}

proptest! {
    #[test]
    fn any_sample_of_a_shipped_type_survives_cdr_but_its_padding(
        seed in proptest::collection::vec(any::<u8>(), 4096),
        nan_at in any::<prop::sample::Index>(),
    ) {
        for m in shipped() {
            let mut bytes = seed[..m.size as usize].to_vec();
            // A quiet NaN with a payload somewhere 8-aligned: its bits must come back.
            if m.size >= 8 {
                let at = nan_at.index(m.size as usize / 8) * 8;
                bytes[at..at + 8].copy_from_slice(&0x7ff8_0000_0bad_f00du64.to_ne_bytes());
            }
            let mut out = Vec::new();
            cdr::encode(&m, &bytes, &mut out);
            prop_assert_eq!(&out[..4], &[0, 1, 0, 0]);
            let back = cdr::decode(&m, &out).unwrap();
            let want: Vec<u8> = bytes
                .iter()
                .zip(padding(&m))
                .map(|(b, pad)| if pad { 0 } else { *b })
                .collect();
            prop_assert_eq!(back, want, "{}", m.type_name);
            // Cut anywhere inside, it is refused.
            let cut = out.len() / 2;
            prop_assert!(cdr::decode(&m, &out[..cut]).is_err());
        }
    }
}

#[test]
fn a_sonar_sample_is_the_cdr_a_ros_reader_expects() {
    let mut s = skillfab_msgs::Sonar {
        range: [f64::INFINITY; 24],
        age_ms: [0.0; 24],
    };
    s.range[3] = 1.25;
    s.age_ms[0] = f64::NAN;
    let bytes: Vec<u8> = s
        .range
        .iter()
        .chain(&s.age_ms)
        .flat_map(|x| x.to_ne_bytes())
        .collect();
    let mut out = Vec::new();
    cdr::encode(&schema_of("skillfab.Sonar"), &bytes, &mut out);
    // Header, then 24 + 24 float64 with no length prefix.
    assert_eq!(out.len(), 4 + 48 * 8);
    assert_eq!(out[4 + 3 * 8..4 + 4 * 8], 1.25f64.to_le_bytes());
    assert_eq!(
        ros2msg::schema_text(&schema_of("skillfab.Sonar")),
        "float64[24] range\nfloat64[24] age_ms\n"
    );
}
