//! What a replay is judged by: the replayed skills' outputs against the recorded ones, cycle
//! by cycle, field by field on the bytes of each field (padding not compared).

use super::{Divergence, Recording, Report, Sample};
use serde_json::Value as Json;
use skillfab_manager::recorder::hex;
use skillfab_proto::schema::{FieldKind, Prim};
use std::collections::{BTreeMap, BTreeSet};

/// The outputs of the replayed skills, by cycle: (skill, port) → sample.
fn outputs<'a>(
    rec: &'a Recording,
    skills: &[String],
    from: u64,
    to: u64,
) -> BTreeMap<u64, BTreeMap<(String, String), &'a Sample>> {
    let mut m: BTreeMap<u64, BTreeMap<(String, String), &Sample>> = BTreeMap::new();
    for (cycle, samples) in rec.samples.range(from..=to) {
        for s in samples.iter().filter(|s| skills.contains(&s.skill)) {
            m.entry(*cycle)
                .or_default()
                .insert((s.skill.clone(), s.port.clone()), s);
        }
    }
    m
}

/// The first field (a dotted path) where two decoded values differ.
fn first_difference(a: &Json, b: &Json, path: &str) -> Option<(String, Json, Json)> {
    match (a, b) {
        (Json::Object(x), Json::Object(y)) => x.iter().find_map(|(k, v)| {
            let p = if path.is_empty() {
                k.clone()
            } else {
                format!("{path}.{k}")
            };
            first_difference(v, y.get(k).unwrap_or(&Json::Null), &p)
        }),
        (Json::Array(x), Json::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .find_map(|(i, (v, w))| first_difference(v, w, &format!("{path}[{i}]"))),
        _ if a == b => None,
        _ => Some((path.to_string(), a.clone(), b.clone())),
    }
}

/// A primitive field of a message: its path, byte range and kind.
struct Leaf {
    path: String,
    at: std::ops::Range<usize>,
    prim: Prim,
}

fn kind_size(k: &FieldKind) -> usize {
    match k {
        FieldKind::Prim(p) => p.size(),
        FieldKind::Array { elem, len } => kind_size(elem) * *len as usize,
        FieldKind::Struct(m) => m.size as usize,
    }
}

fn leaves_of(kind: &FieldKind, path: String, offset: usize, out: &mut Vec<Leaf>) {
    match kind {
        FieldKind::Prim(p) => out.push(Leaf {
            path,
            at: offset..offset + p.size(),
            prim: *p,
        }),
        FieldKind::Array { elem, len } => {
            for i in 0..*len as usize {
                leaves_of(
                    elem,
                    format!("{path}[{i}]"),
                    offset + i * kind_size(elem),
                    out,
                );
            }
        }
        FieldKind::Struct(m) => {
            for f in &m.fields {
                let p = if path.is_empty() {
                    f.name.clone()
                } else {
                    format!("{path}.{}", f.name)
                };
                leaves_of(&f.ty, p, offset + f.offset as usize, out);
            }
        }
    }
}

/// The fields of a sample's message type in declaration order: of the layout the recording
/// gives, else of the shared catalog (`None`: neither knows it).
fn leaves(sample: &Sample) -> Option<Vec<Leaf>> {
    let schema = match &sample.schema {
        Some(s) => s.as_ref().clone(),
        None => {
            let t = skillfab_msgs::registry()
                .iter()
                .find(|t| t.type_name == sample.type_name)?;
            (t.schema)()
        }
    };
    let mut out = Vec::new();
    leaves_of(&FieldKind::Struct(schema), String::new(), 0, &mut out);
    Some(out)
}

/// A primitive read from bytes, as JSON (non-finite floats as text).
fn prim_json(b: &[u8], p: Prim) -> Json {
    let float = |v: f64| {
        if v.is_finite() {
            Json::from(v)
        } else {
            Json::from(v.to_string())
        }
    };
    let mut w = [0u8; 8];
    w[..p.size()].copy_from_slice(&b[..p.size()]);
    let (w2, w4) = ([w[0], w[1]], [w[0], w[1], w[2], w[3]]);
    match p {
        Prim::Bool => Json::from(w[0] != 0),
        Prim::U8 => Json::from(w[0]),
        Prim::I8 => Json::from(i8::from_ne_bytes([w[0]])),
        Prim::U16 => Json::from(u16::from_ne_bytes(w2)),
        Prim::I16 => Json::from(i16::from_ne_bytes(w2)),
        Prim::U32 => Json::from(u32::from_ne_bytes(w4)),
        Prim::I32 => Json::from(i32::from_ne_bytes(w4)),
        Prim::F32 => float(f64::from(f32::from_ne_bytes(w4))),
        Prim::U64 => Json::from(u64::from_ne_bytes(w)),
        Prim::I64 => Json::from(i64::from_ne_bytes(w)),
        Prim::F64 => float(f64::from_ne_bytes(w)),
    }
}

/// Where two samples of one port differ: the first field (declaration order) whose bytes
/// differ, with both values. Padding between fields is not compared (it holds whatever the
/// publisher's memory held). A type outside the catalog is compared as bytes.
fn sample_difference(
    a: &Sample,
    b: &Sample,
    fields: Option<&[Leaf]>,
) -> Option<(String, Json, Json)> {
    let Some(fields) = fields else {
        return (a.bytes != b.bytes).then(|| {
            first_difference(&a.value, &b.value, "").unwrap_or_else(|| {
                (
                    "bytes".into(),
                    Json::from(hex(&a.bytes)),
                    Json::from(hex(&b.bytes)),
                )
            })
        });
    };
    fields.iter().find_map(|l| {
        let (x, y) = (a.bytes.get(l.at.clone())?, b.bytes.get(l.at.clone())?);
        (x != y).then(|| (l.path.clone(), prim_json(x, l.prim), prim_json(y, l.prim)))
    })
}

pub(super) fn compare(
    rec: &Recording,
    replayed: &Recording,
    skills: &[String],
    from: u64,
    to: u64,
) -> Report {
    let want = outputs(rec, skills, from, to);
    let got = outputs(replayed, skills, from, to);
    let mut report = Report {
        skills: skills.to_vec(),
        from,
        to,
        cycles: to - from + 1,
        identical_cycles: 0,
        samples: 0,
        divergence: None,
        kills: Vec::new(),
        wall_s: 0.0,
    };
    let empty = BTreeMap::new();
    let mut layouts: std::collections::HashMap<String, Option<Vec<Leaf>>> =
        std::collections::HashMap::new();
    for cycle in from..=to {
        let (w, g) = (
            want.get(&cycle).unwrap_or(&empty),
            got.get(&cycle).unwrap_or(&empty),
        );
        let keys: BTreeSet<&(String, String)> = w.keys().chain(g.keys()).collect();
        let mut same = true;
        for key in keys {
            report.samples += 1;
            let diff = match (w.get(key), g.get(key)) {
                (Some(a), Some(b)) if a.bytes == b.bytes => None,
                (Some(a), Some(b)) => {
                    let fields = layouts
                        .entry(a.type_name.clone())
                        .or_insert_with(|| leaves(a));
                    sample_difference(a, b, fields.as_deref())
                }
                (a, b) => Some((
                    "-".into(),
                    Json::from(if a.is_some() { "published" } else { "nothing" }),
                    Json::from(if b.is_some() { "published" } else { "nothing" }),
                )),
            };
            if let Some((field, recorded, replayed)) = diff {
                same = false;
                if report.divergence.is_none() {
                    report.divergence = Some(Divergence {
                        cycle,
                        skill: key.0.clone(),
                        port: key.1.clone(),
                        field,
                        recorded,
                        replayed,
                    });
                }
            }
        }
        report.identical_cycles += u64::from(same);
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn the_first_difference_is_named_by_its_field_path() {
        let a = json!({"translate": 0.3, "rotate": 0.0, "ranges": [1.0, 2.0]});
        let b = json!({"translate": 0.3, "rotate": 0.0, "ranges": [1.0, 2.5]});
        assert_eq!(
            first_difference(&a, &b, ""),
            Some(("ranges[1]".into(), json!(2.0), json!(2.5)))
        );
        assert_eq!(first_difference(&a, &a, ""), None);
    }

    fn sample(type_name: &str, bytes: Vec<u8>) -> Sample {
        Sample {
            skill: "s".into(),
            port: "p".into(),
            topic: "t".into(),
            type_name: type_name.into(),
            bytes,
            schema: None,
            value: Json::Null,
        }
    }

    #[test]
    fn padding_is_not_compared_and_a_non_finite_value_is_named() {
        // skillfab.Door: found (bool) at 0, seven bytes of padding, then x, y, heading, width.
        let mut a = vec![0u8; 40];
        let mut b = a.clone();
        a[1..8].copy_from_slice(&[0x66, 0xc4, 0x33, 0xef, 0x55, 0, 0]);
        let fields = leaves(&sample("skillfab.Door", Vec::new())).unwrap();
        assert!(
            sample_difference(
                &sample("skillfab.Door", a.clone()),
                &sample("skillfab.Door", b.clone()),
                Some(&fields)
            )
            .is_none()
        );
        b[16..24].copy_from_slice(&f64::NAN.to_ne_bytes());
        a[16..24].copy_from_slice(&f64::INFINITY.to_ne_bytes());
        assert_eq!(
            sample_difference(
                &sample("skillfab.Door", a),
                &sample("skillfab.Door", b),
                Some(&fields)
            ),
            Some(("y".into(), json!("inf"), json!("NaN")))
        );
    }
}
