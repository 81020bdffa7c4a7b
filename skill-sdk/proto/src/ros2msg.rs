//! Message schemas as ROS 2 message definitions (`ros2msg`, what an MCAP file's `cdr`
//! channels carry as their schema): the ROS tools decode a recording's samples ([`crate::cdr`])
//! with them.
//!
//! A skillfab type `package.Name` is the ROS type `package/msg/Name`; its fields keep their
//! names; `f64` is `float64`, `u8` `uint8`, …, `bool` `bool`; a fixed-length array is
//! `type[N] name` (a two-dimensional one, which ROS has no syntax for, is flattened — CDR lays
//! both out alike); a nested message is `package/Name name`, and its definition follows the
//! message's, as rosbag2 writes them:
//!
//! ```text
//! float64 width
//! skillfab/Odometry at
//! ================================================================================
//! MSG: skillfab/Odometry
//! float64 x
//! …
//! ```

use crate::schema::{FieldKind, MessageSchema, Prim};

/// What separates nested definitions (80 `=`, as rosbag2 and the ROS tools expect).
const SEPARATOR: &str =
    "================================================================================";

/// "skillfab.Sonar" -> "skillfab/msg/Sonar" (ROS 2 naming; a package name as ROS requires).
///
/// The package (before the last `.`) is made a ROS package name: lower case, `_` for any
/// other character, a letter first (`skillfab` if there is none). The type keeps its letters
/// and digits, its first letter upper case.
pub fn schema_name(type_name: &str) -> String {
    let (package, name) = ros_parts(type_name);
    format!("{package}/msg/{name}")
}

/// The ros2msg schema text of the message, nested types appended as ROS 2 does
/// ("=====…\nMSG: pkg/Type\n…").
pub fn schema_text(schema: &MessageSchema) -> String {
    let mut out = String::new();
    let mut nested: Vec<&MessageSchema> = Vec::new();
    definition(schema, &mut out, &mut nested);
    // Each nested type once, in the order first met (theirs included).
    let mut i = 0;
    while let Some(m) = nested.get(i).copied() {
        out.push_str(SEPARATOR);
        out.push('\n');
        let (package, name) = ros_parts(&m.type_name);
        out.push_str(&format!("MSG: {package}/{name}\n"));
        definition(m, &mut out, &mut nested);
        i += 1;
    }
    out
}

/// The ROS name of a primitive.
fn prim_name(p: Prim) -> &'static str {
    match p {
        Prim::Bool => "bool",
        Prim::U8 => "uint8",
        Prim::U16 => "uint16",
        Prim::U32 => "uint32",
        Prim::U64 => "uint64",
        Prim::I8 => "int8",
        Prim::I16 => "int16",
        Prim::I32 => "int32",
        Prim::I64 => "int64",
        Prim::F32 => "float32",
        Prim::F64 => "float64",
    }
}

/// The field lines of `m`; the nested types it uses, not yet in `nested`, are added to it.
fn definition<'a>(m: &'a MessageSchema, out: &mut String, nested: &mut Vec<&'a MessageSchema>) {
    for f in &m.fields {
        // Arrays of arrays are flattened: the element and the product of the lengths.
        let (mut elem, mut len) = (&f.ty, None::<u64>);
        while let FieldKind::Array { elem: e, len: n } = elem {
            len = Some(len.unwrap_or(1) * u64::from(*n));
            elem = e;
        }
        match elem {
            FieldKind::Prim(p) => out.push_str(prim_name(*p)),
            FieldKind::Struct(s) => {
                let (package, name) = ros_parts(&s.type_name);
                out.push_str(&format!("{package}/{name}"));
                if !nested.iter().any(|n| n.type_name == s.type_name) {
                    nested.push(s);
                }
            }
            FieldKind::Array { .. } => {}
        }
        if let Some(n) = len {
            out.push_str(&format!("[{n}]"));
        }
        out.push(' ');
        out.push_str(&f.name);
        out.push('\n');
    }
}

/// The ROS package and type names of a skillfab type name.
fn ros_parts(type_name: &str) -> (String, String) {
    let (package, name) = type_name.rsplit_once('.').unwrap_or(("", type_name));
    let mut pkg: String = package
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    if !pkg.starts_with(|c: char| c.is_ascii_lowercase()) {
        pkg = if pkg.is_empty() {
            "skillfab".into()
        } else {
            format!("p{pkg}")
        };
    }
    let mut ty: String = name.chars().filter(char::is_ascii_alphanumeric).collect();
    if let Some(first) = ty.get(..1) {
        ty.replace_range(..1, &first.to_ascii_uppercase());
    }
    if !ty.starts_with(|c: char| c.is_ascii_uppercase()) {
        ty.insert(0, 'T');
    }
    (pkg, ty)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schema::FieldSchema;

    fn field(name: &str, offset: u32, ty: FieldKind) -> FieldSchema {
        FieldSchema {
            name: name.into(),
            offset,
            ty,
        }
    }

    fn message(type_name: &str, fields: Vec<FieldSchema>) -> MessageSchema {
        MessageSchema {
            type_name: type_name.into(),
            doc: String::new(),
            size: 0,
            align: 1,
            fields,
        }
    }

    #[test]
    fn type_names_become_ros_names() {
        assert_eq!(schema_name("skillfab.Sonar"), "skillfab/msg/Sonar");
        assert_eq!(schema_name("my_robot.Arm2"), "my_robot/msg/Arm2");
        assert_eq!(schema_name("My-Robot.arm"), "my_robot/msg/Arm");
        assert_eq!(schema_name("Blob"), "skillfab/msg/Blob");
        assert_eq!(schema_name("a.b.Grip"), "a_b/msg/Grip");
        assert_eq!(schema_name("9lives.Cat"), "p9lives/msg/Cat");
    }

    #[test]
    fn nested_types_follow_once_each_arrays_keep_their_lengths() {
        let odom = message(
            "skillfab.Odometry",
            vec![
                field("x", 0, FieldKind::Prim(Prim::F64)),
                field("w", 8, FieldKind::Prim(Prim::F32)),
            ],
        );
        let finger = message(
            "test_pkg.Finger",
            vec![
                field("id", 0, FieldKind::Prim(Prim::U8)),
                field("at", 8, FieldKind::Struct(odom.clone())),
            ],
        );
        let array = |elem: FieldKind, len| FieldKind::Array {
            elem: Box::new(elem),
            len,
        };
        let grasp = message(
            "test_pkg.Grasp",
            vec![
                field("width", 0, FieldKind::Prim(Prim::F64)),
                field("at", 8, FieldKind::Struct(odom)),
                field("closed", 24, array(FieldKind::Prim(Prim::Bool), 3)),
                field("fingers", 32, array(FieldKind::Struct(finger), 2)),
                field("cov", 64, array(array(FieldKind::Prim(Prim::I16), 3), 2)),
            ],
        );
        let sep = "=".repeat(80);
        assert_eq!(
            schema_text(&grasp),
            format!(
                "float64 width\nskillfab/Odometry at\nbool[3] closed\ntest_pkg/Finger[2] fingers\n\
                 int16[6] cov\n{sep}\nMSG: skillfab/Odometry\nfloat64 x\nfloat32 w\n\
                 {sep}\nMSG: test_pkg/Finger\nuint8 id\nskillfab/Odometry at\n"
            )
        );
    }

    #[test]
    fn every_primitive_has_its_ros_name() {
        let prims = [
            (Prim::Bool, "bool"),
            (Prim::U8, "uint8"),
            (Prim::U16, "uint16"),
            (Prim::U32, "uint32"),
            (Prim::U64, "uint64"),
            (Prim::I8, "int8"),
            (Prim::I16, "int16"),
            (Prim::I32, "int32"),
            (Prim::I64, "int64"),
            (Prim::F32, "float32"),
            (Prim::F64, "float64"),
        ];
        let m = message(
            "skillfab.All",
            prims
                .iter()
                .enumerate()
                .map(|(i, (p, _))| field(&format!("f{i}"), 0, FieldKind::Prim(*p)))
                .collect(),
        );
        let want: String = prims
            .iter()
            .enumerate()
            .map(|(i, (_, n))| format!("{n} f{i}\n"))
            .collect();
        assert_eq!(schema_text(&m), want);
    }
}
