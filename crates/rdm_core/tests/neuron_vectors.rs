//! The Neuron frame codec of the Rust bank against the golden vectors of
//! `firmware_protocol/neuron/vectors.json` (built from the fact sheet with struct formulas,
//! independent of this code): every Spinal -> Neuron vector decodes to its fields, every
//! Neuron -> Spinal vector is rejected for its direction, and the encoders reproduce the
//! Neuron -> Spinal payloads byte for byte.

use rdm_core::firmware::neuron_frame::{
    decode_spinal_to_neuron, enum_response, imu_frame, initial_config_0, initial_config_1,
    initial_config_2, initial_config_3, servo_state, BoardConfig, CanFrame, NeuronCommand, RxError,
    FRAME_KINDS,
};
use serde_json::Value;

mod neuron_vectors_common;
use neuron_vectors_common::{data_of, id_of, int, vectors};

fn check_s2n(v: &Value, cmd: NeuronCommand) {
    let kind = v["kind"].as_str().expect("kind");
    assert_eq!(FRAME_KINDS[cmd.kind()], kind, "{}", v["name"]);
    match cmd {
        NeuronCommand::Pwm {
            frame_index,
            values,
        } => {
            assert_eq!(frame_index as i64, int(v, "frame_index"));
            let want: Vec<i64> = v["fields"]["values"]
                .as_array()
                .expect("values")
                .iter()
                .map(|x| x.as_i64().expect("int"))
                .collect();
            assert_eq!(values.iter().map(|&x| x as i64).collect::<Vec<_>>(), want);
        }
        NeuronCommand::ServoTargetAngles(w) | NeuronCommand::ServoTargetCurrents(w) => {
            let values: Vec<i64> = v["fields"]["values"]
                .as_array()
                .expect("values")
                .iter()
                .map(|x| x.as_i64().expect("int"))
                .collect();
            let flags: Vec<bool> = v["fields"]["flags"]
                .as_array()
                .expect("flags")
                .iter()
                .map(|x| x.as_bool().expect("bool"))
                .collect();
            assert_eq!(w.count, values.len());
            assert_eq!(
                w.values[..w.count]
                    .iter()
                    .map(|&x| x as i64)
                    .collect::<Vec<_>>(),
                values
            );
            assert_eq!(w.flags[..w.count].to_vec(), flags);
        }
        NeuronCommand::Board(b) => match b {
            BoardConfig::SetSlaveId { new_id } => assert_eq!(new_id as i64, int(v, "new_id")),
            BoardConfig::SetImuSendFlag { flag }
            | BoardConfig::SetDynamixelTtlRs485Mixed { flag } => {
                assert_eq!(flag as i64, int(v, "flag"))
            }
            BoardConfig::SetServoHomingOffset { index, offset }
            | BoardConfig::SetServoRoundOffset { index, offset } => {
                assert_eq!(
                    (index as i64, offset as i64),
                    (int(v, "index"), int(v, "offset"))
                )
            }
            BoardConfig::SetServoPidGain { index, p, i, d } => assert_eq!(
                [index as i64, p as i64, i as i64, d as i64],
                [
                    int(v, "index"),
                    int(v, "p_gain"),
                    int(v, "i_gain"),
                    int(v, "d_gain")
                ]
            ),
            BoardConfig::SetServoProfileVel {
                index,
                profile_velocity,
            } => assert_eq!(
                (index as i64, profile_velocity as i64),
                (int(v, "index"), int(v, "profile_velocity"))
            ),
            BoardConfig::SetSendDataFlag { index, flag }
            | BoardConfig::SetExternalEncoderFlag { index, flag } => {
                assert_eq!(
                    (index as i64, flag as i64),
                    (int(v, "index"), int(v, "flag"))
                )
            }
            BoardConfig::SetServoCurrentLimit {
                index,
                current_limit,
            } => assert_eq!(
                (index as i64, current_limit as i64),
                (int(v, "index"), int(v, "current_limit"))
            ),
            BoardConfig::SetResolutionRatio {
                index,
                joint,
                servo,
            } => assert_eq!(
                [index as i64, joint as i64, servo as i64],
                [
                    int(v, "index"),
                    int(v, "joint_resolution"),
                    int(v, "servo_resolution")
                ]
            ),
            BoardConfig::SetServoPulleySkipThresh { thresh } => {
                assert_eq!(thresh as i64, int(v, "thresh"))
            }
            BoardConfig::Reboot => {}
        },
        NeuronCommand::EnumRequest | NeuronCommand::InitialConfigRequest => {}
    }
}

/// The encoder of a Neuron -> Spinal vector from its fields.
fn encode_n2s(v: &Value) -> CanFrame {
    let s = int(v, "slave") as u8;
    let i = |k: &str| int(v, k);
    match v["kind"].as_str().expect("kind") {
        "enum_response" => enum_response(s),
        "initial_config_0" => initial_config_0(
            s,
            i("servo_num") as u8,
            i("imu_send_flag") != 0,
            i("ttl_rs485_mixed") != 0,
            i("pulley_skip_thresh") as u16,
        ),
        "initial_config_1" => initial_config_1(
            s,
            i("index") as u8,
            i("dynamixel_id") as u8,
            [i("p_gain") as u16, i("i_gain") as u16, i("d_gain") as u16],
        ),
        "initial_config_2" => initial_config_2(
            s,
            i("index") as u8,
            i("present_position") as i16,
            i("profile_velocity") as u16,
            i("current_limit") as u16,
            (i("send_data_flag") | i("external_encoder_flag") << 1) as u8,
        ),
        "initial_config_3" => initial_config_3(
            s,
            i("index") as u8,
            i("hardware_error_status") as u8,
            i("goal_current") as i16,
            [i("joint_resolution") as i16, i("servo_resolution") as i16],
        ),
        "servo_state" => servo_state(
            s,
            i("index") as u8,
            i("angle") as i16,
            i("temperature") as u8,
            (i("force_servo_off") | i("moving") << 1 | i("goal_reported") << 2) as u8,
            i("current") as i16,
            i("servo_error") as u8,
        ),
        "imu" => {
            let sensor = match v["fields"]["sensor"].as_str() {
                Some("gyro") => 0,
                Some("acc") => 1,
                Some("mag") => 2,
                _ => i("sensor") as u8,
            };
            imu_frame(s, sensor, [i("x") as i16, i("y") as i16, i("z") as i16])
        }
        other => panic!("no encoder for {other}"),
    }
}

#[test]
fn golden_vectors_decode_and_encode() {
    let all = vectors();
    let (mut s2n, mut n2s) = (0, 0);
    for v in &all {
        let id = id_of(v);
        let data = data_of(v);
        match v["direction"].as_str().expect("direction") {
            "spinal_to_neuron" => {
                let cmd = decode_spinal_to_neuron(id, &data)
                    .unwrap_or_else(|e| panic!("{}: {e:?}", v["name"]));
                check_s2n(v, cmd);
                s2n += 1;
            }
            _ => {
                // Ids shared with a Spinal -> Neuron frame (servo words on messages 0/1,
                // board config on CONFIG_1) may read as that frame, or fail its DLC first
                // (a DLC error ranks before a direction error); the rest are refused.
                // INITIAL_CONFIG_0 shares its id with the DLC-0 request: the reference
                // reports the request's DLC mismatch before the direction.
                let shared = matches!(id >> 4, 0x20 | 0x21 | 0x72);
                let config0 = id >> 4 == 0x71;
                let got = decode_spinal_to_neuron(id, &data);
                assert!(
                    got == Err(RxError::Direction)
                        || (shared && got.is_ok())
                        || ((config0 || shared) && got == Err(RxError::Dlc)),
                    "{}: {got:?}",
                    v["name"]
                );
                let f = encode_n2s(v);
                assert_eq!(f.id as u32, id, "{}", v["name"]);
                assert_eq!(f.payload(), &data[..], "{}", v["name"]);
                n2s += 1;
            }
        }
    }
    assert!(s2n >= 15 && n2s >= 9, "{s2n} / {n2s} vectors");
}

#[test]
fn malformed_frames_give_the_reference_reasons() {
    // One example per reason (expected reasons from the fact sheet's layouts).
    let cases: [(u32, &[u8], RxError); 10] = [
        (0x201, &[0, 0, 0], RxError::Dlc), // odd number of servo bytes
        (0x00F, &[0, 0, 0, 0x80, 0, 0, 0, 0], RxError::ReservedBits), // PWM bit 31
        (0x00F, &[0xE9, 0x03, 0, 0, 0, 0, 0, 0], RxError::Range), // 1001 > 1000
        (0x00E, &[0; 8], RxError::UnknownId), // PWM id not broadcast
        (0x501, &[], RxError::UnknownId),  // device 5
        (0x721, &[], RxError::Range),      // board config without command
        (0x721, &[0, 15], RxError::Range), // SET_SLAVE_ID 15
        (0x721, &[0, 1, 2], RxError::Dlc), // SET_SLAVE_ID with 3 bytes
        (0x721, &[3, 9, 0, 0, 0, 0, 0, 0], RxError::Range), // PID of servo 9
        (0x1234, &[], RxError::NotStandardId),
    ];
    for (id, data, want) in cases {
        assert_eq!(
            decode_spinal_to_neuron(id, data),
            Err(want),
            "id 0x{id:X} {data:?}"
        );
    }
}
