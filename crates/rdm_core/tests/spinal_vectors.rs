//! Spinal's side of the Neuron codec against the golden vectors of
//! `firmware_protocol/neuron/vectors.json` (built from the fact sheet, independent of this
//! code): every Neuron -> Spinal vector decodes to its fields, every Spinal -> Neuron vector
//! is refused (direction, or the reply's DLC / field complaint that ranks first), and the
//! master's encoders reproduce the Spinal -> Neuron payloads byte for byte.

use rdm_core::firmware::neuron_frame::RxError;
use rdm_core::firmware::spinal_frame::{
    decode_neuron_to_spinal, enum_request, initial_config_request, pwm, servo_words, NeuronReply,
    REPLY_KINDS,
};
use serde_json::Value;

mod neuron_vectors_common;
use neuron_vectors_common::{data_of, id_of, int, vectors};

fn ints(v: &Value, key: &str) -> Vec<i64> {
    v["fields"][key]
        .as_array()
        .expect("array")
        .iter()
        .map(|x| {
            x.as_i64()
                .or_else(|| x.as_bool().map(i64::from))
                .expect("int")
        })
        .collect()
}

fn check_reply(v: &Value, r: NeuronReply) {
    assert_eq!(REPLY_KINDS[r.kind()], v["kind"].as_str().expect("kind"));
    let got: Vec<(&str, i64)> = match r {
        NeuronReply::EnumResponse { slave } => vec![("slave", slave as i64)],
        NeuronReply::InitialConfig0 {
            slave,
            servo_num,
            imu_send_flag,
            ttl_rs485_mixed,
            pulley_skip_thresh,
        } => vec![
            ("slave", slave as i64),
            ("servo_num", servo_num as i64),
            ("imu_send_flag", imu_send_flag as i64),
            ("ttl_rs485_mixed", ttl_rs485_mixed as i64),
            ("pulley_skip_thresh", pulley_skip_thresh as i64),
        ],
        NeuronReply::InitialConfig1 {
            slave,
            index,
            dynamixel_id,
            gains,
        } => vec![
            ("slave", slave as i64),
            ("index", index as i64),
            ("dynamixel_id", dynamixel_id as i64),
            ("p_gain", gains[0] as i64),
            ("i_gain", gains[1] as i64),
            ("d_gain", gains[2] as i64),
        ],
        NeuronReply::InitialConfig2 {
            slave,
            index,
            present_position,
            profile_velocity,
            current_limit,
            send_data_flag,
            external_encoder_flag,
        } => vec![
            ("slave", slave as i64),
            ("index", index as i64),
            ("present_position", present_position as i64),
            ("profile_velocity", profile_velocity as i64),
            ("current_limit", current_limit as i64),
            ("send_data_flag", send_data_flag as i64),
            ("external_encoder_flag", external_encoder_flag as i64),
        ],
        NeuronReply::InitialConfig3 {
            slave,
            index,
            hardware_error_status,
            goal_current,
            joint_resolution,
            servo_resolution,
        } => vec![
            ("slave", slave as i64),
            ("index", index as i64),
            ("hardware_error_status", hardware_error_status as i64),
            ("goal_current", goal_current as i64),
            ("joint_resolution", joint_resolution as i64),
            ("servo_resolution", servo_resolution as i64),
        ],
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
        } => vec![
            ("slave", slave as i64),
            ("index", index as i64),
            ("angle", angle as i64),
            ("temperature", temperature as i64),
            ("force_servo_off", force_servo_off as i64),
            ("moving", moving as i64),
            ("goal_reported", goal_reported as i64),
            ("current", current as i64),
            ("servo_error", servo_error as i64),
        ],
        NeuronReply::Imu { slave, sensor, xyz } => {
            let name = ["gyro", "acc", "mag"][sensor as usize];
            assert_eq!(v["fields"]["sensor"].as_str(), Some(name));
            vec![
                ("slave", slave as i64),
                ("x", xyz[0] as i64),
                ("y", xyz[1] as i64),
                ("z", xyz[2] as i64),
            ]
        }
    };
    for (key, value) in got {
        assert_eq!(value, int(v, key), "{}: {key}", v["name"]);
    }
}

#[test]
fn golden_vectors_decode_and_encode() {
    let (mut n2s, mut s2n) = (0, 0);
    for v in &vectors() {
        let (id, data) = (id_of(v), data_of(v));
        if v["direction"] == "neuron_to_spinal" {
            let r = decode_neuron_to_spinal(id, &data)
                .unwrap_or_else(|e| panic!("{}: {e:?}", v["name"]));
            check_reply(v, r);
            n2s += 1;
            continue;
        }
        // Refused: a direction error, or a reply reading's DLC / field complaint that the
        // reference ranks before it (servo ids, CONFIG_0 / CONFIG_1 ids). A DLC-8 board
        // config whose sub-command byte is 0..3 also reads as INITIAL_CONFIG_1 (shared id).
        let kind = v["kind"].as_str().expect("kind");
        let got = decode_neuron_to_spinal(id, &data);
        let shared = kind.starts_with("board_config") && data.len() == 8 && data[0] < 4;
        assert!(
            matches!(
                got,
                Err(RxError::Direction | RxError::Dlc | RxError::Range | RxError::ReservedBits)
            ) || (shared && matches!(got, Ok(NeuronReply::InitialConfig1 { .. }))),
            "{}: {got:?}",
            v["name"]
        );
        let encoded = match kind {
            "pwm" => {
                let values: Vec<u16> = ints(v, "values").iter().map(|&x| x as u16).collect();
                let mut six = [0u16; 6];
                six.copy_from_slice(&values);
                Some(pwm(int(v, "frame_index") as u8, &six))
            }
            "servo_target_angle" | "servo_target_current" => {
                let values: Vec<i16> = ints(v, "values").iter().map(|&x| x as i16).collect();
                let flags: Vec<bool> = ints(v, "flags").iter().map(|&x| x != 0).collect();
                let current = kind == "servo_target_current";
                Some(servo_words(current, int(v, "slave") as u8, &values, &flags))
            }
            "enum_request" => Some(enum_request()),
            "initial_config_request" => Some(initial_config_request(int(v, "slave") as u8)),
            _ => None,
        };
        if let Some(f) = encoded {
            assert_eq!((f.id as u32, f.payload()), (id, &data[..]), "{}", v["name"]);
        }
        s2n += 1;
    }
    assert!(n2s >= 9 && s2n >= 15, "{n2s} / {s2n} vectors");
}

#[test]
fn malformed_replies_give_the_reference_reasons() {
    let cases: [(u32, &[u8], RxError); 12] = [
        (0x223, &[0; 7], RxError::Dlc),
        (0x223, &[0, 0, 0, 8, 0, 0, 0, 0], RxError::ReservedBits),
        (0x240, &[0; 8], RxError::UnknownId),
        (0x200, &[0; 8], RxError::UnknownId), // slave 0
        (0x105, &[0; 5], RxError::Dlc),
        (0x135, &[0; 6], RxError::UnknownId), // sensor 3
        (0x714, &[5, 0, 0, 0, 0], RxError::Range),
        (0x714, &[], RxError::Dlc), // the request's reading: DLC before direction
        (0x724, &[4, 0, 0, 0, 0, 0, 0, 0], RxError::Range),
        (0x734, &[0, 0, 0, 0, 0, 0, 0, 4], RxError::ReservedBits),
        (0x70F, &[], RxError::Direction),
        (0x800, &[], RxError::NotStandardId),
    ];
    for (id, data, want) in cases {
        assert_eq!(
            decode_neuron_to_spinal(id, data),
            Err(want),
            "0x{id:03X} {data:?}"
        );
    }
}
