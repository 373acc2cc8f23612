//! The plan of `SpinalMirror.kernel_plan()` (the window in which a tick is only the CAN ms)
//! and its busy part (`SpinalMirror._kernel_busy_plan`), read from the mirror's tuples.

use pyo3::prelude::*;
use pyo3::types::{PyBool, PyTuple};
use rdm_core::control::attitude::SpinalOutput;

use super::SpinalFast;
use crate::attitude::{PySpinalStep, SpinalStepOutput};
use crate::can_master::CanMaster;
use crate::kernel::attr::read_plan;
use crate::spinal_mirror::exact_i64;

/// Plan of `SpinalMirror.kernel_plan()`: the window in which a tick is only the CAN ms.
/// The clock, CAN ms, control time and battery are the mirror's `SpinalMirrorState`,
/// read and changed in place.
pub(super) struct Plan {
    pub(super) idle_lo: i64,
    pub(super) idle_hi: i64,
    /// False: `_publish` returns at once (the boot before the session is configured and
    /// a control output exists) whatever `next_pub_ms` says.
    pub(super) publish_live: bool,
    /// None: busy ms are the Python tick's.
    pub(super) busy: Option<Busy>,
    /// Before the CAN master first runs: its phase index (booting, enumerating,
    /// configuring), which a CAN ms here must leave unchanged; None: the steady master.
    pub(super) boot_state: Option<u8>,
}

/// The busy part of the plan (`SpinalMirror._kernel_busy_plan`), kept up to date here.
pub(super) struct Busy {
    /// The `SpinalStep` when a control step can run here.
    pub(super) core: Option<Py<PySpinalStep>>,
    pub(super) period: f64,
    pub(super) idle_duty: f64,
    pub(super) configured: bool,
    /// `last_output is not None`, and its values when it is a `SpinalStepOutput`.
    pub(super) has_output: bool,
    pub(super) output: Option<SpinalOutput>,
    pub(super) imu_topic: Option<u16>,
    /// `ClientClock`'s sync state as `client_stamp` takes it (None: not synced); `sync_ok`
    /// false when the clock is no `ClientClock` or its values are not exact (then
    /// `spinal_imu_frame` declines): publications are then the Python tick's.
    pub(super) sync: Option<(i64, i64)>,
    pub(super) sync_ok: bool,
    pub(super) imu_last: Option<i64>,
    pub(super) imu_period: i64,
    pub(super) servo_topic: Option<u16>,
    pub(super) servo_core: Option<Py<CanMaster>>,
    pub(super) servo_last: Option<i64>,
    pub(super) servo_period: i64,
    /// First ms another publisher (battery status, motor pwms, torque states) is due.
    pub(super) others_next: i64,
    pub(super) output_size: usize,
    pub(super) chunk_bytes: usize,
    /// Chunks of the TX ring (None: the ring is not empty).
    pub(super) chunks: Option<usize>,
    pub(super) writes_whole: bool,
    pub(super) max_pending: usize,
    /// The UART chain `(droppable, tapped, end)` the kernel writes the output through; None
    /// (no chain to write through): the publications are the Python tick's.
    pub(super) chain: Option<Chain>,
}

/// `UartPump._chain` (`inproc_chain`): the optional cuttable link and capture tap, the
/// in-process end.
pub(super) struct Chain {
    pub(super) droppable: Option<Py<PyAny>>,
    pub(super) tapped: Option<Py<PyAny>>,
    pub(super) end: Py<PyAny>,
}

impl Chain {
    fn load(v: &Bound<'_, PyAny>) -> PyResult<Option<Chain>> {
        if v.is_none() {
            return Ok(None);
        }
        let t = v.cast::<PyTuple>()?;
        let opt = |i: usize| -> PyResult<Option<Py<PyAny>>> {
            let x = t.get_item(i)?;
            Ok(if x.is_none() { None } else { Some(x.unbind()) })
        };
        Ok(Some(Chain {
            droppable: opt(0)?,
            tapped: opt(1)?,
            end: t.get_item(2)?.unbind(),
        }))
    }
}

fn opt_i64(v: &Bound<'_, PyAny>) -> PyResult<Option<i64>> {
    if v.is_none() {
        Ok(None)
    } else {
        Ok(Some(v.extract()?))
    }
}

fn opt_topic(v: &Bound<'_, PyAny>) -> PyResult<Option<u16>> {
    Ok(opt_i64(v)?.and_then(|t| u16::try_from(t).ok()))
}

impl Busy {
    fn load(t: &Bound<'_, PyTuple>) -> PyResult<Busy> {
        let core = t.get_item(0)?;
        let core = if core.is_none() {
            None
        } else {
            Some(core.cast_into::<PySpinalStep>()?.unbind())
        };
        let last_output = t.get_item(4)?;
        let output = last_output
            .cast_exact::<SpinalStepOutput>()
            .ok()
            .map(|o| o.get().inner);
        // spinal_imu_frame's argument checks: an exact bool, exact ints when synced.
        let synced = t.get_item(6)?;
        let (sync, sync_ok) = match synced.cast_exact::<PyBool>() {
            Ok(s) if s.is_true() => {
                match (exact_i64(&t.get_item(7)?), exact_i64(&t.get_item(8)?)) {
                    (Some(tick), Some(ns)) => (Some((tick, ns)), true),
                    _ => (None, false),
                }
            }
            Ok(_) => (None, true),
            Err(_) => (None, false),
        };
        let servo_core = t.get_item(12)?;
        let servo_core = if servo_core.is_none() {
            None
        } else {
            Some(servo_core.cast_into_exact::<CanMaster>()?.unbind())
        };
        let chunks: i64 = t.get_item(18)?.extract()?;
        Ok(Busy {
            core,
            period: t.get_item(1)?.extract()?,
            idle_duty: t.get_item(2)?.extract()?,
            configured: t.get_item(3)?.is_truthy()?,
            has_output: !last_output.is_none(),
            output,
            imu_topic: opt_topic(&t.get_item(5)?)?,
            sync,
            sync_ok,
            imu_last: opt_i64(&t.get_item(9)?)?,
            imu_period: t.get_item(10)?.extract()?,
            servo_topic: opt_topic(&t.get_item(11)?)?,
            servo_core,
            servo_last: opt_i64(&t.get_item(13)?)?,
            servo_period: t.get_item(14)?.extract()?,
            others_next: t.get_item(15)?.extract()?,
            output_size: t.get_item(16)?.extract()?,
            chunk_bytes: t.get_item(17)?.extract()?,
            chunks: usize::try_from(chunks).ok(),
            writes_whole: t.get_item(19)?.is_truthy()?,
            max_pending: t.get_item(20)?.extract()?,
            chain: Chain::load(&t.get_item(21)?)?,
        })
    }
}

impl SpinalFast {
    pub(super) fn ensure_loaded(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.loaded {
            return Ok(());
        }
        let plan = read_plan(self.node.bind(py))?;
        self.load(plan)
    }

    /// The plan from `SpinalMirror.kernel_plan()`'s tuple (None: no plan).
    pub(super) fn load(&mut self, plan: Option<Bound<'_, PyTuple>>) -> PyResult<()> {
        self.plan = if let Some(t) = plan {
            let busy = t.get_item(3)?;
            Some(Plan {
                idle_lo: t.get_item(0)?.extract()?,
                idle_hi: t.get_item(1)?.extract()?,
                publish_live: t.get_item(2)?.is_truthy()?,
                busy: if busy.is_none() {
                    None
                } else {
                    Some(Busy::load(busy.cast::<PyTuple>()?)?)
                },
                boot_state: t.get_item(4)?.extract()?,
            })
        } else {
            None
        };
        self.loaded = true;
        Ok(())
    }
}
