//! Neuron CAN frame decoding, both directions: what a Neuron accepts from Spinal
//! (`rdm_core::firmware::neuron_frame::decode_spinal_to_neuron`) and what Spinal accepts
//! from a Neuron (`rdm_core::firmware::spinal_frame::decode_neuron_to_spinal`).
//!
//! Input: the CAN id as a little-endian u16 (ids above 0x7FF exercise the 11-bit check),
//! then the payload (any length: more than 8 bytes exercises the DLC check).
//!
//! Checks: an accepted frame has an 11-bit id and at most 8 bytes, and re-encodes to the
//! same id and payload (the codec is canonical; byte 7 of a servo state is padding, written
//! 0 and ignored on decode, so it is left out of the comparison). Spinal's frames are
//! rebuilt with the master's encoders (`spinal_frame::{pwm, servo_words, ...}`) and the
//! board-config sub-commands with the byte layout written out below (fact sheet sec. 2.4);
//! the Neurons' replies with the board's encoders (`neuron_frame::{servo_state, ...}`).

use rdm_core::firmware::neuron_frame::{
    decode_spinal_to_neuron, enum_response, imu_frame, initial_config_0, initial_config_1,
    initial_config_2, initial_config_3, servo_state, BoardConfig, CanFrame, NeuronCommand, RxError,
};
use rdm_core::firmware::spinal_frame::{
    decode_neuron_to_spinal, enum_request, initial_config_request, pwm, servo_words, NeuronReply,
};

/// The payload of a BOARD_CONFIG_REQUEST sub-command: command number, then its fields,
/// little-endian (SetBoardConfig.srv order).
fn board_payload(b: &BoardConfig) -> Vec<u8> {
    let mut out = Vec::with_capacity(8);
    match *b {
        BoardConfig::SetSlaveId { new_id } => out.extend([0, new_id]),
        BoardConfig::SetImuSendFlag { flag } => out.extend([1, u8::from(flag)]),
        BoardConfig::SetServoHomingOffset { index, offset } => {
            out.extend([2, index]);
            out.extend(offset.to_le_bytes());
        }
        BoardConfig::SetServoPidGain { index, p, i, d } => {
            out.extend([3, index]);
            for g in [p, i, d] {
                out.extend(g.to_le_bytes());
            }
        }
        BoardConfig::SetServoProfileVel {
            index,
            profile_velocity,
        } => {
            out.extend([4, index]);
            out.extend(profile_velocity.to_le_bytes());
        }
        BoardConfig::SetSendDataFlag { index, flag } => out.extend([5, index, u8::from(flag)]),
        BoardConfig::SetServoCurrentLimit {
            index,
            current_limit,
        } => {
            out.extend([6, index]);
            out.extend(current_limit.to_le_bytes());
        }
        BoardConfig::Reboot => out.push(7),
        BoardConfig::SetDynamixelTtlRs485Mixed { flag } => out.extend([8, u8::from(flag)]),
        BoardConfig::SetExternalEncoderFlag { index, flag } => {
            out.extend([9, index, u8::from(flag)])
        }
        BoardConfig::SetResolutionRatio {
            index,
            joint,
            servo,
        } => {
            out.extend([10, index]);
            out.extend(joint.to_le_bytes());
            out.extend(servo.to_le_bytes());
        }
        BoardConfig::SetServoRoundOffset { index, offset } => {
            out.extend([11, index]);
            out.extend(offset.to_le_bytes());
        }
        BoardConfig::SetServoPulleySkipThresh { thresh } => {
            out.push(12);
            out.extend(thresh.to_le_bytes());
        }
    }
    out
}

fn same(what: &str, can_id: u32, data: &[u8], frame: &CanFrame, ignore_byte_7: bool) {
    let mut got = frame.payload().to_vec();
    let mut want = data.to_vec();
    if ignore_byte_7 && got.len() == 8 && want.len() == 8 {
        got[7] = 0;
        want[7] = 0;
    }
    assert!(
        u32::from(frame.id) == can_id && got == want,
        "not canonical: {what} id 0x{can_id:03X} {data:02X?} re-encodes as 0x{:03X} {:02X?}",
        frame.id,
        frame.payload()
    );
}

fn check_command(can_id: u32, data: &[u8], cmd: &NeuronCommand) {
    let slave = (can_id & 0xF) as u8;
    let frame = match cmd {
        NeuronCommand::Pwm {
            frame_index,
            values,
        } => pwm(*frame_index, values),
        NeuronCommand::EnumRequest => enum_request(),
        NeuronCommand::InitialConfigRequest => initial_config_request(slave),
        NeuronCommand::ServoTargetAngles(w) | NeuronCommand::ServoTargetCurrents(w) => {
            assert!(
                (1..=4).contains(&w.count) && w.count * 2 == data.len(),
                "bad frame accepted: {} servo words from {} bytes",
                w.count,
                data.len()
            );
            let current = matches!(cmd, NeuronCommand::ServoTargetCurrents(_));
            servo_words(current, slave, &w.values[..w.count], &w.flags[..w.count])
        }
        NeuronCommand::Board(b) => {
            let payload = board_payload(b);
            let mut d = [0u8; 8];
            d[..payload.len()].copy_from_slice(&payload);
            CanFrame {
                id: (0x700 | 0x20 | u16::from(slave)),
                len: payload.len() as u8,
                data: d,
            }
        }
    };
    same("command", can_id, data, &frame, false);
}

fn check_reply(can_id: u32, data: &[u8], reply: &NeuronReply) {
    let frame = match *reply {
        NeuronReply::EnumResponse { slave } => enum_response(slave),
        NeuronReply::InitialConfig0 {
            slave,
            servo_num,
            imu_send_flag,
            ttl_rs485_mixed,
            pulley_skip_thresh,
        } => initial_config_0(
            slave,
            servo_num,
            imu_send_flag,
            ttl_rs485_mixed,
            pulley_skip_thresh,
        ),
        NeuronReply::InitialConfig1 {
            slave,
            index,
            dynamixel_id,
            gains,
        } => initial_config_1(slave, index, dynamixel_id, gains),
        NeuronReply::InitialConfig2 {
            slave,
            index,
            present_position,
            profile_velocity,
            current_limit,
            send_data_flag,
            external_encoder_flag,
        } => initial_config_2(
            slave,
            index,
            present_position,
            profile_velocity,
            current_limit,
            u8::from(send_data_flag) | u8::from(external_encoder_flag) << 1,
        ),
        NeuronReply::InitialConfig3 {
            slave,
            index,
            hardware_error_status,
            goal_current,
            joint_resolution,
            servo_resolution,
        } => initial_config_3(
            slave,
            index,
            hardware_error_status,
            goal_current,
            [joint_resolution, servo_resolution],
        ),
        NeuronReply::ServoState {
            slave,
            index,
            angle,
            temperature,
            force_servo_off,
            moving,
            goal_reported,
            current,
            servo_error,
        } => servo_state(
            slave,
            index,
            angle,
            temperature,
            u8::from(force_servo_off) | u8::from(moving) << 1 | u8::from(goal_reported) << 2,
            current,
            servo_error,
        ),
        NeuronReply::Imu { slave, sensor, xyz } => imu_frame(slave, sensor, xyz),
    };
    let servo = matches!(reply, NeuronReply::ServoState { .. });
    same("reply", can_id, data, &frame, servo);
}

/// The rejection both decoders must give before looking at the id's fields.
fn framing_error(can_id: u32, data: &[u8]) -> Option<RxError> {
    if data.len() > 8 {
        Some(RxError::Dlc)
    } else if can_id > 0x7FF {
        Some(RxError::NotStandardId)
    } else {
        None
    }
}

/// Decode `data` (see the module doc) in both directions; panics on a broken rule.
pub fn check(data: &[u8]) {
    let [lo, hi, payload @ ..] = data else {
        return;
    };
    let can_id = u32::from(u16::from_le_bytes([*lo, *hi]));
    let framing = framing_error(can_id, payload);
    match decode_spinal_to_neuron(can_id, payload) {
        Ok(cmd) => {
            assert!(
                framing.is_none(),
                "bad frame accepted: {framing:?} frame as {cmd:?}"
            );
            check_command(can_id, payload, &cmd);
        }
        Err(e) => {
            if let Some(f) = framing {
                assert_eq!(
                    e,
                    f,
                    "wrong rejection: id 0x{can_id:X}, {} bytes",
                    payload.len()
                );
            }
        }
    }
    match decode_neuron_to_spinal(can_id, payload) {
        Ok(reply) => {
            assert!(
                framing.is_none(),
                "bad frame accepted: {framing:?} frame as {reply:?}"
            );
            check_reply(can_id, payload, &reply);
        }
        Err(e) => {
            if let Some(f) = framing {
                assert_eq!(
                    e,
                    f,
                    "wrong rejection: id 0x{can_id:X}, {} bytes",
                    payload.len()
                );
            }
        }
    }
}
