//! Caller-owned buffers of one robot's evaluation: built once, reused in loops, so that
//! `evaluate` and every query after it allocate nothing.

use nalgebra::{DVector, Dyn, Isometry3, Matrix3, OMatrix, UnitQuaternion, Vector2, Vector3, U6};

use super::description::RobotDescription;

/// 6 x N matrix (allocation matrix Q, force rows then torque rows).
pub type Matrix6xN = OMatrix<f64, U6, Dyn>;

/// Everything `RobotDescription::evaluate` computes for one (base pose, q).
/// Positions and directions are in the world frame unless the name says otherwise.
#[derive(Clone, Debug)]
pub struct ModelWorkspace {
    pub(crate) evaluated: bool,
    /// Joint vector of the last evaluation.
    pub q: DVector<f64>,
    /// Pose of the root link (the base) in the world.
    pub base: Isometry3<f64>,
    /// Pose of every link in the world (description's link order).
    pub link_pose: Vec<Isometry3<f64>>,
    /// World axis of every `q` joint.
    pub joint_axis: Vec<Vector3<f64>>,
    /// A world point on the axis of every `q` joint.
    pub joint_point: Vec<Vector3<f64>>,
    /// Rotor positions p_rotor,i.
    pub rotor_position: Vec<Vector3<f64>>,
    /// Rotor thrust directions u_i (unit).
    pub rotor_direction: Vec<Vector3<f64>>,
    /// Total mass m [kg].
    pub mass: f64,
    /// Centre of gravity in the world.
    pub cog: Vector3<f64>,
    /// Orientation of the CoG frame C in the world (axes of the foot frame, Sec. III).
    pub cog_rotation: UnitQuaternion<f64>,
    /// Inertia about the CoG, world axes.
    pub inertia_world: Matrix3<f64>,
    /// I(q): inertia about the CoG in the CoG frame.
    pub inertia: Matrix3<f64>,
    /// Q(q) of eqs. (7)-(9) in the CoG frame: rows fx fy fz mx my mz, one column per rotor.
    pub allocation: Matrix6xN,
    pub(crate) hull: Vec<Vector2<f64>>,
    pub(crate) projected: Vec<Vector2<f64>>,
    pub(crate) scratch_q: DVector<f64>,
}

impl ModelWorkspace {
    /// Buffers sized for `robot`.
    pub fn new(robot: &RobotDescription) -> Self {
        let n_links = robot.links.len();
        let n_q = robot.n_q();
        let n_r = robot.n_rotors();
        Self {
            evaluated: false,
            q: DVector::zeros(n_q),
            base: Isometry3::identity(),
            link_pose: vec![Isometry3::identity(); n_links],
            joint_axis: vec![Vector3::zeros(); n_q],
            joint_point: vec![Vector3::zeros(); n_q],
            rotor_position: vec![Vector3::zeros(); n_r],
            rotor_direction: vec![Vector3::zeros(); n_r],
            mass: 0.0,
            cog: Vector3::zeros(),
            cog_rotation: UnitQuaternion::identity(),
            inertia_world: Matrix3::zeros(),
            inertia: Matrix3::zeros(),
            allocation: Matrix6xN::zeros(n_r),
            hull: Vec::with_capacity(2 * n_r + 2),
            projected: vec![Vector2::zeros(); n_r],
            scratch_q: DVector::zeros(n_q),
        }
    }

    /// Whether the buffers fit `robot`.
    pub(crate) fn fits(&self, robot: &RobotDescription) -> bool {
        self.link_pose.len() == robot.links.len()
            && self.q.len() == robot.n_q()
            && self.rotor_position.len() == robot.n_rotors()
    }

    /// The CoG frame C's pose in the world.
    pub fn cog_pose(&self) -> Isometry3<f64> {
        Isometry3::from_parts(self.cog.into(), self.cog_rotation)
    }
}
