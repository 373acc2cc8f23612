//! The refusal of a perching parameter: the field at fault and the rule it breaks (shared by
//! the parameter set and the contact plane).

/// A parameter that cannot be used, with the name of the field at fault.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamError {
    /// Field name in [`super::PerchParams`].
    pub field: &'static str,
    /// Why it was refused.
    pub reason: &'static str,
}

impl core::fmt::Display for ParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "perch parameter `{}`: {}", self.field, self.reason)
    }
}

impl std::error::Error for ParamError {}
