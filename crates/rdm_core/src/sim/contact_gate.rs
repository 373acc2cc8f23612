//! Whether the next physics step can produce any contact: the plant's collision gate.
//!
//! MuJoCo spends ~3 us of every position pass on collision detection (broad and narrow
//! phase) even while the robot flies a metre from the floor and the ceiling. The gate proves,
//! before a step, that no collidable pair can touch in it; the plant then sets
//! `mjDSBL_CONTACT` for that pass, which skips `mj_collision`. A pass that finds no contact
//! computes exactly the same numbers with the flag as without it, so the gate changes no
//! result (docs/plant.md "The collision gate").
//!
//! The proof, for the models it supports (every collidable pair = one geom of the robot's
//! tree against one static plane or box; anything else: the gate says "possible" always):
//! - each moving geom is a sphere of its `rbound` about `geom_xpos` (MuJoCo's own bound);
//! - the state about to be collided is one step ahead of the `geom_xpos` at hand, and
//!   positions advance with the velocity the last step produced (`qpos += dt * qvel` in
//!   MuJoCo's integrators), so no point of the tree moves further than
//!   `dt * (|v| + |w| * rho + sum_j |qdot_j| * L_j)`: `v`, `w` the free joint's linear and
//!   angular speed, `rho` the farthest geom surface from the root body's origin, `L_j` the
//!   hinge's anchor distance to the root plus `rho` (slides: 1);
//! - a fixed slack covers second-order motion over the step and the pair's margins.

/// A static obstacle of the world.
#[derive(Clone, Debug, PartialEq)]
pub enum Obstacle {
    /// MuJoCo plane: the half space below `normal` through `point` is solid.
    Plane { point: [f64; 3], normal: [f64; 3] },
    /// Box: centre, row-major rotation (world from box), half sizes.
    Box {
        center: [f64; 3],
        rot: [f64; 9],
        half: [f64; 3],
    },
}

impl Obstacle {
    /// Distance from `p` to the obstacle's solid (0 inside; signed for a plane, negative
    /// below its surface).
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        match self {
            Obstacle::Plane { point, normal } => {
                dot(sub(p, *point), *normal) / dot(*normal, *normal).sqrt()
            }
            Obstacle::Box { center, rot, half } => {
                let d = sub(p, *center);
                let mut out = 0.0;
                for k in 0..3 {
                    // local coordinate k = column k of the rotation . d
                    let local = rot[k] * d[0] + rot[3 + k] * d[1] + rot[6 + k] * d[2];
                    let excess = (local.abs() - half[k]).max(0.0);
                    out += excess * excess;
                }
                out.sqrt()
            }
        }
    }
}

/// A geom of the robot's tree that collides with obstacles.
#[derive(Clone, Debug, PartialEq)]
pub struct MovingGeom {
    /// Index into `geom_xpos` rows.
    pub geom: usize,
    /// `geom_rbound` (its bounding sphere about `geom_xpos`).
    pub rbound: f64,
    /// Per obstacle: the pair's margin (MuJoCo contacts below it), `None`: the pair does
    /// not collide.
    pub margins: Vec<Option<f64>>,
}

/// One joint of the tree below the free joint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TreeJoint {
    /// Hinge: its `xanchor` row and its dof.
    Hinge { joint: usize, dof: usize },
    /// Slide: its dof.
    Slide { dof: usize },
}

/// Why the gate cannot read a state.
#[derive(Clone, Debug, PartialEq)]
pub enum ContactGateError {
    /// An array is shorter than the model needs.
    Short {
        what: &'static str,
        need: usize,
        got: usize,
    },
}

impl std::fmt::Display for ContactGateError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ContactGateError::Short { what, need, got } => {
                write!(f, "{what}: {got} values, the model needs {need}")
            }
        }
    }
}

impl std::error::Error for ContactGateError {}

/// The gate of one model (see the module docs).
#[derive(Clone, Debug)]
pub struct ContactGate {
    dt: f64,
    slack: f64,
    obstacles: Vec<Obstacle>,
    geoms: Vec<MovingGeom>,
    /// The free joint's first dof (3 linear, then 3 angular).
    free_dof: usize,
    joints: Vec<TreeJoint>,
    need_geom: usize,
    need_anchor: usize,
    need_qvel: usize,
}

/// What the gate found for one state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GateReading {
    /// Smallest (distance to the obstacle - rbound - margin) over the colliding pairs [m].
    pub clearance: f64,
    /// How far any point of the tree can move in the step [m], slack included.
    pub reach: f64,
}

impl GateReading {
    /// True when some pair may touch in the step (or a value was not finite).
    pub fn possible(&self) -> bool {
        // NaN on either side is unordered: "possible", the safe answer.
        self.clearance.partial_cmp(&self.reach) != Some(std::cmp::Ordering::Greater)
    }
}

impl ContactGate {
    /// A gate for physics steps of `dt` with `slack` metres of extra reach.
    pub fn new(
        dt: f64,
        slack: f64,
        obstacles: Vec<Obstacle>,
        geoms: Vec<MovingGeom>,
        free_dof: usize,
        joints: Vec<TreeJoint>,
    ) -> Self {
        let need_geom = geoms.iter().map(|g| g.geom + 1).max().unwrap_or(0) * 3;
        let need_anchor = joints
            .iter()
            .filter_map(|j| match j {
                TreeJoint::Hinge { joint, .. } => Some((joint + 1) * 3),
                TreeJoint::Slide { .. } => None,
            })
            .max()
            .unwrap_or(0);
        let need_qvel = joints
            .iter()
            .map(|j| match j {
                TreeJoint::Hinge { dof, .. } | TreeJoint::Slide { dof } => dof + 1,
            })
            .chain(std::iter::once(free_dof + 6))
            .max()
            .unwrap_or(0);
        ContactGate {
            dt,
            slack,
            obstacles,
            geoms,
            free_dof,
            joints,
            need_geom,
            need_anchor,
            need_qvel,
        }
    }

    /// The obstacles the gate watches.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    /// Clearance and reach of the state: `geom_xpos` (ngeom x 3, row-major), the root body's
    /// origin, `xanchor` (njnt x 3) and `qvel`. Allocates nothing.
    pub fn read(
        &self,
        geom_xpos: &[f64],
        root: [f64; 3],
        xanchor: &[f64],
        qvel: &[f64],
    ) -> Result<GateReading, ContactGateError> {
        check("geom_xpos", self.need_geom, geom_xpos.len())?;
        check("xanchor", self.need_anchor, xanchor.len())?;
        check("qvel", self.need_qvel, qvel.len())?;
        let mut rho: f64 = 0.0;
        let mut clearance = f64::INFINITY;
        for g in &self.geoms {
            let c = row(geom_xpos, g.geom);
            rho = rho.max(norm(sub(c, root)) + g.rbound);
            for (o, margin) in self.obstacles.iter().zip(&g.margins) {
                if let Some(margin) = margin {
                    let gap = o.distance(c) - g.rbound - margin;
                    if gap.is_nan() {
                        // f64::min would drop the NaN: report it (possible() is then true)
                        return Ok(GateReading {
                            clearance: f64::NAN,
                            reach: f64::INFINITY,
                        });
                    }
                    clearance = clearance.min(gap);
                }
            }
        }
        let f = self.free_dof;
        let v = norm([qvel[f], qvel[f + 1], qvel[f + 2]]);
        let w = norm([qvel[f + 3], qvel[f + 4], qvel[f + 5]]);
        let mut speed = v + w * rho;
        for j in &self.joints {
            speed += match *j {
                TreeJoint::Hinge { joint, dof } => {
                    qvel[dof].abs() * (norm(sub(row(xanchor, joint), root)) + rho)
                }
                TreeJoint::Slide { dof } => qvel[dof].abs(),
            };
        }
        Ok(GateReading {
            clearance,
            reach: self.dt * speed + self.slack,
        })
    }
}

fn check(what: &'static str, need: usize, got: usize) -> Result<(), ContactGateError> {
    if got < need {
        return Err(ContactGateError::Short { what, need, got });
    }
    Ok(())
}

fn row(a: &[f64], i: usize) -> [f64; 3] {
    [a[3 * i], a[3 * i + 1], a[3 * i + 2]]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gate() -> ContactGate {
        ContactGate::new(
            0.001,
            0.01,
            vec![
                Obstacle::Plane {
                    point: [0.0; 3],
                    normal: [0.0, 0.0, 1.0],
                },
                Obstacle::Box {
                    center: [0.0, 0.0, 2.05],
                    rot: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                    half: [5.0, 5.0, 0.05],
                },
            ],
            vec![MovingGeom {
                geom: 1,
                rbound: 0.1,
                margins: vec![Some(0.0), Some(0.0)],
            }],
            0,
            vec![TreeJoint::Hinge { joint: 1, dof: 6 }],
        )
    }

    #[test]
    fn far_from_both_is_clear_and_near_is_possible() {
        let g = gate();
        let anchors = [0.0; 6];
        let mut qvel = [0.0; 7];
        let at = |z: f64| [9.0, 9.0, 9.0, 0.0, 0.0, z];
        let r = g.read(&at(1.0), [0.0, 0.0, 1.0], &anchors, &qvel).unwrap();
        assert!((r.clearance - 0.9).abs() < 1e-12, "{r:?}"); // floor 1.0 - 0.1, ceiling 0.9
        assert!(!r.possible());
        let r = g.read(&at(0.105), [0.0; 3], &anchors, &qvel).unwrap();
        assert!(r.possible(), "5 mm above the floor is inside the slack");
        // 10 m/s up: 1 cm in the step + 1 cm slack = 2 cm of reach; the ceiling's face is
        // at 2.0 m, so a 0.1 m sphere at 1.875 m is 2.5 cm clear and at 1.885 m 1.5 cm
        qvel[2] = 10.0;
        let r = g
            .read(&at(1.875), [0.0, 0.0, 1.875], &anchors, &qvel)
            .unwrap();
        assert!(!r.possible() && (r.reach - 0.02).abs() < 1e-12, "{r:?}");
        let r = g
            .read(&at(1.885), [0.0, 0.0, 1.885], &anchors, &qvel)
            .unwrap();
        assert!(r.possible(), "{r:?}");
    }

    #[test]
    fn rotation_and_joints_widen_the_reach() {
        let g = gate();
        let mut qvel = [0.0; 7];
        let pos = [0.0, 0.0, 0.0, 0.5, 0.0, 1.0];
        let root = [0.0, 0.0, 1.0];
        qvel[3] = 2.0; // 2 rad/s about x: rho = 0.5 + 0.1
        qvel[6] = -1.0; // hinge at the root: L = 0 + 0.6
        let anchors = [0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        let r = g.read(&pos, root, &anchors, &qvel).unwrap();
        let expect = 0.001 * (2.0 * 0.6 + 1.0 * 0.6) + 0.01;
        assert!((r.reach - expect).abs() < 1e-15, "{r:?}");
    }

    #[test]
    fn nan_and_short_arrays_are_safe() {
        let g = gate();
        let r = g
            .read(
                &[0.0, 0.0, 0.0, f64::NAN, 0.0, 1.0],
                [0.0; 3],
                &[0.0; 6],
                &[0.0; 7],
            )
            .unwrap();
        assert!(r.possible());
        let mut qvel = [0.0; 7];
        qvel[0] = f64::NAN;
        let r = g
            .read(
                &[0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
                [0.0, 0.0, 1.0],
                &[0.0; 6],
                &qvel,
            )
            .unwrap();
        assert!(r.possible());
        let e = g
            .read(&[0.0; 3], [0.0; 3], &[0.0; 6], &[0.0; 7])
            .unwrap_err();
        assert_eq!(
            e,
            ContactGateError::Short {
                what: "geom_xpos",
                need: 6,
                got: 3
            }
        );
    }

    #[test]
    fn box_distance_is_euclidean_outside_and_zero_inside() {
        let b = Obstacle::Box {
            center: [1.0, 0.0, 0.0],
            // 90 degrees about z: box x along world y
            rot: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            half: [2.0, 0.5, 0.5],
        };
        assert_eq!(b.distance([1.0, 0.0, 0.0]), 0.0);
        assert!((b.distance([1.0, 3.0, 0.0]) - 1.0).abs() < 1e-12);
        assert!((b.distance([2.5, 0.0, 0.0]) - 1.0).abs() < 1e-12);
        assert!((b.distance([2.5, 3.0, 0.0]) - 2f64.sqrt()).abs() < 1e-12);
    }
}
