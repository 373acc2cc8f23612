//! Spinal's CAN-master role (fact sheet sec. 2.5-2.7), frame for frame as the Python
//! reference `rdm.nodes.can_master.CanMaster` (which stays the reference).
//!
//! Time is `HAL_GetTick()` in whole milliseconds. Start-up: wait `boot_delay_ms`, broadcast
//! ENUM_REQUEST and collect responses for 200 ms, then per Neuron (slave-id order) an
//! INITIAL_CONFIG_REQUEST and 200 ms, then 100 ms of IMU init per Neuron, then infer the
//! `uav_model`. Running, at the start of each ms: even ms the PWM broadcast, odd ms servo
//! target angles then currents to one Neuron, round-robin. A board config is sent alone and
//! pauses transmission for 2000 ms; after REBOOT the Neuron's config is requested again
//! 5000 ms later. Everything lives in fixed-size storage: a tick allocates nothing.

use super::neuron_frame::{CanFrame, RxError, MAX_SERVO_NUM};
use super::neuron_tx::{RxFrame, TxQueue, FLAG_ERROR, FLAG_EXTENDED, FLAG_FD, FLAG_REMOTE};
use super::spinal_frame::{
    decode_neuron_to_spinal, enum_request, initial_config_request, pwm, servo_words, NeuronReply,
    REPLY_KINDS,
};

/// Default power-on wait before ENUM_REQUEST.
pub const BOOT_DELAY_MS: i64 = 5000;
/// ENUM_RESPONSE collection time.
pub const ENUM_WAIT_MS: i64 = 200;
/// Wait after each INITIAL_CONFIG_REQUEST.
pub const CONFIG_WAIT_MS: i64 = 200;
/// IMU init time per Neuron (no CAN traffic).
pub const IMU_INIT_MS: i64 = 100;
/// No frame for longer than this: disconnected.
pub const DISCONNECT_MS: i64 = 100;
/// At most one "CAN disconnected!!" per this interval.
pub const DISCONNECT_LOG_INTERVAL_MS: i64 = 1000;
/// `CAN_TX_PAUSE_TIME` after a board-config request.
pub const TX_PAUSE_MS: i64 = 2000;
/// After REBOOT the config is requested again after this long.
pub const REBOOT_REQUEST_MS: i64 = 5000;
/// A late tick replays at most this many missed milliseconds.
pub const MAX_CATCH_UP_MS: i64 = 10;
/// Most Neurons on one bus (slave ids 1..14).
pub const MAX_NEURONS: usize = 14;
/// The PWM broadcast carries at most this many motors.
pub const PWM_MAX_MOTORS: usize = 12;
/// Board configs waiting to be sent (fixed queue).
pub const BOARD_QUEUE: usize = 64;
/// Log events kept until taken (further ones are counted in `events_dropped`).
pub const EVENT_QUEUE: usize = 256;
/// Frames one tick can send (10 replayed ms x 2 frames + re-requests, with margin).
pub const TX_CAPACITY: usize = 256;
/// `uav_model` codes (sec. 2.7).
pub const HYDRUS: u8 = 16;
/// Hydrus XI: one gimbal servo per motor.
pub const HYDRUS_XI: u8 = 17;
/// Dragon: two gimbal servos per motor.
pub const DRAGON: u8 = 32;
/// Servo word value range (15-bit signed).
pub const WORD_VALUE_MIN: i32 = -(1 << 14);
/// Servo word value range (15-bit signed).
pub const WORD_VALUE_MAX: i32 = (1 << 14) - 1;

/// Master phase.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MasterState {
    /// Waiting for the boot delay.
    Booting,
    /// ENUM_REQUEST sent, collecting responses.
    Enumerating,
    /// Requesting configs / IMU init.
    Configuring,
    /// The 1 kHz schedule.
    Running,
    /// No Neuron answered.
    Disabled,
}

/// Why the master refused a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MasterError {
    /// `set_motor_duties` got this many duties for `motor_number`.
    DutyCount(usize),
    /// Duty `k` is not finite in 0.5..1.0.
    Duty(usize),
    /// No servo `index` on Neuron `slave`.
    NoServo(u8, u8),
    /// A servo word outside the 15-bit range.
    WordValue,
    /// The board-config queue is full.
    BoardQueueFull,
    /// A board-config frame that is not one (DLC > 8 or id > 0x7FF).
    BadFrame,
}

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

/// Counts by key, remembering the order keys were first counted (a Python `Counter`'s
/// insertion order, which the logs show).
#[derive(Debug, Clone, Copy)]
pub struct OrderedCounts<const N: usize> {
    counts: [u64; N],
    order: [u8; N],
    len: usize,
}

impl<const N: usize> OrderedCounts<N> {
    fn new() -> Self {
        OrderedCounts {
            counts: [0; N],
            order: [0; N],
            len: 0,
        }
    }

    fn add(&mut self, key: usize) {
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
    fn new(index: u8) -> ServoEntry {
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

#[derive(Debug, Clone, Copy, Default)]
struct BoardRequest {
    frame: CanFrame,
    reboot_slave: Option<u8>,
}

/// Spinal's side of the Neuron bus.
#[derive(Debug, Clone)]
pub struct CanMaster {
    /// Current phase.
    pub state: MasterState,
    /// Boot delay (ms).
    pub boot_delay_ms: i64,
    neurons: [NeuronEntry; MAX_NEURONS],
    neuron_count: usize,
    enumerated: [bool; 16],
    /// Motor count (= Neuron count once running).
    pub motor_number: usize,
    /// Inferred model, if consistent.
    pub uav_model: Option<u8>,
    /// Frames received.
    pub rx_count: u64,
    /// Receive errors by reason ([`RX_ERROR_NAMES`]).
    pub rx_errors: OrderedCounts<11>,
    /// Accepted replies by kind ([`REPLY_KINDS`]).
    pub rx_kinds: OrderedCounts<7>,
    imu: [ImuSlot; 16],
    imu_seen: u32,
    pwm_values: [u16; PWM_MAX_MOTORS],
    // Deadlines in i128: `t + wait` never overflows (the reference's ints are unbounded).
    phase_end: i128,
    config_cursor: usize,
    round_robin: usize,
    last_ms: Option<i64>,
    last_rx_ms: i64,
    last_disconnect_log: Option<i64>,
    tx_pause_until: Option<i128>,
    board: [BoardRequest; BOARD_QUEUE],
    board_head: usize,
    board_len: usize,
    rerequest: [Option<(i128, u64)>; 16],
    rerequest_seq: u64,
    events: [Option<Event>; EVENT_QUEUE],
    event_len: usize,
    /// Events lost because the queue was full.
    pub events_dropped: u64,
    tx: TxQueue,
}

impl CanMaster {
    /// A master that starts at `start_ms` and waits `boot_delay_ms` before enumerating.
    pub fn new(boot_delay_ms: i64, start_ms: i64) -> CanMaster {
        CanMaster {
            state: MasterState::Booting,
            boot_delay_ms,
            neurons: [NeuronEntry::default(); MAX_NEURONS],
            neuron_count: 0,
            enumerated: [false; 16],
            motor_number: 0,
            uav_model: None,
            rx_count: 0,
            rx_errors: OrderedCounts::new(),
            rx_kinds: OrderedCounts::new(),
            imu: [ImuSlot::default(); 16],
            imu_seen: 0,
            pwm_values: [0; PWM_MAX_MOTORS],
            phase_end: start_ms as i128 + boot_delay_ms as i128,
            config_cursor: 0,
            round_robin: 0,
            last_ms: None,
            last_rx_ms: start_ms,
            last_disconnect_log: None,
            tx_pause_until: None,
            board: [BoardRequest::default(); BOARD_QUEUE],
            board_head: 0,
            board_len: 0,
            rerequest: [None; 16],
            rerequest_seq: 0,
            events: [None; EVENT_QUEUE],
            event_len: 0,
            events_dropped: 0,
            tx: TxQueue::with_capacity(TX_CAPACITY),
        }
    }

    // ------------------------------------------------------------------ tick
    /// One 1 kHz core-task tick at `now_ms`: receive `frames` (in bus order), then run the
    /// schedule (replaying at most [`MAX_CATCH_UP_MS`] skipped ms; older or repeated times
    /// only receive). Returns the frames to send, in order.
    pub fn tick_ms(&mut self, now_ms: i64, frames: &[RxFrame]) -> &[super::neuron_tx::TxEntry] {
        self.tx.clear();
        for f in frames {
            self.receive(f, now_ms);
        }
        match self.last_ms {
            None => {
                self.step(now_ms);
                self.last_ms = Some(now_ms);
            }
            Some(last) if last.checked_add(1) == Some(now_ms) => {
                self.step(now_ms);
                self.last_ms = Some(now_ms);
            }
            Some(last) if now_ms > last => {
                let first = last
                    .saturating_add(1)
                    .max(now_ms.saturating_sub(MAX_CATCH_UP_MS - 1));
                for t in first..=now_ms {
                    self.step(t);
                }
                self.last_ms = Some(now_ms);
            }
            Some(_) => {}
        }
        self.tx.frames()
    }

    // ------------------------------------------------------------------ commands
    /// Duties (0.5 stop .. 1.0) of motors `0..motor_number`, sent as `(duty*2000 - 1000)`
    /// truncated (the firmware's cast).
    pub fn set_motor_duties(&mut self, duties: &[f64]) -> Result<(), MasterError> {
        if duties.len() != self.motor_number {
            return Err(MasterError::DutyCount(duties.len()));
        }
        if let Some(k) = duties
            .iter()
            .position(|d| !d.is_finite() || !(0.5..=1.0).contains(d))
        {
            return Err(MasterError::Duty(k));
        }
        for (slot, d) in self.pwm_values.iter_mut().zip(duties) {
            *slot = (*d * 2000.0 - 1000.0) as u16;
        }
        Ok(())
    }

    fn servo_mut(&mut self, slave: u8, index: u8) -> Result<&mut ServoEntry, MasterError> {
        let count = self.neuron_count;
        self.neurons
            .iter_mut()
            .take(count)
            .find(|n| n.slave == slave)
            .and_then(|n| {
                let c = n.servo_count;
                n.servos
                    .get_mut(..c)
                    .and_then(|s| s.get_mut(index as usize))
            })
            .ok_or(MasterError::NoServo(slave, index))
    }

    /// The entry of servo `index` on Neuron `slave`.
    pub fn servo(&self, slave: u8, index: u8) -> Result<&ServoEntry, MasterError> {
        self.neurons()
            .iter()
            .find(|n| n.slave == slave)
            .and_then(|n| n.servos().get(index as usize))
            .ok_or(MasterError::NoServo(slave, index))
    }

    fn word(value: i32) -> Result<i16, MasterError> {
        if (WORD_VALUE_MIN..=WORD_VALUE_MAX).contains(&value) {
            Ok(value as i16)
        } else {
            Err(MasterError::WordValue)
        }
    }

    /// Goal position (15-bit) of one servo.
    pub fn set_servo_target(
        &mut self,
        slave: u8,
        index: u8,
        value: i32,
    ) -> Result<(), MasterError> {
        let v = Self::word(value)?;
        self.servo_mut(slave, index)?.goal_position = v;
        Ok(())
    }

    /// Torque enable; refused while the Neuron reports force-off; off invalidates the goal.
    pub fn set_servo_torque(
        &mut self,
        slave: u8,
        index: u8,
        enable: bool,
    ) -> Result<(), MasterError> {
        let e = self.servo_mut(slave, index)?;
        if e.force_servo_off {
            return Ok(());
        }
        e.torque_enable = enable;
        if !enable {
            e.goal_valid = false;
        }
        Ok(())
    }

    /// Goal current (15-bit) of one servo.
    pub fn set_servo_current(
        &mut self,
        slave: u8,
        index: u8,
        value: i32,
    ) -> Result<(), MasterError> {
        let v = Self::word(value)?;
        self.servo_mut(slave, index)?.goal_current = v;
        Ok(())
    }

    /// Queue one BOARD_CONFIG_REQUEST (`reboot_slave`: the REBOOT sub-command's target).
    pub fn configure_board(
        &mut self,
        can_id: u32,
        payload: &[u8],
        reboot_slave: Option<u8>,
    ) -> Result<(), MasterError> {
        if payload.len() > 8 || can_id > super::neuron_frame::MAX_STD_ID {
            return Err(MasterError::BadFrame);
        }
        if self.board_len >= BOARD_QUEUE {
            return Err(MasterError::BoardQueueFull);
        }
        let mut data = [0u8; 8];
        for (d, p) in data.iter_mut().zip(payload) {
            *d = *p;
        }
        let at = (self.board_head + self.board_len) % BOARD_QUEUE;
        if let Some(slot) = self.board.get_mut(at) {
            *slot = BoardRequest {
                frame: CanFrame {
                    id: can_id as u16,
                    len: payload.len() as u8,
                    data,
                },
                reboot_slave,
            };
            self.board_len += 1;
        }
        Ok(())
    }

    // ------------------------------------------------------------------ views
    /// Neurons in slave-id order (empty until enumeration ends).
    pub fn neurons(&self) -> &[NeuronEntry] {
        self.neurons.get(..self.neuron_count).unwrap_or(&[])
    }

    /// True when a frame arrived within [`DISCONNECT_MS`] of the last tick.
    pub fn connected(&self) -> bool {
        matches!(self.last_ms, Some(last) if last.saturating_sub(self.last_rx_ms) <= DISCONNECT_MS)
    }

    /// IMU slot of `slave` if any sample arrived.
    pub fn imu(&self, slave: u8) -> Option<&ImuSlot> {
        self.imu
            .get(slave as usize)
            .filter(|s| s.have.iter().any(|h| *h))
    }

    /// The PWM slot values the next broadcast carries.
    pub fn pwm_values(&self) -> &[u16] {
        self.pwm_values
            .get(..self.motor_number.min(PWM_MAX_MOTORS))
            .unwrap_or(&[])
    }

    /// Events not yet taken, oldest first.
    pub fn events(&self) -> impl Iterator<Item = &Event> {
        self.events.iter().take(self.event_len).flatten()
    }

    /// Forget the events taken.
    pub fn clear_events(&mut self) {
        self.event_len = 0;
    }

    // ------------------------------------------------------------------ schedule
    fn send(&mut self, frame: CanFrame) {
        // Capacity covers a full catch-up; a frame beyond it would be lost (never reached).
        let _ = self.tx.push(0, frame);
    }

    fn log(&mut self, t: i64, kind: EventKind) {
        match self.events.get_mut(self.event_len) {
            Some(slot) => {
                *slot = Some(Event { stamp_ms: t, kind });
                self.event_len += 1;
            }
            None => self.events_dropped += 1,
        }
    }

    fn step(&mut self, t: i64) {
        match self.state {
            MasterState::Booting => {
                if t as i128 >= self.phase_end {
                    self.state = MasterState::Enumerating;
                    self.send(enum_request());
                    self.phase_end = t as i128 + ENUM_WAIT_MS as i128;
                }
            }
            MasterState::Enumerating => {
                if t as i128 >= self.phase_end {
                    self.end_enumeration(t);
                }
            }
            MasterState::Configuring => {
                if t as i128 >= self.phase_end {
                    self.next_config(t);
                }
            }
            MasterState::Running => self.run(t),
            MasterState::Disabled => {}
        }
    }

    fn end_enumeration(&mut self, t: i64) {
        let mut n = 0;
        for (slave, seen) in self.enumerated.iter().enumerate() {
            if *seen {
                if let Some(entry) = self.neurons.get_mut(n) {
                    *entry = NeuronEntry {
                        slave: slave as u8,
                        ..NeuronEntry::default()
                    };
                    n += 1;
                }
            }
        }
        self.neuron_count = n;
        let Some(first) = self.neurons().first().map(|e| e.slave) else {
            self.state = MasterState::Disabled;
            self.log(t, EventKind::Disabled);
            return;
        };
        self.state = MasterState::Configuring;
        self.config_cursor = 0;
        self.send(initial_config_request(first));
        self.phase_end = t as i128 + CONFIG_WAIT_MS as i128;
    }

    fn next_config(&mut self, t: i64) {
        self.config_cursor += 1;
        let n = self.neuron_count;
        if self.config_cursor < n {
            if let Some(slave) = self.neurons().get(self.config_cursor).map(|e| e.slave) {
                self.send(initial_config_request(slave));
            }
            self.phase_end = t as i128 + CONFIG_WAIT_MS as i128;
        } else if self.config_cursor < 2 * n {
            self.phase_end = t as i128 + IMU_INIT_MS as i128;
        } else {
            self.start_running(t);
        }
    }

    fn start_running(&mut self, t: i64) {
        for k in 0..self.neuron_count {
            if let Some(e) = self.neurons.get(k).copied() {
                if !e.configured {
                    self.log(t, EventKind::NotConfigured(e.slave));
                }
            }
        }
        self.motor_number = self.neuron_count;
        self.pwm_values = [0; PWM_MAX_MOTORS]; // IDLE_DUTY 0.5 -> value 0
        let gimbals: usize = self
            .neurons()
            .iter()
            .map(|n| n.servos().iter().filter(|s| s.is_gimbal()).count())
            .sum();
        self.uav_model = if gimbals == 0 {
            Some(HYDRUS)
        } else if gimbals == self.motor_number {
            Some(HYDRUS_XI)
        } else if gimbals == 2 * self.motor_number {
            Some(DRAGON)
        } else {
            None
        };
        if self.uav_model.is_none() {
            self.log(t, EventKind::GimbalMismatch(gimbals));
        }
        self.state = MasterState::Running;
        self.last_rx_ms = self.last_rx_ms.max(t);
        self.log(t, EventKind::Running);
    }

    fn run(&mut self, t: i64) {
        if t.saturating_sub(self.last_rx_ms) > DISCONNECT_MS {
            let due = match self.last_disconnect_log {
                None => true,
                Some(last) => t.saturating_sub(last) >= DISCONNECT_LOG_INTERVAL_MS,
            };
            if due {
                self.last_disconnect_log = Some(t);
                self.log(t, EventKind::Disconnected);
            }
        }
        self.send_rerequests(t);
        if let Some(until) = self.tx_pause_until {
            if (t as i128) < until {
                return;
            }
            self.tx_pause_until = None;
        }
        if self.board_len > 0 {
            let request = self.board.get(self.board_head).copied().unwrap_or_default();
            self.board_head = (self.board_head + 1) % BOARD_QUEUE;
            self.board_len -= 1;
            self.send(request.frame);
            self.tx_pause_until = Some(t as i128 + TX_PAUSE_MS as i128);
            if let Some(slave) = request.reboot_slave {
                self.schedule_rerequest(slave, t as i128 + REBOOT_REQUEST_MS as i128);
            }
            return;
        }
        if t.rem_euclid(2) == 0 {
            let n = self.motor_number.min(PWM_MAX_MOTORS);
            let mut slots = [0u16; 6];
            for (s, v) in slots.iter_mut().zip(self.pwm_values.iter().take(n)) {
                *s = *v;
            }
            self.send(pwm(0, &slots));
            if n > 6 {
                let mut slots = [0u16; 6];
                for (s, v) in slots.iter_mut().zip(self.pwm_values.iter().take(n).skip(6)) {
                    *s = *v;
                }
                self.send(pwm(1, &slots));
            }
            return;
        }
        let count = self.neuron_count.max(1);
        let Some(neuron) = self.neurons.get(self.round_robin % count).copied() else {
            return;
        };
        self.round_robin = (self.round_robin + 1) % count;
        let servos = neuron.servos();
        if servos.is_empty() {
            return; // a DLC-0 servo frame is not a valid frame of this protocol
        }
        let mut values = [0i16; MAX_SERVO_NUM];
        let mut flags = [false; MAX_SERVO_NUM];
        for (k, s) in servos.iter().enumerate() {
            if let (Some(v), Some(f)) = (values.get_mut(k), flags.get_mut(k)) {
                *v = s.goal_position;
                *f = s.goal_valid;
            }
        }
        let n = servos.len();
        let (v, f) = (
            values.get(..n).unwrap_or(&[]),
            flags.get(..n).unwrap_or(&[]),
        );
        self.send(servo_words(false, neuron.slave, v, f));
        for (k, s) in servos.iter().enumerate() {
            if let (Some(v), Some(f)) = (values.get_mut(k), flags.get_mut(k)) {
                *v = s.goal_current;
                *f = s.torque_enable && !s.force_servo_off;
            }
        }
        let (v, f) = (
            values.get(..n).unwrap_or(&[]),
            flags.get(..n).unwrap_or(&[]),
        );
        self.send(servo_words(true, neuron.slave, v, f));
    }

    fn schedule_rerequest(&mut self, slave: u8, when: i128) {
        // The reference's dict: re-assigning a key keeps its place, a new key goes last.
        let seq = self.rerequest_seq;
        if let Some(slot) = self.rerequest.get_mut(slave as usize) {
            match slot {
                Some((w, _)) => *w = when,
                None => {
                    *slot = Some((when, seq));
                    self.rerequest_seq += 1;
                }
            }
        }
    }

    fn send_rerequests(&mut self, t: i64) {
        // Due re-requests in insertion order (at most 16 entries).
        loop {
            let mut best: Option<(usize, u64)> = None;
            for (slave, slot) in self.rerequest.iter().enumerate() {
                if let Some((when, seq)) = slot {
                    if t as i128 >= *when && best.is_none_or(|(_, s)| *seq < s) {
                        best = Some((slave, *seq));
                    }
                }
            }
            let Some((slave, _)) = best else { break };
            if let Some(slot) = self.rerequest.get_mut(slave) {
                *slot = None;
            }
            self.send(initial_config_request(slave as u8));
        }
    }

    // ------------------------------------------------------------------ receive
    fn receive(&mut self, f: &RxFrame, now_ms: i64) {
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

    /// Slaves with IMU samples, in order of their first sample.
    pub fn imu_slaves(&self, out: &mut [u8; 16]) -> usize {
        let mut n = 0;
        for order in 0..self.imu_seen {
            for (slave, slot) in self.imu.iter().enumerate() {
                if slot.have.iter().any(|h| *h) && slot.first == order {
                    if let Some(o) = out.get_mut(n) {
                        *o = slave as u8;
                        n += 1;
                    }
                }
            }
        }
        n
    }

    /// Frame counts: `(rx_count, errors total)`.
    pub fn rx_error_total(&self) -> u64 {
        self.rx_errors.iter().map(|(_, c)| c).sum()
    }
}

fn clamp_word(v: i16) -> i16 {
    (v as i32).clamp(WORD_VALUE_MIN, WORD_VALUE_MAX) as i16
}

/// The reply kind names (re-exported for bindings).
pub fn reply_kind_name(k: usize) -> &'static str {
    REPLY_KINDS.get(k).copied().unwrap_or("?")
}
