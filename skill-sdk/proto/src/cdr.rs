//! Samples as CDR, the encoding of ROS 2 (and DDS): what a recording writes, so the ROS
//! tools (Foxglove, `mcap`'s ROS 2 support, rosbag2) decode it with the ros2msg schema of
//! [`crate::ros2msg`].
//!
//! The encoding is XCDR1 little-endian (`CDR_LE`): a 4-byte encapsulation header
//! `00 01 00 00`, then the message's primitive fields in declaration order, each aligned to its
//! size (at most 8) counted from the end of the header; a nested message is its fields, in
//! place; a fixed-length array is its elements, with no length in front; a bool is one byte.
//! The repr(C) layout and CDR differ only in where padding goes, so a sample's bytes survive
//! the round trip [`encode`] → [`decode`] exactly — NaN payloads, infinities, the sign of a zero
//! — except for the padding between fields, which comes back as zeros.

use crate::schema::{FieldKind, MessageSchema, Prim};

/// The encapsulation header of little-endian plain CDR (`CDR_LE`, options 0).
const HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Why CDR bytes cannot be read back into a sample.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum CdrError {
    /// The bytes do not start with the little-endian CDR encapsulation header.
    #[error("not little-endian CDR: the encapsulation header is {found:02x?}, not 00 01 00 00")]
    Header {
        /// The first bytes found (up to four).
        found: Vec<u8>,
    },
    /// The bytes end before the message does.
    #[error("CDR of {type_name} is cut short: {len} bytes, field '{field}' needs {needed}")]
    Truncated {
        /// The message type.
        type_name: String,
        /// The field that did not fit (a path: `range[3]`, `at.x`).
        field: String,
        /// The bytes needed up to the end of that field (header included).
        needed: usize,
        /// The bytes given.
        len: usize,
    },
    /// More bytes follow the message than the alignment padding a writer may add (3 at most).
    #[error("CDR of {type_name} has {extra} bytes after the message")]
    Trailing {
        /// The message type.
        type_name: String,
        /// Bytes after the message's last field.
        extra: usize,
    },
    /// The schema places a field outside the message's size (a schema that does not describe
    /// a repr(C) type).
    #[error("schema of {type_name}: field '{field}' lies outside its {size} bytes")]
    Layout {
        /// The message type.
        type_name: String,
        /// The field.
        field: String,
        /// The message's size.
        size: u32,
    },
}

/// Appends the CDR (XCDR1, little-endian, with the 4-byte encapsulation header 00 01 00 00)
/// encoding of the sample `bytes` (the repr(C) layout described by `schema`).
///
/// `bytes` is a whole sample (`schema.size` bytes, as a topic carries it); a field that lies
/// beyond a shorter slice is encoded as zeros.
pub fn encode(schema: &MessageSchema, bytes: &[u8], out: &mut Vec<u8>) {
    out.extend_from_slice(&HEADER);
    let mut w = Writer {
        out,
        origin: 0,
        src: bytes,
    };
    w.origin = w.out.len();
    w.fields(schema, 0);
}

/// The repr(C) bytes of a sample back from its CDR encoding (padding zeroed); error on
/// short/garbage input.
pub fn decode(schema: &MessageSchema, cdr: &[u8]) -> Result<Vec<u8>, CdrError> {
    if cdr.get(..2) != Some(&HEADER[..2]) {
        return Err(CdrError::Header {
            found: cdr.iter().take(4).copied().collect(),
        });
    }
    if cdr.len() < HEADER.len() {
        return Err(CdrError::Truncated {
            type_name: schema.type_name.clone(),
            field: "(header)".into(),
            needed: HEADER.len(),
            len: cdr.len(),
        });
    }
    let mut r = Reader {
        cdr: &cdr[HEADER.len()..],
        at: 0,
        out: vec![0; schema.size as usize],
        top: schema,
    };
    r.fields(schema, 0, "")?;
    let extra = r.cdr.len() - r.at;
    // Writers may pad the message to a multiple of 4 (what XCDR1's options field counts).
    if extra > 3 {
        return Err(CdrError::Trailing {
            type_name: schema.type_name.clone(),
            extra,
        });
    }
    Ok(r.out)
}

/// Where a CDR encoding is appended.
struct Writer<'a> {
    out: &'a mut Vec<u8>,
    /// Where the message starts in `out` (after the header): CDR aligns relative to it.
    origin: usize,
    /// The sample.
    src: &'a [u8],
}

impl Writer<'_> {
    fn align(&mut self, size: usize) {
        let pos = self.out.len() - self.origin;
        let pad = (size - pos % size) % size;
        self.out.resize(self.out.len() + pad, 0);
    }

    fn fields(&mut self, m: &MessageSchema, base: usize) {
        for f in &m.fields {
            self.kind(&f.ty, base + f.offset as usize);
        }
    }

    /// `count` primitives of one kind, contiguous in the sample from `at`.
    fn prims(&mut self, p: Prim, at: usize, count: usize) {
        let size = p.size();
        self.align(size);
        let end = at + size * count;
        match self.src.get(at..end) {
            Some(b) => put(self.out, b, size),
            None => {
                // Short input: what there is, then zeros (documented on `encode`).
                let mut whole = self.src.get(at..).unwrap_or(&[]).to_vec();
                whole.resize(size * count, 0);
                put(self.out, &whole, size);
            }
        }
    }

    fn kind(&mut self, k: &FieldKind, at: usize) {
        match k {
            FieldKind::Prim(p) => self.prims(*p, at, 1),
            FieldKind::Array { elem, len } => match elem.as_ref() {
                FieldKind::Prim(p) => self.prims(*p, at, *len as usize),
                other => {
                    let stride = kind_size(other);
                    for i in 0..*len as usize {
                        self.kind(other, at + i * stride);
                    }
                }
            },
            FieldKind::Struct(m) => self.fields(m, at),
        }
    }
}

/// Appends primitives of `size` bytes each, from host order to little-endian.
fn put(out: &mut Vec<u8>, b: &[u8], size: usize) {
    if cfg!(target_endian = "little") {
        // CDR_LE on a little-endian host: the sample's bytes as they are.
        out.extend_from_slice(b);
    } else {
        for e in b.chunks_exact(size) {
            out.extend(e.iter().rev());
        }
    }
}

/// A CDR encoding being read into a sample.
struct Reader<'a> {
    /// The bytes after the header.
    cdr: &'a [u8],
    /// Read position in `cdr`.
    at: usize,
    /// The sample, zeroed where no field is.
    out: Vec<u8>,
    /// The top-level message (for errors).
    top: &'a MessageSchema,
}

impl Reader<'_> {
    fn fields(&mut self, m: &MessageSchema, base: usize, path: &str) -> Result<(), CdrError> {
        for f in &m.fields {
            let p = if path.is_empty() {
                f.name.clone()
            } else {
                format!("{path}.{}", f.name)
            };
            self.kind(&f.ty, base + f.offset as usize, &p)?;
        }
        Ok(())
    }

    fn prims(&mut self, p: Prim, to: usize, count: usize, path: &str) -> Result<(), CdrError> {
        let size = p.size();
        let start = self.at + (size - self.at % size) % size;
        let end = start + size * count;
        let Some(b) = self.cdr.get(start..end) else {
            return Err(CdrError::Truncated {
                type_name: self.top.type_name.clone(),
                field: path.to_string(),
                needed: HEADER.len() + end,
                len: HEADER.len() + self.cdr.len(),
            });
        };
        let Some(dst) = self.out.get_mut(to..to + size * count) else {
            return Err(CdrError::Layout {
                type_name: self.top.type_name.clone(),
                field: path.to_string(),
                size: self.top.size,
            });
        };
        if cfg!(target_endian = "little") {
            dst.copy_from_slice(b);
        } else {
            for (d, s) in dst.chunks_exact_mut(size).zip(b.chunks_exact(size)) {
                d.iter_mut().zip(s.iter().rev()).for_each(|(d, s)| *d = *s);
            }
        }
        self.at = end;
        Ok(())
    }

    fn kind(&mut self, k: &FieldKind, to: usize, path: &str) -> Result<(), CdrError> {
        match k {
            FieldKind::Prim(p) => self.prims(*p, to, 1, path),
            FieldKind::Array { elem, len } => match elem.as_ref() {
                FieldKind::Prim(p) => self.prims(*p, to, *len as usize, path),
                other => {
                    let stride = kind_size(other);
                    for i in 0..*len as usize {
                        self.kind(other, to + i * stride, &format!("{path}[{i}]"))?;
                    }
                    Ok(())
                }
            },
            FieldKind::Struct(m) => self.fields(m, to, path),
        }
    }
}

/// Size of a field kind in the repr(C) layout (an array's stride is its element's size).
fn kind_size(k: &FieldKind) -> usize {
    match k {
        FieldKind::Prim(p) => p.size(),
        FieldKind::Array { elem, len } => kind_size(elem) * *len as usize,
        FieldKind::Struct(m) => m.size as usize,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schema::FieldSchema;
    use proptest::prelude::*;

    fn field(name: &str, offset: u32, ty: FieldKind) -> FieldSchema {
        FieldSchema {
            name: name.into(),
            offset,
            ty,
        }
    }

    /// `skillfab.Door`'s layout: a bool, seven bytes of padding, four f64.
    fn door() -> MessageSchema {
        let f64_ = || FieldKind::Prim(Prim::F64);
        MessageSchema {
            type_name: "skillfab.Door".into(),
            doc: String::new(),
            size: 40,
            align: 8,
            fields: vec![
                field("found", 0, FieldKind::Prim(Prim::Bool)),
                field("x", 8, f64_()),
                field("y", 16, f64_()),
                field("heading", 24, f64_()),
                field("width", 32, f64_()),
            ],
        }
    }

    /// A test package's grasp: an f64, a nested message of u8 + f32 (padding inside), a bool
    /// array, then an array of that nested message.
    fn grasp() -> MessageSchema {
        let finger = MessageSchema {
            type_name: "test_pkg.Finger".into(),
            doc: String::new(),
            size: 8,
            align: 4,
            fields: vec![
                field("id", 0, FieldKind::Prim(Prim::U8)),
                field("force", 4, FieldKind::Prim(Prim::F32)),
            ],
        };
        MessageSchema {
            type_name: "test_pkg.Grasp".into(),
            doc: String::new(),
            size: 40,
            align: 8,
            fields: vec![
                field("width", 0, FieldKind::Prim(Prim::F64)),
                field("at", 8, FieldKind::Struct(finger.clone())),
                field(
                    "closed",
                    16,
                    FieldKind::Array {
                        elem: Box::new(FieldKind::Prim(Prim::Bool)),
                        len: 3,
                    },
                ),
                field(
                    "fingers",
                    20,
                    FieldKind::Array {
                        elem: Box::new(FieldKind::Struct(finger)),
                        len: 2,
                    },
                ),
            ],
        }
    }

    fn door_bytes(found: bool, xs: [f64; 4]) -> Vec<u8> {
        let mut b = vec![0u8; 40];
        b[0] = u8::from(found);
        for (i, x) in xs.iter().enumerate() {
            b[8 + 8 * i..16 + 8 * i].copy_from_slice(&x.to_ne_bytes());
        }
        b
    }

    #[test]
    fn fields_are_aligned_from_the_end_of_the_header() {
        let mut out = vec![0xaa];
        encode(&door(), &door_bytes(true, [1.0, 2.0, 3.0, 4.0]), &mut out);
        // What was there stays; the header; `found`; 7 bytes to align x at 8 after the header.
        assert_eq!(out[..9], [0xaa, 0, 1, 0, 0, 1, 0, 0, 0]);
        assert_eq!(out[9..13], [0, 0, 0, 0]);
        assert_eq!(out[13..21], 1.0f64.to_le_bytes());
        assert_eq!(out.len(), 1 + 4 + 40);
    }

    #[test]
    fn nested_messages_and_arrays_are_inline_with_no_length() {
        let mut b = vec![0u8; 40];
        b[..8].copy_from_slice(&0.5f64.to_ne_bytes());
        b[8] = 7;
        b[12..16].copy_from_slice(&1.5f32.to_ne_bytes());
        b[16..19].copy_from_slice(&[1, 0, 1]);
        b[20] = 1;
        b[24..28].copy_from_slice(&2.5f32.to_ne_bytes());
        b[28] = 2;
        b[32..36].copy_from_slice(&3.5f32.to_ne_bytes());
        let mut out = Vec::new();
        encode(&grasp(), &b, &mut out);
        let mut want = HEADER.to_vec();
        want.extend(0.5f64.to_le_bytes()); // width at 0
        want.push(7); // at.id at 8
        want.extend([0, 0, 0]);
        want.extend(1.5f32.to_le_bytes()); // at.force at 12
        want.extend([1, 0, 1]); // closed at 16..19
        want.push(1); // fingers[0].id at 19: a u8 needs no alignment
        want.extend(2.5f32.to_le_bytes()); // fingers[0].force at 20
        want.push(2); // fingers[1].id at 24
        want.extend([0, 0, 0]);
        want.extend(3.5f32.to_le_bytes()); // at 28
        assert_eq!(out, want);
        assert_eq!(decode(&grasp(), &out).unwrap(), b);
    }

    #[test]
    fn float_bits_and_values_survive_padding_does_not() {
        let quiet_nan_with_payload = f64::from_bits(0x7ff8_0000_dead_beef);
        let mut b = door_bytes(
            true,
            [
                quiet_nan_with_payload,
                f64::INFINITY,
                -0.0,
                f64::NEG_INFINITY,
            ],
        );
        let clean = b.clone();
        b[1..8].copy_from_slice(&[0x66, 0xc4, 0x33, 0xef, 0x55, 1, 2]);
        let mut out = Vec::new();
        encode(&door(), &b, &mut out);
        let back = decode(&door(), &out).unwrap();
        assert_eq!(back, clean);
        assert_eq!(
            f64::from_ne_bytes(back[8..16].try_into().unwrap()).to_bits(),
            0x7ff8_0000_dead_beef
        );
    }

    #[test]
    fn cut_or_foreign_bytes_are_refused_with_what_is_wrong() {
        let mut out = Vec::new();
        encode(&door(), &door_bytes(false, [1.0; 4]), &mut out);
        let e = decode(&door(), &out[..out.len() - 1]).unwrap_err();
        assert_eq!(
            e,
            CdrError::Truncated {
                type_name: "skillfab.Door".into(),
                field: "width".into(),
                needed: 44,
                len: 43
            }
        );
        assert!(e.to_string().contains("width"), "{e}");
        assert!(matches!(
            decode(&door(), &out[..3]),
            Err(CdrError::Truncated { .. })
        ));
        let mut big_endian = out.clone();
        big_endian[1] = 0;
        assert!(matches!(
            decode(&door(), &big_endian),
            Err(CdrError::Header { .. })
        ));
        assert!(matches!(
            decode(&door(), b"{\"x\":1}"),
            Err(CdrError::Header { .. })
        ));
        assert!(matches!(decode(&door(), &[]), Err(CdrError::Header { .. })));
        // Padding to a multiple of 4 is a writer's right; more is not this message.
        let mut padded = out.clone();
        padded.extend([0, 0, 0]);
        assert!(decode(&door(), &padded).is_ok());
        padded.push(0);
        assert_eq!(
            decode(&door(), &padded),
            Err(CdrError::Trailing {
                type_name: "skillfab.Door".into(),
                extra: 4
            })
        );
    }

    #[test]
    fn a_schema_that_is_not_a_layout_is_refused_not_a_panic() {
        let mut bad = door();
        bad.size = 16;
        let mut out = Vec::new();
        encode(&door(), &door_bytes(true, [1.0; 4]), &mut out);
        assert!(matches!(
            decode(&bad, &out),
            Err(CdrError::Layout { ref field, .. }) if field == "y"
        ));
    }

    #[test]
    fn a_short_sample_is_encoded_as_if_zero_extended() {
        let mut short = Vec::new();
        encode(&door(), &door_bytes(true, [1.0; 4])[..12], &mut short);
        let mut whole = door_bytes(true, [0.0; 4]);
        whole[8..12].copy_from_slice(&1.0f64.to_ne_bytes()[..4]);
        let mut want = Vec::new();
        encode(&door(), &whole, &mut want);
        assert_eq!(short, want);
    }

    /// The padding of the test schemas' layouts (the bytes no field covers).
    fn padding(m: &MessageSchema) -> Vec<bool> {
        fn mark(k: &FieldKind, at: usize, used: &mut [bool]) {
            match k {
                FieldKind::Prim(p) => used[at..at + p.size()].fill(true),
                FieldKind::Array { elem, len } => {
                    for i in 0..*len as usize {
                        mark(elem, at + i * kind_size(elem), used);
                    }
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

    proptest! {
        #[test]
        fn any_bytes_round_trip_but_their_padding(
            door_b in proptest::collection::vec(any::<u8>(), 40),
            grasp_b in proptest::collection::vec(any::<u8>(), 40),
        ) {
            for (m, b) in [(door(), door_b), (grasp(), grasp_b)] {
                let mut out = Vec::new();
                encode(&m, &b, &mut out);
                let back = decode(&m, &out).unwrap();
                let want: Vec<u8> = b
                    .iter()
                    .zip(padding(&m))
                    .map(|(x, pad)| if pad { 0 } else { *x })
                    .collect();
                prop_assert_eq!(back, want);
            }
        }
    }
}
