//! What the manager checks of a parameter value, an output path or a monitor expression, from
//! the skills' declarations alone. Pure code: a request is checked with it before the manager
//! acts (control), and a plan before it runs (`skillfab sequence --check`, against a launch
//! file's skills or a running domain's), so the two cannot disagree.

use crate::monitors::expr::{self, Expr, PathRef};
use skillfab_proto::control::{ControlError, ParamArg, shorten};
use skillfab_proto::decl::{PortDecl, SkillDecl};
use skillfab_proto::param::{ParamError, ParamSpec, ParamValue, check_bounds};
use skillfab_proto::schema::FieldKind;
use skillfab_proto::value::{self, FieldPath, PathError};

/// The value `arg` gives parameter `param` of the skill declared by `decl`, checked against its
/// declared type and bounds; with the parameter's declaration.
pub fn param_value<'d>(
    decl: &'d SkillDecl,
    param: &str,
    arg: ParamArg,
) -> Result<(ParamValue, &'d ParamSpec), ParamError> {
    let spec = decl
        .params
        .iter()
        .find(|p| p.name == param)
        .ok_or_else(|| ParamError::Unknown {
            param: param.into(),
        })?;
    let value = match arg {
        ParamArg::Text(t) => {
            ParamValue::parse(spec.kind, &t).ok_or_else(|| ParamError::Unparsable {
                param: param.into(),
                expected: spec.kind,
                text: shorten(&t, 120),
            })?
        }
        ParamArg::Value(v) => v.coerce(spec.kind).ok_or_else(|| ParamError::WrongType {
            param: param.into(),
            expected: spec.kind,
            got: v,
        })?,
    };
    check_bounds(spec, value)?;
    Ok((value, spec))
}

/// The output port `output` of the skill declared by `decl` and the field `field` of its
/// message (empty: the whole message).
pub fn output_field<'d>(
    decl: &'d SkillDecl,
    output: &str,
    field: &str,
) -> Result<(&'d PortDecl, FieldPath), PathError> {
    let port = decl
        .outputs
        .iter()
        .find(|p| p.port == output)
        .ok_or_else(|| PathError::NoOutput {
            skill: decl.name.clone(),
            output: output.into(),
            outputs: decl.outputs.iter().map(|p| p.port.clone()).collect(),
        })?;
    Ok((port, value::resolve(&port.schema, field)?))
}

/// A plain path must name one number; inside min()/max() an array or range of numbers.
pub fn check_numeric(f: &FieldPath, aggregate: bool) -> Result<(), PathError> {
    let prim = |k: &FieldKind| matches!(k, FieldKind::Prim(_));
    match (aggregate, &f.kind, f.count) {
        (false, k, None) if prim(k) => Ok(()),
        (false, _, _) => Err(PathError::NotOneNumber),
        (true, k, Some(_)) if prim(k) => Ok(()),
        (true, FieldKind::Array { elem, .. }, None) if prim(elem) => Ok(()),
        (true, _, _) => Err(PathError::NotNumbers),
    }
}

/// Whether `p` is read as a plain number somewhere in `e` (not only inside min()/max()).
pub fn read_as_number(e: &Expr, p: &PathRef) -> bool {
    use expr::Expr::*;
    match e {
        Path(q) => q == p,
        Min(_) | Max(_) | Num(_) | Bool(_) => false,
        Neg(x) | Not(x) => read_as_number(x, p),
        Arith(_, l, r) | Cmp(_, l, r) | And(l, r) | Or(l, r) => {
            read_as_number(l, p) || read_as_number(r, p)
        }
    }
}

/// Parses a monitor expression and checks every path it reads against the declarations
/// `decl_of` gives by skill name: the skill, its output, the field, a number where one is
/// compared and numbers inside min()/max().
pub fn expression<'d>(
    text: &str,
    decl_of: &dyn Fn(&str) -> Option<&'d SkillDecl>,
) -> Result<Expr, ControlError> {
    let parsed = expr::parse(text).map_err(|error| ControlError::BadExpression {
        expr: shorten(text, 120),
        error,
    })?;
    for p in expr::paths(&parsed) {
        let decl = decl_of(&p.skill).ok_or_else(|| ControlError::UnknownSkill(p.skill.clone()))?;
        let bad = |error| ControlError::BadPath {
            path: p.text.clone(),
            error,
        };
        let (_, field) = output_field(decl, &p.output, &p.field).map_err(bad)?;
        check_numeric(&field, !read_as_number(&parsed, p)).map_err(bad)?;
    }
    Ok(parsed)
}
