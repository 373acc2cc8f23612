//! The foot plate's contact sums for the ground truth: force, moment about the plate origin
//! and centre-of-pressure numerator of every contact between the plate and the environment,
//! in world axes, from MuJoCo's contact list and constraint forces.
//!
//! This is the contact measurement of `FootContactTracker.measure_contacts`
//! (`rdm.plant.truth`), its only form; tests/test_truthlog_truth.py compares its bits with
//! a numpy derivation through `mj_contactForce` on perched states:
//! * the contact force is `mj_contactForce`'s: for an elliptic cone the contact's `dim`
//!   constraint forces copied from `efc_force`; for a pyramidal cone `mju_decodePyramid` of
//!   its `2 (dim - 1)` pyramid forces (normal: their sum in order; tangent i:
//!   `(p[2i] - p[2i+1]) mu_i`; a frictionless contact its one force); zeros after them and
//!   for an excluded contact (`efc_address < 0`). ASSUMPTION: no adhesion (the plant has no
//!   adhesion actuator, so MuJoCo subtracts 0 from the normal force);
//! * the contact frame's rows are (normal, tangent 1, tangent 2); `frameᵀ f` is summed in row
//!   order, `(a0 b0 + a1 b1) + a2 b2` (what numpy's small matrix-vector product gives);
//! * `sign` is +1 when the plate is `geom2`, -1 when it is `geom1` (the force acts on geom2).
//!
//! Sums holding a NaN (a diverged state) keep their NaN: the foot-frame numbers are NaN
//! where numpy's would be, with this module's NaN bits.
//!
//! [`PlateContactModel::measure`] goes on to the foot-frame numbers of `_contact_result`
//! (`-(Rᵀ Σf)`, `-(Rᵀ Στ)`, the ZMP `Rᵀ (Σ|f_n| r / Σ|f_n|)`) and [`yaw_about`] is
//! `_yaw_about`: the products `Rᵀ v` and the dot products summed in index order, as numpy's
//! small products do (the tests compare the bits against a numpy derivation).

/// One row of MuJoCo's contact list (the fields the sums read).
#[derive(Debug, Clone, Copy)]
pub struct ContactRow {
    /// `contact.geom` (geom1, geom2).
    pub geom: [i32; 2],
    /// `contact.frame`, row-major: normal, tangent 1, tangent 2.
    pub frame: [f64; 9],
    /// `contact.pos` (world).
    pub pos: [f64; 3],
    /// `contact.efc_address` (-1: excluded, no constraint rows).
    pub efc_address: i32,
    /// `contact.dim` (1, 3, 4 or 6).
    pub dim: i32,
    /// `contact.friction` (tangent 1, tangent 2, spin, roll 1, roll 2): a pyramidal cone's mu.
    pub friction: [f64; 5],
}

/// What the plate's contacts sum to (world axes, moments about `origin`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlateContactSums {
    /// Contacts between the plate and an environment geom.
    pub points: usize,
    /// Σ f (environment on the plate).
    pub force: [f64; 3],
    /// Σ (sign·t + r × f), r = contact position - origin.
    pub torque: [f64; 3],
    /// Σ |f_normal| r (the centre-of-pressure numerator).
    pub cop_numerator: [f64; 3],
    /// Σ |f_normal|.
    pub normal_sum: f64,
}

/// The foot-frame measurement of the plate's contacts (`_contact_result` before its
/// anchor bookkeeping).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateMeasure {
    /// Contacts between the plate and an environment geom.
    pub points: usize,
    /// What the robot applies to the environment, foot frame: `-(Rᵀ Σf)`.
    pub force: [f64; 3],
    /// Its moment about the plate origin, foot frame: `-(Rᵀ Στ)`.
    pub torque: [f64; 3],
    /// Centre of pressure (x, y) in the foot frame; NaN without a normal force.
    pub zmp: [f64; 2],
}

/// `Rᵀ v` for a row-major rotation `r`, each component summed over `r`'s rows in order.
#[inline]
fn rotate_back(r: &[f64; 9], v: [f64; 3]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (j, o) in out.iter_mut().enumerate() {
        *o = r[j] * v[0] + r[3 + j] * v[1] + r[6 + j] * v[2];
    }
    out
}

#[inline]
fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The rotation from `r0` to `r1` about `r0`'s z axis (both row-major): the x axes
/// projected on the plane normal to it, `atan2(n · (x0 × x1), x0 · x1)`
/// (`rdm.plant.truth._yaw_about`). None when an intermediate value is NaN (the caller's
/// numpy form then decides the NaN it returns).
pub fn yaw_about(r0: &[f64; 9], r1: &[f64; 9]) -> Option<f64> {
    let normal = [r0[2], r0[5], r0[8]];
    let project = |r: &[f64; 9]| {
        let x = [r[0], r[3], r[6]];
        let d = dot3(x, normal);
        [
            x[0] - normal[0] * d,
            x[1] - normal[1] * d,
            x[2] - normal[2] * d,
        ]
    };
    let (x0, x1) = (project(r0), project(r1));
    let cross = [
        x0[1] * x1[2] - x0[2] * x1[1],
        x0[2] * x1[0] - x0[0] * x1[2],
        x0[0] * x1[1] - x0[1] * x1[0],
    ];
    if cross.iter().any(|c| c.is_nan()) {
        return None;
    }
    let (y, x) = (dot3(normal, cross), dot3(x0, x1));
    let yaw = y.atan2(x);
    (!yaw.is_nan()).then_some(yaw)
}

/// Why a contact list cannot be summed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PlateContactError {
    /// A geom id outside the model's geoms.
    GeomOutOfRange { contact: usize, geom: i32 },
    /// `efc_address + dim` outside `efc_force`, or a `dim` outside 1..=6.
    BadForceRows { contact: usize },
}

impl std::fmt::Display for PlateContactError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::GeomOutOfRange { contact, geom } => {
                write!(f, "contact {contact}: geom {geom} outside the model")
            }
            Self::BadForceRows { contact } => {
                write!(
                    f,
                    "contact {contact}: its constraint rows lie outside efc_force"
                )
            }
        }
    }
}

impl std::error::Error for PlateContactError {}

/// The model facts the sums need: each geom's body, which geoms are environment, the plate.
#[derive(Debug, Clone)]
pub struct PlateContactModel {
    geom_body: Vec<i32>,
    environment: Vec<bool>,
    plate_body: i32,
}

impl PlateContactModel {
    /// `geom_body[g]` = body of geom g (`model.geom_bodyid`), `environment[g]` = geom g is
    /// an environment surface (ceiling, floor, task objects), `plate_body` = the foot plate.
    /// Geoms beyond the shorter of the two lists count as out of range.
    pub fn new(geom_body: Vec<i32>, environment: Vec<bool>, plate_body: i32) -> Self {
        Self {
            geom_body,
            environment,
            plate_body,
        }
    }

    fn geom(&self, contact: usize, g: i32) -> Result<(i32, bool), PlateContactError> {
        let i = usize::try_from(g)
            .map_err(|_| PlateContactError::GeomOutOfRange { contact, geom: g })?;
        match (self.geom_body.get(i), self.environment.get(i)) {
            (Some(&body), Some(&env)) => Ok((body, env)),
            _ => Err(PlateContactError::GeomOutOfRange { contact, geom: g }),
        }
    }

    /// -1 / +1 when the contact is the plate (geom1 / geom2) against the environment, else
    /// None (`measure_contacts`' test, in its order).
    fn sign(&self, contact: usize, geom: [i32; 2]) -> Result<Option<f64>, PlateContactError> {
        let (b1, env1) = self.geom(contact, geom[0])?;
        let (b2, env2) = self.geom(contact, geom[1])?;
        Ok(if b1 == self.plate_body && env2 {
            Some(-1.0)
        } else if b2 == self.plate_body && env1 {
            Some(1.0)
        } else {
            None
        })
    }

    /// Sum the plate's contacts of `rows` (in list order), moments about `origin`;
    /// `pyramidal`: the model's friction cone is pyramidal (`opt.cone`).
    pub fn sums(
        &self,
        rows: impl IntoIterator<Item = ContactRow>,
        efc_force: &[f64],
        origin: [f64; 3],
        pyramidal: bool,
    ) -> Result<PlateContactSums, PlateContactError> {
        let [o0, o1, o2] = origin;
        let mut s = PlateContactSums::default();
        let (mut fx, mut fy, mut fz) = (0.0, 0.0, 0.0);
        let (mut tx, mut ty, mut tz) = (0.0, 0.0, 0.0);
        let (mut cx, mut cy, mut cz) = (0.0, 0.0, 0.0);
        let mut normal_sum = 0.0;
        for (i, row) in rows.into_iter().enumerate() {
            let Some(sign) = self.sign(i, row.geom)? else {
                continue;
            };
            let buf = contact_force(i, &row, efc_force, pyramidal)?;
            let (frame, pos) = (&row.frame, &row.pos);
            let [f0, f1, f2] = rotate_back(frame, [buf[0], buf[1], buf[2]]);
            let [t0, t1, t2] = rotate_back(frame, [buf[3], buf[4], buf[5]]);
            let (f0, f1, f2) = (sign * f0, sign * f1, sign * f2);
            let (r0, r1, r2) = (pos[0] - o0, pos[1] - o1, pos[2] - o2);
            fx += f0;
            fy += f1;
            fz += f2;
            tx += sign * t0 + (r1 * f2 - r2 * f1);
            ty += sign * t1 + (r2 * f0 - r0 * f2);
            tz += sign * t2 + (r0 * f1 - r1 * f0);
            let n = buf[0].abs();
            cx += n * r0;
            cy += n * r1;
            cz += n * r2;
            normal_sum += n;
            s.points += 1;
        }
        s.force = [fx, fy, fz];
        s.torque = [tx, ty, tz];
        s.cop_numerator = [cx, cy, cz];
        s.normal_sum = normal_sum;
        Ok(s)
    }

    /// [`Self::sums`], then the foot-frame numbers in the plate frame `rot` (row-major,
    /// `data.xmat` of the plate).
    pub fn measure(
        &self,
        rows: impl IntoIterator<Item = ContactRow>,
        efc_force: &[f64],
        origin: [f64; 3],
        rot: &[f64; 9],
        pyramidal: bool,
    ) -> Result<PlateMeasure, PlateContactError> {
        let s = self.sums(rows, efc_force, origin, pyramidal)?;
        let neg = |v: [f64; 3]| [-v[0], -v[1], -v[2]];
        let zmp = if s.normal_sum > 0.0 {
            let n = s.normal_sum;
            let c = s.cop_numerator;
            let z = rotate_back(rot, [c[0] / n, c[1] / n, c[2] / n]);
            [z[0], z[1]]
        } else {
            [f64::NAN; 2]
        };
        Ok(PlateMeasure {
            points: s.points,
            force: neg(rotate_back(rot, s.force)),
            torque: neg(rotate_back(rot, s.torque)),
            zmp,
        })
    }
}

/// `mj_contactForce`: an elliptic cone's `dim` constraint forces, or a pyramidal cone's
/// forces decoded (`mju_decodePyramid`), zero-padded to 6; all zeros for an excluded contact.
fn contact_force(
    contact: usize,
    row: &ContactRow,
    efc_force: &[f64],
    pyramidal: bool,
) -> Result<[f64; 6], PlateContactError> {
    let mut buf = [0.0; 6];
    if row.efc_address < 0 {
        return Ok(buf);
    }
    let bad = || PlateContactError::BadForceRows { contact };
    let dim = usize::try_from(row.dim).map_err(|_| bad())?;
    if !(1..=6).contains(&dim) {
        return Err(bad());
    }
    let start = usize::try_from(row.efc_address).map_err(|_| bad())?;
    // a pyramidal contact has 2 (dim - 1) rows (a frictionless one its one row)
    let rows = if pyramidal && dim > 1 {
        2 * (dim - 1)
    } else {
        dim
    };
    let forces = start
        .checked_add(rows)
        .and_then(|end| efc_force.get(start..end))
        .ok_or_else(bad)?;
    if !pyramidal || dim == 1 {
        buf[..dim].copy_from_slice(forces);
        return Ok(buf);
    }
    let mut normal = 0.0;
    for p in forces {
        normal += p;
    }
    buf[0] = normal;
    for i in 0..dim - 1 {
        buf[i + 1] =
            (forces[2 * i] - forces[2 * i + 1]) * row.friction.get(i).copied().unwrap_or(0.0);
    }
    Ok(buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Plate body 1 (geom 1), ceiling geom 0 (body 0), an arm geom 2 on body 2.
    fn model() -> PlateContactModel {
        PlateContactModel::new(vec![0, 1, 2], vec![true, false, false], 1)
    }

    const IDENTITY: [f64; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    const MU: [f64; 5] = [1.0, 1.0, 0.005, 0.0001, 0.0001];

    #[test]
    fn a_normal_push_sums_to_its_force_moment_and_centre_of_pressure() {
        let rows = [ContactRow {
            geom: [0, 1],
            frame: IDENTITY,
            pos: [0.1, 0.0, 1.6],
            efc_address: 0,
            dim: 4,
            friction: MU,
        }];
        let s = model()
            .sums(rows, &[5.0, 0.5, -0.25, 0.01], [0.0, 0.0, 1.6], false)
            .unwrap();
        assert_eq!(s.points, 1);
        assert_eq!(s.force, [5.0, 0.5, -0.25]);
        // r = (0.1, 0, 0): r × f = (0, 0.025, 0.05); + the torsional moment about x
        assert_eq!(s.torque, [0.01, 0.1 * 0.25, 0.1 * 0.5]);
        assert_eq!(s.cop_numerator, [0.5, 0.0, 0.0]);
        assert_eq!(s.normal_sum, 5.0);
    }

    #[test]
    fn the_plate_as_geom1_flips_the_sign_and_other_contacts_are_skipped() {
        let row = |geom| ContactRow {
            geom,
            frame: IDENTITY,
            pos: [0.0; 3],
            efc_address: 0,
            dim: 1,
            friction: MU,
        };
        let s = model()
            .sums([row([1, 0]), row([2, 0])], &[3.0], [0.0; 3], false)
            .unwrap();
        assert_eq!(s.points, 1);
        assert_eq!(s.force, [-3.0, -0.0, -0.0]);
        assert_eq!(s.normal_sum, 3.0);
    }

    #[test]
    fn an_excluded_contact_counts_with_zero_force() {
        let rows = [ContactRow {
            geom: [0, 1],
            frame: IDENTITY,
            pos: [0.0; 3],
            efc_address: -1,
            dim: 3,
            friction: MU,
        }];
        let s = model().sums(rows, &[], [0.0; 3], true).unwrap();
        assert_eq!((s.points, s.normal_sum, s.force), (1, 0.0, [0.0; 3]));
    }

    #[test]
    fn the_measure_is_in_the_plate_frame_and_nan_sums_stay_nan() {
        let m = model();
        let row = ContactRow {
            geom: [0, 1],
            frame: IDENTITY,
            pos: [0.1, 0.0, 1.6],
            efc_address: 0,
            dim: 1,
            friction: MU,
        };
        // plate turned 90 deg about z: world x is the plate's -y
        let rot = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        let out = m
            .measure([row], &[4.0], [0.0, 0.0, 1.6], &rot, false)
            .unwrap();
        assert_eq!(out.points, 1);
        assert_eq!(out.force, [-0.0, 4.0, -0.0]);
        assert_eq!(out.zmp, [0.0, -0.1]);
        let nan = m
            .measure([row], &[f64::NAN], [0.0; 3], &rot, false)
            .unwrap();
        assert!(nan.force[1].is_nan() && nan.zmp.iter().all(|z| z.is_nan()));
        let none = m.measure([], &[], [0.0; 3], &rot, false).unwrap();
        assert!(none.zmp.iter().all(|z| z.is_nan()) && none.points == 0);
    }

    #[test]
    fn a_pyramidal_contact_is_decoded() {
        // dim 3: pyramid rows (p0, p1, p2, p3); normal p0 + p1 + p2 + p3 in order,
        // tangent i = (p[2i] - p[2i+1]) mu_i
        let row = ContactRow {
            geom: [0, 1],
            frame: IDENTITY,
            pos: [0.0, 0.0, 1.6],
            efc_address: 1,
            dim: 3,
            friction: [0.5, 0.25, 0.0, 0.0, 0.0],
        };
        let efc = [9.0, 1.0, 2.0, 3.0, 5.0];
        let s = model().sums([row], &efc, [0.0, 0.0, 1.6], true).unwrap();
        assert_eq!(s.force, [11.0, (1.0 - 2.0) * 0.5, (3.0 - 5.0) * 0.25]);
        // the rows past dim are read: a short efc_force is an error
        assert_eq!(
            model().sums([row], &efc[..4], [0.0; 3], true).unwrap_err(),
            PlateContactError::BadForceRows { contact: 0 }
        );
        // a frictionless pyramidal contact is its one force
        let one = ContactRow { dim: 1, ..row };
        let s = model().sums([one], &efc, [0.0, 0.0, 1.6], true).unwrap();
        assert_eq!(s.force, [1.0, 0.0, 0.0]);
    }

    #[test]
    fn yaw_about_measures_a_turn_about_the_normal() {
        let a = 0.3f64;
        let turned = [a.cos(), -a.sin(), 0.0, a.sin(), a.cos(), 0.0, 0.0, 0.0, 1.0];
        let yaw = yaw_about(&IDENTITY, &turned).unwrap();
        assert!((yaw - a).abs() < 1e-15);
        assert_eq!(yaw_about(&IDENTITY, &IDENTITY), Some(0.0));
        let mut bad = IDENTITY;
        bad[0] = f64::NAN;
        assert_eq!(yaw_about(&IDENTITY, &bad), None);
    }

    #[test]
    fn bad_rows_are_errors_not_panics() {
        let row = |geom, efc_address, dim| ContactRow {
            geom,
            frame: IDENTITY,
            pos: [0.0; 3],
            efc_address,
            dim,
            friction: MU,
        };
        let m = model();
        let err = |r| m.sums([r], &[1.0, 2.0], [0.0; 3], false).unwrap_err();
        assert_eq!(
            err(row([0, 7], 0, 1)),
            PlateContactError::GeomOutOfRange {
                contact: 0,
                geom: 7
            }
        );
        assert_eq!(
            err(row([-1, 1], 0, 1)),
            PlateContactError::GeomOutOfRange {
                contact: 0,
                geom: -1
            }
        );
        assert_eq!(
            err(row([0, 1], 1, 3)),
            PlateContactError::BadForceRows { contact: 0 }
        );
        assert_eq!(
            err(row([0, 1], 0, 7)),
            PlateContactError::BadForceRows { contact: 0 }
        );
        // a contact that is not the plate's is skipped before its rows are read
        assert_eq!(
            m.sums([row([2, 0], 5, 9)], &[], [0.0; 3], false)
                .unwrap()
                .points,
            0
        );
    }
}
