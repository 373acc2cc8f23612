//! The Spinal mirror's clock, IMU sample and battery state
//! (`rdm.nodes.spinal_mirror.SpinalMirror`): the tick's millisecond and time, the last CAN
//! millisecond, the next control time, the IMU sample the control steps and the `imu`
//! publication use, the battery task (raw reading, ADC scale, low-passed voltage, next
//! sample ms) and the earliest ms a publisher is due.
//!
//! The mirror's Python tick and the lockstep kernel's fast part (`rdm._rdm.LockstepKernel`)
//! both read and change this one state (docs/spinal.md "State").

use crate::estimate::ImuSample;

/// HAL ms between two battery samples (the firmware's battery task).
pub const BATTERY_SAMPLE_MS: i64 = 20;
/// The battery low-pass per sample: `v = 0.99 v + 0.01 sample`.
pub const BATTERY_FILTER: f64 = 0.99;
/// A ms before any tick: the first tick samples the battery.
pub const NEVER_MS: i64 = -(1 << 62);
/// Slack of the control-time comparison (s): a step is due at `now >= next - 1e-9`.
pub const CONTROL_SLACK_S: f64 = 1e-9;

/// The clock, IMU sample and battery state of one Spinal mirror.
#[derive(Clone, Debug, PartialEq)]
pub struct SpinalState {
    /// The ms of the last tick (None: no tick yet).
    pub now_ms: Option<i64>,
    /// The latest tick time (s); 0 before any tick.
    pub now_s: f64,
    /// The last ms the CAN master ran (None: not yet).
    pub can_ms: Option<i64>,
    /// When the next control step is due (s; None: at the first tick).
    pub next_control: Option<f64>,
    /// The first ms the battery task samples again.
    pub battery_due_ms: i64,
    /// The raw battery reading (V) before the ADC scale.
    pub battery_input: f64,
    /// The ADC scale (`set_adc_scale`).
    pub adc_scale: f64,
    /// The low-passed voltage the firmware uses (None: no sample yet).
    pub battery_voltage: Option<f64>,
    /// The IMU sample (body frame): gyro rad/s, acc m/s^2, mag uT.
    pub imu: ImuSample,
    /// The earliest ms a periodic publisher can be due.
    pub next_pub_ms: i64,
}

impl SpinalState {
    /// The state before the first tick, with the raw battery reading `battery_input` (V),
    /// an ADC scale of 1 and the IMU sample `imu`.
    pub fn new(battery_input: f64, imu: ImuSample) -> Self {
        SpinalState {
            now_ms: None,
            now_s: 0.0,
            can_ms: None,
            next_control: None,
            battery_due_ms: NEVER_MS,
            battery_input,
            adc_scale: 1.0,
            battery_voltage: None,
            imu,
            next_pub_ms: NEVER_MS,
        }
    }

    /// The ms of a time `now` (s, finite): `floor(now * 1000 + 1e-6)` (`rdm.nodes.base.to_ms`).
    pub fn ms_of(now: f64) -> i64 {
        (now * 1000.0 + 1e-6).floor() as i64
    }

    /// The tick's clock at `now` (s, finite) without changing anything: its ms
    /// (`floor(now * 1000 + 1e-6)`, never before the last tick's) and the latest time.
    pub fn clock_at(&self, now: f64) -> (i64, f64) {
        let mut ms = Self::ms_of(now);
        if let Some(last) = self.now_ms {
            ms = ms.max(last); // time never goes back
        }
        (ms, if now > self.now_s { now } else { self.now_s })
    }

    /// The tick's clock at `now` (`clock_at`) taken: returns its ms. Calling it again with
    /// the same `now` changes nothing.
    pub fn tick_begin(&mut self, now: f64) -> i64 {
        let (ms, now_s) = self.clock_at(now);
        self.now_ms = Some(ms);
        self.now_s = now_s;
        ms
    }

    /// Whether a control step is due at the latest tick time.
    pub fn control_due(&self) -> bool {
        self.next_control
            .is_none_or(|t| self.now_s >= t - CONTROL_SLACK_S)
    }

    /// The low-passed voltage a battery sample now would give; None: the sample
    /// (`battery_input * adc_scale`) is not finite.
    pub fn battery_next(&self) -> Option<f64> {
        let sample = self.battery_input * self.adc_scale;
        if !sample.is_finite() {
            return None;
        }
        Some(match self.battery_voltage {
            None => sample,
            Some(v) => BATTERY_FILTER * v + (1.0 - BATTERY_FILTER) * sample,
        })
    }

    /// The battery task at `now_ms`: the next sample is due `BATTERY_SAMPLE_MS` later, the
    /// low-passed voltage takes the sample. False: the sample is not finite (rejected; the
    /// voltage is kept).
    pub fn battery_sample(&mut self, now_ms: i64) -> bool {
        self.battery_due_ms = now_ms.saturating_add(BATTERY_SAMPLE_MS);
        match self.battery_next() {
            Some(v) => {
                self.battery_voltage = Some(v);
                true
            }
            None => false,
        }
    }

    /// The voltage a control step uses: the low-passed one, else the raw reading.
    pub fn step_voltage(&self) -> f64 {
        self.battery_voltage.unwrap_or(self.battery_input)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LEVEL: ImuSample = ImuSample {
        gyro: [0.0; 3],
        acc: [0.0, 0.0, 9.80665],
        mag: [30.0, 0.0, -40.0],
    };

    #[test]
    fn tick_begin_floors_and_never_goes_back() {
        let mut s = SpinalState::new(25.2, LEVEL);
        // Python: math.floor(0.0029989 * 1000 + 1e-6) == 2; the 1e-6 slack takes
        // 0.0029999995 to 3.
        assert_eq!(s.tick_begin(0.0029989), 2);
        assert_eq!(s.tick_begin(0.0029999995), 3);
        assert_eq!(s.tick_begin(0.003), 3);
        assert_eq!(s.tick_begin(0.001), 3);
        assert_eq!(s.now_s, 0.003);
        assert_eq!(s.now_ms, Some(3));
    }

    #[test]
    fn battery_low_pass_and_rejection() {
        let mut s = SpinalState::new(24.0, LEVEL);
        assert!(s.battery_sample(0));
        assert_eq!(s.battery_voltage, Some(24.0));
        assert_eq!(s.battery_due_ms, 20);
        s.battery_input = 22.0;
        assert!(s.battery_sample(20));
        // 0.99 * 24 + (1 - 0.99) * 22, as Python computes it
        let expected = 0.99 * 24.0 + 0.010000000000000009 * 22.0;
        assert_eq!(s.battery_voltage, Some(expected));
        s.adc_scale = f64::NAN;
        assert!(!s.battery_sample(40));
        assert_eq!(s.battery_voltage, Some(expected));
        assert_eq!(s.battery_due_ms, 60);
    }

    #[test]
    fn control_due_with_slack() {
        let mut s = SpinalState::new(25.2, LEVEL);
        assert!(s.control_due());
        s.next_control = Some(0.005);
        s.now_s = 0.005 - 5e-10;
        assert!(s.control_due());
        s.now_s = 0.005 - 2e-9;
        assert!(!s.control_due());
        assert_eq!(s.step_voltage(), 25.2);
    }
}
