//! Binding of `rdm_core::sim::plate_contact`: the foot plate's contact measurement of
//! `rdm.plant.truth.FootContactTracker.measure_contacts` (its only form), read straight from
//! MuJoCo's contact-list views (strided numpy arrays) and `efc_force`.

use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyIndexError, PyValueError};
use pyo3::prelude::*;
use rdm_core::sim::plate_contact::{yaw_about, ContactRow, PlateContactModel};

use crate::lqi::to_vector;

/// `(points, force, torque, zmp)` of the plate's contacts.
type MeasureOut<'py> = (
    usize,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
);

/// The plate-contact sums for one model (see `rdm_core::sim::plate_contact`).
#[pyclass(module = "rdm._rdm", frozen)]
struct PlateContactCore {
    inner: PlateContactModel,
}

#[pymethods]
impl PlateContactCore {
    /// ``geom_body`` = ``model.geom_bodyid``, ``environment[g]`` = geom g is an environment
    /// surface, ``plate_body`` = the foot plate's body.
    #[new]
    fn new(geom_body: Vec<i32>, environment: Vec<bool>, plate_body: i32) -> PyResult<Self> {
        if geom_body.len() != environment.len() {
            return Err(PyValueError::new_err(format!(
                "environment: {} flags for {} geoms",
                environment.len(),
                geom_body.len()
            )));
        }
        Ok(Self {
            inner: PlateContactModel::new(geom_body, environment, plate_body),
        })
    }

    /// The plate's contacts measured in its frame: ``geom`` (n, 2), ``frame`` (n, 9),
    /// ``pos`` (n, 3), ``efc_address`` (n,), ``dim`` (n,), ``friction`` (n, 5) (the
    /// ``data.contact`` views), ``efc_force``, the plate origin and its row-major rotation
    /// (``data.xmat`` row), and whether the friction cone is pyramidal (``opt.cone``).
    /// Returns ``(points, force, torque, zmp)`` (new float64 arrays: what the robot applies,
    /// foot frame; ZMP NaN without a normal force; NaN sums stay NaN). ValueError
    /// (``RdmError`` for origin / rot) on mismatched shapes, IndexError on a geom or
    /// constraint row outside the model / ``efc_force``.
    #[allow(clippy::too_many_arguments)]
    fn measure<'py>(
        &self,
        py: Python<'py>,
        geom: PyReadonlyArray2<'py, i32>,
        frame: PyReadonlyArray2<'py, f64>,
        pos: PyReadonlyArray2<'py, f64>,
        efc_address: PyReadonlyArray1<'py, i32>,
        dim: PyReadonlyArray1<'py, i32>,
        friction: PyReadonlyArray2<'py, f64>,
        efc_force: PyReadonlyArray1<'py, f64>,
        origin: PyReadonlyArray1<'py, f64>,
        rot: PyReadonlyArray1<'py, f64>,
        pyramidal: bool,
    ) -> PyResult<MeasureOut<'py>> {
        let (geom, frame, pos) = (geom.as_array(), frame.as_array(), pos.as_array());
        let friction = friction.as_array();
        let (efc_address, dim) = (efc_address.as_array(), dim.as_array());
        let n = geom.nrows();
        if geom.ncols() != 2
            || frame.dim() != (n, 9)
            || pos.dim() != (n, 3)
            || efc_address.len() != n
            || dim.len() != n
            || friction.dim() != (n, 5)
        {
            return Err(PyValueError::new_err(format!(
                "contact views: geom {:?}, frame {:?}, pos {:?}, efc_address {}, dim {}, \
                 friction {:?} (expected (n, 2), (n, 9), (n, 3), n, n, (n, 5))",
                geom.dim(),
                frame.dim(),
                pos.dim(),
                efc_address.len(),
                dim.len(),
                friction.dim()
            )));
        }
        let origin: [f64; 3] = to_vector::<3>(&origin, "origin")?.into();
        let rot: [f64; 9] = to_vector::<9>(&rot, "rot")?.into();
        let rows = (0..n).map(|i| {
            let mut row = ContactRow {
                geom: [geom[(i, 0)], geom[(i, 1)]],
                frame: [0.0; 9],
                pos: [0.0; 3],
                efc_address: efc_address[i],
                dim: dim[i],
                friction: [0.0; 5],
            };
            for (k, v) in row.frame.iter_mut().enumerate() {
                *v = frame[(i, k)];
            }
            for (k, v) in row.pos.iter_mut().enumerate() {
                *v = pos[(i, k)];
            }
            for (k, v) in row.friction.iter_mut().enumerate() {
                *v = friction[(i, k)];
            }
            row
        });
        let m = match efc_force.as_slice() {
            Ok(f) => self.inner.measure(rows, f, origin, &rot, pyramidal),
            Err(_) => self.inner.measure(
                rows,
                &efc_force.as_array().to_vec(),
                origin,
                &rot,
                pyramidal,
            ),
        }
        .map_err(|e| PyIndexError::new_err(e.to_string()))?;
        Ok((
            m.points,
            PyArray1::from_slice(py, &m.force),
            PyArray1::from_slice(py, &m.torque),
            PyArray1::from_slice(py, &m.zmp),
        ))
    }

    /// ``_yaw_about(r0[:, 2], r0, r1)`` of two row-major rotations (9 values each): the
    /// turn from ``r0`` to ``r1`` about ``r0``'s z axis; None when a value on the way is NaN.
    #[staticmethod]
    fn yaw_about(
        r0: PyReadonlyArray1<'_, f64>,
        r1: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Option<f64>> {
        let r0: [f64; 9] = to_vector::<9>(&r0, "r0")?.into();
        let r1: [f64; 9] = to_vector::<9>(&r1, "r1")?.into();
        Ok(yaw_about(&r0, &r1))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PlateContactCore>()?;
    Ok(())
}
