//! Run-time description of message layouts.
//!
//! Every [`Message`](crate::Message) carries a [`MessageSchema`]: field names, kinds and byte
//! offsets. The manager uses it to check wiring (and, later, to evaluate monitors and decode
//! values for queries and the console) without knowing the Rust type.

use serde::{Deserialize, Serialize};

/// A primitive field type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Prim {
    /// A 8-bit unsigned integer (`u8`).
    U8,
    /// A 16-bit unsigned integer (`u16`).
    U16,
    /// A 32-bit unsigned integer (`u32`).
    U32,
    /// A 64-bit unsigned integer (`u64`).
    U64,
    /// A 8-bit signed integer (`i8`).
    I8,
    /// A 16-bit signed integer (`i16`).
    I16,
    /// A 32-bit signed integer (`i32`).
    I32,
    /// A 64-bit signed integer (`i64`).
    I64,
    /// A 32-bit IEEE 754 float (`f32`).
    F32,
    /// A 64-bit IEEE 754 float (`f64`).
    F64,
    /// One byte, 0 or 1 (`bool`).
    Bool,
}

impl Prim {
    /// Size in bytes.
    pub fn size(self) -> usize {
        match self {
            Prim::U8 | Prim::I8 | Prim::Bool => 1,
            Prim::U16 | Prim::I16 => 2,
            Prim::U32 | Prim::I32 | Prim::F32 => 4,
            Prim::U64 | Prim::I64 | Prim::F64 => 8,
        }
    }
}

/// What a field holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum FieldKind {
    /// One primitive value.
    Prim(Prim),
    /// A fixed-length array.
    Array {
        /// Element kind.
        elem: Box<FieldKind>,
        /// Number of elements.
        len: u32,
    },
    /// A nested message.
    Struct(MessageSchema),
}

/// One named field at a byte offset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FieldSchema {
    /// Field name as written in the Rust struct.
    pub name: String,
    /// Byte offset from the start of the message.
    pub offset: u32,
    /// What the field holds.
    pub ty: FieldKind,
}

/// The layout of a `#[repr(C)]` message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MessageSchema {
    /// The type name shared by every process and language (also iceoryx2's type name).
    pub type_name: String,
    /// The doc comment of the type.
    pub doc: String,
    /// `size_of` in bytes.
    pub size: u32,
    /// `align_of` in bytes.
    pub align: u32,
    /// Fields in declaration order.
    pub fields: Vec<FieldSchema>,
}

/// A type that may appear as a message field.
///
/// # Safety
/// Implementors are plain old data: no pointers, a fixed layout, and every all-zero bit
/// pattern is a valid value (the SDK hands out zero-initialised output buffers).
pub unsafe trait FieldType: Copy + 'static {
    /// Describes the type.
    fn field_type() -> FieldKind;
}

macro_rules! prim {
    ($($t:ty => $p:ident),*) => {$(
        // SAFETY: primitive numbers and bool are POD and valid when zeroed.
        unsafe impl FieldType for $t {
            fn field_type() -> FieldKind { FieldKind::Prim(Prim::$p) }
        }
    )*};
}
prim!(u8 => U8, u16 => U16, u32 => U32, u64 => U64, i8 => I8, i16 => I16, i32 => I32,
      i64 => I64, f32 => F32, f64 => F64, bool => Bool);

// SAFETY: an array of POD is POD and valid when zeroed.
unsafe impl<T: FieldType, const N: usize> FieldType for [T; N] {
    fn field_type() -> FieldKind {
        FieldKind::Array {
            elem: Box::new(T::field_type()),
            len: N as u32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrays_nest() {
        let k = <[[f32; 3]; 2]>::field_type();
        assert_eq!(
            k,
            FieldKind::Array {
                elem: Box::new(FieldKind::Array {
                    elem: Box::new(FieldKind::Prim(Prim::F32)),
                    len: 3
                }),
                len: 2
            }
        );
    }
}
