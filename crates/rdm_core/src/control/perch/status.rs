//! Typed outcome of one perching tick and the counters of every outcome.

/// What happened in one perching tick.
///
/// Every status other than [`PerchStatus::Solved`], [`PerchStatus::AlmostSolved`] and
/// [`PerchStatus::RateLimited`] means the thrust is the documented safe command (see
/// `PerchQp::safe_thrust`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PerchStatus {
    /// The active-set solver's KKT check passed, or Clarabel converged to the requested
    /// tolerances.
    Solved,
    /// Clarabel converged to its reduced tolerances; the thrust is used after clipping to
    /// the bounds of eqs. (45) and (48).
    AlmostSolved,
    /// The constraints of eq. (49) have no common point (the active-set solver's Farkas
    /// certificate, or Clarabel's infeasibility certificate).
    Infeasible,
    /// Clarabel's iteration cap (`PerchParams::max_iter`) was reached (the active-set
    /// solver's cap hands over to Clarabel instead).
    MaxIterations,
    /// Clarabel stopped on a numerical error or lack of progress, or returned a non-finite point.
    NumericalError,
    /// An input (wrench, thrust, allocation, mass) was NaN or infinite.
    NonFiniteInput,
    /// `Q̄(q)` of eq. (47) is singular, or every controlled row of `Q̄_perch` is zero.
    SingularAllocation,
    /// An input outside its physical range (a mass not above 0): the safe command.
    InvalidInput,
    /// Eq. (49) was infeasible only because of the rate limit of eq. (48) (our improvement,
    /// `PerchParams::relax_rate_limit`): the problem without it was solved and the thrust
    /// moves toward that solution by at most `δλ_perch` (e.g. a press `ε_z` larger than one
    /// step can reach from zero thrust).
    RateLimited,
}

impl PerchStatus {
    /// All statuses in counter order.
    pub const ALL: [PerchStatus; 9] = [
        PerchStatus::Solved,
        PerchStatus::AlmostSolved,
        PerchStatus::Infeasible,
        PerchStatus::MaxIterations,
        PerchStatus::NumericalError,
        PerchStatus::NonFiniteInput,
        PerchStatus::SingularAllocation,
        PerchStatus::RateLimited,
        PerchStatus::InvalidInput,
    ];

    /// True when the thrust comes from the QP solution rather than the safe command.
    pub fn is_solution(self) -> bool {
        matches!(
            self,
            PerchStatus::Solved | PerchStatus::AlmostSolved | PerchStatus::RateLimited
        )
    }

    /// Stable snake_case name (used by the bindings and logs).
    pub fn as_str(self) -> &'static str {
        match self {
            PerchStatus::Solved => "solved",
            PerchStatus::AlmostSolved => "almost_solved",
            PerchStatus::Infeasible => "infeasible",
            PerchStatus::MaxIterations => "max_iterations",
            PerchStatus::NumericalError => "numerical_error",
            PerchStatus::NonFiniteInput => "non_finite_input",
            PerchStatus::SingularAllocation => "singular_allocation",
            PerchStatus::RateLimited => "rate_limited",
            PerchStatus::InvalidInput => "invalid_input",
        }
    }

    fn index(self) -> usize {
        match self {
            PerchStatus::Solved => 0,
            PerchStatus::AlmostSolved => 1,
            PerchStatus::Infeasible => 2,
            PerchStatus::MaxIterations => 3,
            PerchStatus::NumericalError => 4,
            PerchStatus::NonFiniteInput => 5,
            PerchStatus::SingularAllocation => 6,
            PerchStatus::RateLimited => 7,
            PerchStatus::InvalidInput => 8,
        }
    }
}

/// How many ticks ended in each [`PerchStatus`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PerchCounters {
    counts: [u64; 9],
    fallbacks: u64,
}

impl PerchCounters {
    /// Count one tick with `status`.
    pub fn record(&mut self, status: PerchStatus) {
        let slot = &mut self.counts[status.index()];
        *slot = slot.saturating_add(1);
    }

    /// Count one tick on which the active-set solver handed over to Clarabel.
    pub fn record_fallback(&mut self) {
        self.fallbacks = self.fallbacks.saturating_add(1);
    }

    /// Ticks on which the active-set solver handed over to Clarabel (iteration cap or
    /// numerically unsure); their status is Clarabel's.
    pub fn fallbacks(&self) -> u64 {
        self.fallbacks
    }

    /// Ticks that ended in `status`.
    pub fn count(&self, status: PerchStatus) -> u64 {
        self.counts[status.index()]
    }

    /// All ticks.
    pub fn total(&self) -> u64 {
        self.counts.iter().fold(0u64, |a, c| a.saturating_add(*c))
    }

    /// Ticks whose thrust is the safe command.
    pub fn failures(&self) -> u64 {
        self.total()
            - self.count(PerchStatus::Solved)
            - self.count(PerchStatus::AlmostSolved)
            - self.count(PerchStatus::RateLimited)
    }
}
