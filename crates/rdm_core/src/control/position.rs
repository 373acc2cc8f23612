//! Horizontal position control and vectoring-apparatus angles (Sec. IV-A-2, eqs. 30-36).
//!
//! Runs at the position rate (40 Hz in the paper). Per step:
//! 1. eq. (30): PID on the world x/y error to a desired acceleration, with a clamp on the
//!    integral term (anti-windup; the paper has none, see [`AxisPid::integral_limit`]);
//! 2. eqs. (31)-(32): roll/pitch targets (Table V: `k_φd = 0`, i.e. the paper's `φ_d = 0`);
//! 3. eqs. (33)-(36): angles `α_i`, `β_i` of each vectoring apparatus from the rotation
//!    that eq. (36) applies (`ᶜ_{Lᵢ}R` as the paper writes it), and the desired yaw `ψ_d`.
//!
//! Geometric meaning of (33)-(34): with `n = n_va/|n_va|` and `n_z > 0`,
//! `R_x(α) R_y(β) e_z = n`, i.e. turning the apparatus z axis first by α about x, then by
//! β about the new y, aligns it with n.

use nalgebra::{Matrix3, Vector2, Vector3};

/// Number of vectoring apparatuses.
///
/// ASSUMPTION: the robot has two vectoring apparatuses (the RDM's foot and arm units), each
/// carrying any number of rotors.
pub const N_VECTORING: usize = 2;

/// Standard gravity [m/s²] (assumption: the paper's g).
pub const GRAVITY: f64 = 9.80665;

/// PID gains of one horizontal axis (eq. 30).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisPid {
    pub p: f64,
    pub i: f64,
    pub d: f64,
    /// Bound on `|k_I ∫e dt|` [m/s²]. Assumption (not in the paper): 1.0 m/s²; set to
    /// `f64::INFINITY` for the paper's unbounded integral.
    pub integral_limit: f64,
}

/// Gains of the position controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionGains {
    pub x: AxisPid,
    pub y: AxisPid,
    /// `k_φd` of eq. (31).
    pub k_roll: f64,
    /// `k_θd` of eq. (32).
    pub k_pitch: f64,
    /// `k_θi` of eq. (36), per apparatus.
    pub k_pitch_vectoring: [f64; N_VECTORING],
    /// `k_φi` of eq. (36), per apparatus.
    pub k_roll_vectoring: [f64; N_VECTORING],
    /// g of eqs. (31), (32), (36).
    pub gravity: f64,
    /// Bound on the commanded tilt [rad], in (0, π/2): `|φ_d|`, `|θ_d|` and the tilt of each
    /// apparatus direction `n_i` from its link's z axis, and through it `|p̈_d|` <=
    /// `g tan(max_tilt)`. ASSUMPTION (not in the paper): the attitude controller's roll/pitch
    /// bound, 1.0 rad (firmware `MAX_TILT_ANGLE`, `AttitudeConfig::max_tilt_rad`).
    pub max_tilt: f64,
}

/// Default [`PositionGains::max_tilt`]: the firmware's `MAX_TILT_ANGLE` (rad).
pub const MAX_TILT_RAD: f64 = 1.0;

impl PositionGains {
    /// Table V: x (4.6, 1.5, 7.0), y (7.0, 0.005, 10.5), `k_φd = 0`, `k_θd = 1`,
    /// `(k_θ1, k_φ1) = (0, 1)`, `(k_θ2, k_φ2) = (0, 0)`; integral limit 1 m/s² (assumption).
    pub fn table_v() -> Self {
        Self {
            x: AxisPid {
                p: 4.6,
                i: 1.5,
                d: 7.0,
                integral_limit: 1.0,
            },
            y: AxisPid {
                p: 7.0,
                i: 0.005,
                d: 10.5,
                integral_limit: 1.0,
            },
            k_roll: 0.0,
            k_pitch: 1.0,
            k_pitch_vectoring: [0.0, 0.0],
            k_roll_vectoring: [1.0, 0.0],
            gravity: GRAVITY,
            max_tilt: MAX_TILT_RAD,
        }
    }

    fn validate(&self) -> Result<(), PositionError> {
        let axes_ok = [self.x, self.y].iter().all(|a| {
            a.p.is_finite()
                && a.i.is_finite()
                && a.d.is_finite()
                && !a.integral_limit.is_nan()
                && a.integral_limit >= 0.0
        });
        let rest_ok = self.k_roll.is_finite()
            && self.k_pitch.is_finite()
            && self
                .k_pitch_vectoring
                .iter()
                .chain(self.k_roll_vectoring.iter())
                .all(|k| k.is_finite())
            && self.gravity.is_finite()
            && self.gravity > 0.0
            && self.max_tilt > 0.0
            && self.max_tilt < core::f64::consts::FRAC_PI_2;
        if axes_ok && rest_ok {
            Ok(())
        } else {
            Err(PositionError::InvalidInput { argument: "gains" })
        }
    }
}

impl Default for PositionGains {
    fn default() -> Self {
        Self::table_v()
    }
}

/// Inputs of one position step (world frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionInput {
    /// Estimated x, y [m].
    pub position: Vector2<f64>,
    /// Estimated ẋ, ẏ [m/s].
    pub velocity: Vector2<f64>,
    /// Target x, y [m].
    pub target_position: Vector2<f64>,
    /// Target ẋ, ẏ [m/s].
    pub target_velocity: Vector2<f64>,
    /// Desired yaw `ψ_d` [rad].
    pub target_yaw: f64,
    /// The rotation eq. (36) multiplies, one per vectoring apparatus.
    pub link_rotations: [Matrix3<f64>; N_VECTORING],
    /// Step length [s].
    pub dt: f64,
}

/// Outputs of one position step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionOutput {
    /// `p̈_d` of eq. (30) [m/s²].
    pub acceleration: Vector2<f64>,
    /// `φ_d` of eq. (31) [rad].
    pub roll: f64,
    /// `θ_d` of eq. (32) [rad].
    pub pitch: f64,
    /// `α_i` of eq. (33) [rad].
    pub alpha: [f64; N_VECTORING],
    /// `β_i` of eq. (34) [rad].
    pub beta: [f64; N_VECTORING],
    /// `n_i = n_va,i/|n_va,i|` of eq. (35).
    pub direction: [Vector3<f64>; N_VECTORING],
    /// True when an integral term hit its limit this step.
    pub integral_clamped: bool,
    /// Which outputs were cut to [`PositionGains::max_tilt`] this step.
    pub saturation: Saturation,
}

/// Outputs of a position step cut to the tilt bound (all false: none).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Saturation {
    /// `|p̈_d|` was above `g tan(max_tilt)` and was scaled down to it (direction kept).
    pub acceleration: bool,
    /// `φ_d` or `θ_d` was past `±max_tilt` and was clamped.
    pub attitude: bool,
    /// An apparatus direction leaned more than `max_tilt` from its link's z axis and was
    /// brought back to it (horizontal part scaled, direction kept).
    pub vectoring: bool,
}

impl Saturation {
    /// Whether any output was cut.
    pub fn any(&self) -> bool {
        self.acceleration || self.attitude || self.vectoring
    }
}

/// Why a position step failed; the controller state is left unchanged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PositionError {
    /// NaN/inf or out-of-domain input; names the field.
    InvalidInput { argument: &'static str },
}

impl core::fmt::Display for PositionError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::InvalidInput { argument } => {
                write!(f, "invalid position-control input `{argument}`")
            }
        }
    }
}

impl std::error::Error for PositionError {}

/// Principal value `tan⁻¹(num/den)` in [−π/2, π/2], defined for `den = 0`.
fn atan_ratio(num: f64, den: f64) -> f64 {
    if den > 0.0 {
        num.atan2(den)
    } else if den < 0.0 {
        (-num).atan2(-den)
    } else if num == 0.0 {
        0.0
    } else {
        core::f64::consts::FRAC_PI_2.copysign(num)
    }
}

/// Eqs. (33)-(34): apparatus angles from the unit direction n.
pub fn vectoring_angles(n: &Vector3<f64>) -> (f64, f64) {
    let alpha = atan_ratio(-n.y, n.z);
    let beta = atan_ratio(n.x, -n.y * alpha.sin() + n.z * alpha.cos());
    (alpha, beta)
}

/// PID position controller with vectoring (eqs. 30-36).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionController {
    gains: PositionGains,
    /// `∫e dt` per axis [m s].
    integral: Vector2<f64>,
}

impl PositionController {
    /// Validates the gains.
    pub fn new(gains: PositionGains) -> Result<Self, PositionError> {
        gains.validate()?;
        Ok(Self {
            gains,
            integral: Vector2::zeros(),
        })
    }

    /// The gains in use.
    pub fn gains(&self) -> &PositionGains {
        &self.gains
    }

    /// `∫e dt` of x and y.
    pub fn integral(&self) -> Vector2<f64> {
        self.integral
    }

    /// Zeroes the integrators.
    pub fn reset(&mut self) {
        self.integral = Vector2::zeros();
    }

    /// Bumpless gain switch: carries `previous`'s integral *action* `k_I ∫e` per axis into
    /// this controller, i.e. `∫e` scaled by `k_I,old / k_I,new` and clamped to this
    /// controller's `integral_limit`. An axis whose new `k_I` is 0 starts at 0 (no action to
    /// carry). Without it a gain schedule restarts the integral and the target tilt jumps by
    /// the old action.
    pub fn take_integral_action(&mut self, previous: &PositionController) {
        let pairs = [
            (previous.gains.x.i, &self.gains.x),
            (previous.gains.y.i, &self.gains.y),
        ];
        for (axis, (old_i, new)) in pairs.into_iter().enumerate() {
            let action = old_i * previous.integral[axis];
            self.integral[axis] = if new.i == 0.0 || !action.is_finite() {
                0.0
            } else {
                let bounded = if new.integral_limit.is_finite() {
                    action.clamp(-new.integral_limit, new.integral_limit)
                } else {
                    action
                };
                bounded / new.i
            };
        }
    }

    /// One step. The integral advances by `e dt` (rectangle rule) and is then clamped so
    /// that `|k_I ∫e| <= integral_limit`.
    pub fn step(&mut self, input: &PositionInput) -> Result<PositionOutput, PositionError> {
        validate_input(input)?;
        let g = &self.gains;
        let error = input.target_position - input.position;
        let error_rate = input.target_velocity - input.velocity;
        let mut integral = self.integral + error * input.dt;
        let mut integral_clamped = false;
        for (axis, pid) in [g.x, g.y].iter().enumerate() {
            if pid.i != 0.0 && pid.integral_limit.is_finite() {
                let bound = pid.integral_limit / pid.i.abs();
                if integral[axis].abs() > bound {
                    integral[axis] = bound.copysign(integral[axis]);
                    integral_clamped = true;
                }
            }
        }
        self.integral = integral;
        let mut saturation = Saturation::default();
        let pid_acceleration = Vector2::new(
            g.x.p * error.x + g.x.i * integral.x + g.x.d * error_rate.x,
            g.y.p * error.y + g.y.i * integral.y + g.y.d * error_rate.y,
        );
        // The horizontal acceleration a level thrust of g can give at the tilt bound. A huge
        // (or overflowed, infinite) PID sum keeps its direction.
        let horizontal_limit = g.gravity * g.max_tilt.tan();
        let acceleration = bounded_norm(pid_acceleration, horizontal_limit, &mut saturation);
        let (sin_yaw, cos_yaw) = input.target_yaw.sin_cos();
        // Desired acceleration in the yaw-aligned frame, as eqs. (31), (32), (36) use it.
        let forward = acceleration.x * cos_yaw + acceleration.y * sin_yaw;
        let lateral = acceleration.x * sin_yaw - acceleration.y * cos_yaw;
        let roll = clamp_tilt(g.k_roll * lateral / g.gravity, g.max_tilt, &mut saturation);
        let pitch = clamp_tilt(g.k_pitch * forward / g.gravity, g.max_tilt, &mut saturation);
        let mut alpha = [0.0; N_VECTORING];
        let mut beta = [0.0; N_VECTORING];
        let mut direction = [Vector3::zeros(); N_VECTORING];
        for i in 0..N_VECTORING {
            // Eqs. (33)-(34) solve R_x(α) R_y(β) e_z = n: n is the thrust direction, which must
            // lean toward the desired acceleration, whose heading-frame y component is
            // −lateral. The printed eq. (36) puts eq. (31)'s roll-target sign (+lateral) in that
            // slot, which leans the thrust away from the demand: positive feedback in y (seen
            // in MuJoCo). We use the direction sign; k_roll_vectoring = −1 gives the print.
            let lean = Vector2::new(
                g.k_pitch_vectoring[i] * forward,
                -g.k_roll_vectoring[i] * lateral,
            );
            let mut lean_cut = Saturation::default();
            let lean = bounded_norm(lean, horizontal_limit, &mut lean_cut);
            saturation.vectoring |= lean_cut.acceleration;
            let local = Vector3::new(lean.x, lean.y, g.gravity);
            let n_va = input.link_rotations[i] * local;
            // |n_va| >= g * smallest singular value of the rotation, so > 0 for a valid input.
            let n = n_va / n_va.norm();
            let (a, b) = vectoring_angles(&n);
            alpha[i] = a;
            beta[i] = b;
            direction[i] = n;
        }
        Ok(PositionOutput {
            acceleration,
            roll,
            pitch,
            alpha,
            beta,
            direction,
            integral_clamped,
            saturation,
        })
    }
}

/// `v` scaled down to norm `limit` when longer (`saturation.acceleration` set); an infinite
/// component gives the unit vector of the infinite components' signs. A NaN component (an
/// overflowed sum of opposite infinities) has no direction: zero, saturated.
fn bounded_norm(v: Vector2<f64>, limit: f64, saturation: &mut Saturation) -> Vector2<f64> {
    let norm = v.norm();
    if norm <= limit {
        return v;
    }
    saturation.acceleration = true;
    if v.iter().any(|c| c.is_nan()) {
        return Vector2::zeros();
    }
    let unit = if v.iter().any(|c| c.is_infinite()) {
        let signs = v.map(|c| if c.is_infinite() { c.signum() } else { 0.0 });
        signs / signs.norm()
    } else {
        // scaled by the largest entry first: |v| itself may overflow (1e300 squared)
        let w = v / v.amax();
        w / w.norm()
    };
    unit * limit
}

/// `angle` clamped to `±max_tilt` (`saturation.attitude` set when cut).
fn clamp_tilt(angle: f64, max_tilt: f64, saturation: &mut Saturation) -> f64 {
    if angle.abs() > max_tilt {
        saturation.attitude = true;
        max_tilt.copysign(angle)
    } else {
        angle
    }
}

fn validate_input(input: &PositionInput) -> Result<(), PositionError> {
    let finite2 = |v: &Vector2<f64>| v.iter().all(|x| x.is_finite());
    let check = |ok: bool, argument: &'static str| {
        if ok {
            Ok(())
        } else {
            Err(PositionError::InvalidInput { argument })
        }
    };
    check(finite2(&input.position), "position")?;
    check(finite2(&input.velocity), "velocity")?;
    check(finite2(&input.target_position), "target_position")?;
    check(finite2(&input.target_velocity), "target_velocity")?;
    check(input.target_yaw.is_finite(), "target_yaw")?;
    check(input.dt.is_finite() && input.dt > 0.0, "dt")?;
    for rotation in &input.link_rotations {
        let finite = rotation.iter().all(|x| x.is_finite());
        // A rotation: orthonormal up to rounding (also guarantees |n_va| > 0).
        let orthonormal =
            finite && (rotation.transpose() * rotation - Matrix3::identity()).amax() < 1e-6;
        check(orthonormal, "link_rotations")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input(position: [f64; 2], velocity: [f64; 2]) -> PositionInput {
        PositionInput {
            position: Vector2::from(position),
            velocity: Vector2::from(velocity),
            target_position: Vector2::zeros(),
            target_velocity: Vector2::zeros(),
            target_yaw: 0.3,
            link_rotations: [Matrix3::identity(); N_VECTORING],
            dt: 0.025,
        }
    }

    /// Tilt of a unit direction from the link z axis (identity link rotations).
    fn tilt(n: &Vector3<f64>) -> f64 {
        n.z.clamp(-1.0, 1.0).acos()
    }

    #[test]
    fn huge_errors_command_at_most_the_tilt_bound() {
        let cases = [
            ([1e300, 0.0], [0.0, 0.0]),
            ([-1e300, 3e299], [1e300, -1e300]),
            ([f64::MAX, -f64::MAX], [-f64::MAX, f64::MAX]),
            ([1e308, 0.0], [-1e308, 0.0]),
        ];
        for (position, velocity) in cases {
            let mut c = PositionController::new(PositionGains::table_v()).unwrap();
            let out = c.step(&input(position, velocity)).unwrap();
            let limit = MAX_TILT_RAD;
            assert!(
                out.roll.abs() <= limit && out.pitch.abs() <= limit,
                "{out:?}"
            );
            assert!(out.acceleration.iter().all(|a| a.is_finite()), "{out:?}");
            assert!(out.acceleration.norm() <= GRAVITY * limit.tan() * (1.0 + 1e-12));
            for n in &out.direction {
                assert!(n.iter().all(|v| v.is_finite()), "{out:?}");
                assert!(tilt(n) <= limit + 1e-12, "{out:?}");
            }
            assert!(out.alpha.iter().chain(&out.beta).all(|a| a.is_finite()));
            assert!(
                out.saturation.any() && out.saturation.acceleration,
                "{out:?}"
            );
        }
    }

    #[test]
    fn a_saturated_step_keeps_the_direction_of_the_demand() {
        let mut c = PositionController::new(PositionGains::table_v()).unwrap();
        // error along -x only: the acceleration points along -x (target 0, position +1e300)
        let out = c.step(&input([1e300, 0.0], [0.0, 0.0])).unwrap();
        let expected = -GRAVITY * MAX_TILT_RAD.tan();
        assert!((out.acceleration.x - expected).abs() < 1e-12, "{out:?}");
        assert_eq!(out.acceleration.y, 0.0);
    }

    #[test]
    fn small_errors_are_not_cut() {
        let mut c = PositionController::new(PositionGains::table_v()).unwrap();
        let out = c.step(&input([0.2, -0.1], [0.05, 0.0])).unwrap();
        assert_eq!(out.saturation, Saturation::default());
        // eq. (30) by hand: x: 4.6 e + 1.5 e dt + 7 e_rate
        let ax = 4.6 * -0.2 + 1.5 * (-0.2 * 0.025) + 7.0 * -0.05;
        assert!((out.acceleration.x - ax).abs() < 1e-12);
    }

    #[test]
    fn a_tilt_bound_outside_the_open_quarter_turn_is_refused() {
        for bad in [0.0, -0.1, core::f64::consts::FRAC_PI_2, f64::NAN] {
            let gains = PositionGains {
                max_tilt: bad,
                ..PositionGains::table_v()
            };
            assert_eq!(
                PositionController::new(gains),
                Err(PositionError::InvalidInput { argument: "gains" })
            );
        }
    }
}
