//! The planner: one QP per step (eqs. 50-51, 69-70).

use nalgebra::{Isometry3, Vector3};

use super::config::{Mode, PlannerConfig};
use super::constraints::{all_constraints, Constraint, Context};
use super::leveling::Leveler;
use super::quantities::{Quantities, QuantityLayout};
use super::target::{EeOrientation, TaskRows};
use crate::model::{Frame, Matrix6xN, ModelError, RobotDescription};
use crate::qp::{DenseQp, QpError, QpSettings, QpStatus};

/// Setup or input errors (a QP that fails is a [`StepStatus`], not an error).
#[derive(Clone, Debug, PartialEq)]
pub enum PlannerError {
    /// The description does not fit the planner (message names the part).
    Description(String),
    /// The state or target has the wrong length or holds NaN/inf.
    BadInput(&'static str),
    /// The model failed to evaluate.
    Model(ModelError),
    /// The allocation is singular at this configuration (rho = 0).
    SingularAllocation,
    Qp(QpError),
}

impl std::fmt::Display for PlannerError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlannerError::Description(m) => write!(f, "description: {m}"),
            PlannerError::BadInput(w) => write!(f, "{w}: wrong length or NaN/inf"),
            PlannerError::Model(e) => write!(f, "model: {e}"),
            PlannerError::SingularAllocation => write!(f, "thrust allocation is singular"),
            PlannerError::Qp(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for PlannerError {}

impl From<Option<ModelError>> for PlannerError {
    fn from(e: Option<ModelError>) -> Self {
        e.map_or(PlannerError::SingularAllocation, PlannerError::Model)
    }
}

/// Outcome of one step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepStatus {
    /// zeta was updated.
    Moved,
    /// The QP failed; zeta is unchanged.
    QpFailed(QpStatus),
}

/// Report of one step.
#[derive(Clone, Copy, Debug)]
pub struct StepReport {
    pub status: StepStatus,
    /// End-effector position error before the step [m].
    pub position_error: f64,
    /// End-effector orientation error before the step [rad] (0 without an orientation).
    pub orientation_error: f64,
    /// Constraint family with the largest dual in this QP (`None`: all inactive).
    pub binding: Option<&'static str>,
}

/// Differential-kinematics planner for one robot and mode.
pub struct Planner {
    robot: RobotDescription,
    cfg: PlannerConfig,
    leveler: Leveler,
    quantities: Quantities,
    constraints: Vec<Box<dyn Constraint>>,
    rows: Vec<usize>,
    free: Vec<usize>,
    zeta: Vec<f64>,
    values: Vec<f64>,
    jac: Vec<f64>,
    j_ee: Matrix6xN,
    j_foot: Matrix6xN,
    task: TaskRows,
    limits: Vec<(f64, f64)>,
    thrust_min: Vec<f64>,
    p: Vec<f64>,
    q: Vec<f64>,
    g: Vec<f64>,
    h: Vec<f64>,
    qp: DenseQp,
    foot_hold: Isometry3<f64>,
}

impl std::fmt::Debug for Planner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Planner").field("free", &self.free).finish()
    }
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl Planner {
    /// Build a planner; `zeta0` = [p, eta, q] is the start state (unit angles are re-solved).
    pub fn new(
        robot: RobotDescription,
        cfg: PlannerConfig,
        zeta0: &[f64],
    ) -> Result<Self, PlannerError> {
        if robot.n_rotors() != 4 {
            return Err(PlannerError::Description(format!(
                "the static thrust distribution needs 4 rotors, got {}",
                robot.n_rotors()
            )));
        }
        let leveler = Leveler::new(&robot).map_err(PlannerError::Description)?;
        let n_q = robot.n_q();
        for &(j, w) in &cfg.s1_joint_overrides {
            if j >= n_q || leveler.is_unit_angle(j) || !(w.is_finite() && w >= 0.0) {
                return Err(PlannerError::Description(format!(
                    "s1_joint_overrides: ({j}, {w}) must name a joint of q (not a vectoring \
                     angle) with a finite weight >= 0"
                )));
            }
        }
        let mut free: Vec<usize> = Vec::with_capacity(6 + n_q);
        if cfg.mode == Mode::Flight {
            free.extend(0..6);
        }
        free.extend(
            (0..n_q)
                .filter(|&i| !leveler.is_unit_angle(i))
                .map(|i| 6 + i),
        );
        let quantities = Quantities::new(&robot, &cfg);
        let constraints = all_constraints();
        let rows: Vec<usize> = constraints
            .iter()
            .map(|c| c.n_rows(&quantities.layout, free.len()))
            .collect();
        let n_rows: usize = rows.iter().sum();
        let nf = free.len();
        let qp = DenseQp::new(
            nf,
            0,
            n_rows,
            QpSettings {
                max_iter: cfg.qp_max_iter,
                tolerance: 1e-8,
            },
        )
        .map_err(PlannerError::Qp)?;
        let n_quant = quantities.layout.len();
        let limits = robot.joint_limits();
        let thrust_min = robot.rotors.iter().map(|r| r.thrust_min).collect();
        let mut planner = Self {
            j_ee: Matrix6xN::zeros(6 + n_q),
            j_foot: Matrix6xN::zeros(6 + n_q),
            task: TaskRows::new(6 + n_q),
            robot,
            cfg,
            leveler,
            quantities,
            constraints,
            rows,
            free,
            zeta: vec![0.0; 6 + n_q],
            values: vec![0.0; n_quant],
            jac: vec![0.0; n_quant * nf],
            limits,
            thrust_min,
            p: vec![0.0; nf * nf],
            q: vec![0.0; nf],
            g: vec![0.0; n_rows * nf],
            h: vec![0.0; n_rows],
            qp,
            foot_hold: Isometry3::identity(),
        };
        planner.set_zeta(zeta0)?;
        Ok(planner)
    }

    /// Reset the state (unit angles are re-solved; the foot pose to hold is re-read).
    pub fn set_zeta(&mut self, zeta: &[f64]) -> Result<(), PlannerError> {
        if zeta.len() != self.zeta.len() || !finite(zeta) {
            return Err(PlannerError::BadInput("zeta"));
        }
        self.zeta.copy_from_slice(zeta);
        self.refresh()?;
        let ws = self.quantities.workspace();
        self.foot_hold = ws.link_pose[self.robot.foot_link];
        Ok(())
    }

    fn refresh(&mut self) -> Result<(), PlannerError> {
        self.quantities
            .evaluate(
                &self.robot,
                &self.leveler,
                &self.cfg,
                &mut self.zeta,
                &mut self.values,
            )
            .map_err(PlannerError::from)
    }

    /// Current state.
    pub fn zeta(&self) -> &[f64] {
        &self.zeta
    }
    /// zeta indices of the QP variables.
    pub fn free(&self) -> &[usize] {
        &self.free
    }
    /// Quantity vector at the current state (layout: [`Planner::layout`]).
    pub fn values(&self) -> &[f64] {
        &self.values
    }
    /// Jacobian of the quantity vector after the last `step` or `linearize`.
    pub fn jacobian(&self) -> &[f64] {
        &self.jac
    }
    pub fn layout(&self) -> &QuantityLayout {
        &self.quantities.layout
    }
    pub fn config(&self) -> &PlannerConfig {
        &self.cfg
    }
    pub fn robot(&self) -> &RobotDescription {
        &self.robot
    }

    /// World pose of the end effector at the current state.
    pub fn end_effector_pose(&self) -> Isometry3<f64> {
        self.quantities.workspace().link_pose[self.robot.end_effector_link]
    }

    /// Recompute the quantity Jacobian at the current state.
    pub fn linearize(&mut self) -> Result<(), PlannerError> {
        self.quantities
            .jacobian(
                &self.robot,
                &self.leveler,
                &self.cfg,
                &mut self.zeta,
                &self.free,
                &mut self.values,
                &mut self.jac,
            )
            .map_err(PlannerError::from)
    }

    /// The end-effector task rows of the last `step` or `task_rows` call.
    pub fn task(&self) -> &TaskRows {
        &self.task
    }

    /// Linearize and fill the end-effector task rows toward `position` and `orientation`
    /// (world frame; [`super::target`]) at the current state, as `step` does.
    pub fn task_rows(
        &mut self,
        position: &[f64; 3],
        orientation: &EeOrientation,
    ) -> Result<(f64, f64), PlannerError> {
        if !finite(position) {
            return Err(PlannerError::BadInput("target position"));
        }
        match orientation {
            EeOrientation::Axis(a) if !(finite(a.as_slice()) && a.norm() > 1e-9) => {
                return Err(PlannerError::BadInput("target axis"));
            }
            EeOrientation::Pose(r) if !finite(r.coords.as_slice()) => {
                return Err(PlannerError::BadInput("target orientation"));
            }
            _ => {}
        }
        self.linearize()?;
        let ws = self.quantities.workspace();
        let ee = Frame::Link(self.robot.end_effector_link);
        self.robot
            .frame_jacobian(ws, ee, &mut self.j_ee)
            .map_err(PlannerError::Model)?;
        let ee_pose = ws.link_pose[self.robot.end_effector_link];
        let e = self.task.fill(
            &self.cfg,
            &ee_pose,
            &self.j_ee,
            &Vector3::from(*position),
            orientation,
        );
        Ok((e.position, e.orientation))
    }

    /// One planning step toward `position` and `orientation` (world frame).
    pub fn step(
        &mut self,
        position: &[f64; 3],
        orientation: &EeOrientation,
    ) -> Result<StepReport, PlannerError> {
        let (pos_err, rot_err) = self.task_rows(position, orientation)?;
        let ws = self.quantities.workspace();
        let foot = Frame::Link(self.robot.foot_link);
        self.robot
            .frame_jacobian(ws, foot, &mut self.j_foot)
            .map_err(PlannerError::Model)?;
        let foot_pose = ws.link_pose[self.robot.foot_link];
        // eq. (54)'s step (capped at the remaining error so that it converges instead of
        // chattering around the target) and eq. (56)'s rows: self.task (task_rows).
        let foot_pos = self.foot_hold.translation.vector - foot_pose.translation.vector;
        let foot_rot = (self.foot_hold.rotation * foot_pose.rotation.inverse()).scaled_axis();

        // Cost of eq. (57): P = S1 + J_eeᵀ S2' J_ee + J_footᵀ S2'' J_foot, q = -Jᵀ S2 delta-xi.
        let nf = self.free.len();
        let w_foot = if self.cfg.mode == Mode::Flight {
            self.cfg.s2_foot
        } else {
            0.0
        };
        self.p.fill(0.0);
        self.q.fill(0.0);
        for (a, &ka) in self.free.iter().enumerate() {
            self.p[a * nf + a] = match ka {
                0..=2 => self.cfg.s1_position,
                3..=5 => self.cfg.s1_orientation,
                _ => self
                    .cfg
                    .s1_joint_overrides
                    .iter()
                    .find(|&&(j, _)| j + 6 == ka)
                    .map_or(self.cfg.s1_joint, |&(_, w)| w),
            };
            for r in 0..6 {
                let (w_ee, target_ee) = (self.task.weights[r], self.task.step[r]);
                let target_foot = if r < 3 { foot_pos[r] } else { foot_rot[r - 3] };
                let je = self.task.rows[(r, ka)];
                let jf = self.j_foot[(r, ka)];
                self.q[a] -= w_ee * je * target_ee + w_foot * jf * target_foot;
                for (b, &kb) in self.free.iter().enumerate() {
                    self.p[a * nf + b] +=
                        w_ee * je * self.task.rows[(r, kb)] + w_foot * jf * self.j_foot[(r, kb)];
                }
            }
        }

        let stall = &self.robot.stall_torque;
        let ctx = Context {
            cfg: &self.cfg,
            layout: &self.quantities.layout,
            zeta: &self.zeta,
            free: &self.free,
            values: &self.values,
            jac: &self.jac,
            limits: &self.limits,
            stall,
            thrust_min: &self.thrust_min,
        };
        let mut start = 0;
        for (c, &n) in self.constraints.iter().zip(&self.rows) {
            c.write(
                &ctx,
                &mut self.g[start * nf..(start + n) * nf],
                &mut self.h[start..start + n],
            );
            start += n;
        }
        let status = self
            .qp
            .solve(&self.p, &self.q, &[], &[], &self.g, &self.h)
            .map_err(PlannerError::Qp)?;
        let binding = self.binding();
        let report = |status| StepReport {
            status,
            position_error: pos_err,
            orientation_error: rot_err,
            binding,
        };
        if !status.is_ok() {
            return Ok(report(StepStatus::QpFailed(status)));
        }
        for (a, &k) in self.free.iter().enumerate() {
            self.zeta[k] += self.qp.solution()[a];
        }
        self.refresh()?;
        Ok(report(StepStatus::Moved))
    }

    /// The constraint family carrying the largest total dual in the last QP.
    fn binding(&self) -> Option<&'static str> {
        let duals = self.qp.inequality_duals();
        let mut best: Option<(&'static str, f64)> = None;
        let mut start = 0;
        for (c, &n) in self.constraints.iter().zip(&self.rows) {
            let s: f64 = duals.get(start..start + n).map_or(0.0, |d| d.iter().sum());
            start += n;
            if s > 1e-6 && best.is_none_or(|(_, b)| s > b) {
                best = Some((c.name(), s));
            }
        }
        best.map(|(n, _)| n)
    }
}

impl Planner {
    /// Model workspace at the current state.
    pub fn workspace(&self) -> &crate::model::ModelWorkspace {
        self.quantities.workspace()
    }
}
