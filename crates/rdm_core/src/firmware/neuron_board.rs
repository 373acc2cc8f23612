//! One Neuron board on the CAN bus (reference: `rdm.nodes.neuron_mirror.NeuronMirror`):
//! answers enumeration and configuration requests, applies board-config sub-commands, PWM
//! slots and servo words, reports servo states (and IMU samples) after each servo-angle
//! frame, and stops its ESC after 100 ms without an accepted frame (the watchdog).
//!
//! A tick is split into `begin_tick`, one `receive` per frame pending on the bus, and
//! `end_tick`, so a [`super::neuron_bank::NeuronBank`] can interleave the boards of one bus
//! exactly as separate mirrors on a shared bus would see each other's frames.

use super::neuron_frame::{
    decode_spinal_to_neuron, enum_response, imu_frame, initial_config_0, initial_config_1,
    initial_config_2, initial_config_3, servo_state, BoardConfig, NeuronCommand, RxError,
    BROADCAST_ID, FRAME_KINDS, MAX_SERVO_NUM,
};
use super::neuron_servo::{sat_i16, ServoConfig, ServoConfigError, ServoModel};
use super::neuron_tx::{RxFrame, TxQueue, FLAG_ERROR, FLAG_EXTENDED, FLAG_FD, FLAG_REMOTE};

/// No accepted frame for more than this many ms stops the motor (`CANDeviceManager::tick`).
pub const WATCHDOG_MS: i64 = 100;
/// Simulated reboot time after BOARD_CONFIG REBOOT (assumption, as the reference).
pub const DEFAULT_REBOOT_MS: i64 = 100;
/// PWM value the ESC outputs when stopped (1000 us).
pub const PWM_STOP_VALUE: u16 = 0;

/// Why a board cannot be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoardError {
    /// Slave id not in 1..14.
    SlaveId,
    /// More than four servos.
    ServoCount,
    /// A servo configuration is refused (index, reason).
    Servo(usize, ServoConfigError),
    /// Negative reboot time.
    RebootMs,
}

/// Everything a board is built from (the reference mirror's constructor arguments).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardSettings {
    /// CAN slave id 1..14.
    pub slave_id: u8,
    /// The servos (first `servo_count` used).
    pub servos: [ServoConfig; MAX_SERVO_NUM],
    /// Number of servos 0..4.
    pub servo_count: usize,
    /// IMU samples sent after each servo-angle frame.
    pub imu: bool,
    /// The board drives an ESC (reads its PWM slot).
    pub esc: bool,
    /// A plant drives the servo positions (no built-in motion model).
    pub plant_driven: bool,
    /// TTL / RS485 mixed flag reported in INITIAL_CONFIG_0.
    pub ttl_rs485_mixed: bool,
    /// Pulley skip threshold reported in INITIAL_CONFIG_0.
    pub pulley_skip_thresh: u16,
    /// Reboot time (ms).
    pub reboot_ms: i64,
}

impl BoardSettings {
    /// Defaults of the reference: no servos, no IMU, an ESC, own motion model.
    pub fn new(slave_id: u8) -> BoardSettings {
        BoardSettings {
            slave_id,
            servos: [ServoConfig::default(); MAX_SERVO_NUM],
            servo_count: 0,
            imu: false,
            esc: true,
            plant_driven: false,
            ttl_rs485_mixed: false,
            pulley_skip_thresh: 0,
            reboot_ms: DEFAULT_REBOOT_MS,
        }
    }
}

/// Rx counters of a board.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BoardCounters {
    /// Accepted frames (own slave id or broadcast).
    pub rx_count: u64,
    /// Frames for other boards (or heard while rebooting).
    pub rx_filtered: u64,
    /// Bad frames by reason ([`RxError::ALL`] order).
    pub rx_errors: [u64; RxError::ALL.len()],
    /// Valid frames by kind ([`FRAME_KINDS`] order).
    pub rx_kinds: [u64; FRAME_KINDS.len()],
    /// Frames lost because the bank's send queue was full.
    pub tx_dropped: u64,
    /// Reboots started.
    pub reboots: u64,
}

/// One Neuron.
#[derive(Debug, Clone, PartialEq)]
pub struct NeuronBoard {
    /// Slave id in use.
    pub slave_id: u8,
    /// Id written by SET_SLAVE_ID, taken at the next reboot.
    pub flash_slave_id: u8,
    servos: [ServoModel; MAX_SERVO_NUM],
    servo_count: usize,
    /// IMU samples sent after each servo-angle frame.
    pub imu_send_flag: bool,
    has_esc: bool,
    plant_driven: bool,
    esc_held: u16,
    esc_stopped: bool,
    /// Bumped by every change of a servo goal / torque or of the ESC output.
    pub changes: u64,
    /// TTL / RS485 mixed flag.
    pub ttl_rs485_mixed: bool,
    /// Pulley skip threshold.
    pub pulley_skip_thresh: u16,
    reboot_ms: i64,
    /// Raw gyro, acc, mag samples (int16, sensor frame).
    pub imu_raw: [[i16; 3]; 3],
    /// Counters.
    pub counters: BoardCounters,
    last_rx_ms: Option<i64>,
    last_now: Option<f64>,
    now_ms: i64,
    rebooting_until: Option<i64>,
    // Per tick: the board was resetting when the tick began; a servo-angle frame arrived.
    deaf_this_tick: bool,
    trigger: bool,
}

impl NeuronBoard {
    /// A board in its power-on state.
    pub fn new(settings: &BoardSettings) -> Result<NeuronBoard, BoardError> {
        if !(1..=14).contains(&settings.slave_id) {
            return Err(BoardError::SlaveId);
        }
        if settings.servo_count > MAX_SERVO_NUM {
            return Err(BoardError::ServoCount);
        }
        if settings.reboot_ms < 0 {
            return Err(BoardError::RebootMs);
        }
        let mut servos = [ServoModel::new(ServoConfig::default()); MAX_SERVO_NUM];
        for (k, (slot, config)) in servos.iter_mut().zip(settings.servos.iter()).enumerate() {
            if k < settings.servo_count {
                config.validate().map_err(|e| BoardError::Servo(k, e))?;
            }
            *slot = ServoModel::new(*config);
        }
        Ok(NeuronBoard {
            slave_id: settings.slave_id,
            flash_slave_id: settings.slave_id,
            servos,
            servo_count: settings.servo_count,
            imu_send_flag: settings.imu,
            has_esc: settings.esc,
            plant_driven: settings.plant_driven,
            esc_held: PWM_STOP_VALUE,
            esc_stopped: true,
            changes: 0,
            ttl_rs485_mixed: settings.ttl_rs485_mixed,
            pulley_skip_thresh: settings.pulley_skip_thresh,
            reboot_ms: settings.reboot_ms,
            imu_raw: [[0, 0, 0], [0, 0, 4096], [0, 0, 0]], // 1 g on +z at rest (+-8 g)
            counters: BoardCounters::default(),
            last_rx_ms: None,
            last_now: None,
            now_ms: 0,
            rebooting_until: None,
            deaf_this_tick: false,
            trigger: false,
        })
    }

    /// The servos in index order.
    pub fn servos(&self) -> &[ServoModel] {
        self.servos.get(..self.servo_count).unwrap_or(&[])
    }

    /// Mutable servos in index order (plant feedback, test hooks).
    pub fn servos_mut(&mut self) -> &mut [ServoModel] {
        self.servos.get_mut(..self.servo_count).unwrap_or(&mut [])
    }

    /// PWM value held from the last slot read (0..1000).
    pub fn esc_held_value(&self) -> u16 {
        self.esc_held
    }

    /// Watchdog verdict: the ESC outputs the stop value.
    pub fn esc_stopped(&self) -> bool {
        self.esc_stopped
    }

    /// What the ESC timer outputs now, 0..1000 (pulse - 1000 us).
    pub fn esc_value(&self) -> u16 {
        if self.esc_stopped {
            PWM_STOP_VALUE
        } else {
            self.esc_held
        }
    }

    /// Set the held PWM value (bumps `changes` on a change).
    pub fn set_esc_held_value(&mut self, value: u16) {
        if value != self.esc_held {
            self.esc_held = value;
            self.changes = self.changes.wrapping_add(1);
        }
    }

    fn set_esc_stopped(&mut self, value: bool) {
        if value != self.esc_stopped {
            self.esc_stopped = value;
            self.changes = self.changes.wrapping_add(1);
        }
    }

    /// False once more than 100 ms passed without an accepted frame.
    pub fn connected(&self) -> bool {
        matches!(self.last_rx_ms, Some(t) if self.now_ms - t <= WATCHDOG_MS)
    }

    /// Resetting after a REBOOT sub-command.
    pub fn rebooting(&self) -> bool {
        self.rebooting_until.is_some()
    }

    /// Start of a tick at `now_ms` (whole ms).
    pub fn begin_tick(&mut self, now_ms: i64) {
        self.now_ms = now_ms;
        if self.last_rx_ms.is_none() {
            self.last_rx_ms = Some(now_ms); // the watchdog counter starts at boot
        }
        self.deaf_this_tick = self.rebooting_until.is_some();
        self.trigger = false;
    }

    /// One frame from the bus; replies go to `tx` tagged with `board` (the bank index).
    pub fn receive(&mut self, frame: &RxFrame, board: usize, tx: &mut TxQueue) {
        if self.deaf_this_tick {
            self.counters.rx_filtered += 1; // a resetting MCU hears nothing
            return;
        }
        if frame.flags & FLAG_ERROR != 0 {
            return self.count_error(RxError::ErrorFrame);
        }
        if frame.flags & FLAG_REMOTE != 0 {
            return self.count_error(RxError::Remote);
        }
        if frame.flags & FLAG_EXTENDED != 0 {
            return self.count_error(RxError::NotStandardId);
        }
        let slave_field = (frame.id & 0xF) as u8;
        if slave_field != BROADCAST_ID && slave_field != self.slave_id {
            self.counters.rx_filtered += 1;
            return;
        }
        self.counters.rx_count += 1;
        self.last_rx_ms = Some(self.now_ms);
        if frame.flags & FLAG_FD != 0 {
            return self.count_error(RxError::Fd);
        }
        let decoded = if frame.len > 8 {
            Err(RxError::Dlc)
        } else {
            decode_spinal_to_neuron(frame.id, frame.kept())
        };
        match decoded {
            Err(e) => self.count_error(e),
            Ok(command) => {
                if let Some(k) = self.counters.rx_kinds.get_mut(command.kind()) {
                    *k += 1;
                }
                if self.dispatch(&command, board, tx) {
                    self.trigger = true;
                }
            }
        }
    }

    /// End of the tick at `now` seconds (same instant as `begin_tick`): reboot completion or
    /// the state report, the motion model, the watchdog.
    pub fn end_tick(&mut self, now: f64, board: usize, tx: &mut TxQueue) {
        if self.deaf_this_tick {
            if matches!(self.rebooting_until, Some(t) if self.now_ms >= t) {
                self.finish_reboot();
            }
        } else if self.trigger {
            self.send_states(board, tx);
        }
        if !self.plant_driven {
            let dt = match self.last_now {
                None => 0.0,
                Some(last) => (now - last).max(0.0),
            };
            for servo in self.servos_mut() {
                servo.advance(dt);
            }
        }
        self.last_now = Some(now);
        let stopped = self.rebooting_until.is_some()
            || self.now_ms - self.last_rx_ms.unwrap_or(self.now_ms) > WATCHDOG_MS;
        self.set_esc_stopped(stopped);
    }

    fn count_error(&mut self, e: RxError) {
        if let Some(c) = self.counters.rx_errors.get_mut(e.index()) {
            *c += 1;
        }
    }

    fn send(&mut self, board: usize, tx: &mut TxQueue, frame: super::neuron_frame::CanFrame) {
        if !tx.push(board, frame) {
            self.counters.tx_dropped += 1;
        }
    }

    fn dispatch(&mut self, command: &NeuronCommand, board: usize, tx: &mut TxQueue) -> bool {
        match command {
            NeuronCommand::Pwm {
                frame_index,
                values,
            } => {
                if self.has_esc {
                    let slot = match (self.slave_id, frame_index) {
                        (1..=6, 0) => Some(self.slave_id as usize - 1),
                        (7..=12, 1) => Some(self.slave_id as usize - 7),
                        _ => None,
                    };
                    if let Some(&v) = slot.and_then(|s| values.get(s)) {
                        self.set_esc_held_value(v);
                    }
                }
            }
            NeuronCommand::EnumRequest => {
                let f = enum_response(self.slave_id);
                self.send(board, tx, f);
            }
            NeuronCommand::InitialConfigRequest => self.send_config(board, tx),
            NeuronCommand::Board(config) => self.board_config(config, board, tx),
            NeuronCommand::ServoTargetAngles(words) => {
                if words.count != self.servo_count {
                    self.count_error(RxError::ServoCount);
                    return false;
                }
                let mut changes = self.changes;
                for (k, servo) in self.servos_mut().iter_mut().enumerate() {
                    let value = words.values.get(k).copied().unwrap_or(0) as i64;
                    let ack = words.flags.get(k).copied().unwrap_or(false);
                    servo.command_goal(value, ack, &mut changes);
                }
                self.changes = changes;
                return true;
            }
            NeuronCommand::ServoTargetCurrents(words) => {
                if words.count != self.servo_count {
                    self.count_error(RxError::ServoCount);
                    return false;
                }
                let mut changes = self.changes;
                for (k, servo) in self.servos_mut().iter_mut().enumerate() {
                    servo.goal_current = words.values.get(k).copied().unwrap_or(0) as i64;
                    let torque = words.flags.get(k).copied().unwrap_or(false);
                    servo.set_torque(torque, &mut changes);
                }
                self.changes = changes;
            }
        }
        false
    }

    fn board_config(&mut self, config: &BoardConfig, board: usize, tx: &mut TxQueue) {
        if let Some(index) = config.index() {
            if index as usize >= self.servo_count {
                self.count_error(RxError::ServoIndex);
                return;
            }
        }
        match *config {
            BoardConfig::Reboot => {
                self.start_reboot();
                return;
            }
            BoardConfig::SetSlaveId { new_id } => self.flash_slave_id = new_id,
            BoardConfig::SetImuSendFlag { flag } => self.imu_send_flag = flag,
            BoardConfig::SetDynamixelTtlRs485Mixed { flag } => self.ttl_rs485_mixed = flag,
            BoardConfig::SetServoPulleySkipThresh { thresh } => self.pulley_skip_thresh = thresh,
            _ => self.servo_config(config),
        }
        self.send_config(board, tx);
    }

    fn servo_config(&mut self, config: &BoardConfig) {
        let Some(index) = config.index() else {
            return;
        };
        let mut changes = self.changes;
        let Some(servo) = self.servos_mut().get_mut(index as usize) else {
            return;
        };
        match *config {
            BoardConfig::SetServoHomingOffset { offset, .. } => {
                servo.set_homing_offset(offset as i64, &mut changes)
            }
            BoardConfig::SetServoPidGain { p, i, d, .. } => {
                servo.config.p_gain = p;
                servo.config.i_gain = i;
                servo.config.d_gain = d;
            }
            BoardConfig::SetServoProfileVel {
                profile_velocity, ..
            } => servo.config.profile_velocity = profile_velocity,
            BoardConfig::SetSendDataFlag { flag, .. } => servo.config.send_data_flag = flag,
            BoardConfig::SetServoCurrentLimit { current_limit, .. } => {
                servo.config.current_limit = current_limit
            }
            BoardConfig::SetServoRoundOffset { offset, .. } => servo.round_offset = offset as i64,
            // These two only while torque is off.
            BoardConfig::SetExternalEncoderFlag { flag, .. } if !servo.torque_enable() => {
                servo.config.external_encoder_flag = flag
            }
            BoardConfig::SetResolutionRatio {
                joint, servo: s, ..
            } if !servo.torque_enable() => {
                servo.config.joint_resolution = joint;
                servo.config.servo_resolution = s;
            }
            _ => {}
        }
        self.changes = changes;
    }

    fn start_reboot(&mut self) {
        self.counters.reboots += 1;
        self.rebooting_until = Some(self.now_ms + self.reboot_ms);
        self.set_esc_held_value(PWM_STOP_VALUE);
        let mut changes = self.changes;
        for servo in self.servos_mut() {
            servo.set_torque(false, &mut changes);
        }
        self.changes = changes;
    }

    /// Fault hook (the fault campaign's `neuron-reset`): the MCU resets at the call, unasked (a
    /// brown-out or watchdog reset, not a REBOOT sub-command). Deaf for the reboot time with
    /// the ESC stopped, as after REBOOT; its RAM back to the power-on state: every servo
    /// torque off, its goal at the present position (the shaft stays where it is), no
    /// handshake pending, the goal current and hardware error of power-on. Flash settings
    /// (slave id, IMU flag, servo configuration) are kept. Spinal's next torque bits turn the
    /// servos on again, each reporting its goal (the goal-sync handshake) until acknowledged.
    pub fn power_cycle(&mut self) {
        self.start_reboot();
        let mut changes = self.changes;
        for servo in self.servos_mut() {
            let (position, velocity) = (servo.position, servo.velocity);
            *servo = ServoModel::new(servo.config);
            servo.position = position;
            servo.velocity = velocity;
            servo.set_goal(servo.present_position(), &mut changes);
        }
        self.changes = changes.wrapping_add(1);
    }

    fn finish_reboot(&mut self) {
        self.rebooting_until = None;
        self.slave_id = self.flash_slave_id;
        self.last_rx_ms = Some(self.now_ms);
    }

    /// INITIAL_CONFIG_0, then _1, _2, _3 per servo (the answer to a config request and to
    /// every applied board-config sub-command).
    fn send_config(&mut self, board: usize, tx: &mut TxQueue) {
        let s = self.slave_id;
        let f = initial_config_0(
            s,
            self.servo_count as u8,
            self.imu_send_flag,
            self.ttl_rs485_mixed,
            self.pulley_skip_thresh,
        );
        self.send(board, tx, f);
        for k in 0..self.servo_count.min(MAX_SERVO_NUM) {
            let Some(servo) = self.servos.get(k).copied() else {
                continue;
            };
            let c = servo.config;
            let i = k as u8;
            let flags = c.send_data_flag as u8 | (c.external_encoder_flag as u8) << 1;
            let frames = [
                initial_config_1(s, i, c.dynamixel_id, [c.p_gain, c.i_gain, c.d_gain]),
                initial_config_2(
                    s,
                    i,
                    sat_i16(servo.present_position()),
                    c.profile_velocity,
                    c.current_limit,
                    flags,
                ),
                initial_config_3(
                    s,
                    i,
                    (servo.hardware_error & 0xFF) as u8,
                    sat_i16(servo.goal_current),
                    [c.joint_resolution, c.servo_resolution],
                ),
            ];
            for f in frames {
                self.send(board, tx, f);
            }
        }
    }

    /// Servo states (servos with `send_data_flag`), then gyro, acc, mag if the IMU flag is set.
    fn send_states(&mut self, board: usize, tx: &mut TxQueue) {
        let s = self.slave_id;
        for k in 0..self.servo_count.min(MAX_SERVO_NUM) {
            let Some(servo) = self.servos.get(k).copied() else {
                continue;
            };
            if !servo.config.send_data_flag {
                continue;
            }
            let status = (servo.moving() as u8) << 1 | (servo.send_goal_position as u8) << 2;
            let f = servo_state(
                s,
                k as u8,
                sat_i16(servo.reported_angle()),
                servo.temperature.clamp(0, 255) as u8,
                status,
                sat_i16(servo.current()),
                (servo.hardware_error & 0xFF) as u8,
            );
            self.send(board, tx, f);
        }
        if self.imu_send_flag {
            for sensor in 0..3u8 {
                let xyz = self.imu_raw.get(sensor as usize).copied().unwrap_or([0; 3]);
                self.send(board, tx, imu_frame(s, sensor, xyz));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn power_cycle_is_deaf_then_back_at_power_on() {
        let mut s = BoardSettings::new(1);
        s.servo_count = 1;
        s.plant_driven = true;
        let mut board = NeuronBoard::new(&s).expect("board");
        let mut tx = TxQueue::with_capacity(16);
        board.begin_tick(1000);
        let mut changes = board.changes;
        let servo = &mut board.servos_mut()[0];
        servo.set_torque(true, &mut changes);
        assert!(servo.command_goal(3000, true, &mut changes));
        servo.position = 2500.4;
        board.changes = changes;
        board.set_esc_held_value(600);
        board.end_tick(1.0, 0, &mut tx);
        assert_eq!(board.esc_value(), 600);
        let before = board.changes;
        board.power_cycle();
        assert!(board.changes != before);
        let servo = board.servos()[0];
        assert!(!servo.torque_enable() && !servo.send_goal_position);
        assert_eq!(servo.goal(), 2500); // the goal at the shaft, not the old 3000
        assert_eq!(servo.position, 2500.4);
        for ms in 1001..1100 {
            board.begin_tick(ms);
            board.end_tick(ms as f64 / 1000.0, 0, &mut tx);
            assert!(
                board.rebooting() && board.esc_value() == PWM_STOP_VALUE,
                "{ms}"
            );
        }
        board.begin_tick(1100); // the reboot time (100 ms) after the reset
        board.end_tick(1.1, 0, &mut tx);
        assert!(!board.rebooting());
        assert_eq!(board.counters.reboots, 1);
        assert_eq!(board.esc_held_value(), PWM_STOP_VALUE); // until the next PWM frame
    }
}
