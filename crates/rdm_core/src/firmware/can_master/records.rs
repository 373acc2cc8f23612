//! Spinal's records of the bus: each Neuron and its servos (INITIAL_CONFIG replies, the
//! commands sent, the last state), the raw IMU samples, log events, and the counters that
//! keep the order their keys were first counted.

use crate::firmware::neuron_frame::MAX_SERVO_NUM;

/// Counts by key, remembering the order keys were first counted (a Python `Counter`'s
/// insertion order, which the logs show).
#[derive(Debug, Clone, Copy)]
pub struct OrderedCounts<const N: usize> {
    counts: [u64; N],
    order: [u8; N],
    len: usize,
}

impl<const N: usize> OrderedCounts<N> {
    pub(super) fn new() -> Self {
        OrderedCounts {
            counts: [0; N],
            order: [0; N],
            len: 0,
        }
    }

    pub(super) fn add(&mut self, key: usize) {
        if let Some(c) = self.counts.get_mut(key) {
            if *c == 0 {
                if let Some(slot) = self.order.get_mut(self.len) {
                    *slot = key as u8;
                    self.len += 1;
                }
            }
            *c += 1;
        }
    }

    /// `(key, count)` in first-counted order.
    pub fn iter(&self) -> impl Iterator<Item = (usize, u64)> + '_ {
        self.order.iter().take(self.len).map(|&k| {
            (
                k as usize,
                self.counts.get(k as usize).copied().unwrap_or(0),
            )
        })
    }

    /// Count of `key`.
    pub fn get(&self, key: usize) -> u64 {
        self.counts.get(key).copied().unwrap_or(0)
    }
}

/// Spinal's record of one servo (INITIAL_CONFIG_1/2/3, command, last state).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServoEntry {
    /// Servo index on its Neuron.
    pub index: u8,
    /// INITIAL_CONFIG_1.
    pub dynamixel_id: u8,
    /// P, I, D gains.
    pub gains: [u16; 3],
    /// INITIAL_CONFIG_2.
    pub profile_velocity: u16,
    /// Current limit.
    pub current_limit: u16,
    /// Reports its state (not a gimbal servo).
    pub send_data_flag: bool,
    /// External encoder.
    pub external_encoder_flag: bool,
    /// INITIAL_CONFIG_3.
    pub hardware_error_status: u8,
    /// Joint resolution.
    pub joint_resolution: i16,
    /// Servo resolution.
    pub servo_resolution: i16,
    /// Goal position sent (15-bit).
    pub goal_position: i16,
    /// Bit 15 of the angle word: the Neuron's goal report was taken.
    pub goal_valid: bool,
    /// Torque enable.
    pub torque_enable: bool,
    /// Goal current sent (15-bit).
    pub goal_current: i16,
    /// Last reported angle.
    pub angle: i16,
    /// Last reported temperature.
    pub temperature: u8,
    /// Moving bit.
    pub moving: bool,
    /// Force-servo-off bit.
    pub force_servo_off: bool,
    /// Last reported current.
    pub current: i16,
    /// Last reported error byte.
    pub error: u8,
    /// ms of the last state report.
    pub stamp_ms: Option<i64>,
}

impl ServoEntry {
    pub(super) fn new(index: u8) -> ServoEntry {
        ServoEntry {
            index,
            ..ServoEntry::default()
        }
    }

    /// Spinal's "gimbal servo": one without send_data_flag.
    pub fn is_gimbal(&self) -> bool {
        !self.send_data_flag
    }
}

/// Spinal's record of one Neuron.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NeuronEntry {
    /// Slave id.
    pub slave: u8,
    /// INITIAL_CONFIG_0 fields.
    pub servo_num: u8,
    /// IMU frames enabled.
    pub imu_send_flag: bool,
    /// TTL / RS485 mixed.
    pub ttl_rs485_mixed: bool,
    /// Pulley skip threshold.
    pub pulley_skip_thresh: u16,
    /// INITIAL_CONFIG_0 received.
    pub configured: bool,
    /// Servo entries (first `servo_count` valid).
    pub servos: [ServoEntry; MAX_SERVO_NUM],
    /// Number of servo entries.
    pub servo_count: usize,
}

impl NeuronEntry {
    /// The valid servo entries.
    pub fn servos(&self) -> &[ServoEntry] {
        self.servos.get(..self.servo_count).unwrap_or(&[])
    }
}

/// A log event (the Python side formats the text of the reference).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventKind {
    /// "no Neuron answered ENUM_REQUEST: CAN master disabled" (error).
    Disabled,
    /// "Neuron {slave} sent no INITIAL_CONFIG_0" (warn).
    NotConfigured(u8),
    /// "{gimbals} gimbal servos on {motors} Neurons" (warn).
    GimbalMismatch(usize),
    /// "CAN: {motors} Neurons {slaves}, uav_model {model}" (info).
    Running,
    /// "CAN disconnected!!" (error).
    Disconnected,
}

/// One log event and the ms it happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Event {
    /// `HAL_GetTick()` of the event.
    pub stamp_ms: i64,
    /// What happened.
    pub kind: EventKind,
}

/// One Neuron's latest raw IMU samples (gyro, acc, mag) as received.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ImuSlot {
    /// Raw x, y, z per sensor.
    pub raw: [[i16; 3]; 3],
    /// Whether each sensor was received.
    pub have: [bool; 3],
    /// ms of the last sample.
    pub stamp_ms: i64,
    /// Order of the slave's first sample (dict insertion order of the reference).
    pub first: u32,
}
