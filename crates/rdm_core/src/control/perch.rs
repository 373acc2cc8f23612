//! See [crate::control].
