//! Typed errors of the model: description problems (at load time) and evaluation problems
//! (bad runtime input). Neither ever panics; both name what is at fault.

use std::fmt;

/// What is wrong with a robot description.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DescriptionErrorKind {
    /// The file could not be read.
    Io,
    /// Malformed XML or TOML (syntax, or a missing/ill-typed TOML field).
    Syntax,
    /// A required element or attribute is absent.
    Missing,
    /// A number is NaN or infinite.
    NonFinite,
    /// A mass or inertia is negative, or an inertia tensor is not physical.
    NegativeMass,
    /// A reference to a link, joint or rotor that does not exist.
    UnknownReference,
    /// A value is outside its meaningful range (zero axis, min > max, spin not +-1, ...).
    InvalidValue,
    /// The kinematic tree is not a tree (several roots, cycles, duplicate names).
    Structure,
}

/// A description error naming the file and the field at fault.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DescriptionError {
    /// File (or source name) the problem is in.
    pub file: String,
    /// Element/field path, e.g. `link 'root_link' <inertial>/<mass>`.
    pub field: String,
    /// Category, for programmatic handling.
    pub kind: DescriptionErrorKind,
    /// Human-readable explanation.
    pub message: String,
}

impl DescriptionError {
    pub(crate) fn new(
        file: &str,
        field: impl Into<String>,
        kind: DescriptionErrorKind,
        message: impl Into<String>,
    ) -> Self {
        Self {
            file: file.to_owned(),
            field: field.into(),
            kind,
            message: message.into(),
        }
    }
}

impl fmt::Display for DescriptionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.field.is_empty() {
            write!(f, "{}: {}", self.file, self.message)
        } else {
            write!(f, "{}: {}: {}", self.file, self.field, self.message)
        }
    }
}

impl std::error::Error for DescriptionError {}

/// Bad input to a model evaluation.
#[derive(Clone, Debug, PartialEq)]
pub enum ModelError {
    /// An array has the wrong length (`what` names the argument).
    WrongLength {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    /// An input contains NaN or infinity (`what` names the argument, `index` the element).
    NonFinite { what: &'static str, index: usize },
    /// No frame of this name (frames are `world`, `cog`, link names, rotor names and the
    /// TOML's named frames such as `foot` and `end_effector`).
    UnknownFrame(String),
    /// No vectoring apparatus with this index.
    UnknownUnit(usize),
    /// The workspace was built for another robot (link/rotor/joint counts differ).
    WorkspaceMismatch,
    /// A query needs `evaluate` to have succeeded on this workspace first.
    NotEvaluated,
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::WrongLength {
                what,
                expected,
                got,
            } => write!(f, "{what}: expected {expected} values, got {got}"),
            Self::NonFinite { what, index } => {
                write!(f, "{what}: element {index} is NaN or infinite")
            }
            Self::UnknownFrame(name) => write!(f, "unknown frame '{name}'"),
            Self::UnknownUnit(i) => write!(f, "unknown vectoring apparatus index {i}"),
            Self::WorkspaceMismatch => write!(f, "workspace was built for another robot"),
            Self::NotEvaluated => write!(f, "workspace holds no successful evaluation yet"),
        }
    }
}

impl std::error::Error for ModelError {}

/// Check that every element of `values` is finite.
pub(crate) fn check_finite(what: &'static str, values: &[f64]) -> Result<(), ModelError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(ModelError::NonFinite { what, index }),
        None => Ok(()),
    }
}

/// Check length and finiteness of an input slice.
pub(crate) fn check_input(
    what: &'static str,
    values: &[f64],
    expected: usize,
) -> Result<(), ModelError> {
    if values.len() != expected {
        return Err(ModelError::WrongLength {
            what,
            expected,
            got: values.len(),
        });
    }
    check_finite(what, values)
}
