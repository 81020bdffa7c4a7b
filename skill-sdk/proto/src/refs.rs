//! Typed references: a parameter, a port or a message field by name *and* type.
//!
//! The derives of skill-sdk generate one for each field of the struct they derive, as an
//! associated const named after the field in upper case:
//!
//! | derive | field | reference |
//! |---|---|---|
//! | `Params` on `GoParams` | `speed: f64` | `GoParams::SPEED: Param<f64, GoParams>` |
//! | `Inputs` on `In<'a>` | `sonar: Input<'a, Sonar>` | `In::SONAR: InputRef<Sonar, In<'static>>` |
//! | `Outputs` on `Out<'a>` | `drive: Proposal<'a, Drive>` | `Out::DRIVE: OutputRef<Drive, Out<'static>>` |
//! | `Message` on `Odometry` | `x: f64` | `Odometry::X: Field<f64, Odometry>` |
//!
//! A reference is its name (the text the fabric matches) with two types the compiler checks:
//! the value's (`T`) and the struct it was declared in (`Of`). Renaming a field renames its
//! reference, so code naming the old one stops compiling instead of failing at run time. The
//! test harness takes only the references of the skill it runs; the client (which addresses
//! skill *instances*, named by launch files) takes any, and checks the value types:
//! `client.set("go", GoParams::SPEED, 0.3)`, `client.read("odometry",
//! OdometryOut::ODOM.field(Odometry::X))` (a [`ValuePath`]).
//!
//! A skill declared at run time (C, C++, Python) has no Rust types: a Rust sequencer
//! declares the references it needs by hand, `const GAIN: Param<f64> = Param::new("gain");`
//! (`Of` is then `()`).

use std::fmt;
use std::marker::PhantomData;

/// `fn() -> (T, Of)`: the reference holds no `T` or `Of` (it is `Copy`, `Send` and `Sync`
/// whatever they are) yet is typed by both.
type Marker<T, Of> = PhantomData<fn() -> (T, Of)>;

/// The common items of the reference types (written once, for four types that differ only by
/// what they name).
macro_rules! reference {
    ($(#[$doc:meta])* $name:ident<T, Of $(= $default:ty)?>, $what:literal) => {
        $(#[$doc])*
        pub struct $name<T, Of $(= $default)?> {
            name: &'static str,
            of: Marker<T, Of>,
        }

        impl<T, Of> $name<T, Of> {
            #[doc = concat!("The ", $what, " named `name` (the derives make these).")]
            pub const fn new(name: &'static str) -> Self {
                $name {
                    name,
                    of: PhantomData,
                }
            }

            #[doc = concat!("The ", $what, "'s name, as the fabric and `skillfab ctl` spell it.")]
            pub const fn name(&self) -> &'static str {
                self.name
            }
        }

        // By hand: derived impls would require `T` and `Of` to be `Clone`, `Debug`, ...
        impl<T, Of> Clone for $name<T, Of> {
            fn clone(&self) -> Self {
                *self
            }
        }
        impl<T, Of> Copy for $name<T, Of> {}
        impl<T, Of> PartialEq for $name<T, Of> {
            fn eq(&self, other: &Self) -> bool {
                self.name == other.name
            }
        }
        impl<T, Of> Eq for $name<T, Of> {}
        impl<T, Of> std::hash::Hash for $name<T, Of> {
            fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
                self.name.hash(state);
            }
        }
        impl<T, Of> fmt::Debug for $name<T, Of> {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(
                    f,
                    "{}<{}>({:?})",
                    stringify!($name),
                    std::any::type_name::<T>(),
                    self.name
                )
            }
        }
        /// The name.
        impl<T, Of> fmt::Display for $name<T, Of> {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.name)
            }
        }
    };
}

reference!(
    /// A parameter of type `T` of the parameter struct `Of` (`#[derive(Params)]`).
    Param<T, Of = ()>,
    "parameter"
);
reference!(
    /// An input port carrying message type `T`, of the input struct `Of` (`#[derive(Inputs)]`,
    /// with `'static` for its lifetime). Not an [`OutputRef`]: a test cannot feed an output.
    InputRef<T, Of = ()>,
    "input port"
);
reference!(
    /// An output port carrying message type `T`, of the output struct `Of`
    /// (`#[derive(Outputs)]`, with `'static` for its lifetime): an `Output` or a `Proposal`.
    OutputRef<T, Of = ()>,
    "output port"
);
reference!(
    /// A field of type `T` of the message type `Of` (`#[derive(Message)]`), for
    /// [`ValuePath::field`].
    Field<T, Of>,
    "field"
);

impl<M, Of> OutputRef<M, Of> {
    /// The path of `field` in this output's message: `port.field`.
    pub fn field<T>(self, field: Field<T, M>) -> ValuePath<T> {
        ValuePath::from(self).field(field)
    }
}

/// A value of a skill's output with its type: `port[.field][index]`, built from references
/// (`OdometryOut::ODOM.field(Odometry::X)`, `SonarOut::SONAR.field(Sonar::RANGE).at(3)`; an
/// [`OutputRef`] itself is the path of the whole message). A client reads it from a skill
/// instance (`Client::read("odometry", path)`). Its text does not name the instance: a
/// monitor's expression puts it in front, `format!("odometry.{path} > 2.0")`.
pub struct ValuePath<T> {
    text: String,
    of: Marker<T, ()>,
}

impl<T> ValuePath<T> {
    /// Field `field` of the value (a message).
    pub fn field<F>(self, field: Field<F, T>) -> ValuePath<F> {
        ValuePath {
            text: format!("{}.{}", self.text, field.name()),
            of: PhantomData,
        }
    }

    /// The path's text, `port[.field][index]`.
    pub fn as_str(&self) -> &str {
        &self.text
    }
}

impl<T, const N: usize> ValuePath<[T; N]> {
    /// Element `index` of the value (an array). An index of `N` or more is refused where the
    /// path is resolved (the manager answers `PathError::OutOfBounds`), as in a path written
    /// out.
    pub fn at(self, index: usize) -> ValuePath<T> {
        ValuePath {
            text: format!("{}[{index}]", self.text),
            of: PhantomData,
        }
    }
}

impl<M, Of> From<OutputRef<M, Of>> for ValuePath<M> {
    fn from(port: OutputRef<M, Of>) -> Self {
        ValuePath {
            text: port.name().to_string(),
            of: PhantomData,
        }
    }
}

/// A copy: a path kept in a variable reads many times (`client.read("x", &path)`).
impl<T> From<&ValuePath<T>> for ValuePath<T> {
    fn from(path: &ValuePath<T>) -> Self {
        path.clone()
    }
}

impl<T> Clone for ValuePath<T> {
    fn clone(&self) -> Self {
        ValuePath {
            text: self.text.clone(),
            of: PhantomData,
        }
    }
}

impl<T> PartialEq for ValuePath<T> {
    fn eq(&self, other: &Self) -> bool {
        self.text == other.text
    }
}

impl<T> Eq for ValuePath<T> {}

impl<T> fmt::Debug for ValuePath<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "ValuePath<{}>({:?})",
            std::any::type_name::<T>(),
            self.text
        )
    }
}

/// `port[.field][index]`.
impl<T> fmt::Display for ValuePath<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Message;
    use skill_sdk_macros::Message;

    #[derive(Message, Debug, Clone, Copy, Default)]
    #[message(crate = "crate")]
    #[repr(C)]
    struct Point {
        x: f64,
        y: f64,
    }
    #[derive(Message, Debug, Clone, Copy, Default)]
    #[message(crate = "crate")]
    #[repr(C)]
    struct Scan {
        /// The ranges, m.
        range: [f32; 4],
        at: Point,
        /// Shares its upper-case name with the trait's const: gets no reference.
        type_name: u8,
    }
    /// An output struct's reference, as `#[derive(Outputs)]` would make it.
    struct Out;
    const SCAN: OutputRef<Scan, Out> = OutputRef::new("scan");

    #[test]
    fn paths_are_built_from_references_and_keep_the_leaf_type() {
        let whole: ValuePath<Scan> = SCAN.into();
        assert_eq!(whole.as_str(), "scan");
        let x: ValuePath<f64> = SCAN.field(Scan::AT).field(Point::X);
        assert_eq!(x.to_string(), "scan.at.x");
        let r: ValuePath<f32> = SCAN.field(Scan::RANGE).at(3);
        assert_eq!(format!("lidar.{r} < 0.5"), "lidar.scan.range[3] < 0.5");
        assert_eq!(ValuePath::from(&r), r);
    }

    #[test]
    fn field_references_resolve_against_their_schema() {
        let s = Scan::schema();
        for path in [
            SCAN.field(Scan::AT).field(Point::Y).as_str(),
            SCAN.field(Scan::RANGE).at(1).as_str(),
        ] {
            let field = path.strip_prefix("scan.").unwrap_or(path);
            assert!(crate::value::resolve(&s, field).is_ok(), "{path}");
        }
        // The trait's const keeps its name.
        assert_eq!(Scan::TYPE_NAME, "skillfab.Scan");
    }

    #[test]
    fn a_reference_shows_its_name_and_type() {
        assert_eq!(format!("{:?}", Point::X), "Field<f64>(\"x\")");
        assert_eq!(Point::Y.to_string(), "y");
        const GAIN: Param<f64> = Param::new("gain");
        assert_eq!(GAIN.name(), "gain");
        assert_eq!(GAIN, Param::new("gain"));
    }
}
