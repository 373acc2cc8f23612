//! The Neuron->Spinal frames: each is counted, decoded (or counted as a receive error by
//! reason) and stored in Spinal's records.

use super::{CanMaster, MasterState, ServoEntry, WORD_VALUE_MAX, WORD_VALUE_MIN};
use crate::firmware::neuron_frame::{RxError, MAX_SERVO_NUM};
use crate::firmware::neuron_tx::{RxFrame, FLAG_ERROR, FLAG_EXTENDED, FLAG_FD, FLAG_REMOTE};
use crate::firmware::spinal_frame::{decode_neuron_to_spinal, NeuronReply};

/// Receive-error counter reasons (the reference's `rx_errors` keys), counter order.
pub const RX_ERROR_NAMES: [&str; 11] = [
    "error_frame",
    "remote",
    "not_standard_id",
    "fd",
    "dlc",
    "unknown_id",
    "range",
    "reserved_bits",
    "direction",
    "unknown_slave",
    "servo_index",
];
const UNKNOWN_SLAVE: usize = 9;
const SERVO_INDEX: usize = 10;

fn reason_index(e: RxError) -> usize {
    match e {
        RxError::ErrorFrame => 0,
        RxError::Remote => 1,
        RxError::NotStandardId => 2,
        RxError::Fd => 3,
        RxError::Dlc => 4,
        RxError::UnknownId => 5,
        RxError::Range => 6,
        RxError::ReservedBits => 7,
        RxError::Direction => 8,
        RxError::ServoIndex => SERVO_INDEX,
        // Not produced by the Neuron->Spinal decoder.
        RxError::ServoCount => 6,
    }
}

impl CanMaster {
    // ------------------------------------------------------------------ receive
    pub(super) fn receive(&mut self, f: &RxFrame, now_ms: i64) {
        self.rx_count += 1;
        self.last_rx_ms = now_ms;
        let reason = if f.flags & FLAG_ERROR != 0 {
            Some(RxError::ErrorFrame)
        } else if f.flags & FLAG_REMOTE != 0 {
            Some(RxError::Remote)
        } else if f.flags & FLAG_EXTENDED != 0 {
            Some(RxError::NotStandardId)
        } else if f.flags & FLAG_FD != 0 {
            Some(RxError::Fd)
        } else {
            None
        };
        if let Some(r) = reason {
            self.rx_errors.add(reason_index(r));
            return;
        }
        let decoded = if f.len > 8 {
            Err(RxError::Dlc)
        } else {
            decode_neuron_to_spinal(f.id, f.kept())
        };
        let reply = match decoded {
            Ok(r) => r,
            Err(e) => {
                self.rx_errors.add(reason_index(e));
                return;
            }
        };
        self.rx_kinds.add(reply.kind());
        if let NeuronReply::EnumResponse { slave } = reply {
            if self.state == MasterState::Enumerating {
                if let Some(seen) = self.enumerated.get_mut(slave as usize) {
                    *seen = true;
                }
            }
            return;
        }
        let slave = match reply {
            NeuronReply::InitialConfig0 { slave, .. }
            | NeuronReply::InitialConfig1 { slave, .. }
            | NeuronReply::InitialConfig2 { slave, .. }
            | NeuronReply::InitialConfig3 { slave, .. }
            | NeuronReply::ServoState { slave, .. }
            | NeuronReply::Imu { slave, .. }
            | NeuronReply::EnumResponse { slave } => slave,
        };
        let count = self.neuron_count;
        let Some(k) = self
            .neurons
            .iter()
            .take(count)
            .position(|n| n.slave == slave)
        else {
            self.rx_errors.add(UNKNOWN_SLAVE);
            return;
        };
        if let NeuronReply::Imu { sensor, xyz, .. } = reply {
            self.store_imu(slave, sensor, xyz, now_ms);
            return;
        }
        let Some(neuron) = self.neurons.get_mut(k) else {
            return;
        };
        if let NeuronReply::InitialConfig0 {
            servo_num,
            imu_send_flag,
            ttl_rs485_mixed,
            pulley_skip_thresh,
            ..
        } = reply
        {
            neuron.servo_num = servo_num;
            neuron.imu_send_flag = imu_send_flag;
            neuron.ttl_rs485_mixed = ttl_rs485_mixed;
            neuron.pulley_skip_thresh = pulley_skip_thresh;
            neuron.configured = true;
            // Existing entries are kept by index, new ones start blank, extra ones go.
            let n = (servo_num as usize).min(MAX_SERVO_NUM);
            for i in neuron.servo_count..n {
                if let Some(s) = neuron.servos.get_mut(i) {
                    *s = ServoEntry::new(i as u8);
                }
            }
            neuron.servo_count = n;
            return;
        }
        let index = match reply {
            NeuronReply::InitialConfig1 { index, .. }
            | NeuronReply::InitialConfig2 { index, .. }
            | NeuronReply::InitialConfig3 { index, .. }
            | NeuronReply::ServoState { index, .. } => index as usize,
            _ => usize::MAX,
        };
        let count = neuron.servo_count;
        let Some(entry) = neuron
            .servos
            .get_mut(..count)
            .and_then(|s| s.get_mut(index))
        else {
            self.rx_errors.add(SERVO_INDEX);
            return;
        };
        match reply {
            NeuronReply::ServoState {
                angle,
                temperature,
                force_servo_off,
                moving,
                goal_reported,
                current,
                servo_error,
                ..
            } => {
                entry.temperature = temperature;
                entry.moving = moving;
                entry.force_servo_off = force_servo_off;
                entry.current = current;
                entry.error = servo_error;
                entry.stamp_ms = Some(now_ms);
                if force_servo_off {
                    entry.torque_enable = false;
                    entry.goal_valid = false;
                }
                if goal_reported && entry.goal_valid && entry.torque_enable {
                    // A goal report after the handshake, torque still on: the Neuron lost
                    // its servo state (a reset) or missed the acknowledgement.
                    self.goal_resyncs += 1;
                }
                if goal_reported {
                    // Handshake step 2: take the Neuron's goal, acknowledge it with bit 15.
                    entry.goal_position = clamp_word(angle);
                    entry.goal_valid = true;
                } else {
                    entry.angle = angle;
                }
            }
            NeuronReply::InitialConfig1 {
                dynamixel_id,
                gains,
                ..
            } => {
                entry.dynamixel_id = dynamixel_id;
                entry.gains = gains;
            }
            NeuronReply::InitialConfig2 {
                present_position,
                profile_velocity,
                current_limit,
                send_data_flag,
                external_encoder_flag,
                ..
            } => {
                entry.angle = present_position;
                entry.goal_position = clamp_word(present_position);
                entry.profile_velocity = profile_velocity;
                entry.current_limit = current_limit;
                entry.send_data_flag = send_data_flag;
                entry.external_encoder_flag = external_encoder_flag;
            }
            NeuronReply::InitialConfig3 {
                hardware_error_status,
                joint_resolution,
                servo_resolution,
                ..
            } => {
                entry.hardware_error_status = hardware_error_status;
                entry.joint_resolution = joint_resolution;
                entry.servo_resolution = servo_resolution;
            }
            _ => {}
        }
    }

    fn store_imu(&mut self, slave: u8, sensor: u8, xyz: [i16; 3], now_ms: i64) {
        let seen = self.imu_seen;
        if let Some(slot) = self.imu.get_mut(slave as usize) {
            if !slot.have.iter().any(|h| *h) {
                slot.first = seen;
                self.imu_seen += 1;
            }
            if let (Some(raw), Some(have)) = (
                slot.raw.get_mut(sensor as usize),
                slot.have.get_mut(sensor as usize),
            ) {
                *raw = xyz;
                *have = true;
            }
            slot.stamp_ms = now_ms;
        }
    }
}

fn clamp_word(v: i16) -> i16 {
    (v as i32).clamp(WORD_VALUE_MIN, WORD_VALUE_MAX) as i16
}
