//! Perching controller of Sec. IV-B (eqs. 37-49) with the foot-wrench filter of Sec. VII-B.
//!
//! - [`params`]: Table VII parameters and the ones the paper leaves out.
//! - [`filter`]: the 1 Hz first-order IIR low-pass on the measured foot wrench.
//! - [`dims`]: the QP's size (variables, equality rows, rows).
//! - [`plane`]: the contact plane (normal, face centre) eqs. (39)-(44) are written in.
//! - [`qp`]: the QP of eq. (49): row builder, solver choice, safe command.
//! - [`reduced`]: eq. (38) eliminated, the cost made `½‖y‖²` (4 thrust variables).
//! - [`active_set`]: the dense dual active-set solver (default, allocation-free).
//! - Clarabel (one solver built once, fixed sparsity) as the alternative and the fallback.
//! - [`status`]: typed outcome of a tick and the failure counters.
//! - [`controller`]: filter + QP + the state carried from tick to tick.
//!
//! The exact formulation (decision vector, cost, every constraint row with its equation
//! number) is written out in `docs/perch.md` and next to the row builder in [`qp`].

pub mod active_set;
pub mod controller;
pub mod dims;
pub mod error;
pub mod filter;
pub mod params;
pub mod plane;
pub mod qp;
pub mod reduced;
pub mod status;

pub use controller::PerchController;
pub use dims::{N_ROWS, N_VARS, N_ZERO_ROWS};
pub use error::ParamError;
pub use filter::WrenchFilter;
pub use params::{PerchParams, PerchSolver};
pub use plane::{ContactPlane, CEILING_NORMAL};
pub use qp::{PerchInput, PerchQp, PerchSolution};
pub use status::{PerchCounters, PerchStatus};
