//! Typed, bounded skill parameters.
//!
//! A skill's parameters are a struct deriving [`Params`](crate::prelude::Params): each field
//! has a default, optional bounds and a doc comment. The SDK validates every value, at start-up
//! (`--param k=v`) and on every change at run time; unknown names are refused.

pub use skillfab_proto::param::{
    ParamError, ParamKind, ParamSpec, ParamType, ParamValue, check_bounds,
};

/// A parameter struct. Derive it; do not implement it by hand.
pub trait Params: Clone + Send + 'static {
    /// Every declared parameter.
    fn specs(&self) -> Vec<ParamSpec>;
    /// The current value of `name`.
    fn get(&self, name: &str) -> Option<ParamValue>;
    /// Stores a value without bound checks (generated); use [`Params::set`].
    fn set_unchecked(&mut self, name: &str, value: ParamValue) -> Result<(), ParamError>;

    /// Sets `name` after checking its type and bounds. On error nothing changes.
    fn set(&mut self, name: &str, value: ParamValue) -> Result<(), ParamError> {
        let spec = self
            .specs()
            .into_iter()
            .find(|s| s.name == name)
            .ok_or_else(|| ParamError::Unknown {
                param: name.to_string(),
            })?;
        check_bounds(&spec, value)?;
        let mut next = self.clone();
        next.set_unchecked(name, value)?;
        *self = next;
        Ok(())
    }

    /// Applies `name=value` text, parsed by the parameter's declared type.
    fn assign(&mut self, assignment: &str) -> Result<(), ParamError> {
        let (name, text) = assignment
            .split_once('=')
            .ok_or_else(|| ParamError::Malformed {
                text: assignment.to_string(),
            })?;
        let name = name.trim();
        let spec = self
            .specs()
            .into_iter()
            .find(|s| s.name == name)
            .ok_or_else(|| ParamError::Unknown {
                param: name.to_string(),
            })?;
        let value = ParamValue::parse(spec.kind, text).ok_or_else(|| ParamError::Unparsable {
            param: name.to_string(),
            expected: spec.kind,
            text: text.to_string(),
        })?;
        self.set(name, value)
    }

    /// Every parameter with its current value.
    fn values(&self) -> Vec<(String, ParamValue)> {
        self.specs()
            .into_iter()
            .filter_map(|s| self.get(&s.name).map(|v| (s.name, v)))
            .collect()
    }
}

/// A skill without parameters.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoParams;

impl Params for NoParams {
    fn specs(&self) -> Vec<ParamSpec> {
        Vec::new()
    }
    fn get(&self, _: &str) -> Option<ParamValue> {
        None
    }
    fn set_unchecked(&mut self, name: &str, _: ParamValue) -> Result<(), ParamError> {
        Err(ParamError::Unknown {
            param: name.to_string(),
        })
    }
}
