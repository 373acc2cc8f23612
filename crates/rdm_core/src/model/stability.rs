//! Stability measure of eq. (65): rho = sqrt(det(Q-bar Q-bar^T)), a manipulability-like
//! measure of how well the rotors can produce fz, mx, my, mz at this configuration.

use nalgebra::{Isometry3, Matrix4};

use super::description::RobotDescription;
use super::error::{check_input, ModelError};
use super::workspace::ModelWorkspace;

/// Central finite-difference step for the gradient of rho [rad].
pub const STABILITY_FD_STEP: f64 = 1e-6;

fn rho_of(ws: &ModelWorkspace) -> f64 {
    // Sum of column outer products: a transpose of the dynamic view would allocate.
    let mut gram = Matrix4::zeros();
    for column in ws.allocation.column_iter() {
        let c = column.fixed_rows::<4>(2);
        gram += c * c.transpose();
    }
    gram.determinant().max(0.0).sqrt()
}

impl RobotDescription {
    /// rho_stable of eq. (65) for the evaluated configuration.
    pub fn stability(&self, ws: &ModelWorkspace) -> Result<f64, ModelError> {
        if !ws.evaluated {
            return Err(ModelError::NotEvaluated);
        }
        Ok(rho_of(ws))
    }

    /// Gradient of rho w.r.t. zeta = [p, eta, q] into `out` (6 + n_q). Q-bar lives in the
    /// CoG frame, whose axes follow the foot, so rho does not depend on p or eta: those six
    /// entries are exactly zero. The q entries are central finite differences (step
    /// [`STABILITY_FD_STEP`]). Re-evaluates `ws`; on success it is left evaluated at `q`
    /// with `base`.
    pub fn stability_gradient(
        &self,
        q: &[f64],
        base: &Isometry3<f64>,
        ws: &mut ModelWorkspace,
        out: &mut [f64],
    ) -> Result<(), ModelError> {
        check_input("q", q, self.n_q())?;
        if out.len() != 6 + self.n_q() {
            return Err(ModelError::WrongLength {
                what: "gradient",
                expected: 6 + self.n_q(),
                got: out.len(),
            });
        }
        out.fill(0.0);
        let mut probe = std::mem::take(&mut ws.scratch_q);
        probe.copy_from_slice(q);
        let mut result = Ok(());
        for k in 0..self.n_q() {
            probe[k] = q[k] + STABILITY_FD_STEP;
            result = self.evaluate(probe.as_slice(), base, ws);
            if result.is_err() {
                break;
            }
            let plus = rho_of(ws);
            probe[k] = q[k] - STABILITY_FD_STEP;
            result = self.evaluate(probe.as_slice(), base, ws);
            if result.is_err() {
                break;
            }
            let minus = rho_of(ws);
            probe[k] = q[k];
            out[6 + k] = (plus - minus) / (2.0 * STABILITY_FD_STEP);
        }
        ws.scratch_q = probe;
        result?;
        self.evaluate(q, base, ws)
    }
}
