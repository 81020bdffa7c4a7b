//! Reading message files: names, the line format, packages and search paths.

use crate::{Base, Error, Field, FieldTy, MsgType, Package, Prim};
use std::path::{Path, PathBuf};

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
