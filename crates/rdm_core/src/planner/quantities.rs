//! Every constrained quantity of one configuration in one flat vector, and its Jacobian
//! w.r.t. the free state variables by central finite differences of the model (each probe
//! re-levels the vectoring units, so the Jacobian includes their dependent motion):
//! joint torques (eq. 61), thrusts and their upper limit (eqs. 63-64), rho (eq. 65),
//! shape clearances (eq. 67) and rotor airflow clearances (eq. 68).

use nalgebra::{Isometry3, Point3, Vector3};

use super::config::{Mode, PlannerConfig, ShapePair, ShapeSpec};
use super::leveling::Leveler;
use super::shapes::{ceiling_clearance, clearance, PlacedShape};
use super::thrust::static_thrust;
use crate::model::{
    base_pose_from_zeta, ModelError, ModelWorkspace, RobotDescription, StaticLoads,
};

/// Where each quantity sits in the flat vector.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct QuantityLayout {
    pub n_q: usize,
    pub n_rotors: usize,
    pub n_pairs: usize,
    /// Rotor pairs (i, j) on different units, for the airflow constraint.
    pub airflow_pairs: Vec<(usize, usize)>,
}

impl QuantityLayout {
    pub fn torque(&self) -> usize {
        0
    }
    pub fn thrust(&self) -> usize {
        self.n_q
    }
    pub fn thrust_upper(&self) -> usize {
        self.n_q + self.n_rotors
    }
    pub fn rho(&self) -> usize {
        self.n_q + 2 * self.n_rotors
    }
    pub fn pairs(&self) -> usize {
        self.rho() + 1
    }
    pub fn airflow(&self) -> usize {
        self.pairs() + self.n_pairs
    }
    /// Total length.
    pub fn len(&self) -> usize {
        self.airflow() + self.airflow_pairs.len()
    }
    /// Never empty (torques and rho always exist).
    pub fn is_empty(&self) -> bool {
        false
    }
}

/// Evaluator of the quantity vector (owns its workspace and scratch).
#[derive(Clone, Debug)]
pub struct Quantities {
    pub layout: QuantityLayout,
    ws: ModelWorkspace,
    tau: Vec<f64>,
    q_scratch: Vec<f64>,
    probe: Vec<f64>,
    plus: Vec<f64>,
    minus: Vec<f64>,
}

fn place(spec: &ShapeSpec, ws: &ModelWorkspace) -> PlacedShape {
    let at = |link: usize, p: &[f64; 3]| -> Vector3<f64> {
        ws.link_pose.get(link).map_or(Vector3::zeros(), |pose| {
            pose.transform_point(&Point3::from(*p)).coords
        })
    };
    match spec {
        ShapeSpec::Capsule { link, a, b, radius } => PlacedShape {
            a: at(*link, a),
            b: at(*link, b),
            radius: *radius,
        },
        ShapeSpec::Sphere {
            link,
            center,
            radius,
        } => {
            let c = at(*link, center);
            PlacedShape {
                a: c,
                b: c,
                radius: *radius,
            }
        }
    }
}

impl Quantities {
    /// Evaluator for `robot` with the shape pairs of `cfg`.
    pub fn new(robot: &RobotDescription, cfg: &PlannerConfig) -> Self {
        let mut airflow_pairs = Vec::new();
        let unit_of = |r: usize| robot.units.iter().position(|u| u.rotors.contains(&r));
        for i in 0..robot.n_rotors() {
            for j in i + 1..robot.n_rotors() {
                if unit_of(i) != unit_of(j) || unit_of(i).is_none() {
                    airflow_pairs.push((i, j));
                }
            }
        }
        let layout = QuantityLayout {
            n_q: robot.n_q(),
            n_rotors: robot.n_rotors(),
            n_pairs: cfg.pairs.len(),
            airflow_pairs,
        };
        let n = layout.len();
        Self {
            layout,
            ws: ModelWorkspace::new(robot),
            tau: vec![0.0; robot.n_q()],
            q_scratch: vec![0.0; robot.n_q()],
            probe: vec![0.0; 6 + robot.n_q()],
            plus: vec![0.0; n],
            minus: vec![0.0; n],
        }
    }

    /// The workspace of the last `evaluate` (for poses and Jacobians).
    pub fn workspace(&self) -> &ModelWorkspace {
        &self.ws
    }

    /// Level the units in `zeta` (in place) and fill `out` with the quantity vector.
    /// Err: model error or a singular allocation (reported as `Err(None)`).
    pub fn evaluate(
        &mut self,
        robot: &RobotDescription,
        leveler: &Leveler,
        cfg: &PlannerConfig,
        zeta: &mut [f64],
        out: &mut [f64],
    ) -> Result<(), Option<ModelError>> {
        let n_q = robot.n_q();
        if zeta.len() != 6 + n_q || out.len() != self.layout.len() {
            return Err(None);
        }
        let p = Vector3::new(zeta[0], zeta[1], zeta[2]);
        let eta = Vector3::new(zeta[3], zeta[4], zeta[5]);
        let base: Isometry3<f64> = base_pose_from_zeta(&p, &eta);
        self.q_scratch.copy_from_slice(&zeta[6..]);
        robot
            .evaluate(&self.q_scratch, &base, &mut self.ws)
            .map_err(Some)?;
        leveler.level(&self.ws, &mut self.q_scratch);
        robot
            .evaluate(&self.q_scratch, &base, &mut self.ws)
            .map_err(Some)?;
        zeta[6..].copy_from_slice(&self.q_scratch);

        let perched = cfg.mode == Mode::Perched;
        let st = static_thrust(
            robot,
            &self.ws,
            cfg.gravity,
            perched.then_some(cfg.perch_force),
            &cfg.ee_force,
        )
        .ok_or(None)?;
        let l = &self.layout;
        let mut foot_wrench = [0.0; 6];
        if perched {
            foot_wrench[2] = -cfg.perch_force;
        }
        let ee_wrench = [
            cfg.ee_force[0],
            cfg.ee_force[1],
            cfg.ee_force[2],
            0.0,
            0.0,
            0.0,
        ];
        let gravity = [0.0, 0.0, -cfg.gravity];
        let thrusts = [st.thrust[0], st.thrust[1], st.thrust[2], st.thrust[3]];
        let thrusts = thrusts.get(..l.n_rotors).ok_or(None)?;
        let residual = robot
            .static_torques(
                &self.ws,
                &StaticLoads {
                    thrusts,
                    foot_wrench: &foot_wrench,
                    end_effector_wrench: &ee_wrench,
                    gravity: &gravity,
                },
                &mut self.tau,
            )
            .map_err(Some)?;
        if perched && residual.norm() > 1e-9 {
            // The ceiling absorbs whatever the loads leave over (the end-effector force).
            let foot = self.ws.link_pose[robot.foot_link].translation.vector;
            let lever = foot - self.ws.base.translation.vector;
            let f = -residual.fixed_rows::<3>(0).into_owned();
            let m = -residual.fixed_rows::<3>(3).into_owned() - lever.cross(&f);
            for k in 0..3 {
                foot_wrench[k] += f[k];
                foot_wrench[3 + k] += m[k];
            }
            robot
                .static_torques(
                    &self.ws,
                    &StaticLoads {
                        thrusts,
                        foot_wrench: &foot_wrench,
                        end_effector_wrench: &ee_wrench,
                        gravity: &gravity,
                    },
                    &mut self.tau,
                )
                .map_err(Some)?;
        }
        out[l.torque()..l.torque() + n_q].copy_from_slice(&self.tau);
        for i in 0..l.n_rotors {
            out[l.thrust() + i] = st.thrust[i];
            out[l.thrust_upper() + i] = st.upper[i];
        }
        out[l.rho()] = st.rho;
        for (k, pair) in cfg.pairs.iter().enumerate() {
            let d = match *pair {
                ShapePair::Shapes(i, j) => match (cfg.shapes.get(i), cfg.shapes.get(j)) {
                    (Some(a), Some(b)) => clearance(&place(a, &self.ws), &place(b, &self.ws)),
                    _ => f64::INFINITY,
                },
                ShapePair::Ceiling(i) => cfg.shapes.get(i).map_or(f64::INFINITY, |s| {
                    ceiling_clearance(&place(s, &self.ws), cfg.ceiling_z)
                }),
            };
            out[l.pairs() + k] = d.min(1e3);
        }
        for (k, &(i, j)) in l.airflow_pairs.iter().enumerate() {
            let d = (self.ws.rotor_position[i] - self.ws.rotor_position[j]).norm();
            let diameter = robot.rotors[i].diameter.max(robot.rotors[j].diameter);
            out[l.airflow() + k] = d - diameter;
        }
        Ok(())
    }

    /// Central-difference Jacobian of the quantity vector w.r.t. `zeta[free[k]]` into
    /// `jac` (row-major, len x free.len()). Leaves the workspace at `zeta` (re-levelled).
    #[allow(clippy::too_many_arguments)]
    pub fn jacobian(
        &mut self,
        robot: &RobotDescription,
        leveler: &Leveler,
        cfg: &PlannerConfig,
        zeta: &mut [f64],
        free: &[usize],
        values: &mut [f64],
        jac: &mut [f64],
    ) -> Result<(), Option<ModelError>> {
        let n = self.layout.len();
        let nf = free.len();
        if jac.len() != n * nf || zeta.len() != self.probe.len() {
            return Err(None);
        }
        let h = cfg.fd_step;
        let mut plus = std::mem::take(&mut self.plus);
        let mut minus = std::mem::take(&mut self.minus);
        let mut probe = std::mem::take(&mut self.probe);
        let mut result = Ok(());
        for (c, &k) in free.iter().enumerate() {
            probe.copy_from_slice(zeta);
            probe[k] += h;
            result = self.evaluate(robot, leveler, cfg, &mut probe, &mut plus);
            if result.is_err() {
                break;
            }
            probe.copy_from_slice(zeta);
            probe[k] -= h;
            result = self.evaluate(robot, leveler, cfg, &mut probe, &mut minus);
            if result.is_err() {
                break;
            }
            for r in 0..n {
                jac[r * nf + c] = (plus[r] - minus[r]) / (2.0 * h);
            }
        }
        self.plus = plus;
        self.minus = minus;
        self.probe = probe;
        result?;
        self.evaluate(robot, leveler, cfg, zeta, values)
    }
}
