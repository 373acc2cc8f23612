//! The Spinal -> Neuron frames a Neuron accepts, decoded with the reference codec's error
//! reasons (`rdm.protocol.neuron.codec` with direction Spinal->Neuron), and the Neuron ->
//! Spinal frames it sends (`jsk-wire-protocols.md`, Neuron section).
//!
//! StdId = device << 8 | message << 4 | slave. All multi-byte fields little-endian.

/// Device field of the CAN id (bits 10..8).
pub const DEVICE_MOTOR: u32 = 0;
/// IMU frames (Neuron -> Spinal).
pub const DEVICE_IMU: u32 = 1;
/// Servo words (Spinal -> Neuron) and servo states (Neuron -> Spinal).
pub const DEVICE_SERVO: u32 = 2;
/// Enumeration, configuration request / reply and board configuration.
pub const DEVICE_INITIALIZER: u32 = 7;
/// Slave field of broadcast frames.
pub const BROADCAST_ID: u8 = 15;
/// A Neuron drives at most this many servos.
pub const MAX_SERVO_NUM: usize = 4;
/// Largest 11-bit standard identifier.
pub const MAX_STD_ID: u32 = 0x7FF;

/// Why a received frame was not applied (the reference mirror's `rx_errors` keys).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RxError {
    /// A CAN error frame.
    ErrorFrame,
    /// A remote (RTR) frame.
    Remote,
    /// An extended (29-bit) id, or a standard id above 0x7FF.
    NotStandardId,
    /// A CAN FD frame (the Neuron link is classic CAN).
    Fd,
    /// Wrong payload length for every reading of the id.
    Dlc,
    /// The id is no Neuron frame.
    UnknownId,
    /// A field out of range (or an unknown board-config sub-command).
    Range,
    /// Reserved bits set.
    ReservedBits,
    /// A valid frame, but one a Neuron sends rather than receives.
    Direction,
    /// A servo-word frame whose word count differs from the board's servo count.
    ServoCount,
    /// A board-config sub-command for a servo index the board does not have.
    ServoIndex,
}

impl RxError {
    /// Every reason, in counter order.
    pub const ALL: [RxError; 11] = [
        RxError::ErrorFrame,
        RxError::Remote,
        RxError::NotStandardId,
        RxError::Fd,
        RxError::Dlc,
        RxError::UnknownId,
        RxError::Range,
        RxError::ReservedBits,
        RxError::Direction,
        RxError::ServoCount,
        RxError::ServoIndex,
    ];

    /// The reference's name of the reason (`NeuronFrameError.reason` or mirror key).
    pub fn name(self) -> &'static str {
        match self {
            RxError::ErrorFrame => "error_frame",
            RxError::Remote => "remote",
            RxError::NotStandardId => "not_standard_id",
            RxError::Fd => "fd",
            RxError::Dlc => "dlc",
            RxError::UnknownId => "unknown_id",
            RxError::Range => "range",
            RxError::ReservedBits => "reserved_bits",
            RxError::Direction => "direction",
            RxError::ServoCount => "servo_count",
            RxError::ServoIndex => "servo_index",
        }
    }

    /// Position in [`RxError::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Rank used by the reference codec to pick the most telling error among candidates:
    /// field errors first, then a DLC mismatch, a direction mismatch last.
    fn rank(self) -> u8 {
        match self {
            RxError::Dlc => 1,
            RxError::Direction => 2,
            _ => 0,
        }
    }

    /// The error the reference reports among two failed candidates (stable sort by rank).
    fn most_telling(first: RxError, second: RxError) -> RxError {
        if second.rank() < first.rank() {
            second
        } else {
            first
        }
    }
}

/// BOARD_CONFIG_REQUEST sub-commands (`SetBoardConfig.srv` numbers 0..12).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoardConfig {
    /// 0: new slave id (1..14), applied at the next reboot.
    SetSlaveId { new_id: u8 },
    /// 1: IMU frames after each servo-angle frame.
    SetImuSendFlag { flag: bool },
    /// 2: servo homing offset.
    SetServoHomingOffset { index: u8, offset: i32 },
    /// 3: servo position PID gains.
    SetServoPidGain { index: u8, p: u16, i: u16, d: u16 },
    /// 4: servo profile velocity.
    SetServoProfileVel { index: u8, profile_velocity: u16 },
    /// 5: whether the servo reports its state.
    SetSendDataFlag { index: u8, flag: bool },
    /// 6: servo current limit.
    SetServoCurrentLimit { index: u8, current_limit: u16 },
    /// 7: reboot the board.
    Reboot,
    /// 8: TTL / RS485 mixed Dynamixel bus.
    SetDynamixelTtlRs485Mixed { flag: bool },
    /// 9: external encoder (only applied while torque is off).
    SetExternalEncoderFlag { index: u8, flag: bool },
    /// 10: joint / servo resolution (only applied while torque is off).
    SetResolutionRatio { index: u8, joint: i16, servo: i16 },
    /// 11: round offset.
    SetServoRoundOffset { index: u8, offset: i32 },
    /// 12: pulley skip threshold.
    SetServoPulleySkipThresh { thresh: u16 },
}

impl BoardConfig {
    /// The servo index the sub-command addresses, if any.
    pub fn index(&self) -> Option<u8> {
        match *self {
            BoardConfig::SetServoHomingOffset { index, .. }
            | BoardConfig::SetServoPidGain { index, .. }
            | BoardConfig::SetServoProfileVel { index, .. }
            | BoardConfig::SetSendDataFlag { index, .. }
            | BoardConfig::SetServoCurrentLimit { index, .. }
            | BoardConfig::SetExternalEncoderFlag { index, .. }
            | BoardConfig::SetResolutionRatio { index, .. }
            | BoardConfig::SetServoRoundOffset { index, .. } => Some(index),
            _ => None,
        }
    }

    /// Kind counter index (see [`FRAME_KINDS`]).
    fn kind(&self) -> usize {
        5 + match self {
            BoardConfig::SetSlaveId { .. } => 0,
            BoardConfig::SetImuSendFlag { .. } => 1,
            BoardConfig::SetServoHomingOffset { .. } => 2,
            BoardConfig::SetServoPidGain { .. } => 3,
            BoardConfig::SetServoProfileVel { .. } => 4,
            BoardConfig::SetSendDataFlag { .. } => 5,
            BoardConfig::SetServoCurrentLimit { .. } => 6,
            BoardConfig::Reboot => 7,
            BoardConfig::SetDynamixelTtlRs485Mixed { .. } => 8,
            BoardConfig::SetExternalEncoderFlag { .. } => 9,
            BoardConfig::SetResolutionRatio { .. } => 10,
            BoardConfig::SetServoRoundOffset { .. } => 11,
            BoardConfig::SetServoPulleySkipThresh { .. } => 12,
        }
    }
}

/// Names of the accepted frame kinds (the reference frame classes' `KIND`), counter order.
pub const FRAME_KINDS: [&str; 18] = [
    "pwm",
    "enum_request",
    "initial_config_request",
    "servo_target_angle",
    "servo_target_current",
    "board_config_set_slave_id",
    "board_config_set_imu_send_flag",
    "board_config_set_servo_homing_offset",
    "board_config_set_servo_pid_gain",
    "board_config_set_servo_profile_vel",
    "board_config_set_send_data_flag",
    "board_config_set_servo_current_limit",
    "board_config_reboot",
    "board_config_set_dynamixel_ttl_rs485_mixed",
    "board_config_set_external_encoder_flag",
    "board_config_set_resolution_ratio",
    "board_config_set_servo_round_offset",
    "board_config_set_servo_pulley_skip_thresh",
];

/// Up to four 15-bit signed servo words with their bit-15 flags.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServoWords {
    /// Number of words (DLC / 2), 1..4.
    pub count: usize,
    /// Sign-extended values of bits 14..0.
    pub values: [i16; MAX_SERVO_NUM],
    /// Bit 15 of each word.
    pub flags: [bool; MAX_SERVO_NUM],
}

/// A valid Spinal -> Neuron frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NeuronCommand {
    /// MOTOR broadcast: frame 0 (slaves 1..6) or 1 (slaves 7..12), six 10-bit values.
    Pwm { frame_index: u8, values: [u16; 6] },
    /// Enumeration request (broadcast).
    EnumRequest,
    /// INITIAL_CONFIG_REQUEST.
    InitialConfigRequest,
    /// Goal positions with the goal-sync ack flags.
    ServoTargetAngles(ServoWords),
    /// Goal currents with the torque-enable flags.
    ServoTargetCurrents(ServoWords),
    /// A BOARD_CONFIG_REQUEST sub-command.
    Board(BoardConfig),
}

impl NeuronCommand {
    /// Kind counter index (see [`FRAME_KINDS`]).
    pub fn kind(&self) -> usize {
        match self {
            NeuronCommand::Pwm { .. } => 0,
            NeuronCommand::EnumRequest => 1,
            NeuronCommand::InitialConfigRequest => 2,
            NeuronCommand::ServoTargetAngles(_) => 3,
            NeuronCommand::ServoTargetCurrents(_) => 4,
            NeuronCommand::Board(b) => b.kind(),
        }
    }
}

/// Upper bound of a 10-bit PWM slot value Spinal sends (pulse 1000..2000 us).
const PWM_VALUE_MAX: u16 = 1000;

fn u16_at(data: &[u8], at: usize) -> u16 {
    match (data.get(at), data.get(at + 1)) {
        (Some(&lo), Some(&hi)) => u16::from_le_bytes([lo, hi]),
        _ => 0,
    }
}

fn i16_at(data: &[u8], at: usize) -> i16 {
    u16_at(data, at) as i16
}

fn i32_at(data: &[u8], at: usize) -> i32 {
    let mut b = [0u8; 4];
    for (k, slot) in b.iter_mut().enumerate() {
        *slot = data.get(at + k).copied().unwrap_or(0);
    }
    i32::from_le_bytes(b)
}

fn byte_at(data: &[u8], at: usize) -> u8 {
    data.get(at).copied().unwrap_or(0)
}

fn need_dlc(data: &[u8], dlc: usize) -> Result<(), RxError> {
    if data.len() == dlc {
        Ok(())
    } else {
        Err(RxError::Dlc)
    }
}

fn flag(value: u8) -> Result<bool, RxError> {
    match value {
        0 => Ok(false),
        1 => Ok(true),
        _ => Err(RxError::Range),
    }
}

fn servo_index(value: u8) -> Result<u8, RxError> {
    if (value as usize) < MAX_SERVO_NUM {
        Ok(value)
    } else {
        Err(RxError::Range)
    }
}

fn decode_pwm(frame_index: u8, data: &[u8]) -> Result<NeuronCommand, RxError> {
    need_dlc(data, 8)?;
    let mut b = [0u8; 8];
    b.copy_from_slice(data);
    let word = u64::from_le_bytes(b);
    if word & ((0b11 << 30) | (0b11 << 62)) != 0 {
        return Err(RxError::ReservedBits);
    }
    let mut values = [0u16; 6];
    for (slot, v) in values.iter_mut().enumerate() {
        let offset = 10 * (slot % 3) + 32 * (slot / 3);
        *v = ((word >> offset) & 0x3FF) as u16;
        if *v > PWM_VALUE_MAX {
            return Err(RxError::Range);
        }
    }
    Ok(NeuronCommand::Pwm {
        frame_index,
        values,
    })
}

fn decode_words(data: &[u8]) -> Result<ServoWords, RxError> {
    if !matches!(data.len(), 2 | 4 | 6 | 8) {
        return Err(RxError::Dlc);
    }
    let mut words = ServoWords {
        count: data.len() / 2,
        values: [0; MAX_SERVO_NUM],
        flags: [false; MAX_SERVO_NUM],
    };
    for k in 0..words.count.min(MAX_SERVO_NUM) {
        let w = u16_at(data, 2 * k);
        let mut v = (w & 0x7FFF) as i32;
        if v & 0x4000 != 0 {
            v -= 0x8000;
        }
        if let (Some(value), Some(f)) = (words.values.get_mut(k), words.flags.get_mut(k)) {
            *value = v as i16;
            *f = w & 0x8000 != 0;
        }
    }
    Ok(words)
}

/// The Neuron -> Spinal reading of a SERVO id (a servo state): why it is no command.
fn servo_state_error(data: &[u8]) -> RxError {
    if data.len() != 8 {
        RxError::Dlc
    } else if byte_at(data, 3) & !0b111 != 0 {
        RxError::ReservedBits
    } else {
        RxError::Direction
    }
}

pub(crate) fn decode_board_config(data: &[u8]) -> Result<BoardConfig, RxError> {
    let command = byte_at(data, 0);
    let b = |k| byte_at(data, k);
    Ok(match command {
        0 => {
            need_dlc(data, 2)?;
            let new_id = b(1);
            if !(1..=14).contains(&new_id) {
                return Err(RxError::Range);
            }
            BoardConfig::SetSlaveId { new_id }
        }
        1 => {
            need_dlc(data, 2)?;
            BoardConfig::SetImuSendFlag { flag: flag(b(1))? }
        }
        2 => {
            need_dlc(data, 6)?;
            BoardConfig::SetServoHomingOffset {
                index: servo_index(b(1))?,
                offset: i32_at(data, 2),
            }
        }
        3 => {
            need_dlc(data, 8)?;
            BoardConfig::SetServoPidGain {
                index: servo_index(b(1))?,
                p: u16_at(data, 2),
                i: u16_at(data, 4),
                d: u16_at(data, 6),
            }
        }
        4 => {
            need_dlc(data, 4)?;
            BoardConfig::SetServoProfileVel {
                index: servo_index(b(1))?,
                profile_velocity: u16_at(data, 2),
            }
        }
        5 => {
            need_dlc(data, 3)?;
            let index = servo_index(b(1))?;
            BoardConfig::SetSendDataFlag {
                index,
                flag: flag(b(2))?,
            }
        }
        6 => {
            need_dlc(data, 4)?;
            BoardConfig::SetServoCurrentLimit {
                index: servo_index(b(1))?,
                current_limit: u16_at(data, 2),
            }
        }
        7 => {
            need_dlc(data, 1)?;
            BoardConfig::Reboot
        }
        8 => {
            need_dlc(data, 2)?;
            BoardConfig::SetDynamixelTtlRs485Mixed { flag: flag(b(1))? }
        }
        9 => {
            need_dlc(data, 3)?;
            let index = servo_index(b(1))?;
            BoardConfig::SetExternalEncoderFlag {
                index,
                flag: flag(b(2))?,
            }
        }
        10 => {
            need_dlc(data, 6)?;
            BoardConfig::SetResolutionRatio {
                index: servo_index(b(1))?,
                joint: i16_at(data, 2),
                servo: i16_at(data, 4),
            }
        }
        11 => {
            need_dlc(data, 6)?;
            BoardConfig::SetServoRoundOffset {
                index: servo_index(b(1))?,
                offset: i32_at(data, 2),
            }
        }
        12 => {
            need_dlc(data, 3)?;
            BoardConfig::SetServoPulleySkipThresh {
                thresh: u16_at(data, 1),
            }
        }
        _ => return Err(RxError::Range),
    })
}

/// INITIAL_CONFIG_1 / _3 (Neuron -> Spinal: DLC 8, servo index in byte 0, no other
/// constrained field): why such a frame is no command.
fn indexed_reply_error(data: &[u8]) -> RxError {
    if data.len() != 8 {
        RxError::Dlc
    } else if (byte_at(data, 0) as usize) >= MAX_SERVO_NUM {
        RxError::Range
    } else {
        RxError::Direction
    }
}

/// `(device, message, slave)` of a classic standard frame's id (fact sheet sec. 2.5), after
/// the checks both directions make first: payload of at most 8 bytes, an 11-bit id.
pub(crate) fn split_frame_id(can_id: u32, data: &[u8]) -> Result<(u32, u8, u8), RxError> {
    if data.len() > 8 {
        return Err(RxError::Dlc);
    }
    if can_id > MAX_STD_ID {
        return Err(RxError::NotStandardId);
    }
    Ok((
        (can_id >> 8) & 0x7,
        ((can_id >> 4) & 0xF) as u8,
        (can_id & 0xF) as u8,
    ))
}

/// Decode one classic standard frame as a Neuron receives it (direction Spinal -> Neuron),
/// with the reference codec's reason on failure. `data` is the payload (its length the DLC).
pub fn decode_spinal_to_neuron(can_id: u32, data: &[u8]) -> Result<NeuronCommand, RxError> {
    let (device, message, slave) = split_frame_id(can_id, data)?;
    let addressed = (1..=14).contains(&slave);
    match device {
        DEVICE_MOTOR if message <= 1 && slave == BROADCAST_ID => decode_pwm(message, data),
        DEVICE_IMU if message <= 2 && addressed => {
            // Only an IMU sample (Neuron -> Spinal) uses these ids.
            Err(if data.len() == 6 {
                RxError::Direction
            } else {
                RxError::Dlc
            })
        }
        DEVICE_SERVO if (message as usize) < MAX_SERVO_NUM && addressed => {
            let state = servo_state_error(data);
            match message {
                0 => decode_words(data)
                    .map(NeuronCommand::ServoTargetAngles)
                    .map_err(|e| RxError::most_telling(state, e)),
                1 => decode_words(data)
                    .map(NeuronCommand::ServoTargetCurrents)
                    .map_err(|e| RxError::most_telling(state, e)),
                _ => Err(state),
            }
        }
        DEVICE_INITIALIZER => decode_initializer(message, slave, data),
        _ => Err(RxError::UnknownId),
    }
}

fn decode_initializer(message: u8, slave: u8, data: &[u8]) -> Result<NeuronCommand, RxError> {
    if message == 0 {
        if slave == BROADCAST_ID {
            need_dlc(data, 0)?;
            return Ok(NeuronCommand::EnumRequest);
        }
        if slave == 0 {
            return Err(RxError::UnknownId);
        }
        // ENUM_RESPONSE is sent by a Neuron.
        return Err(if data.is_empty() {
            RxError::Direction
        } else {
            RxError::Dlc
        });
    }
    if !(1..=14).contains(&slave) {
        return Err(RxError::UnknownId);
    }
    match message {
        1 => {
            if data.is_empty() {
                return Ok(NeuronCommand::InitialConfigRequest);
            }
            // INITIAL_CONFIG_0 (DLC 5: servo_num 0..4, two 0/1 flags) is sent by a Neuron.
            if data.len() != 5 {
                return Err(RxError::Dlc);
            }
            let fields_ok = (byte_at(data, 0) as usize) <= MAX_SERVO_NUM
                && byte_at(data, 1) <= 1
                && byte_at(data, 2) <= 1;
            Err(if fields_ok {
                RxError::Dlc
            } else {
                RxError::Range
            })
        }
        2 => {
            let Some(&command) = data.first() else {
                return Err(RxError::Range);
            };
            if command > 12 {
                // Unknown sub-command: only INITIAL_CONFIG_1 could fit, its index is > 3.
                return Err(RxError::Range);
            }
            decode_board_config(data)
                .map(NeuronCommand::Board)
                .map_err(|e| RxError::most_telling(indexed_reply_error(data), e))
        }
        3 => {
            // INITIAL_CONFIG_2 is sent by a Neuron.
            if data.len() != 8 {
                Err(RxError::Dlc)
            } else if byte_at(data, 7) & !0b11 != 0 {
                Err(RxError::ReservedBits)
            } else if (byte_at(data, 0) as usize) >= MAX_SERVO_NUM {
                Err(RxError::Range)
            } else {
                Err(RxError::Direction)
            }
        }
        4 => Err(indexed_reply_error(data)),
        _ => Err(RxError::UnknownId),
    }
}

/// One classic CAN frame a Neuron transmits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CanFrame {
    /// 11-bit standard id.
    pub id: u16,
    /// Payload length (DLC), 0..8.
    pub len: u8,
    /// Payload; bytes past `len` are zero.
    pub data: [u8; 8],
}

impl CanFrame {
    /// The payload bytes.
    pub fn payload(&self) -> &[u8] {
        self.data.get(..self.len as usize).unwrap_or(&self.data)
    }

    fn new(device: u32, message: u32, slave: u8, payload: &[u8]) -> CanFrame {
        let mut data = [0u8; 8];
        let len = payload.len().min(8);
        for (d, p) in data.iter_mut().zip(payload.iter()) {
            *d = *p;
        }
        CanFrame {
            id: ((device << 8) | ((message & 0xF) << 4) | (slave as u32 & 0xF)) as u16,
            len: len as u8,
            data,
        }
    }
}

/// ENUM_RESPONSE (DLC 0).
pub fn enum_response(slave: u8) -> CanFrame {
    CanFrame::new(DEVICE_INITIALIZER, 0, slave, &[])
}

/// INITIAL_CONFIG_0: servo_num, imu flag, ttl/rs485 flag, pulley skip threshold (DLC 5).
pub fn initial_config_0(slave: u8, servo_num: u8, imu: bool, ttl: bool, pulley: u16) -> CanFrame {
    let p = pulley.to_le_bytes();
    CanFrame::new(
        DEVICE_INITIALIZER,
        1,
        slave,
        &[servo_num, imu as u8, ttl as u8, p[0], p[1]],
    )
}

/// INITIAL_CONFIG_1: index, Dynamixel id, P, I, D gains (DLC 8).
pub fn initial_config_1(slave: u8, index: u8, dxl_id: u8, gains: [u16; 3]) -> CanFrame {
    let [p, i, d] = gains.map(u16::to_le_bytes);
    CanFrame::new(
        DEVICE_INITIALIZER,
        2,
        slave,
        &[index, dxl_id, p[0], p[1], i[0], i[1], d[0], d[1]],
    )
}

/// INITIAL_CONFIG_2: index, present position, profile velocity, current limit, flags (DLC 8).
pub fn initial_config_2(
    slave: u8,
    index: u8,
    position: i16,
    profile_velocity: u16,
    current_limit: u16,
    flags: u8,
) -> CanFrame {
    let q = position.to_le_bytes();
    let v = profile_velocity.to_le_bytes();
    let c = current_limit.to_le_bytes();
    CanFrame::new(
        DEVICE_INITIALIZER,
        3,
        slave,
        &[index, q[0], q[1], v[0], v[1], c[0], c[1], flags],
    )
}

/// INITIAL_CONFIG_3: index, hardware error, goal current, joint / servo resolution (DLC 8).
pub fn initial_config_3(
    slave: u8,
    index: u8,
    hardware_error: u8,
    goal_current: i16,
    resolution: [i16; 2],
) -> CanFrame {
    let g = goal_current.to_le_bytes();
    let j = resolution[0].to_le_bytes();
    let s = resolution[1].to_le_bytes();
    CanFrame::new(
        DEVICE_INITIALIZER,
        4,
        slave,
        &[index, hardware_error, g[0], g[1], j[0], j[1], s[0], s[1]],
    )
}

/// Servo state: angle, temperature, status bits, current, error byte, padding (DLC 8).
pub fn servo_state(
    slave: u8,
    index: u8,
    angle: i16,
    temperature: u8,
    status: u8,
    current: i16,
    error: u8,
) -> CanFrame {
    let a = angle.to_le_bytes();
    let c = current.to_le_bytes();
    CanFrame::new(
        DEVICE_SERVO,
        index as u32,
        slave,
        &[a[0], a[1], temperature, status, c[0], c[1], error, 0],
    )
}

/// IMU sample: sensor 0 gyro, 1 acc, 2 mag; raw x, y, z (DLC 6).
pub fn imu_frame(slave: u8, sensor: u8, xyz: [i16; 3]) -> CanFrame {
    let [x, y, z] = xyz.map(i16::to_le_bytes);
    CanFrame::new(
        DEVICE_IMU,
        sensor as u32,
        slave,
        &[x[0], x[1], y[0], y[1], z[0], z[1]],
    )
}
