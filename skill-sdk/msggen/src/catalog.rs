//! A checked set of message types and their C layout.

use crate::{Base, Error, MsgType, Package};

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
