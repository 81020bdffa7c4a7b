//! Decoding message bytes through their schema: dynamic values and field paths.
//!
//! The manager (queries, monitors), the CLI and the console read any message without its Rust
//! type: a [`FieldPath`] such as `range[3]` or `pose.x` is resolved against a
//! [`MessageSchema`] once, then read from sample bytes each time.

use crate::schema::{FieldKind, MessageSchema, Prim};
use serde::{Deserialize, Serialize};
use std::fmt;

/// A decoded value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Value {
    /// A `bool` field.
    Bool(bool),
    /// A signed integer field, widened.
    Int(i64),
    /// An unsigned integer field, widened.
    UInt(u64),
    /// An `f32` or `f64` field, widened.
    Float(f64),
    /// A fixed-size array field, element by element.
    Array(Vec<Value>),
    /// A nested message: its fields by name, in declaration order.
    Struct(Vec<(String, Value)>),
    /// Text the manager adds: a channel's device, policy and winner in a channel query, or
    /// the "… N more" marker of a shortened event.
    Text(String),
    /// Nothing there (a channel with no winner or no command yet).
    Null,
}

impl Value {
    /// The value as a number (bools are 0/1); `None` for arrays and structs.
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Value::Bool(b) => Some(f64::from(u8::from(b))),
            Value::Int(i) => Some(i as f64),
            Value::UInt(u) => Some(u as f64),
            Value::Float(f) => Some(f),
            _ => None,
        }
    }

    /// Every number in the value, flattened.
    pub fn numbers(&self) -> Vec<f64> {
        match self {
            Value::Array(v) => v.iter().flat_map(Value::numbers).collect(),
            Value::Struct(v) => v.iter().flat_map(|(_, x)| x.numbers()).collect(),
            other => other.as_f64().into_iter().collect(),
        }
    }
}

/// JSON text (non-finite floats become `null`), so human and `--json` output agree.
impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Bool(b) => write!(f, "{b}"),
            Value::Int(i) => write!(f, "{i}"),
            Value::UInt(u) => write!(f, "{u}"),
            Value::Float(x) if x.is_finite() => write!(f, "{x}"),
            Value::Float(_) | Value::Null => f.write_str("null"),
            Value::Text(t) => write!(f, "{t:?}"),
            Value::Array(v) => {
                f.write_str("[")?;
                for (i, x) in v.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{x}")?;
                }
                f.write_str("]")
            }
            Value::Struct(v) => {
                f.write_str("{")?;
                for (i, (k, x)) in v.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "\"{k}\": {x}")?;
                }
                f.write_str("}")
            }
        }
    }
}

/// A parameter's value as a decoded value (the same four kinds).
impl From<crate::param::ParamValue> for Value {
    fn from(v: crate::param::ParamValue) -> Value {
        use crate::param::ParamValue as P;
        match v {
            P::Bool(b) => Value::Bool(b),
            P::Int(i) => Value::Int(i),
            P::UInt(u) => Value::UInt(u),
            P::Float(f) => Value::Float(f),
        }
    }
}

/// A Rust type a decoded [`Value`] converts back to: what a typed read returns
/// (`skillfab-client`'s `Client::read`, given a [`ValuePath`](crate::refs::ValuePath)).
/// Implemented for every message field type — numbers and `bool`, arrays of them, and each
/// `#[derive(Message)]` type (the derive writes it).
///
/// The kinds must match as the schema decodes them: a float from a float, a signed integer
/// from a signed one that fits, an unsigned from an unsigned. A value of another kind means
/// the skill declares the field otherwise than the reference says (another version of the
/// message): `None`, not a converted guess.
pub trait FromValue: Sized {
    /// The value as `Self`, or `None` if it is of another kind or out of range.
    fn from_value(value: &Value) -> Option<Self>;
}

impl FromValue for bool {
    fn from_value(value: &Value) -> Option<Self> {
        match *value {
            Value::Bool(b) => Some(b),
            _ => None,
        }
    }
}

macro_rules! from_value {
    ($variant:ident => $($t:ty),*) => {$(
        impl FromValue for $t {
            fn from_value(value: &Value) -> Option<Self> {
                match *value {
                    Value::$variant(v) => <$t>::try_from(v).ok(),
                    _ => None,
                }
            }
        }
    )*};
}
from_value!(Int => i8, i16, i32, i64);
from_value!(UInt => u8, u16, u32, u64);
from_value!(Float => f64);

impl FromValue for f32 {
    fn from_value(value: &Value) -> Option<Self> {
        match *value {
            // Widened from an f32 when decoded: narrowing gives it back exactly.
            Value::Float(v) => Some(v as f32),
            _ => None,
        }
    }
}

impl<T: FromValue, const N: usize> FromValue for [T; N] {
    fn from_value(value: &Value) -> Option<Self> {
        let Value::Array(items) = value else {
            return None;
        };
        let items: Vec<T> = items.iter().map(T::from_value).collect::<Option<_>>()?;
        items.try_into().ok()
    }
}

/// Field `name` of a decoded message (the derived [`FromValue`] of a message reads its
/// fields through it).
pub fn field_of<'v>(value: &'v Value, name: &str) -> Option<&'v Value> {
    match value {
        Value::Struct(fields) => fields.iter().find(|(n, _)| n == name).map(|(_, v)| v),
        _ => None,
    }
}

/// Bytes one value of `kind` occupies (array stride included).
pub fn kind_size(kind: &FieldKind) -> usize {
    match kind {
        FieldKind::Prim(p) => p.size(),
        FieldKind::Array { elem, len } => kind_size(elem) * *len as usize,
        FieldKind::Struct(s) => s.size as usize,
    }
}

fn prim_at(p: Prim, b: &[u8]) -> Option<Value> {
    macro_rules! rd {
        ($t:ty) => {
            <$t>::from_ne_bytes(b.get(..std::mem::size_of::<$t>())?.try_into().ok()?)
        };
    }
    Some(match p {
        Prim::U8 => Value::UInt(u64::from(rd!(u8))),
        Prim::U16 => Value::UInt(u64::from(rd!(u16))),
        Prim::U32 => Value::UInt(u64::from(rd!(u32))),
        Prim::U64 => Value::UInt(rd!(u64)),
        Prim::I8 => Value::Int(i64::from(rd!(i8))),
        Prim::I16 => Value::Int(i64::from(rd!(i16))),
        Prim::I32 => Value::Int(i64::from(rd!(i32))),
        Prim::I64 => Value::Int(rd!(i64)),
        Prim::F32 => Value::Float(f64::from(rd!(f32))),
        Prim::F64 => Value::Float(rd!(f64)),
        Prim::Bool => Value::Bool(*b.first()? != 0),
    })
}

/// Decodes one value of `kind` from the start of `bytes`; `None` if too short.
pub fn decode(kind: &FieldKind, bytes: &[u8]) -> Option<Value> {
    match kind {
        FieldKind::Prim(p) => prim_at(*p, bytes),
        FieldKind::Array { elem, len } => {
            let step = kind_size(elem);
            (0..*len as usize)
                .map(|i| decode(elem, bytes.get(i * step..)?))
                .collect::<Option<Vec<_>>>()
                .map(Value::Array)
        }
        FieldKind::Struct(s) => decode_message(s, bytes),
    }
}

/// Decodes a whole message.
pub fn decode_message(schema: &MessageSchema, bytes: &[u8]) -> Option<Value> {
    if bytes.len() < schema.size as usize {
        return None;
    }
    schema
        .fields
        .iter()
        .map(|f| {
            Some((
                f.name.clone(),
                decode(&f.ty, bytes.get(f.offset as usize..)?)?,
            ))
        })
        .collect::<Option<Vec<_>>>()
        .map(Value::Struct)
}

/// Why a value path does not name a value: each variant names the offending part. Sent to
/// clients as is (a `query` or a monitor refused).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, Serialize, Deserialize)]
#[non_exhaustive]
pub enum PathError {
    /// Not of the form `skill.output[.field][index]`.
    #[error("'{text}' is not skill.output[.field][index]")]
    NotAnOutputPath {
        /// As given.
        text: String,
    },
    /// The skill has no output of that name.
    #[error("skill '{skill}' has no output '{output}' (outputs: {})", outputs.join(", "))]
    NoOutput {
        /// The skill.
        skill: String,
        /// The output asked for.
        output: String,
        /// Its outputs.
        outputs: Vec<String>,
    },
    /// Something after a range `[a..b]`.
    #[error("nothing may follow a range in '{path}'")]
    AfterRange {
        /// The field path.
        path: String,
    },
    /// A `[` with no `]`.
    #[error("missing ']' in '{path}'")]
    UnclosedIndex {
        /// The field path.
        path: String,
    },
    /// An index on something that is not an array.
    #[error("'{path}': [{index}] indexes something that is not an array")]
    NotAnArray {
        /// The field path.
        path: String,
        /// The index as written.
        index: String,
    },
    /// An index that is not a number.
    #[error("'{path}': '{index}' is not an index")]
    NotAnIndex {
        /// The field path.
        path: String,
        /// The index as written.
        index: String,
    },
    /// An index or range past the array's end.
    #[error("'{path}': index {index} is out of bounds (length {len})")]
    OutOfBounds {
        /// The field path.
        path: String,
        /// The index or range as written.
        index: String,
        /// The array's length.
        len: u32,
    },
    /// A field name on something that has no fields.
    #[error("'{path}': '{field}' is a field of something that has none")]
    NotAStruct {
        /// The field path.
        path: String,
        /// The field asked for.
        field: String,
    },
    /// A field the message does not have.
    #[error("{type_name} has no field '{field}' (fields: {})", fields.join(", "))]
    NoField {
        /// The message type.
        type_name: String,
        /// The field asked for.
        field: String,
        /// Its fields.
        fields: Vec<String>,
    },
    /// A single value was needed and the path names several.
    #[error("names more than one number: use min() or max(), or index it")]
    NotOneNumber,
    /// `min()`/`max()` of something that is not numbers.
    #[error("min()/max() need an array or a range of numbers")]
    NotNumbers,
    /// A channel query names something other than its command.
    #[error("a channel has '.command[.field]' and nothing else")]
    NotACommand,
    /// No channel of that name has been arbitrated.
    #[error("no channel '{channel}' has been arbitrated (channels: {})", channels.join(", "))]
    NoChannel {
        /// The channel asked for.
        channel: String,
        /// The channels arbitrated so far.
        channels: Vec<String>,
    },
}

/// A reference to a value of a skill's output, `skill.output[.field][index]`: the one parser
/// of such paths (value queries, monitor expressions).
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct OutputPath {
    /// As written.
    pub text: String,
    /// Skill instance.
    pub skill: String,
    /// Output port.
    pub output: String,
    /// Field path inside the message, for [`resolve`] (empty: the whole message).
    pub field: String,
}

impl OutputPath {
    /// Splits `text` into skill, output and field path. The field path is not checked here:
    /// that needs the output's schema ([`resolve`]).
    pub fn parse(text: &str) -> Result<OutputPath, PathError> {
        let text = text.trim();
        let bad = || PathError::NotAnOutputPath {
            text: text.to_string(),
        };
        let (skill, rest) = text.split_once('.').ok_or_else(bad)?;
        let split = rest.find(['.', '[']).unwrap_or(rest.len());
        let (output, field) = (&rest[..split], &rest[split..]);
        if skill.is_empty() || output.is_empty() {
            return Err(bad());
        }
        Ok(OutputPath {
            text: text.to_string(),
            skill: skill.to_string(),
            output: output.to_string(),
            field: field.strip_prefix('.').unwrap_or(field).to_string(),
        })
    }
}

/// A path resolved against a schema: where the value is and what it is.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldPath {
    /// Byte offset of the first element.
    pub offset: usize,
    /// Kind of one element.
    pub kind: FieldKind,
    /// Number of consecutive elements (a range `[a..b]` of an array), or `None` for one.
    pub count: Option<usize>,
}

impl FieldPath {
    /// Reads the value from message bytes (an array for a range).
    pub fn read(&self, bytes: &[u8]) -> Option<Value> {
        let start = bytes.get(self.offset..)?;
        match self.count {
            None => decode(&self.kind, start),
            Some(n) => {
                let step = kind_size(&self.kind);
                (0..n)
                    .map(|i| decode(&self.kind, start.get(i * step..)?))
                    .collect::<Option<Vec<_>>>()
                    .map(Value::Array)
            }
        }
    }
}

/// Resolves `path` (e.g. `range[3]`, `pose.x`, `range[0..3]`, `range[0..=2]`, or empty for
/// the whole message) inside `schema`.
pub fn resolve(schema: &MessageSchema, path: &str) -> Result<FieldPath, PathError> {
    let mut kind = FieldKind::Struct(schema.clone());
    let mut offset = 0usize;
    let mut count = None;
    let mut rest = path.trim();
    while !rest.is_empty() {
        if count.is_some() {
            return Err(PathError::AfterRange { path: path.into() });
        }
        if let Some(r) = rest.strip_prefix('[') {
            let end = r
                .find(']')
                .ok_or_else(|| PathError::UnclosedIndex { path: path.into() })?;
            let inside = r[..end].trim();
            rest = &r[end + 1..];
            let FieldKind::Array { elem, len } = kind else {
                return Err(PathError::NotAnArray {
                    path: path.into(),
                    index: inside.into(),
                });
            };
            let num = |s: &str| {
                s.trim()
                    .parse::<usize>()
                    .map_err(|_| PathError::NotAnIndex {
                        path: path.into(),
                        index: s.trim().into(),
                    })
            };
            let (a, b) = if let Some((a, b)) = inside.split_once("..=") {
                (num(a)?, num(b)? + 1)
            } else if let Some((a, b)) = inside.split_once("..") {
                (num(a)?, num(b)?)
            } else {
                let i = num(inside)?;
                (i, i + 1)
            };
            if a >= b || b > len as usize {
                return Err(PathError::OutOfBounds {
                    path: path.into(),
                    index: inside.into(),
                    len,
                });
            }
            offset += a * kind_size(&elem);
            if inside.contains("..") {
                count = Some(b - a);
            }
            kind = *elem;
        } else {
            let r = rest.strip_prefix('.').unwrap_or(rest);
            let end = r.find(['.', '[']).unwrap_or(r.len());
            let name = &r[..end];
            rest = &r[end..];
            let FieldKind::Struct(s) = &kind else {
                return Err(PathError::NotAStruct {
                    path: path.into(),
                    field: name.into(),
                });
            };
            let f = s
                .fields
                .iter()
                .find(|f| f.name == name)
                .ok_or_else(|| PathError::NoField {
                    type_name: s.type_name.clone(),
                    field: name.into(),
                    fields: s.fields.iter().map(|f| f.name.clone()).collect(),
                })?;
            offset += f.offset as usize;
            kind = f.ty.clone();
        }
    }
    Ok(FieldPath {
        offset,
        kind,
        count,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Message;
    use skill_sdk_macros::Message;

    #[derive(Message, Debug, Clone, Copy, Default)]
    #[message(crate = "crate")]
    #[repr(C)]
    struct Inner {
        x: f32,
        ok: bool,
    }
    #[derive(Message, Debug, Clone, Copy, Default)]
    #[message(crate = "crate")]
    #[repr(C)]
    struct Outer {
        id: u16,
        range: [f64; 4],
        inner: Inner,
        grid: [[i8; 2]; 2],
    }

    fn bytes<T: Copy>(v: &T) -> Vec<u8> {
        // SAFETY: reading the bytes of a POD value for a test.
        unsafe {
            std::slice::from_raw_parts((v as *const T).cast::<u8>(), std::mem::size_of::<T>())
                .to_vec()
        }
    }

    #[test]
    fn output_paths_split_into_skill_output_and_field() {
        let p = |t: &str| OutputPath::parse(t).map(|p| (p.skill, p.output, p.field));
        let own = |a: &str, b: &str, c: &str| Ok((a.to_string(), b.to_string(), c.to_string()));
        assert_eq!(p("denning.sonar"), own("denning", "sonar", ""));
        assert_eq!(
            p("denning.sonar.range[3]"),
            own("denning", "sonar", "range[3]")
        );
        assert_eq!(p("cam.image[0..3]"), own("cam", "image", "[0..3]"));
        assert_eq!(p(" a.b[1].x.y "), own("a", "b", "[1].x.y"));
        for bad in ["", "denning", ".sonar", "denning.", "denning.[0]"] {
            assert!(p(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn paths_read_the_right_bytes() {
        let v = Outer {
            id: 7,
            range: [0.5, 1.5, 2.5, 3.5],
            inner: Inner { x: -2.0, ok: true },
            grid: [[1, -2], [3, -4]],
        };
        let b = bytes(&v);
        let s = Outer::schema();
        let read = |p: &str| resolve(&s, p).unwrap().read(&b).unwrap();
        assert_eq!(read("id"), Value::UInt(7));
        assert_eq!(read("range[2]"), Value::Float(2.5));
        assert_eq!(
            read("range[1..3]"),
            Value::Array(vec![Value::Float(1.5), Value::Float(2.5)])
        );
        assert_eq!(read("range[0..=1]").numbers(), vec![0.5, 1.5]);
        assert_eq!(read("inner.x"), Value::Float(-2.0));
        assert_eq!(read("inner.ok"), Value::Bool(true));
        assert_eq!(read("grid[1][1]"), Value::Int(-4));
        assert_eq!(
            read("").to_string(),
            r#"{"id": 7, "range": [0.5, 1.5, 2.5, 3.5], "inner": {"x": -2, "ok": true}, "grid": [[1, -2], [3, -4]]}"#
        );
    }

    #[test]
    fn bad_paths_say_why_as_values_a_client_can_match() {
        let s = Outer::schema();
        let e = |p: &str| resolve(&s, p).unwrap_err();
        assert!(matches!(e("nope"), PathError::NoField { field, .. } if field == "nope"));
        assert!(e("nope").to_string().contains("no field 'nope'"));
        assert!(matches!(
            e("range[4]"),
            PathError::OutOfBounds { len: 4, .. }
        ));
        assert!(matches!(e("id[0]"), PathError::NotAnArray { .. }));
        assert!(matches!(e("range[x]"), PathError::NotAnIndex { index, .. } if index == "x"));
        assert!(matches!(e("range[0..2].y"), PathError::AfterRange { .. }));
        assert!(e("range[1").to_string().contains("missing ']'"));
        // On the wire and back, unchanged.
        let err = e("nope");
        let bytes = postcard::to_allocvec(&err).unwrap();
        assert_eq!(postcard::from_bytes::<PathError>(&bytes).unwrap(), err);
    }

    #[test]
    fn short_bytes_decode_to_none() {
        assert_eq!(decode_message(&Outer::schema(), &[0u8; 3]), None);
    }

    #[test]
    fn decoded_values_convert_back_to_their_rust_types() {
        let v = Outer {
            id: 7,
            range: [0.5, 1.5, 2.5, 3.5],
            inner: Inner { x: -2.0, ok: true },
            grid: [[1, -2], [3, -4]],
        };
        let decoded = decode_message(&Outer::schema(), &bytes(&v)).unwrap();
        let back = Outer::from_value(&decoded).unwrap();
        assert_eq!(format!("{back:?}"), format!("{v:?}"));
        let read = |p: &str| {
            resolve(&Outer::schema(), p)
                .unwrap()
                .read(&bytes(&v))
                .unwrap()
        };
        assert_eq!(f32::from_value(&read("inner.x")), Some(-2.0));
        assert_eq!(<[i8; 2]>::from_value(&read("grid[1]")), Some([3, -4]));
    }

    #[test]
    fn a_value_of_another_kind_does_not_convert() {
        // The kinds must match: no float from an integer, no unsigned from a signed.
        assert_eq!(f64::from_value(&Value::Int(1)), None);
        assert_eq!(u8::from_value(&Value::Int(1)), None);
        assert_eq!(u8::from_value(&Value::UInt(300)), None);
        assert_eq!(i64::from_value(&Value::Int(-3)), Some(-3));
        assert_eq!(bool::from_value(&Value::UInt(1)), None);
        assert_eq!(
            <[u8; 2]>::from_value(&Value::Array(vec![Value::UInt(1)])),
            None
        );
        // A message from a struct lacking one of its fields.
        let partial = Value::Struct(vec![("x".into(), Value::Float(1.0))]);
        assert!(Inner::from_value(&partial).is_none());
    }
}
