//! Bindings of `rdm_core::firmware::neuron_bank`: every Neuron of one CAN bus ticked in one
//! call (python-can messages in, `(board, can_id, payload)` frames out).

use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PyTuple};
use rdm_core::firmware::bank_bridge::{BankBridge, BridgeError, ServoEntry};
use rdm_core::firmware::neuron_bank::{BankError, NeuronBank as CoreBank, DEFAULT_TX_CAPACITY};
use rdm_core::firmware::neuron_board::{BoardError, BoardSettings};
use rdm_core::firmware::neuron_frame::{RxError, FRAME_KINDS, MAX_SERVO_NUM};
use rdm_core::firmware::neuron_servo::{ServoConfig, ServoConfigError};
use rdm_core::firmware::neuron_tx::RxFrame;

use crate::can_frame::rx_frame_of;
use crate::errors::RdmError;

create_exception!(
    _rdm,
    NeuronBankError,
    RdmError,
    "Bad argument of the Neuron bank (the message names it)."
);

fn err(msg: String) -> PyErr {
    NeuronBankError::new_err(msg)
}

fn servo_reason(e: ServoConfigError) -> String {
    match e {
        ServoConfigError::InitialPosition => {
            "initial_position outside [min_position, max_position]".into()
        }
        ServoConfigError::TimeConstant => "time_constant must be finite and > 0".into(),
        ServoConfigError::CurrentPerTick => "current_per_tick must be finite".into(),
        ServoConfigError::DynamixelId => "dynamixel_id not in 0..252".into(),
    }
}

fn bank_err(e: BankError) -> PyErr {
    err(match e {
        BankError::Board(k, BoardError::SlaveId) => format!("boards[{k}].slave_id not in 1..14"),
        BankError::Board(k, BoardError::ServoCount) => format!("boards[{k}].servos: more than 4"),
        BankError::Board(k, BoardError::RebootMs) => format!("boards[{k}].reboot_ms must be >= 0"),
        BankError::Board(k, BoardError::Servo(i, r)) => {
            format!("boards[{k}].servos[{i}]: {}", servo_reason(r))
        }
        BankError::BoardCount => "boards: need 1..14 boards".into(),
        BankError::DuplicateSlave(s) => format!("boards: slave_id {s} given twice"),
        BankError::NonFiniteTime => "now must be finite".into(),
        BankError::BoardIndex(k) => format!("board index {k} out of range"),
        BankError::ServoIndex(k, i) => format!("board {k}: servo index {i} out of range"),
        BankError::NonFinitePosition(k, i) => {
            format!("board {k} servo {i}: present position is not finite")
        }
        BankError::Sensor(s) => format!("sensor {s} not in 0..2 (gyro, acc, mag)"),
    })
}

fn bridge_err(e: BridgeError) -> PyErr {
    err(match e {
        BridgeError::ServoEntry(n) => format!("servos[{n}]: no such board/servo in the bank"),
        BridgeError::JointIndex(n) => format!("servos[{n}]: joint index outside qadr"),
        BridgeError::RotorEntry(n) => {
            format!("rotors[{n}]: no such board, or rotor outside duties")
        }
        BridgeError::QposAddress(j) => format!("qadr[{j}]: outside qpos"),
        BridgeError::Scale(j) => format!("scale[{j}]: must be finite and non-zero"),
        BridgeError::Length => "targets/scale: length differs from qadr".into(),
        BridgeError::NonFiniteJoint(j) => format!("qpos: joint {j} is not finite"),
    })
}

fn item<'py, T: FromPyObjectOwned<'py>>(
    d: &Bound<'py, PyDict>,
    key: &str,
    what: &str,
) -> PyResult<T> {
    match d.get_item(key)? {
        Some(v) => v
            .extract::<T>()
            .map_err(|e| err(format!("{what}.{key}: {}", Into::<PyErr>::into(e)))),
        None => Err(err(format!("{what}: missing key {key:?}"))),
    }
}

fn servo_config(d: &Bound<'_, PyDict>, what: &str) -> PyResult<ServoConfig> {
    let ranged = |key: &str, low: i64, high: i64| -> PyResult<i64> {
        let v: i64 = item(d, key, what)?;
        if v < low || v > high {
            return Err(err(format!("{what}.{key}={v} not in {low}..{high}")));
        }
        Ok(v)
    };
    let c = ServoConfig {
        dynamixel_id: ranged("dynamixel_id", 0, 252)? as u8,
        send_data_flag: item(d, "send_data_flag", what)?,
        external_encoder_flag: item(d, "external_encoder_flag", what)?,
        p_gain: ranged("p_gain", 0, 0xFFFF)? as u16,
        i_gain: ranged("i_gain", 0, 0xFFFF)? as u16,
        d_gain: ranged("d_gain", 0, 0xFFFF)? as u16,
        profile_velocity: ranged("profile_velocity", 0, 0xFFFF)? as u16,
        current_limit: ranged("current_limit", 0, 0xFFFF)? as u16,
        goal_current: item(d, "goal_current", what)?,
        joint_resolution: ranged("joint_resolution", -0x8000, 0x7FFF)? as i16,
        servo_resolution: ranged("servo_resolution", -0x8000, 0x7FFF)? as i16,
        min_position: item(d, "min_position", what)?,
        max_position: item(d, "max_position", what)?,
        initial_position: item(d, "initial_position", what)?,
        temperature: item(d, "temperature", what)?,
        time_constant: item(d, "time_constant", what)?,
        current_per_tick: item(d, "current_per_tick", what)?,
    };
    c.validate()
        .map_err(|e| err(format!("{what}: {}", servo_reason(e))))?;
    Ok(c)
}

fn board_settings(d: &Bound<'_, PyDict>, k: usize) -> PyResult<BoardSettings> {
    let what = format!("boards[{k}]");
    let slave: i64 = item(d, "slave_id", &what)?;
    if !(1..=14).contains(&slave) {
        return Err(err(format!("{what}.slave_id={slave} not in 1..14")));
    }
    let mut s = BoardSettings::new(slave as u8);
    let servos: Vec<Bound<'_, PyDict>> = item(d, "servos", &what)?;
    if servos.len() > MAX_SERVO_NUM {
        return Err(err(format!("{what}.servos: {} > 4", servos.len())));
    }
    for (i, sd) in servos.iter().enumerate() {
        if let Some(slot) = s.servos.get_mut(i) {
            *slot = servo_config(sd, &format!("{what}.servos[{i}]"))?;
        }
    }
    s.servo_count = servos.len();
    s.imu = item(d, "imu", &what)?;
    s.esc = item(d, "esc", &what)?;
    s.plant_driven = item(d, "plant_driven", &what)?;
    s.ttl_rs485_mixed = item(d, "ttl_rs485_mixed", &what)?;
    let pulley: i64 = item(d, "pulley_skip_thresh", &what)?;
    if !(0..=0xFFFF).contains(&pulley) {
        return Err(err(format!(
            "{what}.pulley_skip_thresh={pulley} not in 0..65535"
        )));
    }
    s.pulley_skip_thresh = pulley as u16;
    s.reboot_ms = item(d, "reboot_ms", &what)?;
    Ok(s)
}

/// Every Neuron of one CAN bus (reference: one `rdm.nodes.neuron_mirror.NeuronMirror` per
/// board on a shared bus, ticked in list order at the same instant).
#[pyclass(module = "rdm._rdm")]
pub struct NeuronBank {
    core: CoreBank,
    rx: Vec<RxFrame>,
    bridge: Option<BankBridge>,
}

#[pymethods]
impl NeuronBank {
    /// `boards`: dicts with `slave_id`, `servos` (dicts of `ServoConfig` fields), `imu`,
    /// `esc`, `plant_driven`, `ttl_rs485_mixed`, `pulley_skip_thresh`, `reboot_ms`.
    #[new]
    #[pyo3(signature = (boards, tx_capacity=DEFAULT_TX_CAPACITY))]
    fn new(boards: Vec<Bound<'_, PyDict>>, tx_capacity: usize) -> PyResult<Self> {
        let mut settings = Vec::with_capacity(boards.len());
        for (k, d) in boards.iter().enumerate() {
            settings.push(board_settings(d, k)?);
        }
        let core = CoreBank::new(&settings, tx_capacity).map_err(bank_err)?;
        Ok(NeuronBank {
            core,
            rx: Vec::with_capacity(256),
            bridge: None,
        })
    }

    /// Attach the plant bridge's per-millisecond coupling (`rdm.nodes.plant_bridge`):
    /// `center` ticks, per joint its qpos address `qadr` and ticks per radian `scale`,
    /// `servos` `(board, servo, joint)` grouped by board in the order of `group_boards`,
    /// `rotors` `(rotor, board)`.
    fn attach_bridge(
        &mut self,
        center: i64,
        qadr: Vec<usize>,
        scale: Vec<f64>,
        servos: Vec<(usize, usize, usize)>,
        rotors: Vec<(usize, usize)>,
        group_boards: Vec<usize>,
    ) -> PyResult<()> {
        let entries: Vec<ServoEntry> = servos
            .iter()
            .map(|&(board, servo, joint)| ServoEntry {
                board,
                servo,
                joint,
            })
            .collect();
        let b = BankBridge::new(
            &self.core,
            center,
            &qadr,
            &scale,
            &entries,
            &rotors,
            &group_boards,
        )
        .map_err(bridge_err)?;
        self.bridge = Some(b);
        Ok(())
    }

    /// Fault hook: joint `joint`'s servo output stops following its goal (its plant target
    /// frozen at the next snapshot's angle; `BankBridge::stick_joint`).
    fn stick_joint(&mut self, joint: usize) -> PyResult<()> {
        let bridge = self
            .bridge
            .as_mut()
            .ok_or_else(|| err("stick_joint: no bridge attached".into()))?;
        if bridge.stick_joint(joint) {
            Ok(())
        } else {
            Err(err(format!(
                "stick_joint: joint {joint} outside the joint table"
            )))
        }
    }

    /// Push the last bridge snapshot's present positions to the servos (once per snapshot).
    fn bridge_push_positions(&mut self) -> PyResult<()> {
        if let Some(b) = self.bridge.as_mut() {
            b.push_positions(&mut self.core).map_err(bridge_err)?;
        }
        Ok(())
    }

    /// Advance to `now` (s) with the python-can messages drained from the bus (in order);
    /// returns `[(board_index, can_id, payload), ...]` to send, in order. With the bridge
    /// attached, its snapshot's present positions are pushed first when a frame of this tick
    /// reads them (`push_positions_if_read`).
    fn tick<'py>(
        &mut self,
        py: Python<'py>,
        now: f64,
        messages: &Bound<'py, PyList>,
    ) -> PyResult<Bound<'py, PyList>> {
        self.rx.clear();
        for m in messages.iter() {
            self.rx.push(rx_frame_of(py, &m)?);
        }
        self.push_positions_if_read()?;
        let out = self.core.tick(now, &self.rx).map_err(bank_err)?;
        let list = PyList::empty(py);
        for e in out {
            let t = PyTuple::new(
                py,
                [
                    e.board.into_pyobject(py)?.into_any(),
                    e.frame.id.into_pyobject(py)?.into_any(),
                    PyBytes::new(py, e.frame.payload()).into_any(),
                ],
            )?;
            list.append(t)?;
        }
        Ok(list)
    }

    /// [`tick`] on a `CanWire`: the frames the master sent, replies sent on the wire stamped
    /// `stamp` (the channel clock); returns the sending board index of each reply. The one
    /// form of the wire tick: the lockstep kernel calls it too (`kernel_tick_wire`).
    fn tick_wire(
        &mut self,
        now: f64,
        stamp: f64,
        wire: &Bound<'_, crate::can_master::CanWire>,
    ) -> PyResult<Vec<usize>> {
        let mut boards = Vec::new();
        self.kernel_tick_wire(now, stamp, &mut wire.borrow_mut().core, &mut boards)?;
        Ok(boards)
    }

    /// A frame of board `k` (a [`tick`] output) went to the bus (`sent`) or the bus refused
    /// it (the wire's frames are counted by [`tick_wire`] itself).
    fn count_tx(&mut self, k: usize, sent: bool) -> PyResult<()> {
        self.core.count_tx(k, sent).map_err(bank_err)
    }

    /// `(sent, refused)` frames of board `k`.
    fn tx_count(&self, k: usize) -> PyResult<(u64, u64)> {
        let c = self.core.tx_count(k).map_err(bank_err)?;
        Ok((c.sent, c.errors))
    }

    /// Change counter of board `k` (bumped by goal / torque / ESC output changes).
    fn board_changes(&self, k: usize) -> PyResult<u64> {
        Ok(self.core.board(k).map_err(bank_err)?.changes)
    }

    /// Whether the plant bridge's coupling is attached (`attach_bridge`).
    #[getter]
    fn bridged(&self) -> bool {
        self.bridge.is_some()
    }

    /// Number of boards.
    fn __len__(&self) -> usize {
        self.core.boards().len()
    }

    /// Change counter of every board (bumped by goal / torque / ESC output changes).
    fn changes(&self) -> Vec<u64> {
        self.core.boards().iter().map(|b| b.changes).collect()
    }

    /// `(goals, torque_enable)` of board `k`'s servos in index order.
    fn servo_outputs(&self, k: usize) -> PyResult<(Vec<i64>, Vec<bool>)> {
        let b = self.core.board(k).map_err(bank_err)?;
        Ok((
            b.servos().iter().map(|s| s.goal()).collect(),
            b.servos().iter().map(|s| s.torque_enable()).collect(),
        ))
    }

    /// `(held_value, stopped)` of board `k`'s ESC.
    fn esc(&self, k: usize) -> PyResult<(u16, bool)> {
        let b = self.core.board(k).map_err(bank_err)?;
        Ok((b.esc_held_value(), b.esc_stopped()))
    }

    /// Fault hook: board `k`'s MCU resets at the call (deaf for its reboot time, ESC stopped, its
    /// servos back to power-on: torque off, goal at the present position).
    fn power_cycle(&mut self, k: usize) -> PyResult<()> {
        self.core.power_cycle(k).map_err(bank_err)
    }

    /// Set board `k`'s held ESC value (a test hook, as writing the reference's attribute).
    fn set_esc_held_value(&mut self, k: usize, value: u16) -> PyResult<()> {
        self.core
            .board_mut(k)
            .map_err(bank_err)?
            .set_esc_held_value(value);
        Ok(())
    }

    /// Plant feedback: `ticks[n]` is the present position of servo `servos[n]` of board
    /// `boards[n]`.
    fn set_positions(
        &mut self,
        boards: Vec<usize>,
        servos: Vec<usize>,
        ticks: Vec<f64>,
    ) -> PyResult<()> {
        if boards.len() != servos.len() || boards.len() != ticks.len() {
            return Err(err(
                "set_positions: boards, servos, ticks differ in length".into()
            ));
        }
        for ((b, s), t) in boards.iter().zip(servos.iter()).zip(ticks.iter()) {
            self.core.set_position(*b, *s, *t).map_err(bank_err)?;
        }
        Ok(())
    }

    /// Raw int16 sample of `sensor` (0 gyro, 1 acc, 2 mag) of board `k`.
    fn set_imu_raw(&mut self, k: usize, sensor: usize, xyz: [i16; 3]) -> PyResult<()> {
        self.core.set_imu_raw(k, sensor, xyz).map_err(bank_err)
    }

    /// Raw IMU samples of board `k` (`[gyro, acc, mag]`).
    fn imu_raw(&self, k: usize) -> PyResult<[[i16; 3]; 3]> {
        Ok(self.core.board(k).map_err(bank_err)?.imu_raw)
    }

    /// Set a servo's hardware error byte or external current (test hooks of the reference:
    /// `field` is "hardware_error", "external_current" (None clears), "temperature").
    #[pyo3(signature = (k, index, field, value))]
    fn set_servo_field(
        &mut self,
        k: usize,
        index: usize,
        field: &str,
        value: Option<i64>,
    ) -> PyResult<()> {
        let b = self.core.board_mut(k).map_err(bank_err)?;
        let s = b
            .servos_mut()
            .get_mut(index)
            .ok_or_else(|| err(format!("board {k}: servo index {index} out of range")))?;
        match (field, value) {
            ("hardware_error", Some(v)) => s.hardware_error = v,
            ("temperature", Some(v)) => s.temperature = v,
            ("external_current", v) => s.external_current = v,
            _ => {
                return Err(err(format!(
                    "set_servo_field: field {field:?} with {value:?}"
                )))
            }
        }
        Ok(())
    }

    /// Everything about board `k` (diagnostics and tests): ids, flags, ESC, counters, and
    /// per servo its state and configuration.
    fn board_state<'py>(&self, py: Python<'py>, k: usize) -> PyResult<Bound<'py, PyDict>> {
        let b = self.core.board(k).map_err(bank_err)?;
        let d = PyDict::new(py);
        d.set_item("slave_id", b.slave_id)?;
        d.set_item("flash_slave_id", b.flash_slave_id)?;
        d.set_item("imu_send_flag", b.imu_send_flag)?;
        d.set_item("ttl_rs485_mixed", b.ttl_rs485_mixed)?;
        d.set_item("pulley_skip_thresh", b.pulley_skip_thresh)?;
        d.set_item("esc_held_value", b.esc_held_value())?;
        d.set_item("esc_stopped", b.esc_stopped())?;
        d.set_item("changes", b.changes)?;
        d.set_item("connected", b.connected())?;
        d.set_item("rebooting", b.rebooting())?;
        let c = &b.counters;
        d.set_item("rx_count", c.rx_count)?;
        d.set_item("rx_filtered", c.rx_filtered)?;
        d.set_item("tx_dropped", c.tx_dropped)?;
        d.set_item("reboots", c.reboots)?;
        let errors = PyDict::new(py);
        for (e, n) in RxError::ALL.iter().zip(c.rx_errors.iter()) {
            if *n > 0 {
                errors.set_item(e.name(), *n)?;
            }
        }
        d.set_item("rx_errors", errors)?;
        let kinds = PyDict::new(py);
        for (name, n) in FRAME_KINDS.iter().zip(c.rx_kinds.iter()) {
            if *n > 0 {
                kinds.set_item(*name, *n)?;
            }
        }
        d.set_item("rx_kinds", kinds)?;
        let servos = PyList::empty(py);
        for s in b.servos() {
            let sd = PyDict::new(py);
            sd.set_item("position", s.position)?;
            sd.set_item("velocity", s.velocity)?;
            sd.set_item("goal", s.goal())?;
            sd.set_item("goal_current", s.goal_current)?;
            sd.set_item("torque_enable", s.torque_enable())?;
            sd.set_item("send_goal_position", s.send_goal_position)?;
            sd.set_item("homing_offset", s.homing_offset)?;
            sd.set_item("round_offset", s.round_offset)?;
            sd.set_item("hardware_error", s.hardware_error)?;
            sd.set_item("temperature", s.temperature)?;
            sd.set_item("present_position", s.present_position())?;
            sd.set_item("current", s.current())?;
            sd.set_item("moving", s.moving())?;
            let cfg = s.config;
            let cd = PyDict::new(py);
            cd.set_item("dynamixel_id", cfg.dynamixel_id)?;
            cd.set_item("send_data_flag", cfg.send_data_flag)?;
            cd.set_item("external_encoder_flag", cfg.external_encoder_flag)?;
            cd.set_item("p_gain", cfg.p_gain)?;
            cd.set_item("i_gain", cfg.i_gain)?;
            cd.set_item("d_gain", cfg.d_gain)?;
            cd.set_item("profile_velocity", cfg.profile_velocity)?;
            cd.set_item("current_limit", cfg.current_limit)?;
            cd.set_item("joint_resolution", cfg.joint_resolution)?;
            cd.set_item("servo_resolution", cfg.servo_resolution)?;
            sd.set_item("config", cd)?;
            servos.append(sd)?;
        }
        d.set_item("servos", servos)?;
        Ok(d)
    }
}

/// Register `NeuronBank` and `NeuronBankError`.
/// Accessors of the lockstep kernel (`crate::kernel`): the same work as the Python-facing
/// methods above, on slices and the core wire, without Python objects in between.
impl NeuronBank {
    /// One bridge tick (`crate::plant_bridge::PlantBridgeCore`): snapshot the joints of
    /// `qpos`, then write the servo targets (rad) of changed boards into `targets` and their
    /// ESC duties into `duties`; returns `(targets_changed, duties_changed)`.
    pub(crate) fn kernel_bridge_tick(
        &mut self,
        qpos: &[f64],
        targets: &mut [f64],
        duties: &mut [f64],
    ) -> PyResult<(bool, bool)> {
        let bridge = self
            .bridge
            .as_mut()
            .ok_or_else(|| err("bridge_tick: no bridge attached".into()))?;
        bridge.snapshot(qpos).map_err(bridge_err)?;
        let c = bridge
            .couple(&self.core, targets, duties)
            .map_err(bridge_err)?;
        Ok((c.targets, c.duties))
    }

    /// With the bridge attached, push its snapshot's present positions when a frame of this
    /// tick (`rx`) reads them: positions are read only while handling a frame other than a
    /// PWM broadcast (MOTOR device, id < 0x100: servo words, requests, board configs) or a
    /// frame a board sent last tick that another board accepts (colliding slave ids). The
    /// snapshot is fixed until the next one, so pushing before the frames are handled gives
    /// the positions a servo reads when it first needs them.
    fn push_positions_if_read(&mut self) -> PyResult<()> {
        let Some(b) = self.bridge.as_mut() else {
            return Ok(());
        };
        if self.rx.iter().any(|f| f.id >= 0x100) || self.core.sent_frames_heard() {
            b.push_positions(&mut self.core).map_err(bridge_err)?;
        }
        Ok(())
    }

    /// [`NeuronBank::tick_wire`] on the core wire; the sending boards go to `boards`.
    pub(crate) fn kernel_tick_wire(
        &mut self,
        now: f64,
        stamp: f64,
        wire: &mut rdm_core::firmware::can_wire::CanWire,
        boards: &mut Vec<usize>,
    ) -> PyResult<()> {
        boards.clear();
        wire.take_for_neurons(&mut self.rx);
        self.push_positions_if_read()?;
        let out = self.core.tick(now, &self.rx).map_err(bank_err)?;
        for e in out {
            wire.send(
                rdm_core::firmware::can_wire::Sender::Neurons,
                stamp,
                e.frame,
            );
            boards.push(e.board);
        }
        for &b in boards.iter() {
            self.core.count_tx(b, true).map_err(bank_err)?;
        }
        Ok(())
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("NeuronBankError", py.get_type::<NeuronBankError>())?;
    m.add_class::<NeuronBank>()?;
    Ok(())
}
