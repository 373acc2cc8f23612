//! One ESC's PWM duty command: the duty clamp and the SQRT-mode duty -> steady thrust map of
//! `rdm.plant.esc` (`Esc.command_duty`, `EscParams.steady_thrust`), the same IEEE operations
//! in the same order (no fused multiply-add), so the plant's targets are bit-identical with
//! either form. The voltage factor `(V_ref / V)^2` is computed by the caller (Python's `**`,
//! i.e. libm `pow`): this module only multiplies, adds, divides and compares.

/// Duty of a stopped motor (a 1000 us pulse).
pub const IDLE_DUTY: f64 = 0.5;

/// Python's builtin `max(a, b)` on floats: `b` only if `b > a` (a NaN `a` is kept).
#[inline]
fn py_max(a: f64, b: f64) -> f64 {
    if b > a {
        b
    } else {
        a
    }
}

/// Python's builtin `min(a, b)` on floats: `b` only if `b < a` (a NaN `a` is kept).
#[inline]
fn py_min(a: f64, b: f64) -> f64 {
    if b < a {
        b
    } else {
        a
    }
}

/// The duty -> thrust map of one ESC and its last command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EscDuty {
    /// SQRT-mode coefficients as the firmware stores them ("x10").
    pub p2: f64,
    /// Linear coefficient.
    pub p1: f64,
    /// Constant coefficient.
    pub p0: f64,
    /// Thrust cap [N].
    pub thrust_max: f64,
    /// `(V_ref / V)^2` at the present battery voltage.
    pub v_factor: f64,
    /// The last commanded duty after the clamp.
    pub duty: f64,
    /// Non-finite commands replaced by a stop.
    pub rejected: u64,
}

impl EscDuty {
    /// A stopped ESC with this map.
    pub fn new(p2: f64, p1: f64, p0: f64, thrust_max: f64, v_factor: f64) -> Self {
        Self {
            p2,
            p1,
            p0,
            thrust_max,
            v_factor,
            duty: IDLE_DUTY,
            rejected: 0,
        }
    }

    /// Steady thrust [N] of `duty` (`EscParams.steady_thrust`).
    pub fn steady_thrust(&self, duty: f64) -> f64 {
        if !duty.is_finite() || duty <= IDLE_DUTY {
            return 0.0;
        }
        let x = 100.0 * py_min(duty, 1.0);
        let f = (0.1 * self.p2 * x * x + 0.1 * self.p1 * x + self.p0) / self.v_factor;
        py_min(py_max(f, 0.0), self.thrust_max)
    }

    /// Command `duty` (`Esc.command_duty`): a non-finite duty counts as rejected and stops
    /// the motor; the duty is clamped to [0.5, 1]. Returns the new target thrust [N].
    pub fn command(&mut self, duty: f64) -> f64 {
        let duty = if duty.is_finite() {
            duty
        } else {
            self.rejected = self.rejected.saturating_add(1);
            IDLE_DUTY
        };
        self.duty = py_min(py_max(duty, IDLE_DUTY), 1.0);
        self.steady_thrust(self.duty)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn esc() -> EscDuty {
        EscDuty::new(0.07983707, -6.627443098, 12.3593793002, 20.0, 1.0)
    }

    #[test]
    fn clamp_and_reject() {
        let mut e = esc();
        assert_eq!(e.command(f64::NAN), 0.0);
        assert_eq!((e.duty, e.rejected), (IDLE_DUTY, 1));
        assert_eq!(e.command(0.2), 0.0);
        assert_eq!(e.duty, IDLE_DUTY);
        let full = e.command(3.0);
        assert_eq!(e.duty, 1.0);
        assert_eq!(full, 20.0); // 0.1 p2 1e4 - 0.1 p1 100 ... capped at thrust_max
        assert_eq!(e.rejected, 1);
    }

    #[test]
    fn map_matches_the_formula() {
        let mut e = esc();
        e.v_factor = (25.2f64 / 23.0) * (25.2 / 23.0);
        let t = e.command(0.8);
        let x: f64 = 80.0;
        let f = (0.1 * e.p2 * x * x + 0.1 * e.p1 * x + e.p0) / e.v_factor;
        assert_eq!(t, f.clamp(0.0, 20.0));
    }
}
