//! `SpinalMirrorState`: the Spinal mirror's clock, IMU sample and battery state
//! (`rdm_core::firmware::spinal_state::SpinalState`), shared by the mirror's Python tick
//! and the lockstep kernel's fast part.

use pyo3::prelude::*;
use rdm_core::estimate::ImuSample;
use rdm_core::firmware::spinal_state::SpinalState;

/// The Spinal mirror's clock, IMU sample and battery state:
/// `SpinalMirrorState(battery_input, gyro, acc, mag)` before the first tick (raw battery
/// reading in V, ADC scale 1, the IMU sample: rad/s, m/s^2, uT).
#[pyclass(module = "rdm._rdm")]
pub struct SpinalMirrorState {
    pub(crate) inner: SpinalState,
}

#[pymethods]
impl SpinalMirrorState {
    #[new]
    fn new(battery_input: f64, gyro: [f64; 3], acc: [f64; 3], mag: [f64; 3]) -> Self {
        SpinalMirrorState {
            inner: SpinalState::new(battery_input, ImuSample { gyro, acc, mag }),
        }
    }

    /// The IMU sample the next control steps and `imu` publications use: gyro rad/s, acc
    /// m/s^2, mag uT (body frame; three numbers each).
    fn set_imu_sample(&mut self, gyro: [f64; 3], acc: [f64; 3], mag: [f64; 3]) {
        self.inner.imu = ImuSample { gyro, acc, mag };
    }

    /// The IMU sample's gyro (rad/s).
    #[getter]
    fn gyro(&self) -> (f64, f64, f64) {
        let [x, y, z] = self.inner.imu.gyro;
        (x, y, z)
    }

    /// The IMU sample's accelerometer (m/s^2).
    #[getter]
    fn acc(&self) -> (f64, f64, f64) {
        let [x, y, z] = self.inner.imu.acc;
        (x, y, z)
    }

    /// The IMU sample's magnetometer (uT).
    #[getter]
    fn mag(&self) -> (f64, f64, f64) {
        let [x, y, z] = self.inner.imu.mag;
        (x, y, z)
    }

    /// The tick's clock at `now` (s): its ms (`floor(now * 1000 + 1e-6)`, never before the
    /// last tick's), and `now_s` the latest time. A non-finite `now` raises `ValueError`.
    fn tick_begin(&mut self, now: f64) -> PyResult<i64> {
        if !now.is_finite() {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "SpinalMirror.tick: now {now} is not a finite time"
            )));
        }
        Ok(self.inner.tick_begin(now))
    }

    /// Whether a control step is due at `now_s` (`next_control` None or reached, 1e-9 s
    /// slack).
    fn control_due(&self) -> bool {
        self.inner.control_due()
    }

    /// The battery task at `now_ms`: next sample 20 ms later, the low-passed voltage
    /// `0.99 v + 0.01 battery_input * adc_scale` (the sample itself when there is none yet).
    /// False: that sample is not finite (rejected, the voltage kept).
    fn battery_sample(&mut self, now_ms: i64) -> bool {
        self.inner.battery_sample(now_ms)
    }

    /// The voltage a control step uses: `battery_voltage`, else `battery_input`.
    fn step_voltage(&self) -> f64 {
        self.inner.step_voltage()
    }

    /// The ms of the last tick (None: no tick yet).
    #[getter]
    fn now_ms(&self) -> Option<i64> {
        self.inner.now_ms
    }

    /// The latest tick time (s).
    #[getter]
    fn now_s(&self) -> f64 {
        self.inner.now_s
    }

    /// The last ms the CAN master ran (None: not yet).
    #[getter]
    fn can_ms(&self) -> Option<i64> {
        self.inner.can_ms
    }

    #[setter]
    fn set_can_ms(&mut self, ms: Option<i64>) {
        self.inner.can_ms = ms;
    }

    /// When the next control step is due (s; None: at the next tick).
    #[getter]
    fn next_control(&self) -> Option<f64> {
        self.inner.next_control
    }

    #[setter]
    fn set_next_control(&mut self, t: Option<f64>) {
        self.inner.next_control = t;
    }

    /// The first ms the battery task samples again.
    #[getter]
    fn battery_due_ms(&self) -> i64 {
        self.inner.battery_due_ms
    }

    /// The raw battery reading (V).
    #[getter]
    fn battery_input(&self) -> f64 {
        self.inner.battery_input
    }

    #[setter]
    fn set_battery_input(&mut self, volts: f64) {
        self.inner.battery_input = volts;
    }

    /// The ADC scale (`set_adc_scale`).
    #[getter]
    fn adc_scale(&self) -> f64 {
        self.inner.adc_scale
    }

    #[setter]
    fn set_adc_scale(&mut self, scale: f64) {
        self.inner.adc_scale = scale;
    }

    /// The earliest ms a periodic publisher can be due.
    #[getter]
    fn next_pub_ms(&self) -> i64 {
        self.inner.next_pub_ms
    }

    #[setter]
    fn set_next_pub_ms(&mut self, ms: i64) {
        self.inner.next_pub_ms = ms;
    }

    /// The low-passed battery voltage (V; None: no sample yet).
    #[getter]
    fn battery_voltage(&self) -> Option<f64> {
        self.inner.battery_voltage
    }
}

/// Register `SpinalMirrorState`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<SpinalMirrorState>()?;
    Ok(())
}
