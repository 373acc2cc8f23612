//! `FootTrackerCore`: `rdm_core::sim::foot_track::FootTrack` (the foot plate's contact
//! anchor and last contact time) with the plate's geoms and the cached view of MuJoCo's
//! contact geom pairs. Its Python face is `rdm.plant.truth.FootContactTracker`; the lockstep
//! kernel's plant step calls `update` on the same object.

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rdm_core::sim::foot_track::{plate_in, FootTrack};

use crate::lqi::to_vector;

/// `update`: done.
pub(crate) const DONE: u8 = 0;
/// `update`: the contact list has no cached view (the caller builds it, `keep_view`, and
/// calls `update` again).
pub(crate) const NEEDS_VIEW: u8 = 1;
/// `update`: a contact began without an anchor (the caller sets it with `set_anchor`).
pub(crate) const NEEDS_ANCHOR: u8 = 2;

/// The view of `data.contact.geom` last read: its MjData, ncon, address and the view.
struct GeomView {
    data: Py<PyAny>,
    ncon: i64,
    address: usize,
    geom: Py<PyArray2<i32>>,
}

/// The foot plate's contact anchor (see the module doc).
#[pyclass(module = "rdm._rdm")]
pub struct FootTrackerCore {
    track: FootTrack,
    plate_geoms: Vec<i32>,
    view: Option<GeomView>,
    view_misses: u64,
}

impl FootTrackerCore {
    /// The cached view when it is `data`'s list of `ncon` contacts.
    fn view_for<'py>(
        &self,
        data: &Bound<'py, PyAny>,
        ncon: i64,
    ) -> Option<&Bound<'py, PyArray2<i32>>> {
        let v = self.view.as_ref()?;
        (v.ncon == ncon && v.data.bind(data.py()).is(data)).then(|| v.geom.bind(data.py()))
    }

    fn plate_in_view(&self, geom: &Bound<'_, PyArray2<i32>>) -> bool {
        // SAFETY: read only, no Python runs while the view lives (untracked.rs); a strided
        // view of MuJoCo's contact structs, hence the array view, not a slice.
        let pairs = unsafe { geom.as_array() };
        plate_in(pairs.iter().copied(), &self.plate_geoms)
    }

    /// No anchor and no contact time to release.
    pub(crate) fn idle_now(&self) -> bool {
        self.track.idle()
    }

    /// One step's bookkeeping (`update`'s rule), see `update`.
    pub(crate) fn update_at(&mut self, data: &Bound<'_, PyAny>, ncon: i64, time: f64) -> u8 {
        let in_contact = if ncon != 0 {
            let Some(geom) = self.view_for(data, ncon) else {
                return NEEDS_VIEW;
            };
            self.plate_in_view(geom)
        } else if self.track.idle() {
            return DONE;
        } else {
            false
        };
        if self.track.track(time, in_contact) {
            NEEDS_ANCHOR
        } else {
            DONE
        }
    }
}

#[pymethods]
impl FootTrackerCore {
    /// The plate's geom ids; the anchor survives contact gaps up to `release_time` [s].
    #[new]
    fn new(plate_geoms: Vec<i32>, release_time: f64) -> PyResult<Self> {
        check_release(release_time)?;
        Ok(FootTrackerCore {
            track: FootTrack::new(release_time),
            plate_geoms,
            view: None,
            view_misses: 0,
        })
    }

    /// Longest contact gap [s] the anchor survives.
    #[getter]
    fn release_time(&self) -> f64 {
        self.track.release_time
    }

    #[setter]
    fn set_release_time(&mut self, seconds: f64) -> PyResult<()> {
        check_release(seconds)?;
        self.track.release_time = seconds;
        Ok(())
    }

    /// The last time the plate touched (-inf: none since the last release).
    #[getter]
    fn last_contact_time(&self) -> f64 {
        self.track.last_contact_time()
    }

    /// The plate's world position at first contact (a new array), or None.
    #[getter]
    fn anchor_pos<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.track
            .anchor()
            .map(|a| PyArray1::from_slice(py, &a.pos))
    }

    /// The plate's rotation at first contact (a new 3x3 array), or None.
    #[getter]
    fn anchor_rot<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.track.anchor().map(|a| {
            let r = &a.rot;
            PyArray2::from_owned_array(
                py,
                numpy::ndarray::Array2::from_shape_fn((3, 3), |(i, j)| r[3 * i + j]),
            )
        })
    }

    /// No anchor and no contact time to release.
    fn idle(&self) -> bool {
        self.track.idle()
    }

    /// Forget the anchor and the contact time.
    fn reset(&mut self) {
        self.track.reset();
    }

    /// One step at `time` with or without a plate contact; True: a contact without an
    /// anchor (set it with `set_anchor`).
    fn track(&mut self, time: f64, in_contact: bool) -> bool {
        self.track.track(time, in_contact)
    }

    /// The anchor: the plate's world position `pos` (3) and row-major rotation `rot` (9).
    fn set_anchor(
        &mut self,
        pos: PyReadonlyArray1<'_, f64>,
        rot: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<()> {
        let pos: [f64; 3] = to_vector::<3>(&pos, "pos")?.into();
        let rot: [f64; 9] = to_vector::<9>(&rot, "rot")?.into();
        self.track.set_anchor(pos, rot);
        Ok(())
    }

    /// One step's bookkeeping at `time` for `data` with `ncon` contacts: 0 done, 1 the
    /// cached view is not this list's (build it, `keep_view`, call again; nothing changed),
    /// 2 a plate contact began without an anchor (`set_anchor`; the time is stamped).
    fn update(&mut self, data: &Bound<'_, PyAny>, ncon: i64, time: f64) -> u8 {
        self.update_at(data, ncon, time)
    }

    /// Keep `geom` (`data.contact.geom` of `ncon` contacts at `address`) as the cached view.
    fn keep_view(
        &mut self,
        data: &Bound<'_, PyAny>,
        ncon: i64,
        address: usize,
        geom: Bound<'_, PyArray2<i32>>,
    ) -> PyResult<()> {
        if geom.ndim() != 2 || geom.shape()[1] != 2 {
            return Err(PyValueError::new_err(format!(
                "geom: expected (n, 2) geom pairs, got shape {:?}",
                geom.shape()
            )));
        }
        self.view = Some(GeomView {
            data: data.clone().unbind(),
            ncon,
            address,
            geom: geom.unbind(),
        });
        Ok(())
    }

    /// The cached view when it is `data`'s list of `ncon` contacts, else None.
    fn view_of<'py>(
        &self,
        data: &Bound<'py, PyAny>,
        ncon: i64,
    ) -> Option<Bound<'py, PyArray2<i32>>> {
        self.view_for(data, ncon).cloned()
    }

    /// The address of the cached view's contact list (None: no view).
    #[getter]
    fn view_address(&self) -> Option<usize> {
        self.view.as_ref().map(|v| v.address)
    }

    /// Drop the cached view: the contact list moved (counted in `view_misses`).
    fn forget_view(&mut self) {
        self.view = None;
        self.view_misses += 1;
    }

    /// Times a cached view was found pointing elsewhere.
    #[getter]
    fn view_misses(&self) -> u64 {
        self.view_misses
    }

    /// Whether a plate geom is in `geom` (a `data.contact.geom` view: n pairs).
    fn plate_in(&self, geom: PyReadonlyArray2<'_, i32>) -> bool {
        plate_in(geom.as_array().iter().copied(), &self.plate_geoms)
    }
}

fn check_release(seconds: f64) -> PyResult<()> {
    if seconds.is_nan() || seconds < 0.0 {
        return Err(PyValueError::new_err(format!(
            "release_time: must be >= 0, got {seconds}"
        )));
    }
    Ok(())
}

/// Register `FootTrackerCore`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<FootTrackerCore>()?;
    Ok(())
}
