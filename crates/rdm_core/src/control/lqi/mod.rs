//! LQI attitude and altitude gain synthesis (Sec. IV-A-1, eqs. 21-29).
//!
//! [`LqiSynthesizer::synthesize`] takes the model quantities as plain inputs (mass,
//! inertia `I(q)`, allocation `Q̄(q)`), builds the augmented system of eq. (26)
//! ([`system`]), solves the ARE ([`crate::control::riccati`], warm-started from the
//! previous gains), and maps `K` onto the per-rotor [`GainSet`] Spinal applies
//! ([`gain_map`], JSK sec. 4, with `clampGain`). [`gyro`] holds eq. (29) and the
//! gyro-compensation data; [`pc_axes`] the altitude/yaw part the PC applies.

pub mod gain_map;
pub mod gyro;
pub mod pc_axes;
pub mod system;

use nalgebra::Matrix3;

use crate::control::gains::GainSet;
use crate::control::riccati::{
    CareConfig, CareError, CareReport, CareSolver, GainMatrix, InputMatrix, InputWeight,
    StateMatrix, N_STATE,
};
use crate::MAX_ROTORS;

pub use gain_map::{clamp_gain, gain_set_from_k, ClampScales, MAX_WIRE_GAIN};
pub use gyro::{flight_thrust, AllocationInverse, GyroCompensation, LqiState, RotorVector};
pub use pc_axes::{PcAxisCommand, PcAxisController, PcAxisErrors};
pub use system::{augmented_input_matrix, augmented_state_matrix, Allocation, JSK_TO_PAPER};

/// Diagonal weights `W1 = Q` (JSK state order) and `W2 = R`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LqiWeights {
    /// `diag(W1)` for `[z, ż, φ, φ̇, θ, θ̇, ψ, ψ̇, ∫z, ∫φ, ∫θ, ∫ψ]`.
    pub q: [f64; N_STATE],
    /// `diag(W2)`, one per rotor (the entries past the rotor count are not read).
    pub r: [f64; MAX_ROTORS],
}

impl LqiWeights {
    /// Table V of the paper, read as `W1` = the 12-entry diagonal in JSK order and `W2` =
    /// `diag[1, 1, 1, 1]` (the extracted table swaps the two rows; only this reading
    /// fits the matrix sizes, and its yaw entries equal the Hydrus defaults).
    pub fn table_v() -> Self {
        Self {
            q: [
                20.0, 30.0, 90.0, 12.8, 600.0, 80.0, 100.0, 50.0, 20.0, 0.15, 1.0, 0.5,
            ],
            r: [1.0; MAX_ROTORS],
        }
    }

    /// Q and R for `rotors` rotors: the R entries past the count are 1 (their columns of B
    /// are zero, so they change nothing but keep R positive definite).
    fn validate(&self, rotors: usize) -> Result<(StateMatrix, InputWeight), LqiError> {
        if crate::check_rotor_count(rotors).is_err() {
            return Err(LqiError::InvalidInput { argument: "rotors" });
        }
        if !self.q.iter().all(|w| w.is_finite() && *w >= 0.0) {
            return Err(LqiError::InvalidInput {
                argument: "weights.q",
            });
        }
        if !self.r[..rotors].iter().all(|w| w.is_finite() && *w > 0.0) {
            return Err(LqiError::InvalidInput {
                argument: "weights.r",
            });
        }
        let mut r = [1.0; MAX_ROTORS];
        r[..rotors].copy_from_slice(&self.r[..rotors]);
        Ok((
            StateMatrix::from_diagonal(&self.q.into()),
            InputWeight::from_diagonal(&r.into()),
        ))
    }
}

impl Default for LqiWeights {
    fn default() -> Self {
        Self::table_v()
    }
}

/// Synthesis configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LqiConfig {
    /// Rotor count, `1..=MAX_ROTORS` (the inputs of the ARE).
    pub rotors: usize,
    /// ARE weights.
    pub weights: LqiWeights,
    /// Apply JSK `clampGain` to the gain set (JSK default: true).
    pub clamp_gain: bool,
    /// ARE solver bounds.
    pub care: CareConfig,
}

impl LqiConfig {
    /// The default configuration for `rotors` rotors.
    pub fn for_rotors(rotors: usize) -> Self {
        Self {
            rotors,
            ..Self::default()
        }
    }
}

impl Default for LqiConfig {
    /// Table V weights for the paper's four-rotor RDM.
    fn default() -> Self {
        Self {
            rotors: 4,
            weights: LqiWeights::table_v(),
            clamp_gain: true,
            care: CareConfig::default(),
        }
    }
}

/// Why a synthesis failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LqiError {
    /// A model input or weight is NaN/inf or out of its domain.
    InvalidInput {
        /// Name of the offending argument (`"mass"`, `"inertia"`, `"allocation"`, ...).
        argument: &'static str,
    },
    /// `Q̄` has no usable (pseudo-)inverse (all zero or SVD failed).
    SingularAllocation,
    /// The ARE solver failed (e.g. `Q̄` rank deficient makes the system not stabilisable).
    Care(CareError),
}

impl core::fmt::Display for LqiError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::InvalidInput { argument } => write!(f, "invalid LQI input `{argument}`"),
            Self::SingularAllocation => write!(f, "allocation matrix has no pseudo-inverse"),
            Self::Care(e) => write!(f, "LQI synthesis: {e}"),
        }
    }
}

impl std::error::Error for LqiError {}

impl From<CareError> for LqiError {
    fn from(e: CareError) -> Self {
        Self::Care(e)
    }
}

/// Result of one synthesis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LqiGains {
    /// Optimal gain `K = −R⁻¹B̄ᵀP` (`λ̄ = K x̄`), MAX_ROTORS x 12 (rows past the rotor
    /// count zero).
    pub k: GainMatrix,
    /// Stabilising ARE solution.
    pub p: StateMatrix,
    /// `B̄(q)` the gains were computed for.
    pub b: InputMatrix,
    /// Per-rotor gains after the sec. 4 mapping (and `clampGain` if enabled).
    pub gains: GainSet,
    /// Factors `clampGain` applied (all 1 when disabled or not needed).
    pub clamp_scales: ClampScales,
    /// How the ARE was solved.
    pub report: CareReport,
}

impl Default for LqiGains {
    fn default() -> Self {
        Self {
            k: GainMatrix::zeros(),
            p: StateMatrix::zeros(),
            b: InputMatrix::zeros(),
            gains: GainSet::default(),
            clamp_scales: ClampScales::default(),
            report: CareReport {
                method: crate::control::riccati::CareMethod::SignFunction,
                iterations: 0,
                fell_back: false,
                relative_residual: 0.0,
            },
        }
    }
}

/// Solved results a synthesizer keeps (the last one included). A holding robot's joint
/// reading flickers between two encoder counts, so its `B̄(q)` alternates between two values;
/// each return to one was a whole CARE solve on the 40 Hz tick before these were kept.
pub const KEPT_SOLUTIONS: usize = 4;

/// Stateful gain synthesizer: keeps its workspace and the last solutions (warm start).
///
/// The gains are a function of the problem: A, Q and R are fixed per synthesizer, so a call
/// whose `B̄(q)` (eq. 25) is bitwise one of the last [`KEPT_SOLUTIONS`] solved returns that
/// solution unchanged instead of solving again. A re-solve from its own warm start would move
/// the last bits of the gains each time (Kleinman's fixed point is not exact in floating
/// point) and costs a whole CARE solve on the 40 Hz tick, while the robot holds a
/// configuration.
#[derive(Clone, Debug)]
pub struct LqiSynthesizer {
    config: LqiConfig,
    a: StateMatrix,
    q: StateMatrix,
    r: InputWeight,
    solver: CareSolver,
    last: LqiGains,
    /// The last solved results, a ring (`kept_len` valid, `kept_next` the slot to write).
    kept: [LqiGains; KEPT_SOLUTIONS],
    kept_len: usize,
    kept_next: usize,
    reused: u64,
    changes: u64,
}

impl LqiSynthesizer {
    /// Validates the rotor count and the weights once; synthesis then allocates nothing.
    pub fn new(config: LqiConfig) -> Result<Self, LqiError> {
        let (q, r) = config.weights.validate(config.rotors)?;
        Ok(Self {
            config,
            a: augmented_state_matrix(),
            q,
            r,
            solver: CareSolver::new(config.care),
            last: LqiGains::default(),
            kept: [LqiGains::default(); KEPT_SOLUTIONS],
            kept_len: 0,
            kept_next: 0,
            reused: 0,
            changes: 0,
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &LqiConfig {
        &self.config
    }

    /// The last successful result (`None` before the first).
    pub fn last(&self) -> Option<&LqiGains> {
        self.solver.has_solution().then_some(&self.last)
    }

    /// Drops the warm start and the kept solutions: the next synthesis solves cold.
    pub fn reset(&mut self) {
        self.solver.reset();
        self.kept_len = 0;
        self.kept_next = 0;
    }

    /// Calls answered with a kept solution because their `B̄` was bitwise its own.
    pub fn reused(&self) -> u64 {
        self.reused
    }

    /// How often [`Self::last`] became another result (a solve, or a kept solution other
    /// than the last one): unchanged, the last result is the same one.
    pub fn changes(&self) -> u64 {
        self.changes
    }

    /// Synthesizes the gains for one configuration (warm-started after the first call; a
    /// kept result itself when `B̄` is bitwise one solved before, see [`Self::reused`]).
    /// On error the previous gains stay available through [`Self::last`].
    pub fn synthesize(
        &mut self,
        mass: f64,
        inertia: &Matrix3<f64>,
        allocation: &Allocation,
    ) -> Result<&LqiGains, LqiError> {
        let b = augmented_input_matrix(mass, inertia, allocation, self.config.rotors)?;
        if self.solver.has_solution() {
            if same_bits(&b, &self.last.b) {
                self.reused += 1;
                return Ok(&self.last);
            }
            let kept = &self.kept[..self.kept_len];
            if let Some(hit) = kept.iter().find(|g| same_bits(&b, &g.b)) {
                self.last = *hit;
                self.reused += 1;
                self.changes += 1;
                return Ok(&self.last);
            }
        }
        let report = self.solver.solve(&self.a, &b, &self.q, &self.r)?;
        let k = *self.solver.k();
        let mut gains = gain_set_from_k(&k);
        let clamp_scales = if self.config.clamp_gain {
            clamp_gain(&mut gains)
        } else {
            ClampScales::default()
        };
        self.last = LqiGains {
            k,
            p: *self.solver.p(),
            b,
            gains,
            clamp_scales,
            report,
        };
        self.kept[self.kept_next] = self.last;
        self.kept_next = (self.kept_next + 1) % KEPT_SOLUTIONS;
        self.kept_len = (self.kept_len + 1).min(KEPT_SOLUTIONS);
        self.changes += 1;
        Ok(&self.last)
    }
}

/// Bitwise equality (a NaN never matches; -0.0 and 0.0 differ).
fn same_bits(a: &InputMatrix, b: &InputMatrix) -> bool {
    a.iter()
        .zip(b.iter())
        .all(|(x, y)| x.to_bits() == y.to_bits())
}
