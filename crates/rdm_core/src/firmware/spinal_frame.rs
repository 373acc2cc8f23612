//! The Neuron link as Spinal sees it: Neuron -> Spinal frames decoded with the reference
//! codec's error reasons (`rdm.protocol.neuron.decode_frame` with direction Neuron->Spinal),
//! and the Spinal -> Neuron frames the CAN master sends (`jsk-wire-protocols.md`, Neuron
//! section). StdId = device << 8 | message << 4 | slave; multi-byte fields little-endian.

use super::neuron_frame::{
    decode_board_config, split_frame_id, CanFrame, RxError, BROADCAST_ID, DEVICE_IMU,
    DEVICE_INITIALIZER, DEVICE_MOTOR, DEVICE_SERVO, MAX_SERVO_NUM, MAX_STD_ID,
};

/// Names of the accepted reply kinds (the reference frame classes' `KIND`), counter order.
pub const REPLY_KINDS: [&str; 7] = [
    "enum_response",
    "initial_config_0",
    "initial_config_1",
    "initial_config_2",
    "initial_config_3",
    "servo_state",
    "imu",
];

/// A valid Neuron -> Spinal frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NeuronReply {
    /// ENUM_RESPONSE of a Neuron.
    EnumResponse { slave: u8 },
    /// INITIAL_CONFIG_0: servo count, IMU flag, TTL/RS485 flag, pulley skip threshold.
    InitialConfig0 {
        slave: u8,
        servo_num: u8,
        imu_send_flag: bool,
        ttl_rs485_mixed: bool,
        pulley_skip_thresh: u16,
    },
    /// INITIAL_CONFIG_1: Dynamixel id and PID gains of one servo.
    InitialConfig1 {
        slave: u8,
        index: u8,
        dynamixel_id: u8,
        gains: [u16; 3],
    },
    /// INITIAL_CONFIG_2: present position, profile velocity, current limit, flags.
    InitialConfig2 {
        slave: u8,
        index: u8,
        present_position: i16,
        profile_velocity: u16,
        current_limit: u16,
        send_data_flag: bool,
        external_encoder_flag: bool,
    },
    /// INITIAL_CONFIG_3: hardware error, goal current, joint / servo resolution.
    InitialConfig3 {
        slave: u8,
        index: u8,
        hardware_error_status: u8,
        goal_current: i16,
        joint_resolution: i16,
        servo_resolution: i16,
    },
    /// A servo state report (message id = servo index).
    ServoState {
        slave: u8,
        index: u8,
        angle: i16,
        temperature: u8,
        force_servo_off: bool,
        moving: bool,
        goal_reported: bool,
        current: i16,
        servo_error: u8,
    },
    /// An IMU sample: sensor 0 gyro, 1 acc, 2 mag; raw x, y, z.
    Imu {
        slave: u8,
        sensor: u8,
        xyz: [i16; 3],
    },
}

impl NeuronReply {
    /// Kind counter index (see [`REPLY_KINDS`]).
    pub fn kind(&self) -> usize {
        match self {
            NeuronReply::EnumResponse { .. } => 0,
            NeuronReply::InitialConfig0 { .. } => 1,
            NeuronReply::InitialConfig1 { .. } => 2,
            NeuronReply::InitialConfig2 { .. } => 3,
            NeuronReply::InitialConfig3 { .. } => 4,
            NeuronReply::ServoState { .. } => 5,
            NeuronReply::Imu { .. } => 6,
        }
    }
}

fn byte(data: &[u8], at: usize) -> u8 {
    data.get(at).copied().unwrap_or(0)
}

fn u16_at(data: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([byte(data, at), byte(data, at + 1)])
}

fn i16_at(data: &[u8], at: usize) -> i16 {
    u16_at(data, at) as i16
}

fn is_neuron(slave: u8) -> bool {
    (1..=14).contains(&slave)
}

/// Largest PWM slot value Spinal sends (pulse 2000 us).
const PWM_VALUE_MAX: u64 = 1000;

/// Why a MOTOR broadcast (a Spinal frame) is no reply: its own error, else its direction.
fn pwm_error(data: &[u8]) -> RxError {
    if data.len() != 8 {
        return RxError::Dlc;
    }
    let mut b = [0u8; 8];
    for (d, s) in b.iter_mut().zip(data) {
        *d = *s;
    }
    let word = u64::from_le_bytes(b);
    if word & ((0b11 << 30) | (0b11 << 62)) != 0 {
        return RxError::ReservedBits;
    }
    let over =
        (0..6).any(|slot| (word >> (10 * (slot % 3) + 32 * (slot / 3))) & 0x3FF > PWM_VALUE_MAX);
    if over {
        RxError::Range
    } else {
        RxError::Direction
    }
}

/// Decode one classic standard frame as Spinal receives it (direction Neuron -> Spinal),
/// with the reference codec's reason on failure (candidates ranked "field error < DLC <
/// direction"). `data` is the payload (its length the DLC).
pub fn decode_neuron_to_spinal(can_id: u32, data: &[u8]) -> Result<NeuronReply, RxError> {
    let (device, message, slave) = split_frame_id(can_id, data)?;
    match device {
        DEVICE_MOTOR if message <= 1 && slave == BROADCAST_ID => Err(pwm_error(data)),
        DEVICE_IMU if message <= 2 && is_neuron(slave) => {
            if data.len() != 6 {
                return Err(RxError::Dlc);
            }
            Ok(NeuronReply::Imu {
                slave,
                sensor: message,
                xyz: [i16_at(data, 0), i16_at(data, 2), i16_at(data, 4)],
            })
        }
        DEVICE_SERVO if (message as usize) < MAX_SERVO_NUM && is_neuron(slave) => {
            // The only Neuron->Spinal reading of a servo id; the target words sharing ids 0
            // and 1 only lose to it (their direction, or the same DLC complaint).
            if data.len() != 8 {
                return Err(RxError::Dlc);
            }
            let status = byte(data, 3);
            if status & !0b111 != 0 {
                return Err(RxError::ReservedBits);
            }
            Ok(NeuronReply::ServoState {
                slave,
                index: message,
                angle: i16_at(data, 0),
                temperature: byte(data, 2),
                force_servo_off: status & 1 != 0,
                moving: status & 2 != 0,
                goal_reported: status & 4 != 0,
                current: i16_at(data, 4),
                servo_error: byte(data, 6),
            })
        }
        DEVICE_INITIALIZER => decode_initializer(message, slave, data),
        _ => Err(RxError::UnknownId),
    }
}

fn decode_initializer(message: u8, slave: u8, data: &[u8]) -> Result<NeuronReply, RxError> {
    if message == 0 && slave == BROADCAST_ID {
        // ENUM_REQUEST: sent by Spinal.
        return Err(if data.is_empty() {
            RxError::Direction
        } else {
            RxError::Dlc
        });
    }
    if !is_neuron(slave) {
        return Err(RxError::UnknownId);
    }
    let index = byte(data, 0);
    let index_ok = (index as usize) < MAX_SERVO_NUM;
    match message {
        0 => {
            if data.is_empty() {
                Ok(NeuronReply::EnumResponse { slave })
            } else {
                Err(RxError::Dlc)
            }
        }
        1 => {
            // INITIAL_CONFIG_REQUEST (DLC 0, Spinal's) or INITIAL_CONFIG_0 (DLC 5).
            if data.len() != 5 {
                return Err(RxError::Dlc);
            }
            let (servo_num, imu, ttl) = (byte(data, 0), byte(data, 1), byte(data, 2));
            if servo_num as usize > MAX_SERVO_NUM || imu > 1 || ttl > 1 {
                return Err(RxError::Range);
            }
            Ok(NeuronReply::InitialConfig0 {
                slave,
                servo_num,
                imu_send_flag: imu == 1,
                ttl_rs485_mixed: ttl == 1,
                pulley_skip_thresh: u16_at(data, 3),
            })
        }
        2 => {
            // INITIAL_CONFIG_1 (DLC 8) or a BOARD_CONFIG_REQUEST (Spinal's).
            let Some(&command) = data.first() else {
                return Err(RxError::Range);
            };
            if command > 12 {
                return Err(RxError::Range);
            }
            if data.len() == 8 {
                if !index_ok {
                    return Err(RxError::Range);
                }
                return Ok(NeuronReply::InitialConfig1 {
                    slave,
                    index,
                    dynamixel_id: byte(data, 1),
                    gains: [u16_at(data, 2), u16_at(data, 4), u16_at(data, 6)],
                });
            }
            // INITIAL_CONFIG_1's DLC complaint unless the board-config reading has a field error.
            match decode_board_config(data) {
                Err(RxError::Range) => Err(RxError::Range),
                _ => Err(RxError::Dlc),
            }
        }
        3 => {
            if data.len() != 8 {
                return Err(RxError::Dlc);
            }
            let flags = byte(data, 7);
            if flags & !0b11 != 0 {
                return Err(RxError::ReservedBits);
            }
            if !index_ok {
                return Err(RxError::Range);
            }
            Ok(NeuronReply::InitialConfig2 {
                slave,
                index,
                present_position: i16_at(data, 1),
                profile_velocity: u16_at(data, 3),
                current_limit: u16_at(data, 5),
                send_data_flag: flags & 1 != 0,
                external_encoder_flag: flags & 2 != 0,
            })
        }
        4 => {
            if data.len() != 8 {
                return Err(RxError::Dlc);
            }
            if !index_ok {
                return Err(RxError::Range);
            }
            Ok(NeuronReply::InitialConfig3 {
                slave,
                index,
                hardware_error_status: byte(data, 1),
                goal_current: i16_at(data, 2),
                joint_resolution: i16_at(data, 4),
                servo_resolution: i16_at(data, 6),
            })
        }
        _ => Err(RxError::UnknownId),
    }
}

fn frame(id: u32, payload: &[u8]) -> CanFrame {
    let mut data = [0u8; 8];
    for (d, p) in data.iter_mut().zip(payload) {
        *d = *p;
    }
    CanFrame {
        id: (id & MAX_STD_ID) as u16,
        len: payload.len().min(8) as u8,
        data,
    }
}

/// ENUM_REQUEST (broadcast, DLC 0).
pub fn enum_request() -> CanFrame {
    frame((DEVICE_INITIALIZER << 8) | BROADCAST_ID as u32, &[])
}

/// INITIAL_CONFIG_REQUEST to one Neuron (DLC 0).
pub fn initial_config_request(slave: u8) -> CanFrame {
    frame(
        (DEVICE_INITIALIZER << 8) | (1 << 4) | (slave as u32 & 0xF),
        &[],
    )
}

/// MOTOR broadcast `frame_index` (0: slots of slaves 1..6, 1: 7..12): six 10-bit values
/// packed LSB-first at bit `10*(k%3) + 32*(k/3)`. A value above 1000 (pulse 2000 us, the
/// largest Spinal sends) is clamped to 1000, never masked into the 10-bit field (masking
/// turns 3360 into 288: a much shorter pulse than asked).
pub fn pwm(frame_index: u8, values: &[u16; 6]) -> CanFrame {
    let mut word = 0u64;
    for (slot, v) in values.iter().enumerate() {
        let value = u64::from(*v).min(PWM_VALUE_MAX);
        word |= value << (10 * (slot % 3) + 32 * (slot / 3));
    }
    frame(
        (frame_index as u32 & 1) << 4 | BROADCAST_ID as u32,
        &word.to_le_bytes(),
    )
}

/// Servo target words (`current` false: goal angles + goal-ack flags, message 0; true: goal
/// currents + torque-enable flags, message 1): `flag << 15 | value & 0x7FFF` per servo.
pub fn servo_words(current: bool, slave: u8, values: &[i16], flags: &[bool]) -> CanFrame {
    let mut data = [0u8; 8];
    let mut len = 0usize;
    for ((chunk, v), f) in data.chunks_exact_mut(2).zip(values).zip(flags) {
        let word = ((*f as u16) << 15) | (*v as u16 & 0x7FFF);
        chunk.copy_from_slice(&word.to_le_bytes());
        len += 2;
    }
    let message = if current { 1 } else { 0 };
    frame(
        (DEVICE_SERVO << 8) | (message << 4) | (slave as u32 & 0xF),
        data.get(..len).unwrap_or(&[]),
    )
}
