//! The Spinal mirror's routine milliseconds (`SpinalMirror.tick` with no UART byte waiting,
//! inside the rosserial idle window, one steady CAN ms):
//!
//! * the idle ms: one Rust CAN master tick on the wire;
//! * the busy ms (docs/spinal.md): the battery sample, one control step
//!   (`SpinalStep.step` on the mirror's IMU sample, the duty list, the duty hand-over to the
//!   Rust master), the `imu` and `servo/states` publications (frames from the Rust builders,
//!   `ClientSession.send_frame`'s checks and counters), then the CAN ms; the frames go to a
//!   buffer written to the UART in one send at the next flush.
//!
//! Anything else (an event of the step, a frame the builders or the TX ring decline, a
//! non-finite battery sample, another publisher, a second control step) is decided before
//! any state changes (the Python tick runs) or, once the step ran, handed to the mirror's
//! `kernel_finish_*` continuation. The mirror's Python state is written back before Python
//! code runs.

use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyFloat, PyList, PyTuple};
use rdm_core::control::attitude::SpinalOutput;
use rdm_core::firmware::rosserial_frame::{client_stamp, imu_frame, ImuValues};
use rdm_core::N_ROTORS;

use super::attr::{read_plan, Name};
use crate::attitude::{PySpinalStep, SpinalStepOutput};
use crate::can_master::{CanMaster, CanWire};
use crate::spinal_mirror::{clamp_duty, exact_i64, float3, servo_states_frame_into, ServoFrame};

struct Names {
    now_ms: Name,
    now_s: Name,
    can_ms: Name,
    master: Name,
    tx_count: Name,
    pending_events: Name,
    next_control: Name,
    counters: Name,
    control_steps: Name,
    last_output: Name,
    duties: Name,
    duties_to_master: Name,
    last_pub: Name,
    next_pub_ms: Name,
    battery_due_ms: Name,
    battery_voltage: Name,
    battery_input: Name,
    adc_scale: Name,
    gyro: Name,
    acc: Name,
    mag: Name,
    imu: Name,
    servo_states: Name,
    battery_sample: Name,
    commit_tx: Name,
    session: Name,
    counts: Name,
    tx_frames: Name,
    published: Name,
    uart: Name,
    bytes_out: Name,
    dropped: Name,
    bytes_lost: Name,
    peer: Name,
    inbox: Name,
    extend: Name,
    tx_bytes: Name,
    tx_file: Name,
    write: Name,
    write_marked: Name,
}

/// Plan of `SpinalMirror.kernel_plan()`: the window in which a tick is only the CAN ms.
struct Plan {
    now_ms: i64,
    now_s: f64,
    idle_lo: i64,
    idle_hi: i64,
    battery_due_ms: i64,
    next_control: f64,
    can_ms: i64,
    next_pub_ms: i64,
    /// None: busy ms are the Python tick's.
    busy: Option<Busy>,
    /// Before the CAN master first runs: its phase index (booting, enumerating,
    /// configuring), which a CAN ms here must leave unchanged; None: the steady master.
    boot_state: Option<u8>,
}

/// The busy part of the plan (`SpinalMirror._kernel_busy_plan`), kept up to date here.
struct Busy {
    /// The `SpinalStep` when a control step can run here.
    core: Option<Py<PySpinalStep>>,
    period: f64,
    idle_duty: f64,
    battery_filter: f64,
    battery_period: i64,
    configured: bool,
    /// `last_output is not None`, and its values when it is a `SpinalStepOutput`.
    has_output: bool,
    output: Option<SpinalOutput>,
    imu_topic: Option<u16>,
    /// `ClientClock`'s sync state as `client_stamp` takes it (None: not synced); `sync_ok`
    /// false when the clock is no `ClientClock` or its values are not exact (then
    /// `spinal_imu_frame` declines): publications are then the Python tick's.
    sync: Option<(i64, i64)>,
    sync_ok: bool,
    imu_last: Option<i64>,
    imu_period: i64,
    servo_topic: Option<u16>,
    servo_core: Option<Py<CanMaster>>,
    servo_last: Option<i64>,
    servo_period: i64,
    /// First ms another publisher (battery status, motor pwms, torque states) is due.
    others_next: i64,
    output_size: usize,
    chunk_bytes: usize,
    /// Chunks of the TX ring (None: the ring is not empty).
    chunks: Option<usize>,
    writes_whole: bool,
    max_pending: usize,
    /// The UART chain `(droppable, tapped, end)` when the kernel writes the output itself
    /// (`SpinalMirror.kernel_tx_direct`); None: `kernel_commit_tx`.
    chain: Option<Chain>,
}

/// `UartPump._chain` (`inproc_chain`): the optional cuttable link and capture tap, the
/// in-process end.
struct Chain {
    droppable: Option<Py<PyAny>>,
    tapped: Option<Py<PyAny>>,
    end: Py<PyAny>,
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

/// What `ready` found the tick at `now` to be.
#[derive(Clone, Copy)]
enum Decision {
    Idle,
    Busy(BusyTick),
}

#[derive(Clone, Copy)]
struct BusyTick {
    /// The battery sample: the new filtered voltage.
    battery: Option<f64>,
    step: Option<StepInput>,
    /// None: `_publish` is a no-op (not configured, no output yet) or not due.
    publish: Option<Publish>,
}

/// A control step's input: the IMU sample, the voltage, and the motor number.
#[derive(Clone, Copy)]
struct StepInput {
    gyro: [f64; 3],
    acc: [f64; 3],
    mag: [f64; 3],
    voltage: f64,
    motors: usize,
    /// The duty list is the clamped controller output (`_duty_list`); false: `motors` idle
    /// duties (`_step_tail` before the CAN model is adopted: the master's motor number is
    /// not yet the controller's).
    from_output: bool,
}

/// The publications of a tick: which are due, the stamp, the `imu` sample's acc and mag.
#[derive(Clone, Copy)]
struct Publish {
    imu_due: bool,
    servo_due: bool,
    stamp: (u32, u32),
    acc: [f64; 3],
    mag: [f64; 3],
}

/// A duty list: values and length.
#[derive(Clone, Copy)]
struct Duties {
    values: [f64; N_ROTORS],
    n: usize,
}

impl Duties {
    fn list<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(py, self.values.iter().take(self.n).copied())
    }
}

/// What the busy ms changed since the last flush.
#[derive(Default)]
struct Deferred {
    steps: i64,
    next_control: bool,
    /// The output of the last control step here (its `SpinalStepOutput` is made at flush).
    output: Option<SpinalOutput>,
    /// The last duty list (`duties`), whether it is also the one handed over, and the last
    /// one handed over (`_duties_to_master`).
    duties: Option<Duties>,
    duties_handed: bool,
    handed: Option<Duties>,
    battery: Option<(i64, f64)>,
    imu_last: bool,
    servo_last: bool,
    next_pub: bool,
    frames: i64,
    imu_frames: i64,
    servo_frames: i64,
}

/// Busy-ms counts (the kernel's `stats()`).
#[derive(Clone, Copy, Default)]
pub(crate) struct BusyCounts {
    pub(crate) steps: u64,
    pub(crate) batteries: u64,
    pub(crate) imu_frames: u64,
    pub(crate) servo_frames: u64,
    pub(crate) finish_step: u64,
    pub(crate) finish_publish: u64,
    /// Ms with bytes to read: received in Python, the rest run here / in Python.
    pub(crate) receive_then_kernel: u64,
    pub(crate) receive_then_python: u64,
}

pub(crate) struct SpinalFast {
    node: Py<PyAny>,
    names: Names,
    master: Py<CanMaster>,
    wire: Py<CanWire>,
    drain_at: usize,
    plan: Option<Plan>,
    loaded: bool,
    tx_delta: i64,
    /// A steady CAN tick ran since the last flush (the master's pending events are 0).
    steady: bool,
    dirty: bool,
    decision: Decision,
    deferred: Deferred,
    /// Frames not yet written (`kernel_commit_tx`), and this tick's.
    tx: Vec<u8>,
    tick_tx: Vec<u8>,
    /// Per publishing tick in `tx`: (its time s, end of its bytes in `tx`), for the capture's
    /// time index (`TimedCaptureFile.write_marked`).
    tx_marks: Vec<(f64, usize)>,
    pub(crate) counts: BusyCounts,
}

/// What a tick did.
pub(crate) enum SpinalTick {
    /// The whole tick ran here.
    Done,
    /// The CAN tick left work for Python (`SpinalMirror.kernel_finish_wire_tick(now_ms)`).
    Finish(i64),
    /// The control step ran here, the rest is Python's
    /// (`SpinalMirror.kernel_finish_step(now_ms, tail)`).
    FinishStep(i64, bool),
    /// Everything up to the publications ran here, they are Python's
    /// (`SpinalMirror.kernel_finish_publish(now_ms)`).
    FinishPublish(i64),
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

/// An exact Python float's value.
fn exact_f64(v: &Bound<'_, PyAny>) -> Option<f64> {
    v.cast_exact::<PyFloat>().ok().map(|f| f.value())
}

impl Busy {
    fn load(t: &Bound<'_, PyTuple>) -> PyResult<Busy> {
        let core = t.get_item(0)?;
        let core = if core.is_none() {
            None
        } else {
            Some(core.cast_into::<PySpinalStep>()?.unbind())
        };
        let last_output = t.get_item(6)?;
        let output = last_output
            .cast_exact::<SpinalStepOutput>()
            .ok()
            .map(|o| o.get().inner);
        // spinal_imu_frame's argument checks: an exact bool, exact ints when synced.
        let synced = t.get_item(8)?;
        let (sync, sync_ok) = match synced.cast_exact::<PyBool>() {
            Ok(s) if s.is_true() => {
                match (exact_i64(&t.get_item(9)?), exact_i64(&t.get_item(10)?)) {
                    (Some(tick), Some(ns)) => (Some((tick, ns)), true),
                    _ => (None, false),
                }
            }
            Ok(_) => (None, true),
            Err(_) => (None, false),
        };
        let servo_core = t.get_item(14)?;
        let servo_core = if servo_core.is_none() {
            None
        } else {
            Some(servo_core.cast_into_exact::<CanMaster>()?.unbind())
        };
        let chunks: i64 = t.get_item(20)?.extract()?;
        Ok(Busy {
            core,
            period: t.get_item(1)?.extract()?,
            idle_duty: t.get_item(2)?.extract()?,
            battery_filter: t.get_item(3)?.extract()?,
            battery_period: t.get_item(4)?.extract()?,
            configured: t.get_item(5)?.is_truthy()?,
            has_output: !last_output.is_none(),
            output,
            imu_topic: opt_topic(&t.get_item(7)?)?,
            sync,
            sync_ok,
            imu_last: opt_i64(&t.get_item(11)?)?,
            imu_period: t.get_item(12)?.extract()?,
            servo_topic: opt_topic(&t.get_item(13)?)?,
            servo_core,
            servo_last: opt_i64(&t.get_item(15)?)?,
            servo_period: t.get_item(16)?.extract()?,
            others_next: t.get_item(17)?.extract()?,
            output_size: t.get_item(18)?.extract()?,
            chunk_bytes: t.get_item(19)?.extract()?,
            chunks: usize::try_from(chunks).ok(),
            writes_whole: t.get_item(21)?.is_truthy()?,
            max_pending: t.get_item(22)?.extract()?,
            chain: Chain::load(&t.get_item(23)?)?,
        })
    }
}

impl SpinalFast {
    pub(crate) fn new(
        node: &Bound<'_, PyAny>,
        master: Py<CanMaster>,
        wire: Py<CanWire>,
        drain_at: usize,
    ) -> Self {
        let py = node.py();
        SpinalFast {
            node: node.clone().unbind(),
            names: Names {
                now_ms: Name::new(py, "now_ms"),
                now_s: Name::new(py, "_now_s"),
                can_ms: Name::new(py, "_can_ms"),
                master: Name::new(py, "master"),
                tx_count: Name::new(py, "tx_count"),
                pending_events: Name::new(py, "_pending_events"),
                next_control: Name::new(py, "_next_control"),
                counters: Name::new(py, "counters"),
                control_steps: Name::new(py, "control_steps"),
                last_output: Name::new(py, "last_output"),
                duties: Name::new(py, "duties"),
                duties_to_master: Name::new(py, "_duties_to_master"),
                last_pub: Name::new(py, "_last_pub"),
                next_pub_ms: Name::new(py, "_next_pub_ms"),
                battery_due_ms: Name::new(py, "_battery_due_ms"),
                battery_voltage: Name::new(py, "battery_voltage"),
                battery_input: Name::new(py, "battery_input"),
                adc_scale: Name::new(py, "adc_scale"),
                gyro: Name::new(py, "gyro"),
                acc: Name::new(py, "acc"),
                mag: Name::new(py, "mag"),
                imu: Name::new(py, "imu"),
                servo_states: Name::new(py, "servo/states"),
                battery_sample: Name::new(py, "_battery_sample"),
                commit_tx: Name::new(py, "kernel_commit_tx"),
                session: Name::new(py, "session"),
                counts: Name::new(py, "counts"),
                tx_frames: Name::new(py, "tx_frames"),
                published: Name::new(py, "published"),
                uart: Name::new(py, "uart"),
                bytes_out: Name::new(py, "bytes_out"),
                dropped: Name::new(py, "dropped"),
                bytes_lost: Name::new(py, "bytes_lost"),
                peer: Name::new(py, "peer"),
                inbox: Name::new(py, "_inbox"),
                extend: Name::new(py, "extend"),
                tx_bytes: Name::new(py, "tx_bytes"),
                tx_file: Name::new(py, "_tx"),
                write: Name::new(py, "write"),
                write_marked: Name::new(py, "write_marked"),
            },
            master,
            wire,
            drain_at,
            plan: None,
            loaded: false,
            tx_delta: 0,
            steady: false,
            dirty: false,
            decision: Decision::Idle,
            deferred: Deferred::default(),
            tx: Vec::with_capacity(8192),
            tick_tx: Vec::with_capacity(1024),
            tx_marks: Vec::with_capacity(64),
            counts: BusyCounts::default(),
        }
    }

    pub(crate) fn invalidate(&mut self) {
        self.loaded = false;
    }

    fn ensure_loaded(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.loaded {
            return Ok(());
        }
        let plan = read_plan(self.node.bind(py))?;
        self.load(plan)
    }

    /// The plan from `SpinalMirror.kernel_plan()`'s tuple (None: no plan).
    fn load(&mut self, plan: Option<Bound<'_, PyTuple>>) -> PyResult<()> {
        self.plan = if let Some(t) = plan {
            let busy = t.get_item(8)?;
            Some(Plan {
                now_ms: t.get_item(0)?.extract()?,
                now_s: t.get_item(1)?.extract()?,
                idle_lo: t.get_item(2)?.extract()?,
                idle_hi: t.get_item(3)?.extract()?,
                battery_due_ms: t.get_item(4)?.extract()?,
                next_control: t.get_item(5)?.extract()?,
                can_ms: t.get_item(6)?.extract()?,
                next_pub_ms: t.get_item(7)?.extract()?,
                busy: if busy.is_none() {
                    None
                } else {
                    Some(Busy::load(busy.cast::<PyTuple>()?)?)
                },
                boot_state: t.get_item(9)?.extract()?,
            })
        } else {
            None
        };
        self.loaded = true;
        Ok(())
    }

    /// A ms this part cannot run from its plan (`ready` false), bytes to read or not:
    /// `SpinalMirror.kernel_receive_tick(now)` receives them in Python and runs the whole
    /// tick there (None), or hands back the plan for the rest of the ms (the caller loads it
    /// with `load_plan` once its `leave_python` is done; `ready` then judges the ms). The
    /// caller brackets the call as Python code (`enter_python` / `leave_python`).
    pub(crate) fn receive_tick<'py>(
        &mut self,
        py: Python<'py>,
        now: f64,
    ) -> PyResult<Option<Bound<'py, PyTuple>>> {
        let plan = self
            .node
            .bind(py)
            .call_method1(pyo3::intern!(py, "kernel_receive_tick"), (now,))?;
        if plan.is_none() {
            self.counts.receive_then_python += 1;
            return Ok(None);
        }
        Ok(Some(plan.cast_into::<PyTuple>()?))
    }

    /// The plan `receive_tick` handed back: read after the mirror's Python code ran, and
    /// nothing has run since.
    pub(crate) fn load_plan(&mut self, plan: Bound<'_, PyTuple>) -> PyResult<()> {
        self.load(Some(plan))
    }

    /// The rest of a `receive_tick` ms that `ready` declined (`kernel_receive_rest`).
    pub(crate) fn receive_rest(&mut self, py: Python<'_>, now: f64) -> PyResult<()> {
        self.counts.receive_then_python += 1;
        self.node
            .bind(py)
            .call_method1(pyo3::intern!(py, "kernel_receive_rest"), (now,))?;
        Ok(())
    }

    /// `to_ms(now)` as the mirror computes it.
    fn to_ms(now: f64) -> i64 {
        (now * 1000.0 + 1e-6).floor() as i64
    }

    /// Whether the tick at `now` runs here (then `tick` does it).
    pub(crate) fn ready(&mut self, py: Python<'_>, now: f64) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        let Some(p) = &self.plan else {
            return Ok(false);
        };
        let m = Self::to_ms(now);
        let now_s = if now > p.now_s { now } else { p.now_s };
        if !(m >= p.now_ms && p.idle_lo <= m && m < p.idle_hi && m == p.can_ms + 1) {
            return Ok(false);
        }
        let battery_due = m >= p.battery_due_ms;
        let control_due = now_s >= p.next_control - 1e-9;
        let publish_due = m >= p.next_pub_ms;
        if !battery_due && !control_due && !publish_due {
            self.decision = Decision::Idle;
            return Ok(true);
        }
        let Some(b) = &p.busy else {
            return Ok(false);
        };
        let node = self.node.bind(py);
        let n = &self.names;
        // _battery: the sample (a finite one; else the Python tick counts the rejection).
        let battery = if battery_due {
            let input = exact_f64(&n.battery_input.get(node)?);
            let scale = exact_f64(&n.adc_scale.get(node)?);
            let (Some(input), Some(scale)) = (input, scale) else {
                return Ok(false);
            };
            let sample = input * scale;
            if !sample.is_finite() {
                return Ok(false);
            }
            // The low-passed voltage: the one a busy ms here left (not yet written back),
            // else the mirror's.
            let v = match self.deferred.battery {
                Some((_, v)) => Some(v),
                None => {
                    let v = n.battery_voltage.get(node)?;
                    if v.is_none() {
                        None
                    } else {
                        let Some(v) = exact_f64(&v) else {
                            return Ok(false);
                        };
                        Some(v)
                    }
                }
            };
            Some(match v {
                None => sample,
                Some(v) => b.battery_filter * v + (1.0 - b.battery_filter) * sample,
            })
        } else {
            None
        };
        // _control: exactly one step, on _step's fast path.
        let step = if control_due {
            let Some(core) = &b.core else {
                return Ok(false);
            };
            if now_s >= (p.next_control + b.period) - 1e-9 {
                return Ok(false); // a catch-up step follows: the Python tick
            }
            let motors = self.master.bind(py).try_borrow()?.core_ref().motor_number;
            let from_output = motors != 0 && motors == core.bind(py).try_borrow()?.motor_count();
            // The steady master: the controller's own duties only. During the boot
            // `_step_tail` gives `motors` idle duties when the numbers differ (no hand-over).
            if motors > N_ROTORS || (p.boot_state.is_none() && !from_output) {
                return Ok(false);
            }
            let three = |name: &Name| -> PyResult<Option<[f64; 3]>> {
                Ok(name.get(node)?.extract::<[f64; 3]>().ok())
            };
            let (Some(gyro), Some(acc), Some(mag)) =
                (three(&n.gyro)?, three(&n.acc)?, three(&n.mag)?)
            else {
                return Ok(false);
            };
            let voltage = match battery.or(self.deferred.battery.map(|(_, v)| v)) {
                Some(v) => v,
                None => {
                    let v = n.battery_voltage.get(node)?;
                    let v = if v.is_none() {
                        n.battery_input.get(node)?
                    } else {
                        v
                    };
                    match v.extract::<f64>() {
                        Ok(v) => v,
                        Err(_) => return Ok(false),
                    }
                }
            };
            Some(StepInput {
                gyro,
                acc,
                mag,
                voltage,
                motors,
                from_output,
            })
        } else {
            None
        };
        // _publish: imu and servo/states as their frame paths, nothing else due.
        let publish = if publish_due && b.configured && (control_due || b.has_output) {
            let imu_due = b.imu_last.is_none_or(|t| m - t >= b.imu_period);
            let servo_due = b.servo_last.is_none_or(|t| m - t >= b.servo_period);
            let imu_ok = b.imu_last.is_some() && b.imu_topic.is_some();
            let servo_ok = b.servo_last.is_some() && b.servo_topic.is_some();
            if m >= b.others_next
                || !b.sync_ok
                || (imu_due && !imu_ok)
                || (servo_due && !servo_ok)
                || (!control_due && b.output.is_none())
                || b.chunks.is_none()
                || !b.writes_whole
            {
                return Ok(false);
            }
            let Some(stamp) = client_stamp(m, b.sync) else {
                return Ok(false);
            };
            let (acc, mag) = if imu_due {
                match (float3(&n.acc.get(node)?), float3(&n.mag.get(node)?)) {
                    (Some(a), Some(g)) => (a, g),
                    _ => return Ok(false),
                }
            } else {
                ([0.0; 3], [0.0; 3])
            };
            Some(Publish {
                imu_due,
                servo_due,
                stamp,
                acc,
                mag,
            })
        } else {
            None
        };
        self.decision = Decision::Busy(BusyTick {
            battery,
            step,
            publish,
        });
        Ok(true)
    }

    /// The tick at `now` (requires `ready`).
    pub(crate) fn tick(&mut self, py: Python<'_>, now: f64) -> PyResult<SpinalTick> {
        let m = Self::to_ms(now);
        let Some(p) = &mut self.plan else {
            return Err(pyo3::exceptions::PyRuntimeError::new_err(
                "kernel: Spinal tick without a plan",
            ));
        };
        if now > p.now_s {
            p.now_s = now;
        }
        p.now_ms = m;
        self.dirty = true;
        let decision = std::mem::replace(&mut self.decision, Decision::Idle);
        let boot = p.boot_state.is_some();
        let busy = match decision {
            Decision::Busy(busy) => Some(busy),
            Decision::Idle => None,
        };
        let no_plan =
            || pyo3::exceptions::PyRuntimeError::new_err("kernel: Spinal busy tick without plan");
        // In `tick`'s order: battery and control step, the CAN ms, the publications.
        if let Some(busy) = busy {
            let b = p.busy.as_mut().ok_or_else(no_plan)?;
            let d = &mut self.deferred;
            if let Some(v) = busy.battery {
                p.battery_due_ms = m + b.battery_period;
                d.battery = Some((m, v));
                self.counts.batteries += 1;
            }
            if let Some(StepInput {
                gyro,
                acc,
                mag,
                voltage,
                motors,
                from_output,
            }) = busy.step
            {
                let core = b.core.as_ref().ok_or_else(|| {
                    pyo3::exceptions::PyRuntimeError::new_err("kernel: Spinal step without core")
                })?;
                let out = core
                    .bind(py)
                    .try_borrow_mut()?
                    .step_raw(p.now_s, gyro, acc, mag, voltage);
                p.next_control += b.period;
                d.next_control = true;
                d.steps += 1;
                d.output = Some(out);
                b.output = Some(out);
                b.has_output = true;
                self.counts.steps += 1;
                let events = &out.control.events;
                if !events.is_empty() || events.dropped() > 0 {
                    self.counts.finish_step += 1;
                    return Ok(SpinalTick::FinishStep(m, true));
                }
                let mut duties = Duties {
                    values: [0.0; N_ROTORS],
                    n: motors,
                };
                for (v, &x) in duties.values.iter_mut().zip(out.control.duty.iter()) {
                    *v = if from_output {
                        clamp_duty(x, b.idle_duty)
                    } else {
                        b.idle_duty
                    };
                }
                d.duties = Some(duties);
                if boot {
                    // `_can` before the master runs hands no duties over.
                    d.duties_handed = false;
                } else {
                    let handed = self
                        .master
                        .bind(py)
                        .try_borrow_mut()?
                        .try_set_duty_slice(&duties.values[..motors]);
                    d.duties_handed = handed;
                    if !handed {
                        self.counts.finish_step += 1;
                        return Ok(SpinalTick::FinishStep(m, false));
                    }
                    d.handed = Some(duties);
                }
            }
        }
        p.can_ms = m;
        if !Self::can_tick(
            &self.master,
            &self.wire,
            self.drain_at,
            p.boot_state,
            py,
            m,
            now,
            &mut self.tx_delta,
            &mut self.steady,
        ) {
            return Ok(SpinalTick::Finish(m));
        }
        if let Some(Publish {
            imu_due,
            servo_due,
            stamp,
            acc,
            mag,
        }) = busy.and_then(|busy| busy.publish)
        {
            let b = p.busy.as_mut().ok_or_else(no_plan)?;
            let d = &mut self.deferred;
            self.tick_tx.clear();
            let mut used = 0usize;
            let cap = b.chunks.unwrap_or(0);
            let mut fits = |len: usize| -> bool {
                if len > b.output_size || b.chunk_bytes == 0 {
                    return false;
                }
                used += len.div_ceil(b.chunk_bytes);
                used <= cap
            };
            let mut imu_sent = false;
            if imu_due {
                let (Some(out), Some(topic)) = (b.output.as_ref(), b.imu_topic) else {
                    self.counts.finish_publish += 1;
                    return Ok(SpinalTick::FinishPublish(m));
                };
                let estimate = &out.estimate;
                let values = ImuValues {
                    acc,
                    gyro: estimate.angular_velocity.into(),
                    mag,
                    quaternion: estimate.quaternion,
                };
                match imu_frame(topic, stamp, &values) {
                    Some(f) if fits(f.len()) => {
                        self.tick_tx.extend_from_slice(&f);
                        imu_sent = true;
                    }
                    _ => {
                        self.counts.finish_publish += 1;
                        return Ok(SpinalTick::FinishPublish(m));
                    }
                }
            }
            let mut servo_sent = false;
            // Before the master runs no servo has reported: `states_frame` gives no
            // message (the publication's time is still taken).
            if servo_due && !boot {
                let (Some(core), Some(topic)) = (b.servo_core.as_ref(), b.servo_topic) else {
                    self.counts.finish_publish += 1;
                    return Ok(SpinalTick::FinishPublish(m));
                };
                let core = core.bind(py).try_borrow()?;
                match servo_states_frame_into(core.core_ref(), topic, stamp, &mut self.tick_tx) {
                    ServoFrame::Empty => {}
                    ServoFrame::Written(len) if fits(len) => servo_sent = true,
                    _ => {
                        self.counts.finish_publish += 1;
                        return Ok(SpinalTick::FinishPublish(m));
                    }
                }
            }
            if self.tx.len() + self.tick_tx.len() > b.max_pending {
                self.counts.finish_publish += 1;
                return Ok(SpinalTick::FinishPublish(m));
            }
            // Committed: _last_pub, _next_pub_ms, the TX counters, the bytes.
            if imu_due {
                b.imu_last = Some(m);
                d.imu_last = true;
            }
            if servo_due {
                b.servo_last = Some(m);
                d.servo_last = true;
            }
            let imu_next = b.imu_last.map_or(i64::MIN, |t| t + b.imu_period);
            let servo_next = b.servo_last.map_or(i64::MIN, |t| t + b.servo_period);
            p.next_pub_ms = imu_next.min(servo_next).min(b.others_next);
            d.next_pub = true;
            let sent = i64::from(imu_sent) + i64::from(servo_sent);
            d.frames += sent;
            d.imu_frames += i64::from(imu_sent);
            d.servo_frames += i64::from(servo_sent);
            self.counts.imu_frames += u64::from(imu_sent);
            self.counts.servo_frames += u64::from(servo_sent);
            self.tx.extend_from_slice(&self.tick_tx);
            if !self.tick_tx.is_empty() {
                // m is whole ms: m / 1000 rounds back to them in the index
                self.tx_marks.push((m as f64 / 1000.0, self.tx.len()));
            }
        }
        Ok(SpinalTick::Done)
    }

    /// The CAN ms (`tick_wire_steady`): the steady master's, or, before it first runs
    /// (`boot_state`), one that stays in that phase with no event and a short log (what
    /// `RustCanMaster.tick_ms` + `apply_wire_tick` then do: count the frames, pending
    /// events 0); false: the tick's result is for Python (`Finish`).
    #[allow(clippy::too_many_arguments)]
    fn can_tick(
        master: &Py<CanMaster>,
        wire: &Py<CanWire>,
        drain_at: usize,
        boot_state: Option<u8>,
        py: Python<'_>,
        m: i64,
        now: f64,
        tx_delta: &mut i64,
        steady: &mut bool,
    ) -> bool {
        let mut master = master.bind(py).borrow_mut();
        let sent = master.tick_wire_steady(m, now, wire.bind(py), drain_at);
        let sent = match boot_state {
            None => sent,
            Some(phase) => {
                let (state, events, sent, logged) = master.last_wire_tick();
                if state == phase && events == 0 && logged < drain_at {
                    i64::try_from(sent).unwrap_or(i64::MAX)
                } else {
                    -1
                }
            }
        };
        if sent >= 0 {
            *tx_delta += sent;
            *steady = true;
            true
        } else {
            false
        }
    }

    /// Write the mirror's state back: clock and CAN ms (`now_ms`, `_now_s`, `_can_ms`), the
    /// master's counters of the steady CAN ms (`tx_count`, `_pending_events` = 0) and what
    /// the busy ms changed (battery, control step, duties, publications, the UART bytes).
    pub(crate) fn flush(&mut self, py: Python<'_>) -> PyResult<()> {
        if !self.dirty {
            return Ok(());
        }
        if let Some(p) = &self.plan {
            let node = self.node.bind(py);
            let n = &self.names;
            n.now_ms.set(node, p.now_ms)?;
            n.now_s.set(node, p.now_s)?;
            n.can_ms.set(node, p.can_ms)?;
            if self.steady {
                let master = n.master.get(node)?;
                let tx = n.tx_count.i64(&master)?;
                n.tx_count.set(&master, tx + self.tx_delta)?;
                n.pending_events.set(&master, 0)?;
            }
            let d = std::mem::take(&mut self.deferred);
            let last_pub = if d.battery.is_some() || d.imu_last || d.servo_last {
                Some(n.last_pub.get(node)?.cast_into::<PyDict>()?)
            } else {
                None
            };
            if let (Some((ms, v)), Some(last)) = (d.battery, &last_pub) {
                last.set_item(n.battery_sample.key(py), ms)?;
                n.battery_due_ms.set(node, p.battery_due_ms)?;
                n.battery_voltage.set(node, v)?;
            }
            if d.steps > 0 {
                let counters = n.counters.get(node)?;
                let steps = n.control_steps.i64(&counters)?;
                n.control_steps.set(&counters, steps + d.steps)?;
            }
            if d.next_control {
                n.next_control.set(node, p.next_control)?;
            }
            if let Some(out) = d.output {
                n.last_output
                    .set(node, Py::new(py, SpinalStepOutput { inner: out })?)?;
            }
            if let Some(duties) = &d.duties {
                let list = duties.list(py)?;
                n.duties.set(node, &list)?;
                if d.duties_handed {
                    n.duties_to_master.set(node, &list)?;
                } else if let Some(handed) = &d.handed {
                    n.duties_to_master.set(node, handed.list(py)?)?;
                }
            }
            if let (Some(b), Some(last)) = (&p.busy, &last_pub) {
                if d.imu_last {
                    last.set_item(n.imu.key(py), b.imu_last)?;
                }
                if d.servo_last {
                    last.set_item(n.servo_states.key(py), b.servo_last)?;
                }
            }
            if d.next_pub {
                n.next_pub_ms.set(node, p.next_pub_ms)?;
            }
            if d.frames > 0 {
                let data = PyBytes::new(py, &self.tx);
                self.tx.clear();
                match p.busy.as_ref().and_then(|b| b.chain.as_ref()) {
                    Some(chain) => Self::commit_tx(n, node, chain, &data, &d, &self.tx_marks)?,
                    None => {
                        node.call_method1(
                            n.commit_tx.key(py),
                            (
                                data,
                                d.frames,
                                d.imu_frames,
                                d.servo_frames,
                                PyList::new(py, &self.tx_marks)?,
                            ),
                        )?;
                    }
                }
            }
        }
        self.tx.clear();
        self.tx_marks.clear();
        self.deferred = Deferred::default();
        self.tx_delta = 0;
        self.steady = false;
        self.dirty = false;
        Ok(())
    }

    /// `SpinalMirror.kernel_commit_tx(data, ...)` without the call: the session's and the
    /// mirror's counters, then `UartPump.send(data)` of a whole write through the chain
    /// (`_write_chain`: the cut line counts the bytes lost; else the peer's inbox and the
    /// capture tap take them) and `bytes_out` (the plan's `writes_whole` held since).
    fn commit_tx(
        n: &Names,
        node: &Bound<'_, PyAny>,
        chain: &Chain,
        data: &Bound<'_, PyBytes>,
        d: &Deferred,
        marks: &[(f64, usize)],
    ) -> PyResult<()> {
        let py = node.py();
        let add = |obj: &Bound<'_, PyAny>, key: &Name, k: i64| -> PyResult<()> {
            let key = key.key(py);
            let v: i64 = obj.get_item(key)?.extract()?;
            obj.set_item(key, v + k)
        };
        add(
            &n.counts.get(&n.session.get(node)?)?,
            &n.tx_frames,
            d.frames,
        )?;
        let published = n.published.get(&n.counters.get(node)?)?;
        if d.imu_frames > 0 {
            add(&published, &n.imu, d.imu_frames)?;
        }
        if d.servo_frames > 0 {
            add(&published, &n.servo_states, d.servo_frames)?;
        }
        let len = i64::try_from(data.as_bytes().len()).unwrap_or(i64::MAX);
        let cut = match &chain.droppable {
            Some(link) => n.dropped.truthy(link.bind(py))?,
            None => false,
        };
        if let (true, Some(link)) = (cut, &chain.droppable) {
            let link = link.bind(py);
            n.bytes_lost.set(link, n.bytes_lost.i64(link)? + len)?;
        } else {
            let peer = n.peer.get(chain.end.bind(py))?;
            n.inbox
                .get(&peer)?
                .call_method1(n.extend.key(py), (data,))?;
            if let Some(tap) = &chain.tapped {
                let tap = tap.bind(py);
                n.tx_bytes.set(tap, n.tx_bytes.i64(tap)? + len)?;
                let file = n.tx_file.get(tap)?;
                if !file.is_none() {
                    // A time-indexed capture takes each tick's bytes at that tick's time.
                    match file.getattr(n.write_marked.key(py)) {
                        Ok(write_marked) => {
                            write_marked.call1((data, PyList::new(py, marks)?))?;
                        }
                        Err(_) => {
                            file.call_method1(n.write.key(py), (data,))?;
                        }
                    }
                }
            }
        }
        let uart = n.uart.get(node)?;
        n.bytes_out.set(&uart, n.bytes_out.i64(&uart)? + len)
    }

    /// `SpinalMirror.kernel_finish_wire_tick(now_ms)` (after a flush of every part).
    pub(crate) fn finish(&self, py: Python<'_>, now_ms: i64) -> PyResult<()> {
        self.node
            .bind(py)
            .call_method1("kernel_finish_wire_tick", (now_ms,))?;
        Ok(())
    }

    /// `SpinalMirror.kernel_finish_step(now_ms, tail)` (after a flush of every part).
    pub(crate) fn finish_step(&self, py: Python<'_>, now_ms: i64, tail: bool) -> PyResult<()> {
        self.node
            .bind(py)
            .call_method1("kernel_finish_step", (now_ms, tail))?;
        Ok(())
    }

    /// `SpinalMirror.kernel_finish_publish(now_ms)` (after a flush of every part).
    pub(crate) fn finish_publish(&self, py: Python<'_>, now_ms: i64) -> PyResult<()> {
        self.node
            .bind(py)
            .call_method1("kernel_finish_publish", (now_ms,))?;
        Ok(())
    }
}
