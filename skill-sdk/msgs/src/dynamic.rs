//! Message types by schema at run time: the shipped catalog (embedded) and the packages on
//! `SKILLFAB_MSG_PATH` (colon-separated directories, each a package or a directory of
//! packages). A C, C++ or Python skill names a type of its own package and the runtime finds
//! its layout here, from the same message file its C header or Python module was generated
//! from.

use skillfab_msggen::{Base, Catalog, FieldTy, MsgType, Package};
use skillfab_proto::schema::{FieldKind, FieldSchema, MessageSchema, Prim};
use std::path::{Path, PathBuf};

include!(concat!(env!("OUT_DIR"), "/sources.rs"));

/// The environment variable listing message package directories.
pub const MSG_PATH_ENV: &str = "SKILLFAB_MSG_PATH";

/// The shipped catalog, from the embedded message files.
pub fn shipped() -> Package {
    let types = SOURCES
        .iter()
        .filter_map(|(path, text)| skillfab_msggen::parse(text, Path::new(path), "skillfab").ok())
        .collect();
    Package {
        name: "skillfab".into(),
        dir: PathBuf::from("skill-sdk/msgs/msg/skillfab"),
        types,
    }
}

/// The directories of `SKILLFAB_MSG_PATH`.
pub fn msg_path() -> Vec<PathBuf> {
    std::env::var_os(MSG_PATH_ENV)
        .map(|v| {
            std::env::split_paths(&v)
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        })
        .unwrap_or_default()
}

/// The shipped catalog and the packages in `dirs`, checked together.
pub fn catalog(dirs: &[PathBuf]) -> Result<(Catalog, Vec<Package>), skillfab_msggen::Error> {
    let mut packages = vec![shipped()];
    packages.extend(skillfab_msggen::load_path(dirs)?);
    Ok((Catalog::new(&packages)?, packages))
}

fn prim(p: skillfab_msggen::Prim) -> Prim {
    use skillfab_msggen::Prim as M;
    match p {
        M::Bool => Prim::Bool,
        M::U8 => Prim::U8,
        M::U16 => Prim::U16,
        M::U32 => Prim::U32,
        M::U64 => Prim::U64,
        M::I8 => Prim::I8,
        M::I16 => Prim::I16,
        M::I32 => Prim::I32,
        M::I64 => Prim::I64,
        M::F32 => Prim::F32,
        M::F64 => Prim::F64,
    }
}

fn kind(c: &Catalog, ty: &FieldTy) -> FieldKind {
    let mut k = match &ty.base {
        Base::Prim(p) => FieldKind::Prim(prim(*p)),
        Base::Named(n) => FieldKind::Struct(
            c.get(n)
                .map_or_else(|| schema(c, &empty(n)), |t| schema(c, t)),
        ),
    };
    for d in ty.dims.iter().rev() {
        k = FieldKind::Array {
            elem: Box::new(k),
            len: *d,
        };
    }
    k
}

fn empty(n: &str) -> MsgType {
    MsgType {
        package: String::new(),
        name: n.to_string(),
        doc: String::new(),
        fields: Vec::new(),
        file: PathBuf::new(),
    }
}

/// The schema of `t` (its C layout: the one the Rust, C and Python code generated from the
/// same file have).
pub fn schema(c: &Catalog, t: &MsgType) -> MessageSchema {
    let layout = c.layout(t);
    MessageSchema {
        type_name: t.type_name(),
        doc: t.doc.clone(),
        size: layout.size,
        align: layout.align,
        fields: t
            .fields
            .iter()
            .zip(c.offsets(t))
            .map(|(f, offset)| FieldSchema {
                name: f.name.clone(),
                offset,
                ty: kind(c, &f.ty),
            })
            .collect(),
    }
}

/// The schema of type `type_name` from the packages on `SKILLFAB_MSG_PATH` (and the shipped
/// catalog they may refer to): `Ok(None)` if no package declares it, `Err` if a message file
/// on the path is wrong (its path and line).
pub fn find_schema(type_name: &str) -> Result<Option<MessageSchema>, skillfab_msggen::Error> {
    let (c, _) = catalog(&msg_path())?;
    Ok(c.get(type_name).map(|t| schema(&c, t)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_schemas_of_the_message_files_are_the_rust_types_layouts() {
        let (c, _) = catalog(&[]).unwrap();
        for t in crate::registry() {
            let from_file = c.get(t.type_name).map(|m| schema(&c, m));
            assert_eq!(from_file, Some((t.schema)()), "{}", t.type_name);
        }
        assert_eq!(c.types.len(), crate::registry().len());
    }
}
