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
//!
//! Files: `records` (Spinal's records of the bus: Neurons, servos, IMU samples, events,
//! ordered counters), `commands` (the host's commands: duties, servo words, board configs),
//! `enumeration` (start-up: boot delay, ENUM_REQUEST, configs, IMU init, `uav_model`),
//! `cyclic` (the running 1 kHz transmit schedule and config re-requests), `receive`
//! (the Neuron->Spinal frames and the receive-error counters).

mod commands;
mod cyclic;
mod enumeration;
mod receive;
mod records;

pub use receive::RX_ERROR_NAMES;
pub use records::{Event, EventKind, ImuSlot, NeuronEntry, OrderedCounts, ServoEntry};

use super::neuron_frame::CanFrame;
use super::neuron_tx::{RxFrame, TxQueue};

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
    /// Servo goal reports (status bit 2) after the goal-sync handshake with torque on: a
    /// Neuron that reset (its servos back to power-on) or missed an acknowledgement.
    pub goal_resyncs: u64,
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
            goal_resyncs: 0,
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

    // ------------------------------------------------------------------ output
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
}
