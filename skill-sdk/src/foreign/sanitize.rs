//! Bools written by C: any non-zero byte, where Rust readers of a message may see only 0 or 1.

use crate::schema::{FieldKind, MessageSchema, Prim};

/// Replaces every bool byte that is not 0 or 1 with 1: C may store any non-zero value in a
/// `bool`, Rust readers of the message may not see one.
pub fn sanitize_bools(kind: &FieldKind, bytes: &mut [u8]) {
    match kind {
        FieldKind::Prim(Prim::Bool) => {
            if let Some(b) = bytes.first_mut()
                && *b > 1
            {
                *b = 1;
            }
        }
        FieldKind::Prim(_) => {}
        FieldKind::Array { elem, len } => {
            let size = crate::value::kind_size(elem);
            if !contains_bool(elem) || size == 0 {
                return;
            }
            for i in 0..*len as usize {
                if let Some(chunk) = bytes.get_mut(i * size..(i + 1) * size) {
                    sanitize_bools(elem, chunk);
                }
            }
        }
        FieldKind::Struct(s) => sanitize_message(s, bytes),
    }
}

/// [`sanitize_bools`] over a whole message.
pub fn sanitize_message(schema: &MessageSchema, bytes: &mut [u8]) {
    for f in &schema.fields {
        if let Some(rest) = bytes.get_mut(f.offset as usize..) {
            sanitize_bools(&f.ty, rest);
        }
    }
}

pub(super) fn contains_bool(kind: &FieldKind) -> bool {
    match kind {
        FieldKind::Prim(p) => *p == Prim::Bool,
        FieldKind::Array { elem, .. } => contains_bool(elem),
        FieldKind::Struct(s) => s.fields.iter().any(|f| contains_bool(&f.ty)),
    }
}
