//! Message files: skillfab's message types declared once, in the spirit of ROS `.msg` files,
//! and generated for every language (docs/messages.md).
//!
//! A **package** is a directory named after it (`skillfab`, `my_robot`) holding one file per
//! type, `<Name>.msg`; the type's full name is `<package>.<Name>`. A file:
//!
//! ```text
//! # A planar pose in the odometry frame.        <- leading comments: the type's doc
//! # (more lines of doc)
//!
//! f64 x          # m                              <- TYPE NAME, an optional trailing doc
//! f64 y          # m
//! f64[3] cov     # a fixed-size array; [3][3] for two dimensions
//! skillfab.Odometry odom   # a type of another package (or `Name` of this one)
//! ```
//!
//! Types: `bool u8 u16 u32 u64 i8 i16 i32 i64 f32 f64`, message types by name, fixed-size
//! arrays of any of them. The layout is C's (`#[repr(C)]`): fields in order, each aligned to
//! its type. A wrong file is refused with its path and line.
//!
//! This crate has no dependencies, so a skill's build script can use it
//! ([`rust_module`]) to turn its own package into Rust types.

#![warn(missing_docs)]

use std::fmt;
use std::path::PathBuf;

/// A primitive field type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Prim {
    /// One byte, 0 or 1 (`bool`).
    Bool,
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
}

impl Prim {
    const ALL: [(&'static str, Prim); 11] = [
        ("bool", Prim::Bool),
        ("u8", Prim::U8),
        ("u16", Prim::U16),
        ("u32", Prim::U32),
        ("u64", Prim::U64),
        ("i8", Prim::I8),
        ("i16", Prim::I16),
        ("i32", Prim::I32),
        ("i64", Prim::I64),
        ("f32", Prim::F32),
        ("f64", Prim::F64),
    ];

    /// The name in a message file (and in Rust).
    pub fn name(self) -> &'static str {
        Prim::ALL
            .iter()
            .find(|(_, p)| *p == self)
            .map_or("?", |(n, _)| n)
    }

    /// Size (and alignment) in bytes.
    pub fn size(self) -> u32 {
        match self {
            Prim::Bool | Prim::U8 | Prim::I8 => 1,
            Prim::U16 | Prim::I16 => 2,
            Prim::U32 | Prim::I32 | Prim::F32 => 4,
            Prim::U64 | Prim::I64 | Prim::F64 => 8,
        }
    }
}

/// What a field's elements are.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Base {
    /// A primitive.
    Prim(Prim),
    /// A message type, by full name (`package.Name`).
    Named(String),
}

/// A field's type: a base and array dimensions (outermost first; empty: a single value).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldTy {
    /// The element type.
    pub base: Base,
    /// Array dimensions, outermost first.
    pub dims: Vec<u32>,
}

/// One field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    /// Its name.
    pub name: String,
    /// Its type.
    pub ty: FieldTy,
    /// Its doc (the trailing comment).
    pub doc: String,
    /// The line it is declared on.
    pub line: usize,
}

/// One message type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MsgType {
    /// Package.
    pub package: String,
    /// Name within the package.
    pub name: String,
    /// Doc (the leading comments, lines joined by spaces).
    pub doc: String,
    /// Fields in order.
    pub fields: Vec<Field>,
    /// The file it came from.
    pub file: PathBuf,
}

impl MsgType {
    /// `package.Name`.
    pub fn type_name(&self) -> String {
        format!("{}.{}", self.package, self.name)
    }
}

/// A package of message types.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Package {
    /// Its name (the directory's).
    pub name: String,
    /// The directory.
    pub dir: PathBuf,
    /// Its types, by name.
    pub types: Vec<MsgType>,
}

/// A refused message file: where and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Error {
    /// The file (or directory).
    pub file: PathBuf,
    /// The line (0: the file as a whole).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line > 0 {
            write!(f, "{}:{}: {}", self.file.display(), self.line, self.message)
        } else {
            write!(f, "{}: {}", self.file.display(), self.message)
        }
    }
}

impl std::error::Error for Error {}

mod catalog;
mod parse;
mod rust;

pub use catalog::{Catalog, Layout};
pub use parse::{load_package, load_path, package_name_ok, parse, type_name_ok};
pub use rust::{build, rust_module};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rust::rust_type;
    use std::path::Path;

    fn parse_ok(text: &str) -> MsgType {
        parse(text, Path::new("pkg/Pose.msg"), "pkg").unwrap()
    }

    #[test]
    fn a_file_gives_its_doc_fields_and_arrays() {
        let t = parse_ok(
            "# A pose.\n# Two lines.\n\n# a note\nf64 x # metres\nf64[3][2] cov\nskillfab/Odometry odom\nInner i\n",
        );
        assert_eq!(t.type_name(), "pkg.Pose");
        assert_eq!(t.doc, "A pose. Two lines.");
        assert_eq!(t.fields.len(), 4);
        assert_eq!(t.fields[0].doc, "metres");
        assert_eq!(t.fields[1].ty.dims, vec![3, 2]);
        assert_eq!(t.fields[2].ty.base, Base::Named("skillfab.Odometry".into()));
        assert_eq!(t.fields[3].ty.base, Base::Named("pkg.Inner".into()));
        assert_eq!(rust_type(&t.fields[1].ty, "pkg"), "[[f64; 2]; 3]");
        assert_eq!(
            rust_type(&t.fields[2].ty, "pkg"),
            "::skillfab_msgs::Odometry"
        );
    }

    #[test]
    fn wrong_files_are_refused_with_file_and_line() {
        let e = |text: &str| {
            parse(text, Path::new("pkg/Pose.msg"), "pkg")
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            e("f64 x\nf65 y\n"),
            "pkg/Pose.msg:2: unknown type 'f65' (a primitive: bool u8 u16 u32 u64 i8 i16 i32 i64 f32 f64; or a message type: Name, package.Name)"
        );
        assert!(e("f64 x y\n").starts_with("pkg/Pose.msg:1: expected 'TYPE NAME"));
        assert!(e("f64 type\n").contains(":1: 'type' cannot name a field"));
        assert!(e("f64 x\nf64 x\n").contains(":2: field 'x' is declared twice"));
        assert!(e("f64[0] x\n").contains(":1: 'f64[0]': an array length"));
        assert!(e("f64[3 x\n").contains(":1: 'f64[3': an array is TYPE[N]"));
        assert!(e("# only a doc\n").contains("at least one field"));
        let bad = parse("f64 x\n", Path::new("pkg/pose.msg"), "pkg").unwrap_err();
        assert!(
            bad.to_string()
                .contains("'pose' is not a message type name")
        );
    }

    #[test]
    fn the_catalog_checks_names_and_cycles_and_lays_out_like_c() {
        let p = |name: &str, types: Vec<MsgType>| Package {
            name: name.into(),
            dir: PathBuf::from(name),
            types,
        };
        let a = parse("bool flag\nf64 x\nu16[3] n\n", Path::new("q/A.msg"), "q").unwrap();
        let b = parse("u8 k\nA a # nested\n", Path::new("q/B.msg"), "q").unwrap();
        let c = Catalog::new(&[p("q", vec![a.clone(), b.clone()])]).unwrap();
        assert_eq!(c.layout(&a), Layout { size: 24, align: 8 });
        assert_eq!(c.offsets(&a), vec![0, 8, 16]);
        assert_eq!(c.offsets(&b), vec![0, 8]);
        assert_eq!(c.layout(&b), Layout { size: 32, align: 8 });
        let missing = parse("Nope n\n", Path::new("q/C.msg"), "q").unwrap();
        let e = Catalog::new(&[p("q", vec![missing])]).unwrap_err();
        assert_eq!(e.to_string(), "q/C.msg:1: unknown message type 'q.Nope'");
        let selfish = parse("D d\n", Path::new("q/D.msg"), "q").unwrap();
        let e = Catalog::new(&[p("q", vec![selfish])]).unwrap_err();
        assert!(e.to_string().contains("contains itself"), "{e}");
    }
}
