//! The shared message types for other languages, generated from their schemas: a C header
//! (`skill-sdk/capi/include/skillfab_msgs.h`), a Python `ctypes` module
//! (`python/skillfab/msgs.py`) and a C program that prints the C layout for the layout test.
//! `skillfab schema --c` / `--python` print the first two; tests check the committed files
//! are what these functions produce and that every language agrees on every offset.

#![warn(missing_docs)]

use skillfab_proto::schema::{FieldKind, MessageSchema, Prim};
use std::fmt::Write;

/// The C name of a message type: `skillfab.Tick` → `sf_Tick`.
pub fn c_name(type_name: &str) -> String {
    match type_name.strip_prefix("skillfab.") {
        Some(rest) => format!("sf_{}", rest.replace('.', "_")),
        None => format!("sf_{}", type_name.replace('.', "_")),
    }
}

/// The Python class name of a message type: `skillfab.Tick` → `Tick`, `my_robot.Pose` →
/// `Pose` (each package is a module of its own).
pub fn py_name(type_name: &str) -> String {
    type_name
        .rsplit_once('.')
        .map_or(type_name, |(_, name)| name)
        .to_string()
}

fn c_prim(p: Prim) -> &'static str {
    match p {
        Prim::U8 => "uint8_t",
        Prim::U16 => "uint16_t",
        Prim::U32 => "uint32_t",
        Prim::U64 => "uint64_t",
        Prim::I8 => "int8_t",
        Prim::I16 => "int16_t",
        Prim::I32 => "int32_t",
        Prim::I64 => "int64_t",
        Prim::F32 => "float",
        Prim::F64 => "double",
        Prim::Bool => "bool",
    }
}

fn py_prim(p: Prim) -> &'static str {
    match p {
        Prim::U8 => "ctypes.c_uint8",
        Prim::U16 => "ctypes.c_uint16",
        Prim::U32 => "ctypes.c_uint32",
        Prim::U64 => "ctypes.c_uint64",
        Prim::I8 => "ctypes.c_int8",
        Prim::I16 => "ctypes.c_int16",
        Prim::I32 => "ctypes.c_int32",
        Prim::I64 => "ctypes.c_int64",
        Prim::F32 => "ctypes.c_float",
        Prim::F64 => "ctypes.c_double",
        Prim::Bool => "ctypes.c_bool",
    }
}

/// A C declarator: `double range[24]`, `sf_Inner inner`.
fn c_field(kind: &FieldKind, name: &str) -> String {
    let mut dims = String::new();
    let mut k = kind;
    while let FieldKind::Array { elem, len } = k {
        let _ = write!(dims, "[{len}]");
        k = elem;
    }
    let base = match k {
        FieldKind::Prim(p) => c_prim(*p).to_string(),
        FieldKind::Struct(s) => c_name(&s.type_name),
        FieldKind::Array { .. } => unreachable!("arrays unwrapped above"),
    };
    format!("{base} {name}{dims}")
}

fn py_type(kind: &FieldKind) -> String {
    match kind {
        FieldKind::Prim(p) => py_prim(*p).to_string(),
        FieldKind::Struct(s) => py_name(&s.type_name),
        FieldKind::Array { elem, len } => format!("({} * {len})", py_type(elem)),
    }
}

/// Nested message types first, each once, then the given ones.
fn in_dependency_order(schemas: &[MessageSchema]) -> Vec<MessageSchema> {
    fn visit(s: &MessageSchema, out: &mut Vec<MessageSchema>) {
        for f in &s.fields {
            let mut k = &f.ty;
            while let FieldKind::Array { elem, .. } = k {
                k = elem;
            }
            if let FieldKind::Struct(inner) = k {
                visit(inner, out);
            }
        }
        if !out.iter().any(|o| o.type_name == s.type_name) {
            out.push(s.clone());
        }
    }
    let mut out = Vec::new();
    for s in schemas {
        visit(s, &mut out);
    }
    out
}

fn comment_lines(doc: &str) -> String {
    doc.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

/// The schemas of every shared message type.
pub fn shared_schemas() -> Vec<MessageSchema> {
    skillfab_msgs::registry()
        .iter()
        .map(|t| (t.schema)())
        .collect()
}

/// The types of `package` among `schemas` and what they contain, in dependency order.
fn of_package(schemas: &[MessageSchema], package: &str) -> Vec<MessageSchema> {
    let prefix = format!("{package}.");
    in_dependency_order(schemas)
        .into_iter()
        .filter(|s| s.type_name.starts_with(&prefix))
        .collect()
}

/// A C header declaring `schemas` as structs with the Rust layout.
pub fn c_header(schemas: &[MessageSchema]) -> String {
    c_header_for(schemas, "skillfab")
}

/// A C header declaring the types of message package `package` among `schemas` (another
/// package's types they contain come from that package's header: `skillfab_msgs.h` for the
/// shipped catalog).
pub fn c_header_for(schemas: &[MessageSchema], package: &str) -> String {
    let mut h = String::new();
    let guard = format!("{}_MSGS_H", package.to_uppercase());
    if package == "skillfab" {
        h.push_str(
            "/* The shared message types of skillfab, generated from their message files\n \
             * (skill-sdk/msgs/msg/skillfab/) by `skillfab schema --c`. Do not edit: a test\n \
             * checks this file is what the generator writes, and that every size and offset\n \
             * matches Rust. */\n",
        );
    } else {
        let _ = writeln!(
            h,
            "/* The message types of package {package}, generated from its message files by\n \
             * `skillfab schema --c --msg-path DIR --package {package}`. Do not edit. */"
        );
    }
    let _ = write!(
        h,
        "#ifndef {guard}\n#define {guard}\n\n#include <stdbool.h>\n#include <stdint.h>\n\n"
    );
    if package != "skillfab" {
        h.push_str("#include \"skillfab_msgs.h\"\n\n");
    }
    for s in of_package(schemas, package) {
        let name = c_name(&s.type_name);
        let upper = name.to_uppercase();
        let _ = writeln!(h, "/** {} */", comment_lines(&s.doc));
        let _ = writeln!(h, "typedef struct {name} {{");
        for f in &s.fields {
            let _ = writeln!(h, "    {};", c_field(&f.ty, &f.name));
        }
        let _ = writeln!(h, "}} {name};");
        let _ = writeln!(h, "#define {upper}_TYPE_NAME \"{}\"", s.type_name);
        let _ = writeln!(h, "#define {upper}_SIZE {}\n", s.size);
    }
    let _ = writeln!(h, "#endif /* {guard} */");
    h
}

/// A C program that prints, per type, one JSON line with the C compiler's size, alignment
/// and field offsets (the layout test compares them with the Rust schemas).
pub fn c_layout_probe(schemas: &[MessageSchema]) -> String {
    let mut c = String::from(
        "#include <stdalign.h>\n#include <stddef.h>\n#include <stdio.h>\n\
         #include \"skillfab_msgs.h\"\n\nint main(void) {\n",
    );
    for s in in_dependency_order(schemas) {
        let name = c_name(&s.type_name);
        let mut fmt = format!(
            "{{\\\"type\\\":\\\"{}\\\",\\\"size\\\":%zu,\\\"align\\\":%zu,\\\"offsets\\\":{{",
            s.type_name
        );
        let mut args = format!("sizeof({name}), alignof({name})");
        for (i, f) in s.fields.iter().enumerate() {
            if i > 0 {
                fmt.push(',');
            }
            let _ = write!(fmt, "\\\"{}\\\":%zu", f.name);
            let _ = write!(args, ", offsetof({name}, {})", f.name);
        }
        fmt.push_str("}}\\n");
        let _ = writeln!(c, "    printf(\"{fmt}\", {args});");
    }
    c.push_str("    return 0;\n}\n");
    c
}

/// A Python module declaring `schemas` as `ctypes.Structure` classes with the Rust layout.
pub fn python_module(schemas: &[MessageSchema]) -> String {
    python_module_for(schemas, "skillfab")
}

/// A Python module declaring the types of message package `package` among `schemas` (the
/// shipped types they contain are imported from `skillfab.msgs`).
pub fn python_module_for(schemas: &[MessageSchema], package: &str) -> String {
    let mut p = if package == "skillfab" {
        String::from(
            "\"\"\"The shared message types of skillfab as ctypes structures.\n\n\
             Generated from their message files (skill-sdk/msgs/msg/skillfab/) by\n\
             `skillfab schema --python`. Do not edit: a test checks this file is what the\n\
             generator writes, and that every size and offset matches Rust.\n\"\"\"\n\n\
             import ctypes\n\n",
        )
    } else {
        format!(
            "\"\"\"The message types of package {package} as ctypes structures.\n\n\
             Generated from its message files by\n\
             `skillfab schema --python --msg-path DIR --package {package}`. Do not edit.\n\"\"\"\n\n\
             import ctypes\n\nfrom skillfab.msgs import *  # noqa: F401,F403 (types they contain)\n\n"
        )
    };
    let ordered = of_package(schemas, package);
    for s in &ordered {
        let name = py_name(&s.type_name);
        let _ = writeln!(p, "\nclass {name}(ctypes.Structure):");
        let _ = writeln!(
            p,
            "    \"\"\"{}\"\"\"\n",
            comment_lines(&s.doc).replace('"', "'")
        );
        let _ = writeln!(p, "    TYPE_NAME = \"{}\"", s.type_name);
        p.push_str("    _fields_ = [\n");
        for f in &s.fields {
            let _ = writeln!(p, "        (\"{}\", {}),", f.name, py_type(&f.ty));
        }
        p.push_str("    ]\n\n");
    }
    p.push_str("\n# Every type, by type name.\nBY_TYPE_NAME = {\n");
    for s in &ordered {
        let _ = writeln!(
            p,
            "    {}.TYPE_NAME: {},",
            py_name(&s.type_name),
            py_name(&s.type_name)
        );
    }
    p.push_str("}\n");
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_declarators() {
        assert_eq!(c_name("skillfab.Tick"), "sf_Tick");
        assert_eq!(c_name("acme.arm.Joint"), "sf_acme_arm_Joint");
        assert_eq!(py_name("skillfab.Sonar"), "Sonar");
        assert_eq!(py_name("my_robot.Pose"), "Pose");
        let k = FieldKind::Array {
            elem: Box::new(FieldKind::Array {
                elem: Box::new(FieldKind::Prim(Prim::F32)),
                len: 3,
            }),
            len: 2,
        };
        assert_eq!(c_field(&k, "m"), "float m[2][3]");
        assert_eq!(py_type(&k), "((ctypes.c_float * 3) * 2)");
    }

    #[test]
    fn every_shared_type_is_in_both_outputs() {
        let schemas = shared_schemas();
        let h = c_header(&schemas);
        let py = python_module(&schemas);
        for s in &schemas {
            assert!(
                h.contains(&format!("}} {};", c_name(&s.type_name))),
                "{}",
                s.type_name
            );
            assert!(py.contains(&format!("class {}(", py_name(&s.type_name))));
        }
        assert!(h.contains("double range[24];"));
        assert!(py.contains("(\"range\", (ctypes.c_double * 24)),"));
    }
}
