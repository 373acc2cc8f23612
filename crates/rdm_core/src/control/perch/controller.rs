//! The 40 Hz perching step: filter the foot wrench (Sec. VII-B), solve eq. (49), remember
//! `λ_perch,t` and `W_foot,t` for the next tick's eqs. (48) and (38).

use nalgebra::{Matrix4, Matrix6x4};

use super::error::ParamError;
use super::filter::WrenchFilter;
use super::params::PerchParams;
use super::qp::{PerchInput, PerchQp, PerchSolution};
use super::status::PerchCounters;
use crate::PERCH_ROTORS;

/// Filter + QP + the state carried between ticks. Allocation-free after [`PerchController::new`].
pub struct PerchController {
    qp: PerchQp,
    filter: WrenchFilter,
    previous_thrust: [f64; PERCH_ROTORS],
    previous_foot_wrench: [f64; 4],
    has_previous_wrench: bool,
}

impl PerchController {
    /// Controller ticking at `rate_hz` with the foot-wrench filter cutoff `cutoff_hz`
    /// (paper: 40 Hz and 1 Hz). Starts with zero perching thrust.
    pub fn new(params: PerchParams, rate_hz: f64, cutoff_hz: f64) -> Result<Self, ParamError> {
        let filter = WrenchFilter::new(cutoff_hz, rate_hz).ok_or(ParamError {
            field: "rate_hz/cutoff_hz",
            reason: "need 0 < cutoff_hz < rate_hz / 2, both finite",
        })?;
        Ok(Self {
            qp: PerchQp::new(params)?,
            filter,
            previous_thrust: [0.0; PERCH_ROTORS],
            previous_foot_wrench: [0.0; 4],
            has_previous_wrench: false,
        })
    }

    /// Start a new perching phase from `thrust` (e.g. zeros at touchdown): the filter
    /// restarts at the next sample and the feedback of eq. (38) starts at zero.
    pub fn reset(&mut self, thrust: [f64; PERCH_ROTORS]) {
        self.filter.reset();
        self.previous_thrust = thrust.map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 });
        self.has_previous_wrench = false;
    }

    /// One tick in the contact plane's coordinates: `raw_foot_wrench` =
    /// `[F_t1, F_t2, F_n, M_t1, M_t2, M_n]` and `foot_allocation` rows `[F_n, M_t1, M_t2, M_n]`
    /// (for the paper's ceiling: the sensor's `[F_x, .., M_z]` in the foot frame; see
    /// [`PerchInput`] for the sign; [`Self::tick_foot`] for any plane from foot axes). Never panics; non-finite input gives
    /// the safe command with [`super::PerchStatus::NonFiniteInput`] and leaves the filter as is.
    pub fn tick(
        &mut self,
        raw_foot_wrench: &[f64; 6],
        foot_allocation: &Matrix4<f64>,
        allocation: &Matrix4<f64>,
        mass: f64,
        flight_thrust: Option<[f64; PERCH_ROTORS]>,
    ) -> PerchSolution {
        let filtered = self.filter.update(raw_foot_wrench);
        let foot_wrench = filtered.unwrap_or(*raw_foot_wrench);
        if filtered.is_some() && !self.has_previous_wrench {
            self.previous_foot_wrench = [
                foot_wrench[2],
                foot_wrench[3],
                foot_wrench[4],
                foot_wrench[5],
            ];
        }
        let input = PerchInput {
            foot_allocation: *foot_allocation,
            allocation: *allocation,
            mass,
            foot_wrench,
            previous_thrust: self.previous_thrust,
            previous_foot_wrench: self.previous_foot_wrench,
            flight_thrust,
        };
        let solution = self.qp.solve(&input);
        self.previous_thrust = solution.thrust;
        if solution.status.is_solution() {
            self.previous_foot_wrench = solution.foot_wrench;
            self.has_previous_wrench = true;
        }
        solution
    }

    /// One tick from foot-axes quantities: `raw_foot_wrench` from the sensor in the foot
    /// frame, `foot_allocation` the six rows `[F_x, F_y, F_z, M_x, M_y, M_z]` unit thrusts
    /// produce about the foot origin. Both are carried into the contact plane
    /// ([`ContactPlane`](super::ContactPlane)) and [`Self::tick`] runs there (the filter too).
    pub fn tick_foot(
        &mut self,
        raw_foot_wrench: &[f64; 6],
        foot_allocation: &Matrix6x4<f64>,
        allocation: &Matrix4<f64>,
        mass: f64,
        flight_thrust: Option<[f64; PERCH_ROTORS]>,
    ) -> PerchSolution {
        let plane = *self.qp.plane();
        let wrench = plane.wrench(raw_foot_wrench);
        let rows = plane.allocation(foot_allocation);
        self.tick(&wrench, &rows, allocation, mass, flight_thrust)
    }

    /// The filtered foot wrench of the last finite sample (plane coordinates).
    pub fn filtered_foot_wrench(&self) -> [f64; 6] {
        self.filter.output()
    }

    /// `λ_perch,t−1` the next tick will rate-limit against.
    pub fn previous_thrust(&self) -> [f64; PERCH_ROTORS] {
        self.previous_thrust
    }

    /// Ticks per outcome.
    pub fn counters(&self) -> PerchCounters {
        self.qp.counters()
    }

    /// The QP (problem data, parameters, weight updates).
    pub fn qp(&self) -> &PerchQp {
        &self.qp
    }

    /// The foot-wrench filter.
    pub fn filter(&self) -> &WrenchFilter {
        &self.filter
    }
}
