//! Rotor allocation matrix Q(q) of eqs. (7)-(9) in the CoG frame, and its rows 3-6, Q-bar
//! (fz, mx, my, mz), used by the LQI (eq. 22) and the stability measure (eq. 65).

use nalgebra::{Dyn, OMatrix, U4};

use super::description::RobotDescription;
use super::workspace::ModelWorkspace;

/// 4 x N matrix: Q-bar(q), rows fz mx my mz.
pub type Matrix4xN = OMatrix<f64, U4, Dyn>;

impl RobotDescription {
    /// Column i of Q: u_i over v_i = (p_i x - c sigma_i) u_i, all in the CoG frame.
    pub(crate) fn fill_allocation(&self, ws: &mut ModelWorkspace) {
        let to_cog = ws.cog_rotation.inverse();
        for (i, rotor) in self.rotors.iter().enumerate() {
            let u = to_cog * ws.rotor_direction[i];
            let p = to_cog * (ws.rotor_position[i] - ws.cog);
            let v = p.cross(&u) - rotor.drag_to_thrust * rotor.spin * u;
            let mut column = ws.allocation.column_mut(i);
            column.fixed_rows_mut::<3>(0).copy_from(&u);
            column.fixed_rows_mut::<3>(3).copy_from(&v);
        }
    }
}

/// Copy Q-bar (rows fz, mx, my, mz of Q) into `out` (4 x N, caller-owned).
/// Returns `false` (leaving `out` untouched) if the column counts differ.
pub fn allocation_bar(ws: &ModelWorkspace, out: &mut Matrix4xN) -> bool {
    if out.ncols() != ws.allocation.ncols() {
        return false;
    }
    out.copy_from(&ws.allocation.fixed_rows::<4>(2));
    true
}
