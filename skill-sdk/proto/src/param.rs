//! Parameters on the wire: their kinds, values, declared specs (default, bounds, doc) and the
//! errors a change can meet. A skill's parameter struct (skill-sdk's `Params`) is declared
//! through these; the manager checks a change against the same specs.

use serde::{Deserialize, Serialize};
use std::fmt;

/// The type of a parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ParamKind {
    /// `true` or `false`.
    Bool,
    /// A signed 64-bit integer.
    Int,
    /// An unsigned 64-bit integer.
    UInt,
    /// A 64-bit float.
    Float,
}

impl fmt::Display for ParamKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ParamKind::Bool => "bool",
            ParamKind::Int => "integer",
            ParamKind::UInt => "unsigned integer",
            ParamKind::Float => "float",
        })
    }
}

/// A parameter value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum ParamValue {
    /// A [`ParamKind::Bool`] value.
    Bool(bool),
    /// A [`ParamKind::Int`] value.
    Int(i64),
    /// A [`ParamKind::UInt`] value.
    UInt(u64),
    /// A [`ParamKind::Float`] value.
    Float(f64),
}

impl ParamValue {
    /// Its kind.
    pub fn kind(&self) -> ParamKind {
        match self {
            ParamValue::Bool(_) => ParamKind::Bool,
            ParamValue::Int(_) => ParamKind::Int,
            ParamValue::UInt(_) => ParamKind::UInt,
            ParamValue::Float(_) => ParamKind::Float,
        }
    }

    /// This value converted to a parameter of `kind`, if it fits: integers to floats, and
    /// integers of the other signedness when in range.
    pub fn coerce(self, kind: ParamKind) -> Option<ParamValue> {
        use ParamKind as K;
        match (kind, self) {
            (K::Bool, ParamValue::Bool(_)) | (K::Float, ParamValue::Float(_)) => Some(self),
            (K::Float, ParamValue::Int(i)) => Some(ParamValue::Float(i as f64)),
            (K::Float, ParamValue::UInt(u)) => Some(ParamValue::Float(u as f64)),
            (K::Int, ParamValue::Int(_)) => Some(self),
            (K::Int, ParamValue::UInt(u)) => i64::try_from(u).ok().map(ParamValue::Int),
            (K::UInt, ParamValue::UInt(_)) => Some(self),
            (K::UInt, ParamValue::Int(i)) => u64::try_from(i).ok().map(ParamValue::UInt),
            _ => None,
        }
    }

    /// Parses text as a value of `kind`.
    pub fn parse(kind: ParamKind, text: &str) -> Option<ParamValue> {
        let t = text.trim();
        match kind {
            ParamKind::Bool => match t {
                "true" | "1" | "on" | "yes" => Some(ParamValue::Bool(true)),
                "false" | "0" | "off" | "no" => Some(ParamValue::Bool(false)),
                _ => None,
            },
            ParamKind::Int => t.parse().ok().map(ParamValue::Int),
            ParamKind::UInt => t.parse().ok().map(ParamValue::UInt),
            ParamKind::Float => t
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .map(ParamValue::Float),
        }
    }

    /// The value as f64, for bound checks.
    pub fn as_f64(&self) -> f64 {
        match *self {
            ParamValue::Bool(b) => f64::from(u8::from(b)),
            ParamValue::Int(v) => v as f64,
            ParamValue::UInt(v) => v as f64,
            ParamValue::Float(v) => v,
        }
    }
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamValue::Bool(v) => write!(f, "{v}"),
            ParamValue::Int(v) => write!(f, "{v}"),
            ParamValue::UInt(v) => write!(f, "{v}"),
            ParamValue::Float(v) => write!(f, "{v}"),
        }
    }
}

/// One declared parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamSpec {
    /// Field name.
    pub name: String,
    /// Value type.
    pub kind: ParamKind,
    /// Value when not set.
    pub default: ParamValue,
    /// Inclusive lower bound.
    pub min: Option<ParamValue>,
    /// Inclusive upper bound.
    pub max: Option<ParamValue>,
    /// The field's doc comment.
    pub doc: String,
}

/// Why a parameter value was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize, Deserialize)]
#[non_exhaustive]
pub enum ParamError {
    /// No parameter of that name.
    #[error("unknown parameter '{param}'")]
    Unknown {
        /// The name asked for.
        param: String,
    },
    /// The value has the wrong type.
    #[error("parameter '{param}' takes a {expected}, got '{got}'")]
    WrongType {
        /// Parameter name.
        param: String,
        /// Its type.
        expected: ParamKind,
        /// What was given.
        got: ParamValue,
    },
    /// Text that does not parse as the parameter's type.
    #[error("parameter '{param}' takes a {expected}, got '{text}'")]
    Unparsable {
        /// Parameter name.
        param: String,
        /// Its type.
        expected: ParamKind,
        /// The text given.
        text: String,
    },
    /// Outside the declared bounds.
    #[error("parameter '{param}' = {value} is out of range [{min}, {max}]")]
    OutOfRange {
        /// Parameter name.
        param: String,
        /// Value given.
        value: ParamValue,
        /// Lower bound (or "-inf").
        min: String,
        /// Upper bound (or "inf").
        max: String,
    },
    /// `name=value` expected.
    #[error("expected NAME=VALUE, got '{text}'")]
    Malformed {
        /// The text given.
        text: String,
    },
}

/// A value type a parameter field may have.
pub trait ParamType: Sized {
    /// Its kind.
    const KIND: ParamKind;
    /// To a value.
    fn to_value(&self) -> ParamValue;
    /// From a value of the right kind (integers convert if they fit).
    fn from_value(v: &ParamValue) -> Option<Self>;
}

impl ParamType for bool {
    const KIND: ParamKind = ParamKind::Bool;
    fn to_value(&self) -> ParamValue {
        ParamValue::Bool(*self)
    }
    fn from_value(v: &ParamValue) -> Option<Self> {
        match *v {
            ParamValue::Bool(b) => Some(b),
            _ => None,
        }
    }
}

macro_rules! float_param {
    ($($t:ty),*) => {$(
        impl ParamType for $t {
            const KIND: ParamKind = ParamKind::Float;
            fn to_value(&self) -> ParamValue { ParamValue::Float(f64::from(*self)) }
            fn from_value(v: &ParamValue) -> Option<Self> {
                match *v {
                    ParamValue::Float(f) => Some(f as $t),
                    ParamValue::Int(i) => Some(i as $t),
                    ParamValue::UInt(u) => Some(u as $t),
                    ParamValue::Bool(_) => None,
                }
            }
        }
    )*};
}
float_param!(f32, f64);

macro_rules! int_param {
    ($kind:ident, $variant:ident, $wide:ty; $($t:ty),*) => {$(
        impl ParamType for $t {
            const KIND: ParamKind = ParamKind::$kind;
            fn to_value(&self) -> ParamValue { ParamValue::$variant(<$wide>::from(*self)) }
            fn from_value(v: &ParamValue) -> Option<Self> {
                match *v {
                    ParamValue::Int(i) => <$t>::try_from(i).ok(),
                    ParamValue::UInt(u) => <$t>::try_from(u).ok(),
                    _ => None,
                }
            }
        }
    )*};
}
int_param!(Int, Int, i64; i8, i16, i32, i64);
int_param!(UInt, UInt, u64; u8, u16, u32, u64);

/// Checks `value` against the declared bounds of `spec`.
pub fn check_bounds(spec: &ParamSpec, value: ParamValue) -> Result<(), ParamError> {
    let v = value.as_f64();
    let below = spec.min.is_some_and(|m| v < m.as_f64());
    let above = spec.max.is_some_and(|m| v > m.as_f64());
    if below || above {
        let show = |b: Option<ParamValue>, inf: &str| b.map_or(inf.to_string(), |b| b.to_string());
        return Err(ParamError::OutOfRange {
            param: spec.name.clone(),
            value,
            min: show(spec.min, "-inf"),
            max: show(spec.max, "inf"),
        });
    }
    Ok(())
}
