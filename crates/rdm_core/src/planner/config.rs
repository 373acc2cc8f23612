//! Planner parameters. None of these numbers is given by the paper; every default is an
//! ASSUMPTION documented in docs/planner.md.

/// Perched (foot fixed on the ceiling) or flight (root free).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Foot fixed: the base pose is eliminated from the QP (hard foot task).
    Perched,
    /// Root free: p and eta are QP variables; the foot task is a weak cost.
    Flight,
}

/// Velocity-damper parameters of one constraint family (eqs. 59-60, 66, 67):
/// rows `delta d >= -gain (d - d_forbidden) / (d_restricted - d_forbidden)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DamperParams {
    /// Distance below which motion toward the limit is slowed (zeta_R, rho_R, d_R).
    pub restricted: f64,
    /// Distance at which motion toward the limit stops (zeta_F, rho_F, d_F).
    pub forbidden: f64,
    /// gamma: allowed approach per step at the restricted distance.
    pub gain: f64,
}

/// A collision shape on a link (link frame coordinates).
#[derive(Clone, Debug, PartialEq)]
pub enum ShapeSpec {
    /// Segment a-b swept by a sphere of `radius` (links).
    Capsule {
        link: usize,
        a: [f64; 3],
        b: [f64; 3],
        radius: f64,
    },
    /// Sphere (a rotor unit's two rotors and guards).
    Sphere {
        link: usize,
        center: [f64; 3],
        radius: f64,
    },
}

/// A pair of shapes that must not touch, or a shape that must stay below the ceiling.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShapePair {
    /// Shapes i and j (indices into `PlannerConfig::shapes`).
    Shapes(usize, usize),
    /// Shape i and the ceiling plane z = `PlannerConfig::ceiling_z`.
    Ceiling(usize),
}

/// Every planner parameter.
#[derive(Clone, Debug)]
pub struct PlannerConfig {
    pub mode: Mode,
    /// kappa of eq. (54) for position [m/step].
    pub kappa_position: f64,
    /// kappa of eq. (54) for orientation [rad/step].
    pub kappa_orientation: f64,
    /// S1 diagonal for base position, base Euler angles and joints (eq. 55).
    pub s1_position: f64,
    pub s1_orientation: f64,
    pub s1_joint: f64,
    /// Per-joint S1 entries (joint index in q, weight) replacing `s1_joint` for those joints,
    /// e.g. a large weight on the yaw joints keeps a point-only plan near the yaw it starts
    /// from (the regulariser acts on every step, so the yaw drifts only where the task needs
    /// it). Empty by default.
    pub s1_joint_overrides: Vec<(usize, f64)>,
    /// S2' (end effector) position and orientation weights (eq. 57).
    pub s2_ee_position: f64,
    pub s2_ee_orientation: f64,
    /// S2'' (foot) weight in flight (perched: the foot is fixed exactly).
    pub s2_foot: f64,
    /// Largest |delta| per step: base position [m], base angles and joints [rad]
    /// (delta-zeta_max of eqs. 59-60).
    pub step_position: f64,
    pub step_angle: f64,
    /// State-limit damper (eqs. 59-60): restricted/forbidden distances [rad]; gain unused
    /// (the per-variable step limit is the gain).
    pub state: DamperParams,
    /// Base roll/pitch limit in flight [rad] (the root must not tip over).
    pub base_tilt_limit: f64,
    pub torque: DamperParams,
    pub thrust: DamperParams,
    pub stability: DamperParams,
    pub collision: DamperParams,
    pub airflow: DamperParams,
    pub shapes: Vec<ShapeSpec>,
    pub pairs: Vec<ShapePair>,
    /// World z of the ceiling plane (perched; collision with `ShapePair::Ceiling`).
    pub ceiling_z: f64,
    /// Perching force F_perch [N] pressed into the ceiling by the rotors (perched).
    pub perch_force: f64,
    /// Planned end-effector force (world) for eq. (64) and the torque model [N].
    pub ee_force: [f64; 3],
    /// Gravity acceleration g [m/s^2].
    pub gravity: f64,
    /// Central finite-difference step for the constraint Jacobians.
    pub fd_step: f64,
    /// Interior-point iteration cap of each QP.
    pub qp_max_iter: u32,
}

impl PlannerConfig {
    /// Defaults for `mode` with no collision shapes (add them with `shapes`/`pairs`).
    pub fn new(mode: Mode) -> Self {
        Self {
            mode,
            kappa_position: 0.01,
            kappa_orientation: 0.03,
            s1_position: 1e-2,
            s1_orientation: 1e-2,
            s1_joint: 1e-4,
            s1_joint_overrides: Vec::new(),
            s2_ee_position: 1.0,
            s2_ee_orientation: 0.0,
            s2_foot: 1e-2,
            step_position: 0.02,
            step_angle: 0.05,
            state: DamperParams {
                restricted: 0.15,
                forbidden: 0.01,
                gain: 0.05,
            },
            base_tilt_limit: 0.6,
            torque: DamperParams {
                restricted: 0.5,
                forbidden: 0.05,
                gain: 0.1,
            },
            thrust: DamperParams {
                restricted: 2.0,
                forbidden: 0.2,
                gain: 0.5,
            },
            // rho is 1.5e-3 (perched) / 1.8e-3 (flight) at the default starts and falls
            // to 0 when the two rotor pairs line up (docs/planner.md, "rho thresholds").
            stability: DamperParams {
                restricted: 3e-4,
                forbidden: 1e-4,
                gain: 5e-5,
            },
            collision: DamperParams {
                restricted: 0.1,
                forbidden: 0.01,
                gain: 0.02,
            },
            airflow: DamperParams {
                restricted: 0.1,
                forbidden: 0.01,
                gain: 0.02,
            },
            shapes: Vec::new(),
            pairs: Vec::new(),
            ceiling_z: 0.0,
            perch_force: 5.0,
            ee_force: [0.0; 3],
            gravity: 9.80665,
            fd_step: 1e-6,
            qp_max_iter: 50,
        }
    }
}
