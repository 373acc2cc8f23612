//! The plant's per-physics-step rotor work: each ESC's first-order thrust lag, the rotor's
//! distance to the ceiling along its axis, the ceiling-effect thrust ratio and the rotor
//! actuator controls. It mirrors `rdm.plant.plant.Plant.step` / `_apply_rotor_thrusts`,
//! `rdm.plant.ceiling.ParametricCeilingEffect.thrust_ratio` and `rdm.plant.esc.Esc.update`
//! operation for operation (same IEEE operations in the same order, no fused multiply-add),
//! so a run is bit-identical with either form.
//!
//! The ESC state (present and target thrust) lives here; the Python `Esc` objects read and
//! write it through the binding, so there is one source of truth.

/// Thrust ratio model of one rotor (the Python `NoCeilingEffect` / `ParametricCeilingEffect`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CeilingRatio {
    /// T/T0 = 1 everywhere.
    Unity,
    /// Sanchez-Cuevas form T/T0 = 1 / (1 - (R / (z + k2))^2 / k1), capped at `max_ratio`.
    Parametric {
        /// Rotor radius R [m].
        radius: f64,
        /// Coefficient k1.
        k1: f64,
        /// Offset k2 [m] (already `k2_over_radius * R`, as the Python form derives it).
        k2: f64,
        /// Ratio cap.
        max_ratio: f64,
        /// The value of s at which the cap takes over (`1 - 1 / max_ratio`).
        s_cap: f64,
    },
}

impl CeilingRatio {
    /// A parametric model from the Python dataclass fields (k2 and the cap threshold derived
    /// with the Python expressions).
    pub fn parametric(radius: f64, k1: f64, k2_over_radius: f64, max_ratio: f64) -> Self {
        CeilingRatio::Parametric {
            radius,
            k1,
            k2: k2_over_radius * radius,
            max_ratio,
            s_cap: 1.0 - 1.0 / max_ratio,
        }
    }

    /// T/T0 at `distance` [m]: NaN or negative counts as contact (0), +inf gives 1.
    pub fn thrust_ratio(&self, distance: f64) -> f64 {
        match *self {
            CeilingRatio::Unity => 1.0,
            CeilingRatio::Parametric {
                radius,
                k1,
                k2,
                max_ratio,
                s_cap,
            } => {
                let z = if distance.is_nan() || distance < 0.0 {
                    0.0
                } else {
                    distance
                };
                if z.is_infinite() {
                    return 1.0;
                }
                // Python's `q ** 2` on floats is the correctly rounded square, i.e. q * q.
                let q = radius / (z + k2);
                let s = q * q / k1;
                if s >= s_cap {
                    max_ratio
                } else {
                    1.0 / (1.0 - s)
                }
            }
        }
    }
}

/// Why a step could not use the MuJoCo buffers it was given.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RotorPlantStatus {
    /// Every rotor control was written.
    Ok,
    /// A rotor site id does not fit `site_xpos` / `site_xmat`; nothing was written.
    SiteOutOfRange,
    /// A rotor actuator id does not fit `ctrl`; nothing was written.
    ActuatorOutOfRange,
}

/// Per-rotor ESC state, ceiling models and MuJoCo indices of one plant.
#[derive(Debug, Clone)]
pub struct RotorPlant {
    thrust: Vec<f64>,
    target: Vec<f64>,
    alpha: Vec<f64>,
    ceiling: Vec<CeilingRatio>,
    applied: Vec<f64>,
    site: Vec<usize>,
    actuator: Vec<usize>,
    ceiling_height: Option<f64>,
}

impl RotorPlant {
    /// One entry per rotor in `site` (rotor site ids) and `actuator` (rotor actuator ids);
    /// rotors start stopped, with lag factor 0 and no ceiling effect. The number of rotors
    /// is the shorter of the two lists.
    pub fn new(site: &[usize], actuator: &[usize], ceiling_height: Option<f64>) -> Self {
        let n = site.len().min(actuator.len());
        Self {
            thrust: vec![0.0; n],
            target: vec![0.0; n],
            alpha: vec![0.0; n],
            ceiling: vec![CeilingRatio::Unity; n],
            applied: vec![0.0; n],
            site: site[..n].to_vec(),
            actuator: actuator[..n].to_vec(),
            ceiling_height,
        }
    }

    /// Number of rotors.
    pub fn len(&self) -> usize {
        self.thrust.len()
    }

    /// True without rotors.
    pub fn is_empty(&self) -> bool {
        self.thrust.is_empty()
    }

    /// Present (lagged) thrust of rotor `i` [N], None out of range.
    pub fn thrust(&self, i: usize) -> Option<f64> {
        self.thrust.get(i).copied()
    }

    /// Target (steady) thrust of rotor `i` [N], None out of range.
    pub fn target(&self, i: usize) -> Option<f64> {
        self.target.get(i).copied()
    }

    /// Set the present thrust of rotor `i`; false out of range.
    pub fn set_thrust(&mut self, i: usize, value: f64) -> bool {
        set_at(&mut self.thrust, i, value)
    }

    /// Set the target thrust of rotor `i`; false out of range.
    pub fn set_target(&mut self, i: usize, value: f64) -> bool {
        set_at(&mut self.target, i, value)
    }

    /// Set the lag factor `1 - exp(-dt/tau)` of rotor `i`; false out of range.
    pub fn set_alpha(&mut self, i: usize, value: f64) -> bool {
        set_at(&mut self.alpha, i, value)
    }

    /// Set the ceiling model of rotor `i`; false out of range.
    pub fn set_ceiling(&mut self, i: usize, model: CeilingRatio) -> bool {
        match self.ceiling.get_mut(i) {
            Some(slot) => {
                *slot = model;
                true
            }
            None => false,
        }
    }

    /// Thrusts applied by the last [`Self::apply`] (ceiling effect included) [N].
    pub fn applied(&self) -> &[f64] {
        &self.applied
    }

    /// Overwrite the applied thrusts (a caller that computed them itself); extra values
    /// are ignored.
    pub fn set_applied(&mut self, values: &[f64]) {
        for (slot, v) in self.applied.iter_mut().zip(values) {
            *slot = *v;
        }
    }

    /// Advance every ESC lag by one physics step: `t += alpha * (target - t)`.
    pub fn advance_lag(&mut self) {
        for ((t, target), alpha) in self.thrust.iter_mut().zip(&self.target).zip(&self.alpha) {
            *t += alpha * (target - *t);
        }
    }

    /// Distance of rotor `i` to the ceiling along its axis from its site's height and the z
    /// component of its z axis (+inf without a ceiling or facing away).
    fn distance(&self, site_z: f64, axis_z: f64) -> f64 {
        match self.ceiling_height {
            // Python's max(h - z, 0.0): keeps the first unless 0.0 is greater (NaN stays)
            Some(h) if axis_z > 1e-6 => {
                let gap = h - site_z;
                let gap = if 0.0 > gap { 0.0 } else { gap };
                gap / axis_z
            }
            _ => f64::INFINITY,
        }
    }

    /// Ceiling-scaled thrusts into the rotor controls. `site_xpos` / `site_xmat` are
    /// MuJoCo's row-major (nsite x 3) / (nsite x 9) buffers, `ctrl` its controls. Checks
    /// every index first: on a bad one nothing is written.
    pub fn apply(
        &mut self,
        site_xpos: &[f64],
        site_xmat: &[f64],
        ctrl: &mut [f64],
    ) -> RotorPlantStatus {
        let ok_sites = self.site.iter().all(|&s| {
            s.checked_mul(9)
                .and_then(|k| k.checked_add(8))
                .is_some_and(|k| k < site_xmat.len())
                && s.checked_mul(3)
                    .and_then(|k| k.checked_add(2))
                    .is_some_and(|k| k < site_xpos.len())
        });
        if !ok_sites {
            return RotorPlantStatus::SiteOutOfRange;
        }
        if !self.actuator.iter().all(|&a| a < ctrl.len()) {
            return RotorPlantStatus::ActuatorOutOfRange;
        }
        for i in 0..self.thrust.len() {
            let (Some(&s), Some(&a), Some(&t), Some(model)) = (
                self.site.get(i),
                self.actuator.get(i),
                self.thrust.get(i),
                self.ceiling.get(i),
            ) else {
                continue;
            };
            let az = site_xmat.get(s * 9 + 8).copied().unwrap_or(f64::NAN);
            let z = site_xpos.get(s * 3 + 2).copied().unwrap_or(f64::NAN);
            let value = t * model.thrust_ratio(self.distance(z, az));
            if let Some(slot) = self.applied.get_mut(i) {
                *slot = value;
            }
            if let Some(slot) = ctrl.get_mut(a) {
                *slot = value;
            }
        }
        RotorPlantStatus::Ok
    }

    /// One physics step's rotor work: [`Self::advance_lag`] then [`Self::apply`].
    pub fn step(
        &mut self,
        site_xpos: &[f64],
        site_xmat: &[f64],
        ctrl: &mut [f64],
    ) -> RotorPlantStatus {
        self.advance_lag();
        self.apply(site_xpos, site_xmat, ctrl)
    }
}

fn set_at(values: &mut [f64], i: usize, value: f64) -> bool {
    match values.get_mut(i) {
        Some(slot) => {
            *slot = value;
            true
        }
        None => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_indices_write_nothing() {
        let mut p = RotorPlant::new(&[0, 5], &[0, 1], Some(2.0));
        p.set_thrust(0, 3.0);
        let mut ctrl = [7.0; 2];
        assert_eq!(
            p.apply(&[0.0; 6], &[0.0; 18], &mut ctrl),
            RotorPlantStatus::SiteOutOfRange
        );
        assert_eq!(ctrl, [7.0; 2]);
        let mut p = RotorPlant::new(&[0], &[4], Some(2.0));
        assert_eq!(
            p.apply(&[0.0; 3], &[0.0; 9], &mut ctrl),
            RotorPlantStatus::ActuatorOutOfRange
        );
        assert_eq!(ctrl, [7.0; 2]);
    }

    #[test]
    fn setters_refuse_out_of_range() {
        let mut p = RotorPlant::new(&[0], &[0], None);
        assert!(!p.set_thrust(1, 1.0) && !p.set_target(1, 1.0) && !p.set_alpha(1, 1.0));
        assert!(!p.set_ceiling(1, CeilingRatio::Unity));
        assert_eq!(p.thrust(1), None);
    }
}
