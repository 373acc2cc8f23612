//! Bindings of `rdm_core::firmware::can_master`: Spinal's CAN master (python-can messages in,
//! `(can_id, payload)` frames out). The Python node `rdm.nodes.can_master` wraps it.

use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyFloat, PyList, PyTuple};
use rdm_core::firmware::can_master::{
    CanMaster as CoreMaster, EventKind, MasterError, MasterState, ServoEntry, RX_ERROR_NAMES,
};
use rdm_core::firmware::can_wire::{
    CanWire as CoreWire, Sender, DEFAULT_LOG_CAPACITY, DEFAULT_QUEUE_CAPACITY,
};
use rdm_core::firmware::neuron_tx::RxFrame;
use rdm_core::firmware::spinal_frame::REPLY_KINDS;

use crate::can_frame::rx_frame_of;
use crate::errors::RdmError;

create_exception!(
    _rdm,
    CanMasterError,
    RdmError,
    "Bad argument of the CAN master (the message names it)."
);

fn master_err(e: MasterError) -> PyErr {
    CanMasterError::new_err(match e {
        MasterError::DutyCount(n) => format!("duties: {n} values for the motor count"),
        MasterError::Duty(k) => format!("duties[{k}] not a finite value in 0.5..1.0"),
        MasterError::NoServo(s, i) => format!("no servo {i} on Neuron {s}"),
        MasterError::WordValue => "value not a 15-bit signed int".into(),
        MasterError::BoardQueueFull => "configure_board: queue full (64 requests)".into(),
        MasterError::BadFrame => "configure_board: id > 0x7FF or payload > 8 bytes".into(),
    })
}

fn state_index(s: MasterState) -> u8 {
    match s {
        MasterState::Booting => 0,
        MasterState::Enumerating => 1,
        MasterState::Configuring => 2,
        MasterState::Running => 3,
        MasterState::Disabled => 4,
    }
}

/// Spinal's side of the Neuron bus (see `rdm_core::firmware::can_master`).
#[pyclass(module = "rdm._rdm")]
pub struct CanMaster {
    core: CoreMaster,
    rx: Vec<RxFrame>,
    /// Scratch of `try_set_motor_duties` (reused, no allocation per call).
    duties: Vec<f64>,
    /// `tick_wire`'s tuple of the last `tick_wire_steady` call.
    last_wire: (u8, usize, usize, usize),
    /// Frames sent: counted by `tick_wire`, and by `count_sent` for the python-can path.
    tx_count: u64,
}

fn servo_tuple<'py>(py: Python<'py>, slave: u8, s: &ServoEntry) -> PyResult<Bound<'py, PyTuple>> {
    let items: Vec<Bound<'py, PyAny>> = vec![
        slave.into_pyobject(py)?.into_any(),
        s.index.into_pyobject(py)?.into_any(),
        s.dynamixel_id.into_pyobject(py)?.into_any(),
        s.gains[0].into_pyobject(py)?.into_any(),
        s.gains[1].into_pyobject(py)?.into_any(),
        s.gains[2].into_pyobject(py)?.into_any(),
        s.profile_velocity.into_pyobject(py)?.into_any(),
        s.current_limit.into_pyobject(py)?.into_any(),
        pyo3::types::PyBool::new(py, s.send_data_flag)
            .to_owned()
            .into_any(),
        pyo3::types::PyBool::new(py, s.external_encoder_flag)
            .to_owned()
            .into_any(),
        s.hardware_error_status.into_pyobject(py)?.into_any(),
        s.joint_resolution.into_pyobject(py)?.into_any(),
        s.servo_resolution.into_pyobject(py)?.into_any(),
        s.goal_position.into_pyobject(py)?.into_any(),
        pyo3::types::PyBool::new(py, s.goal_valid)
            .to_owned()
            .into_any(),
        pyo3::types::PyBool::new(py, s.torque_enable)
            .to_owned()
            .into_any(),
        s.goal_current.into_pyobject(py)?.into_any(),
        s.angle.into_pyobject(py)?.into_any(),
        s.temperature.into_pyobject(py)?.into_any(),
        pyo3::types::PyBool::new(py, s.moving).to_owned().into_any(),
        pyo3::types::PyBool::new(py, s.force_servo_off)
            .to_owned()
            .into_any(),
        s.current.into_pyobject(py)?.into_any(),
        s.error.into_pyobject(py)?.into_any(),
        s.stamp_ms.into_pyobject(py)?.into_any(),
    ];
    PyTuple::new(py, items)
}

impl CanMaster {
    /// The core master (read by the Spinal mirror's busy-ms helpers, `crate::spinal_mirror`).
    pub(crate) fn core_ref(&self) -> &CoreMaster {
        &self.core
    }

    /// `(slave, position)` of every servo in `servo_table` order (`servo_keys`), without a
    /// list (`crate::spinal_commands` looks one up per goal).
    pub(crate) fn servo_key_iter(&self) -> impl Iterator<Item = (u8, usize)> + '_ {
        self.core
            .neurons()
            .iter()
            .flat_map(|n| (0..n.servos().len()).map(move |i| (n.slave, i)))
    }

    /// `set_servo_target_list` without the Python list (`crate::spinal_commands`): the goals
    /// in order, stopping at the first the core refuses (as that method does).
    pub(crate) fn set_targets(&mut self, targets: &[(u8, u8, i32)]) -> PyResult<()> {
        for &(slave, index, value) in targets {
            self.core
                .set_servo_target(slave, index, value)
                .map_err(master_err)?;
        }
        Ok(())
    }

    /// `try_set_motor_duties` of a list of these floats (the lockstep kernel's duty
    /// hand-over, `crate::kernel::spinal`): applies them and returns true when there are
    /// exactly `motor_number` of them and the core takes them; else applies nothing.
    pub(crate) fn try_set_duty_slice(&mut self, duties: &[f64]) -> bool {
        duties.len() == self.core.motor_number && self.core.set_motor_duties(duties).is_ok()
    }
}

#[pymethods]
impl CanMaster {
    #[new]
    #[pyo3(signature = (boot_delay_ms=5000, start_ms=0))]
    fn new(boot_delay_ms: i64, start_ms: i64) -> Self {
        CanMaster {
            core: CoreMaster::new(boot_delay_ms, start_ms),
            rx: Vec::with_capacity(256),
            duties: Vec::with_capacity(16),
            last_wire: (0, 0, 0, 0),
            tx_count: 0,
        }
    }

    /// Receive the python-can `messages` (bus order), run the schedule at `now_ms`; returns
    /// `(state_index, pending_events, [(can_id, payload), ...] to send)`.
    fn tick_ms<'py>(
        &mut self,
        py: Python<'py>,
        now_ms: i64,
        messages: &Bound<'py, PyList>,
    ) -> PyResult<(u8, usize, Bound<'py, PyList>)> {
        self.rx.clear();
        for m in messages.iter() {
            self.rx.push(rx_frame_of(py, &m)?);
        }
        let out = self.core.tick_ms(now_ms, &self.rx);
        let list = PyList::empty(py);
        for e in out {
            list.append((e.frame.id, PyBytes::new(py, e.frame.payload())))?;
        }
        let events = self.core.events().count();
        Ok((state_index(self.core.state), events, list))
    }

    /// [`tick_ms`] on a [`CanWire`]: receive what the Neurons sent, send on the wire stamped
    /// `stamp` (the channel clock); returns `(state_index, pending_events, frames_sent,
    /// log_len)`.
    fn tick_wire(
        &mut self,
        now_ms: i64,
        stamp: f64,
        wire: &Bound<'_, CanWire>,
    ) -> (u8, usize, usize, usize) {
        let mut w = wire.borrow_mut();
        w.core.take_for_master(&mut self.rx);
        let out = self.core.tick_ms(now_ms, &self.rx);
        for e in out {
            w.core.send(Sender::Master, stamp, e.frame);
        }
        let sent = out.len();
        self.tx_count = self.tx_count.saturating_add(sent as u64);
        let events = self.core.events().count();
        (state_index(self.core.state), events, sent, w.core.log_len())
    }

    /// Frames sent: every frame of `tick_wire` plus those `count_sent` added (the python-can
    /// path's accepted sends).
    #[getter]
    fn tx_count(&self) -> u64 {
        self.tx_count
    }

    /// Add `n` frames the python-can path sent (`tick_ms`'s frames the bus accepted).
    fn count_sent(&mut self, n: u64) {
        self.tx_count = self.tx_count.saturating_add(n);
    }

    /// Log events not yet taken by `pop_events`.
    #[getter]
    fn pending_events(&self) -> usize {
        self.core.events().count()
    }

    /// [`tick_wire`] for the steady state, with one int back instead of a tuple: the frames
    /// sent when the master is (still) running, has no pending event and its wire log holds
    /// fewer than `drain_at` frames; otherwise -1, and [`last_wire_tick`] holds `tick_wire`'s
    /// tuple of this tick. Exactly `tick_wire`'s effect on the master and the wire.
    pub(crate) fn tick_wire_steady(
        &mut self,
        now_ms: i64,
        stamp: f64,
        wire: &Bound<'_, CanWire>,
        drain_at: usize,
    ) -> i64 {
        let result = self.tick_wire(now_ms, stamp, wire);
        self.last_wire = result;
        let (state, events, sent, logged) = result;
        if state == state_index(MasterState::Running) && events == 0 && logged < drain_at {
            i64::try_from(sent).unwrap_or(i64::MAX)
        } else {
            -1
        }
    }

    /// `tick_wire`'s `(state_index, pending_events, frames_sent, log_len)` of the last
    /// [`tick_wire_steady`] call (zeros before the first).
    #[getter]
    pub(crate) fn last_wire_tick(&self) -> (u8, usize, usize, usize) {
        self.last_wire
    }

    /// Phase index: 0 booting, 1 enumerating, 2 configuring, 3 running, 4 disabled.
    #[getter]
    fn state_index(&self) -> u8 {
        state_index(self.core.state)
    }

    #[getter]
    fn motor_number(&self) -> usize {
        self.core.motor_number
    }

    #[getter]
    fn uav_model(&self) -> Option<u8> {
        self.core.uav_model
    }

    #[getter]
    fn rx_count(&self) -> u64 {
        self.core.rx_count
    }

    #[getter]
    fn connected(&self) -> bool {
        self.core.connected()
    }

    #[getter]
    fn events_dropped(&self) -> u64 {
        self.core.events_dropped
    }

    /// Servo goal reports after the goal-sync handshake with torque on (a Neuron reset).
    #[getter]
    fn goal_resyncs(&self) -> u64 {
        self.core.goal_resyncs
    }

    /// `[(reason, count), ...]` in first-counted order.
    fn rx_errors(&self) -> Vec<(&'static str, u64)> {
        self.core
            .rx_errors
            .iter()
            .map(|(k, c)| (RX_ERROR_NAMES.get(k).copied().unwrap_or("?"), c))
            .collect()
    }

    /// `[(kind, count), ...]` in first-counted order.
    fn rx_kinds(&self) -> Vec<(&'static str, u64)> {
        self.core
            .rx_kinds
            .iter()
            .map(|(k, c)| (REPLY_KINDS.get(k).copied().unwrap_or("?"), c))
            .collect()
    }

    fn set_motor_duties(&mut self, duties: Vec<f64>) -> PyResult<()> {
        self.core.set_motor_duties(&duties).map_err(master_err)
    }

    /// The duty hand-over without a Python-side check: applies `duties` and returns True when
    /// it is a list of exactly `motor_number` Python floats (not subclasses), each finite in
    /// 0.5..1.0; otherwise applies nothing and returns False (the caller then runs its own
    /// checks, which name the fault).
    fn try_set_motor_duties(&mut self, duties: &Bound<'_, PyList>) -> bool {
        if duties.len() != self.core.motor_number {
            return false;
        }
        self.duties.clear();
        for item in duties.iter() {
            match item.cast_exact::<PyFloat>() {
                Ok(f) => self.duties.push(f.value()),
                Err(_) => return false,
            }
        }
        self.core.set_motor_duties(&self.duties).is_ok()
    }

    fn set_servo_target(&mut self, slave: u8, index: u8, value: i32) -> PyResult<()> {
        self.core
            .set_servo_target(slave, index, value)
            .map_err(master_err)
    }

    /// `set_servo_target` for each `(slave, index, value)` in order (one call for a whole
    /// `servo/target_states`); stops at the first error, which it raises.
    fn set_servo_target_list(&mut self, targets: Vec<(u8, u8, i32)>) -> PyResult<()> {
        self.set_targets(&targets)
    }

    fn set_servo_torque(&mut self, slave: u8, index: u8, enable: bool) -> PyResult<()> {
        self.core
            .set_servo_torque(slave, index, enable)
            .map_err(master_err)
    }

    fn set_servo_current(&mut self, slave: u8, index: u8, value: i32) -> PyResult<()> {
        self.core
            .set_servo_current(slave, index, value)
            .map_err(master_err)
    }

    #[pyo3(signature = (can_id, payload, reboot_slave=None))]
    fn configure_board(
        &mut self,
        can_id: u32,
        payload: Vec<u8>,
        reboot_slave: Option<u8>,
    ) -> PyResult<()> {
        self.core
            .configure_board(can_id, &payload, reboot_slave)
            .map_err(master_err)
    }

    /// Neurons: `[(slave, servo_num, imu_send_flag, ttl_rs485_mixed, pulley_skip_thresh,
    /// configured, servo_count), ...]` in slave-id order.
    fn neurons(&self) -> Vec<(u8, u8, bool, bool, u16, bool, usize)> {
        self.core
            .neurons()
            .iter()
            .map(|n| {
                (
                    n.slave,
                    n.servo_num,
                    n.imu_send_flag,
                    n.ttl_rs485_mixed,
                    n.pulley_skip_thresh,
                    n.configured,
                    n.servo_count,
                )
            })
            .collect()
    }

    /// Servo `i` of Neuron position `k`: `(slave, index, dynamixel_id, p, i, d,
    /// profile_velocity, current_limit, send_data_flag, external_encoder_flag,
    /// hardware_error_status, joint_resolution, servo_resolution, goal_position, goal_valid,
    /// torque_enable, goal_current, angle, temperature, moving, force_servo_off, current,
    /// error, stamp_ms)`.
    fn servo<'py>(&self, py: Python<'py>, k: usize, i: usize) -> PyResult<Bound<'py, PyTuple>> {
        let n =
            self.core.neurons().get(k).ok_or_else(|| {
                CanMasterError::new_err(format!("neuron position {k} out of range"))
            })?;
        let s = n.servos().get(i).ok_or_else(|| {
            CanMasterError::new_err(format!("servo {i} of neuron {k} out of range"))
        })?;
        servo_tuple(py, n.slave, s)
    }

    /// The servo report fields of every servo, in `servo_table` order: `[(send_data_flag,
    /// angle, temperature, current, error, torque_enable), ...]` (what `servo/states` and
    /// `servo/torque_states` carry; one call instead of a 24-field tuple per servo).
    fn servo_reports(&self) -> Vec<(bool, i16, u8, i16, u8, bool)> {
        let mut out = Vec::with_capacity(32);
        for n in self.core.neurons() {
            for s in n.servos() {
                out.push((
                    s.send_data_flag,
                    s.angle,
                    s.temperature,
                    s.current,
                    s.error,
                    s.torque_enable,
                ));
            }
        }
        out
    }

    /// `(slave, position)` of every servo in `servo_table` order (the keys of
    /// `RustCanMaster.servo_states`).
    fn servo_keys(&self) -> Vec<(u8, usize)> {
        self.servo_key_iter().collect()
    }

    /// IMU: `[(slave, [gyro, acc, mag] each (x, y, z) raw or None, stamp_ms), ...]` in order
    /// of each slave's first sample.
    #[allow(clippy::type_complexity)]
    fn imu(&self) -> Vec<(u8, [Option<[i16; 3]>; 3], i64)> {
        let mut order = [0u8; 16];
        let n = self.core.imu_slaves(&mut order);
        order
            .iter()
            .take(n)
            .filter_map(|&s| {
                self.core.imu(s).map(|slot| {
                    let mut out = [None; 3];
                    for (o, (raw, have)) in out.iter_mut().zip(slot.raw.iter().zip(slot.have)) {
                        if have {
                            *o = Some(*raw);
                        }
                    }
                    (s, out, slot.stamp_ms)
                })
            })
            .collect()
    }

    /// Take the pending events: `[(stamp_ms, code, arg), ...]`; codes: "disabled",
    /// "not_configured" (arg slave), "gimbal_mismatch" (arg gimbal count), "running",
    /// "disconnected".
    fn pop_events(&mut self) -> Vec<(i64, &'static str, i64)> {
        let out = self
            .core
            .events()
            .map(|e| match e.kind {
                EventKind::Disabled => (e.stamp_ms, "disabled", 0),
                EventKind::NotConfigured(s) => (e.stamp_ms, "not_configured", s as i64),
                EventKind::GimbalMismatch(g) => (e.stamp_ms, "gimbal_mismatch", g as i64),
                EventKind::Running => (e.stamp_ms, "running", 0),
                EventKind::Disconnected => (e.stamp_ms, "disconnected", 0),
            })
            .collect();
        self.core.clear_events();
        out
    }
}

/// The Neuron bus between this master and a `NeuronBank` without python-can (see
/// `rdm_core::firmware::can_wire`): delivery queues and the candump log.
#[pyclass(module = "rdm._rdm")]
pub struct CanWire {
    /// The core wire (the bank binding sends and receives through it too).
    pub core: CoreWire,
}

#[pymethods]
impl CanWire {
    #[new]
    #[pyo3(signature = (queue_capacity=DEFAULT_QUEUE_CAPACITY, log_capacity=DEFAULT_LOG_CAPACITY, logging=true))]
    fn new(queue_capacity: usize, log_capacity: usize, logging: bool) -> Self {
        CanWire {
            core: CoreWire::new(queue_capacity, log_capacity, logging),
        }
    }

    /// Frames sent on the wire so far.
    #[getter]
    fn frames(&self) -> u64 {
        self.core.frames
    }

    /// `(queue_dropped, log_dropped)`.
    #[getter]
    fn dropped(&self) -> (u64, u64) {
        (self.core.queue_dropped, self.core.log_dropped)
    }

    /// Fault hook: each later frame is lost with probability `p` (0: off), seeded.
    fn set_loss(&mut self, p: f64, seed: u64) -> PyResult<()> {
        self.core.set_loss(p, seed).map_err(|_| {
            pyo3::exceptions::PyValueError::new_err(format!("set_loss: p={p} not in [0, 1]"))
        })
    }

    /// Fault hook: the bus disturbed from channel time `start` for `disturbed_s` s; bus-off
    /// until 128 x 11 recessive bits after its end.
    fn bus_off(&mut self, start: f64, disturbed_s: f64) -> PyResult<()> {
        self.core.bus_off(start, disturbed_s).map_err(|_| {
            pyo3::exceptions::PyValueError::new_err(format!(
                "bus_off: start={start} and disturbed_s={disturbed_s} must be finite, \
                 disturbed_s >= 0"
            ))
        })
    }

    /// The fault hooks' counters: `lost`, `error_frames`, `bus_off`, `bus_off_lost`, and
    /// `silent_until` (channel time the bus carries frames again; -inf: never off).
    fn fault_counters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        let d = pyo3::types::PyDict::new(py);
        d.set_item("lost", self.core.lost)?;
        d.set_item("error_frames", self.core.error_frames)?;
        d.set_item("bus_off", self.core.bus_off)?;
        d.set_item("bus_off_lost", self.core.bus_off_lost)?;
        d.set_item("silent_until", self.core.silent_until())?;
        Ok(d)
    }

    /// Frames waiting in the capture log.
    #[getter]
    fn log_len(&self) -> usize {
        self.core.log_len()
    }

    /// The logged frames as `candump -L` lines on `channel`; empties the log.
    fn drain_log(&mut self, channel: &str) -> String {
        let mut out = String::with_capacity(self.core.log_len() * 40);
        self.core.drain_log(channel, &mut out);
        out
    }
}

/// Register `CanMaster`, `CanWire` and `CanMasterError`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<CanWire>()?;
    m.add("CanMasterError", py.get_type::<CanMasterError>())?;
    m.add_class::<CanMaster>()?;
    Ok(())
}
