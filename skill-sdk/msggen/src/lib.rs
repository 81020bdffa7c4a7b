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

use std::fmt;
use std::path::{Path, PathBuf};

/// A primitive field type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)]
pub enum Prim {
    Bool,
    U8,
    U16,
    U32,
    U64,
    I8,
    I16,
    I32,
    I64,
    F32,
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

const KEYWORDS: &[&str] = &[
    "as",
    "async",
    "await",
    "break",
    "const",
    "continue",
    "crate",
    "dyn",
    "else",
    "enum",
    "extern",
    "false",
    "fn",
    "for",
    "if",
    "impl",
    "in",
    "let",
    "loop",
    "match",
    "mod",
    "move",
    "mut",
    "pub",
    "ref",
    "return",
    "self",
    "static",
    "struct",
    "super",
    "trait",
    "true",
    "type",
    "unsafe",
    "use",
    "where",
    "while",
    "yield",
    "abstract",
    "become",
    "box",
    "do",
    "final",
    "macro",
    "override",
    "priv",
    "typeof",
    "unsized",
    "virtual",
    "try",
    "gen",
    "union",
    // C and C++
    "auto",
    "case",
    "char",
    "default",
    "double",
    "float",
    "goto",
    "int",
    "long",
    "register",
    "short",
    "signed",
    "sizeof",
    "switch",
    "typedef",
    "unsigned",
    "void",
    "volatile",
    "class",
    "delete",
    "new",
    "private",
    "protected",
    "public",
    "template",
    "this",
    "throw",
    "namespace",
    "operator",
    "friend",
    "virtual",
    "bool",
    // Python
    "and",
    "def",
    "del",
    "elif",
    "except",
    "from",
    "global",
    "import",
    "is",
    "lambda",
    "nonlocal",
    "not",
    "or",
    "pass",
    "raise",
    "with",
    "None",
    "True",
    "False",
    "assert",
];

fn identifier(s: &str) -> bool {
    let mut chars = s.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Whether `s` may name a package: lower case letters, digits and `_`, a letter first.
pub fn package_name_ok(s: &str) -> bool {
    identifier(s)
        && s.starts_with(|c: char| c.is_ascii_lowercase())
        && !s.chars().any(|c| c.is_ascii_uppercase())
        && !KEYWORDS.contains(&s)
}

/// Whether `s` may name a message type: an identifier starting with an upper-case letter.
pub fn type_name_ok(s: &str) -> bool {
    identifier(s) && s.starts_with(|c: char| c.is_ascii_uppercase()) && !KEYWORDS.contains(&s)
}

/// Parses one message file's text (`package` and the file's stem give the type's name).
pub fn parse(text: &str, file: &Path, package: &str) -> Result<MsgType, Error> {
    let err = |line: usize, message: String| Error {
        file: file.to_path_buf(),
        line,
        message,
    };
    let name = file
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    if !type_name_ok(&name) {
        return Err(err(
            0,
            format!(
                "'{name}' is not a message type name (an identifier starting with an upper-case letter)"
            ),
        ));
    }
    let mut doc = Vec::new();
    let mut in_header = true;
    let mut fields: Vec<Field> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let n = i + 1;
        let (code, comment) = match raw.find('#') {
            Some(at) => (&raw[..at], Some(raw[at + 1..].trim())),
            None => (raw, None),
        };
        let code = code.trim();
        if code.is_empty() {
            match comment {
                Some(c) if in_header => doc.push(c.to_string()),
                // A blank line ends the type's doc; comments after it are notes.
                None if !doc.is_empty() => in_header = false,
                _ => {}
            }
            continue;
        }
        in_header = false;
        let words: Vec<&str> = code.split_whitespace().collect();
        let [ty, fname] = words[..] else {
            return Err(err(
                n,
                format!("expected 'TYPE NAME [# doc]', found '{code}'"),
            ));
        };
        if !identifier(fname) || KEYWORDS.contains(&fname) {
            return Err(err(
                n,
                format!(
                    "'{fname}' cannot name a field (an identifier, not a keyword of Rust, C, C++ or Python)"
                ),
            ));
        }
        if fields.iter().any(|f| f.name == fname) {
            return Err(err(n, format!("field '{fname}' is declared twice")));
        }
        fields.push(Field {
            name: fname.to_string(),
            ty: field_type(ty, package).map_err(|m| err(n, m))?,
            doc: comment.unwrap_or_default().to_string(),
            line: n,
        });
    }
    if fields.is_empty() {
        return Err(err(0, "a message needs at least one field".into()));
    }
    Ok(MsgType {
        package: package.to_string(),
        name,
        doc: doc.join(" "),
        fields,
        file: file.to_path_buf(),
    })
}

fn field_type(text: &str, package: &str) -> Result<FieldTy, String> {
    let (base, mut rest) = match text.find('[') {
        Some(at) => (&text[..at], &text[at..]),
        None => (text, ""),
    };
    let mut dims = Vec::new();
    while !rest.is_empty() {
        let close = rest
            .find(']')
            .filter(|_| rest.starts_with('['))
            .ok_or_else(|| format!("'{text}': an array is TYPE[N]"))?;
        let n: u32 = rest[1..close]
            .parse()
            .ok()
            .filter(|n| (1..=1 << 24).contains(n))
            .ok_or_else(|| {
                format!(
                    "'{text}': an array length is a number from 1 to 16777216 (messages have a fixed size)"
                )
            })?;
        dims.push(n);
        rest = &rest[close + 1..];
    }
    let base = match Prim::ALL.iter().find(|(n, _)| *n == base) {
        Some((_, p)) => Base::Prim(*p),
        None => {
            // `pkg.Name`, `pkg/Name` (as ROS writes it) or `Name` of this package.
            let full = base.replace('/', ".");
            let (pkg, name) = full.rsplit_once('.').unwrap_or((package, &full));
            if !package_name_ok(pkg) || !type_name_ok(name) {
                return Err(format!(
                    "unknown type '{base}' (a primitive: {}; or a message type: Name, package.Name)",
                    Prim::ALL.map(|(n, _)| n).join(" ")
                ));
            }
            Base::Named(format!("{pkg}.{name}"))
        }
    };
    Ok(FieldTy { base, dims })
}

/// Loads the package in `dir` (every `*.msg` file, by name).
pub fn load_package(dir: &Path) -> Result<Package, Error> {
    let whole = |message: String| Error {
        file: dir.to_path_buf(),
        line: 0,
        message,
    };
    let name = dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    if !package_name_ok(&name) {
        return Err(whole(format!(
            "'{name}' cannot name a message package (lower case, digits and _, a letter first)"
        )));
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| whole(format!("cannot read the directory: {e}")))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "msg"))
        .collect();
    files.sort();
    let mut types = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).map_err(|e| Error {
            file: f.clone(),
            line: 0,
            message: format!("cannot read it: {e}"),
        })?;
        types.push(parse(&text, &f, &name)?);
    }
    if types.is_empty() {
        return Err(whole("no .msg files in it".into()));
    }
    Ok(Package {
        name,
        dir: dir.to_path_buf(),
        types,
    })
}

/// The packages under each directory of a search path (a directory that is itself a package,
/// or holds packages as subdirectories), as `SKILLFAB_MSG_PATH` lists them.
pub fn load_path(dirs: &[PathBuf]) -> Result<Vec<Package>, Error> {
    let mut out = Vec::new();
    for d in dirs {
        let has_msg = std::fs::read_dir(d)
            .map(|it| {
                it.flatten()
                    .any(|e| e.path().extension().is_some_and(|x| x == "msg"))
            })
            .unwrap_or(false);
        if has_msg {
            out.push(load_package(d)?);
            continue;
        }
        let mut subs: Vec<PathBuf> = std::fs::read_dir(d)
            .map_err(|e| Error {
                file: d.clone(),
                line: 0,
                message: format!("cannot read the directory: {e}"),
            })?
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.is_dir())
            .collect();
        subs.sort();
        for s in subs {
            out.push(load_package(&s)?);
        }
    }
    Ok(out)
}

/// A resolved set of message types (one's own packages and what they use).
#[derive(Debug, Clone, Default)]
pub struct Catalog {
    /// Every type, in package order, then by name.
    pub types: Vec<MsgType>,
}

/// Size and alignment of a type in the C layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// `sizeof`.
    pub size: u32,
    /// `alignof`.
    pub align: u32,
}

impl Catalog {
    /// The packages' types, checked: every named type exists, no type contains itself, no
    /// type is declared twice.
    pub fn new(packages: &[Package]) -> Result<Catalog, Error> {
        let types: Vec<MsgType> = packages.iter().flat_map(|p| p.types.clone()).collect();
        for (i, t) in types.iter().enumerate() {
            if let Some(other) = types[..i].iter().find(|o| o.type_name() == t.type_name()) {
                return Err(Error {
                    file: t.file.clone(),
                    line: 0,
                    message: format!(
                        "{} is declared twice (also in {})",
                        t.type_name(),
                        other.file.display()
                    ),
                });
            }
        }
        let c = Catalog { types };
        for t in &c.types {
            for f in &t.fields {
                if let Base::Named(n) = &f.ty.base
                    && c.get(n).is_none()
                {
                    return Err(Error {
                        file: t.file.clone(),
                        line: f.line,
                        message: format!("unknown message type '{n}'"),
                    });
                }
            }
            c.layout_checked(t, &mut Vec::new())?;
        }
        Ok(c)
    }

    /// The type called `type_name`.
    pub fn get(&self, type_name: &str) -> Option<&MsgType> {
        self.types.iter().find(|t| t.type_name() == type_name)
    }

    fn layout_checked(&self, t: &MsgType, stack: &mut Vec<String>) -> Result<Layout, Error> {
        if stack.contains(&t.type_name()) {
            return Err(Error {
                file: t.file.clone(),
                line: 0,
                message: format!("{} contains itself ({})", t.type_name(), stack.join(" → ")),
            });
        }
        stack.push(t.type_name());
        let (mut size, mut align) = (0u64, 1u32);
        for f in &t.fields {
            let e = match &f.ty.base {
                Base::Prim(p) => Layout {
                    size: p.size(),
                    align: p.size(),
                },
                Base::Named(n) => match self.get(n) {
                    Some(inner) => self.layout_checked(inner, stack)?,
                    None => Layout { size: 0, align: 1 },
                },
            };
            let count: u64 = f.ty.dims.iter().map(|d| u64::from(*d)).product();
            size = size.next_multiple_of(u64::from(e.align)) + u64::from(e.size) * count;
            align = align.max(e.align);
        }
        stack.pop();
        let size = size.next_multiple_of(u64::from(align));
        u32::try_from(size)
            .ok()
            .filter(|s| *s <= 1 << 26)
            .map(|size| Layout { size, align })
            .ok_or_else(|| Error {
                file: t.file.clone(),
                line: 0,
                message: format!("{} is {size} bytes: at most 64 MiB", t.type_name()),
            })
    }

    /// The C layout of `t` (it must be in the catalog).
    pub fn layout(&self, t: &MsgType) -> Layout {
        self.layout_checked(t, &mut Vec::new())
            .unwrap_or(Layout { size: 0, align: 1 })
    }

    /// Byte offset of each field of `t`, in order.
    pub fn offsets(&self, t: &MsgType) -> Vec<u32> {
        let mut at = 0u32;
        t.fields
            .iter()
            .map(|f| {
                let e = match &f.ty.base {
                    Base::Prim(p) => Layout {
                        size: p.size(),
                        align: p.size(),
                    },
                    Base::Named(n) => self
                        .get(n)
                        .map_or(Layout { size: 0, align: 1 }, |i| self.layout(i)),
                };
                let count: u32 = f.ty.dims.iter().product();
                at = at.next_multiple_of(e.align);
                let here = at;
                at += e.size * count;
                here
            })
            .collect()
    }
}

/// How generated Rust names a type of another package: `skillfab` types are
/// `::skillfab_msgs::Name`; types of package `p` are `super::p::Name` (each package a module
/// of the same crate).
fn rust_path(full: &str, own: &str) -> String {
    let (pkg, name) = full.rsplit_once('.').unwrap_or(("", full));
    if pkg == own {
        name.to_string()
    } else if pkg == "skillfab" {
        format!("::skillfab_msgs::{name}")
    } else {
        format!("super::{pkg}::{name}")
    }
}

fn rust_type(ty: &FieldTy, own: &str) -> String {
    let mut s = match &ty.base {
        Base::Prim(p) => p.name().to_string(),
        Base::Named(n) => rust_path(n, own),
    };
    for d in ty.dims.iter().rev() {
        s = format!("[{s}; {d}]");
    }
    s
}

fn doc_attr(doc: &str, indent: &str) -> String {
    if doc.is_empty() {
        String::new()
    } else {
        format!("{indent}#[doc = {doc:?}]\n")
    }
}

/// The Rust declarations of `package`'s types (a module's contents): each a `#[repr(C)]`
/// struct deriving `Message` with its type name, `Default` when every array has at most 32
/// elements (the standard library's limit), and `registry()` — the package's types for skills
/// declared at run time. The code uses `skill_sdk` (a dependency of every skill).
pub fn rust_module(catalog: &Catalog, package: &str) -> String {
    let mut out = String::from(
        "// Generated by skillfab-msggen from message files; do not edit.\n\
         #[allow(unused_imports)]\nuse skill_sdk::prelude::Message;\n\n",
    );
    let types: Vec<&MsgType> = catalog
        .types
        .iter()
        .filter(|t| t.package == package)
        .collect();
    for t in &types {
        let small = |t: &MsgType| t.fields.iter().all(|f| f.ty.dims.iter().all(|d| *d <= 32));
        let default = small(t)
            && t.fields.iter().all(|f| match &f.ty.base {
                Base::Named(n) => catalog.get(n).is_some_and(small),
                Base::Prim(_) => true,
            });
        out.push_str(&doc_attr(&t.doc, ""));
        out.push_str(&format!(
            "#[derive(Message, Debug, {}Clone, Copy, PartialEq)]\n#[message(type_name = {:?})]\n#[repr(C)]\npub struct {} {{\n",
            if default { "Default, " } else { "" },
            t.type_name(),
            t.name
        ));
        for f in &t.fields {
            out.push_str(&doc_attr(&f.doc, "    "));
            out.push_str(&format!(
                "    pub {}: {},\n",
                f.name,
                rust_type(&f.ty, package)
            ));
        }
        out.push_str("}\n\n");
    }
    out.push_str(&format!(
        "/// The package's message types, for skills declared at run time (C, C++, Python).\n\
         pub fn registry() -> &'static [skill_sdk::foreign::MessageType] {{\n    \
         static REGISTRY: [skill_sdk::foreign::MessageType; {}] = [\n",
        types.len()
    ));
    for t in &types {
        out.push_str(&format!(
            "        skill_sdk::foreign::MessageType::of::<{}>(),\n",
            t.name
        ));
    }
    out.push_str("    ];\n    &REGISTRY\n}\n");
    out
}

/// For a build script: loads the packages in `dirs` (see [`load_path`]), writes the Rust
/// module of package `package` to `$OUT_DIR/<package>.rs` and tells cargo to rerun when a
/// message file changes. A wrong file stops the build with its path and line.
pub fn build(dirs: &[PathBuf], package: &str) -> Result<PathBuf, Error> {
    for d in dirs {
        println!("cargo:rerun-if-changed={}", d.display());
    }
    let packages = load_path(dirs)?;
    for p in &packages {
        for t in &p.types {
            println!("cargo:rerun-if-changed={}", t.file.display());
        }
    }
    let catalog = Catalog::new(&packages)?;
    if !packages.iter().any(|p| p.name == package) {
        return Err(Error {
            file: dirs.first().cloned().unwrap_or_default(),
            line: 0,
            message: format!("no message package '{package}' here"),
        });
    }
    let out = PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default())
        .join(format!("{package}.rs"));
    std::fs::write(&out, rust_module(&catalog, package)).map_err(|e| Error {
        file: out.clone(),
        line: 0,
        message: format!("cannot write it: {e}"),
    })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

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
