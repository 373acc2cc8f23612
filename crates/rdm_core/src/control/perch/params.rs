//! Parameters of the perching QP. Defaults are Table VII; the rest are named assumptions.

use super::error::ParamError;
use crate::PERCH_ROTORS;

/// Which solver answers the perching QP of eq. (49).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum PerchSolver {
    /// Dense dual active-set solver on the reduced problem (eq. 38 eliminated), warm-started
    /// from the previous tick's active set; Clarabel answers when it hits its iteration cap
    /// or is numerically unsure (counted as a fallback).
    #[default]
    ActiveSet,
    /// Clarabel's interior-point method on the full problem, every tick.
    Clarabel,
}

impl PerchSolver {
    /// Stable snake_case name (`"active_set"`, `"clarabel"`).
    pub fn as_str(self) -> &'static str {
        match self {
            PerchSolver::ActiveSet => "active_set",
            PerchSolver::Clarabel => "clarabel",
        }
    }

    /// Parse [`Self::as_str`]'s names.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "active_set" => Some(PerchSolver::ActiveSet),
            "clarabel" => Some(PerchSolver::Clarabel),
            _ => None,
        }
    }
}

/// Parameters of eqs. (37)-(49) and of the solver.
#[derive(Clone, Debug, PartialEq)]
pub struct PerchParams {
    /// Diagonal of the thrust weight `N` of eq. (37) (Table VII: all 1.0). Must be > 0.
    pub weight: [f64; PERCH_ROTORS],
    /// Diagonal of `U_mask` of eq. (38) over the wrench `[F_z, M_x, M_y, M_z]` (Table VII:
    /// only `F_z`). A masked-out component is not controlled: it is fixed to its measured value.
    pub wrench_mask: [bool; 4],
    /// Rotors used for perching: `Q̄_perch = Q̄_foot diag(perch_rotors)` (Table VII:
    /// `diag[1, 1, 0, 0]`, the two foot rotors).
    pub perch_rotors: [bool; PERCH_ROTORS],
    /// `ε_z` of eq. (39) [N] (Table VII: 1.0).
    pub epsilon_z: f64,
    /// `μ_x` of eq. (40) (Table VII: 0.9).
    pub mu_x: f64,
    /// `μ_y` of eq. (40) (Table VII: 0.9; the paper prints `μ_x` for both, eq. 13 has `μ_j`).
    pub mu_y: f64,
    /// Rotational friction coefficient `μ_z` of eq. (41) [m] (Table VII: 0.5).
    pub mu_z: f64,
    /// Half-length `H_x` of the footplate, eq. (42) [m] (Table VII: 0.04).
    pub half_size_x: f64,
    /// Half-length `H_y` of the footplate, eq. (42) [m] (Table VII: 0.07).
    pub half_size_y: f64,
    /// `p_ZMP_z` of eqs. (43)-(44): height of the contact surface above the moment reference
    /// point along the pressing direction [m] (the plane's `d`, [`super::plane`]).
    /// Not given by the paper; 0.0 because the foot frame origin is on the footplate (Sec. III).
    pub zmp_z: f64,
    /// Outward unit normal of the contact surface in foot axes (from the surface towards the
    /// robot). The paper's ceiling: `(0, 0, −1)` ([`super::plane::CEILING_NORMAL`]); a wall
    /// in front of the foot's +x face: `(−1, 0, 0)`. Eqs. (39)-(44) hold in its plane.
    pub contact_normal: [f64; 3],
    /// Centre of the footplate's contact face in the foot frame [m]: the reference point of
    /// the moments and the ZMP (the ceiling face: the foot origin, `(0, 0, 0)`).
    pub contact_center: [f64; 3],
    /// `δλ_perch` of eq. (48): largest thrust change per tick [N] (Table VII: 5.0 each).
    pub thrust_rate_limit: [f64; PERCH_ROTORS],
    /// `λ_rotor_max` of eq. (47): maximum thrust of each rotor [N]. Not given by the paper;
    /// 30 N is a placeholder to be replaced by the rotor's measured thrust curve.
    pub rotor_thrust_max: [f64; PERCH_ROTORS],
    /// Gain of the feedback term `λ''` of eq. (38) (the paper's is 1; 0 disables it).
    pub feedback_gain: f64,
    /// Gravity `g` of eq. (47) [m/s²].
    pub gravity: f64,
    /// Solver of eq. (49) (default: the active-set solver with Clarabel as fallback).
    pub solver: PerchSolver,
    /// Add/drop passes allowed to the active-set solver before Clarabel takes over.
    pub active_set_max_iter: u32,
    /// Clarabel iteration cap (a tick that needs more is a `MaxIterations` failure).
    pub max_iter: u32,
    /// Clarabel gap and feasibility tolerance (scaled problem).
    pub tolerance: f64,
    /// Our improvement (not in the paper): when eq. (49) is infeasible, solve it again
    /// without the rate limit of eq. (48) and, if that is feasible, move the thrust toward
    /// its solution by at most `δλ_perch` ([`super::PerchStatus::RateLimited`]). Without it
    /// an `ε_z` beyond one rate step from zero thrust (ε_z > 2 δλ_perch with two perch
    /// rotors) is infeasible on every tick and the held thrust never presses (latch-up).
    pub relax_rate_limit: bool,
}

impl Default for PerchParams {
    fn default() -> Self {
        Self {
            weight: [1.0; PERCH_ROTORS],
            wrench_mask: [true, false, false, false],
            perch_rotors: [true, true, false, false],
            epsilon_z: 1.0,
            mu_x: 0.9,
            mu_y: 0.9,
            mu_z: 0.5,
            half_size_x: 0.04,
            half_size_y: 0.07,
            zmp_z: 0.0,
            contact_normal: super::plane::CEILING_NORMAL,
            contact_center: [0.0; 3],
            thrust_rate_limit: [5.0; PERCH_ROTORS],
            rotor_thrust_max: [30.0; PERCH_ROTORS],
            feedback_gain: 1.0,
            gravity: 9.80665,
            solver: PerchSolver::ActiveSet,
            active_set_max_iter: 50,
            max_iter: 50,
            tolerance: 1e-8,
            relax_rate_limit: true,
        }
    }
}

fn positive(field: &'static str, v: f64) -> Result<(), ParamError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(ParamError {
            field,
            reason: "must be finite and > 0",
        })
    }
}

impl PerchParams {
    /// Check every field; the error names the first field at fault.
    pub fn validate(&self) -> Result<(), ParamError> {
        for w in self.weight {
            positive("weight", w)?;
        }
        for d in self.thrust_rate_limit {
            positive("thrust_rate_limit", d)?;
        }
        for m in self.rotor_thrust_max {
            positive("rotor_thrust_max", m)?;
        }
        positive("epsilon_z", self.epsilon_z)?;
        positive("mu_x", self.mu_x)?;
        positive("mu_y", self.mu_y)?;
        positive("mu_z", self.mu_z)?;
        positive("half_size_x", self.half_size_x)?;
        positive("half_size_y", self.half_size_y)?;
        positive("gravity", self.gravity)?;
        positive("tolerance", self.tolerance)?;
        if !self.zmp_z.is_finite() {
            return Err(ParamError {
                field: "zmp_z",
                reason: "must be finite",
            });
        }
        super::plane::ContactPlane::new(self.contact_normal, self.contact_center)?;
        if !(self.feedback_gain.is_finite() && self.feedback_gain >= 0.0) {
            return Err(ParamError {
                field: "feedback_gain",
                reason: "must be finite and >= 0",
            });
        }
        if !self.wrench_mask[0] {
            // F_z,t must be a decision variable: eqs. (39)-(44) bound it from below.
            return Err(ParamError {
                field: "wrench_mask",
                reason: "F_z (first entry) must be controlled",
            });
        }
        if !self.perch_rotors.iter().any(|r| *r) {
            return Err(ParamError {
                field: "perch_rotors",
                reason: "needs at least one rotor",
            });
        }
        if self.max_iter == 0 || self.max_iter > 500 {
            return Err(ParamError {
                field: "max_iter",
                reason: "must be in 1..=500",
            });
        }
        if self.active_set_max_iter == 0 || self.active_set_max_iter > 500 {
            return Err(ParamError {
                field: "active_set_max_iter",
                reason: "must be in 1..=500",
            });
        }
        Ok(())
    }

    /// Scale of every decision variable: the largest rotor thrust, so scaled values are O(1).
    pub fn variable_scale(&self) -> f64 {
        self.rotor_thrust_max.iter().fold(0.0_f64, |a, b| a.max(*b))
    }
}
