//! Whether the tick at `now` runs here: the idle ms (only the CAN ms), or a busy ms whose
//! battery sample, control step and publications are all on the kernel's paths.

use pyo3::prelude::*;
use rdm_core::firmware::rosserial_frame::client_stamp;
use rdm_core::MAX_ROTORS;

use super::plan::exact_f64;
use super::SpinalFast;
use crate::kernel::attr::Name;
use crate::spinal_mirror::float3;

/// What `ready` found the tick at `now` to be.
#[derive(Clone, Copy)]
pub(super) enum Decision {
    Idle,
    Busy(BusyTick),
}

#[derive(Clone, Copy)]
pub(super) struct BusyTick {
    /// The battery sample: the new filtered voltage.
    pub(super) battery: Option<f64>,
    pub(super) step: Option<StepInput>,
    /// None: `_publish` is a no-op (not configured, no output yet) or not due.
    pub(super) publish: Option<Publish>,
}

/// A control step's input: the IMU sample, the voltage, and the motor number.
#[derive(Clone, Copy)]
pub(super) struct StepInput {
    pub(super) gyro: [f64; 3],
    pub(super) acc: [f64; 3],
    pub(super) mag: [f64; 3],
    pub(super) voltage: f64,
    pub(super) motors: usize,
    /// The duty list is the clamped controller output (`_duty_list`); false: `motors` idle
    /// duties (`_step_tail` before the CAN model is adopted: the master's motor number is
    /// not yet the controller's).
    pub(super) from_output: bool,
}

/// The publications of a tick: which are due, the stamp, the `imu` sample's acc and mag.
#[derive(Clone, Copy)]
pub(super) struct Publish {
    pub(super) imu_due: bool,
    pub(super) servo_due: bool,
    pub(super) stamp: (u32, u32),
    pub(super) acc: [f64; 3],
    pub(super) mag: [f64; 3],
}

impl SpinalFast {
    /// Whether the tick at `now` runs here (then `tick` does it).
    pub(crate) fn ready(&mut self, py: Python<'_>, now: f64) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        let Some(p) = &self.plan else {
            return Ok(false);
        };
        let m = Self::to_ms(now);
        let now_s = if now > p.now_s { now } else { p.now_s };
        if !(m >= p.now_ms && p.idle_lo <= m && m < p.idle_hi && m == p.can_ms + 1) {
            return Ok(false);
        }
        let battery_due = m >= p.battery_due_ms;
        let control_due = now_s >= p.next_control - 1e-9;
        let publish_due = m >= p.next_pub_ms;
        if !battery_due && !control_due && !publish_due {
            self.decision = Decision::Idle;
            return Ok(true);
        }
        let Some(b) = &p.busy else {
            return Ok(false);
        };
        let node = self.node.bind(py);
        let n = &self.names;
        // _battery: the sample (a finite one; else the Python tick counts the rejection).
        let battery = if battery_due {
            let input = exact_f64(&n.battery_input.get(node)?);
            let scale = exact_f64(&n.adc_scale.get(node)?);
            let (Some(input), Some(scale)) = (input, scale) else {
                return Ok(false);
            };
            let sample = input * scale;
            if !sample.is_finite() {
                return Ok(false);
            }
            // The low-passed voltage: the one a busy ms here left (not yet written back),
            // else the mirror's.
            let v = match self.deferred.battery {
                Some((_, v)) => Some(v),
                None => {
                    let v = n.battery_voltage.get(node)?;
                    if v.is_none() {
                        None
                    } else {
                        let Some(v) = exact_f64(&v) else {
                            return Ok(false);
                        };
                        Some(v)
                    }
                }
            };
            Some(match v {
                None => sample,
                Some(v) => b.battery_filter * v + (1.0 - b.battery_filter) * sample,
            })
        } else {
            None
        };
        // _control: exactly one step, on _step's fast path.
        let step = if control_due {
            let Some(core) = &b.core else {
                return Ok(false);
            };
            if now_s >= (p.next_control + b.period) - 1e-9 {
                return Ok(false); // a catch-up step follows: the Python tick
            }
            let motors = self.master.bind(py).try_borrow()?.core_ref().motor_number;
            let from_output = motors != 0 && motors == core.bind(py).try_borrow()?.motor_count();
            // The steady master: the controller's own duties only. During the boot
            // `_step_tail` gives `motors` idle duties when the numbers differ (no hand-over).
            if motors > MAX_ROTORS || (p.boot_state.is_none() && !from_output) {
                return Ok(false);
            }
            let three = |name: &Name| -> PyResult<Option<[f64; 3]>> {
                Ok(name.get(node)?.extract::<[f64; 3]>().ok())
            };
            let (Some(gyro), Some(acc), Some(mag)) =
                (three(&n.gyro)?, three(&n.acc)?, three(&n.mag)?)
            else {
                return Ok(false);
            };
            let voltage = match battery.or(self.deferred.battery.map(|(_, v)| v)) {
                Some(v) => v,
                None => {
                    let v = n.battery_voltage.get(node)?;
                    let v = if v.is_none() {
                        n.battery_input.get(node)?
                    } else {
                        v
                    };
                    match v.extract::<f64>() {
                        Ok(v) => v,
                        Err(_) => return Ok(false),
                    }
                }
            };
            Some(StepInput {
                gyro,
                acc,
                mag,
                voltage,
                motors,
                from_output,
            })
        } else {
            None
        };
        // _publish: imu and servo/states as their frame paths, nothing else due.
        let publish = if publish_due && b.configured && (control_due || b.has_output) {
            let imu_due = b.imu_last.is_none_or(|t| m - t >= b.imu_period);
            let servo_due = b.servo_last.is_none_or(|t| m - t >= b.servo_period);
            let imu_ok = b.imu_last.is_some() && b.imu_topic.is_some();
            let servo_ok = b.servo_last.is_some() && b.servo_topic.is_some();
            if m >= b.others_next
                || !b.sync_ok
                || (imu_due && !imu_ok)
                || (servo_due && !servo_ok)
                || (!control_due && b.output.is_none())
                || b.chunks.is_none()
                || !b.writes_whole
            {
                return Ok(false);
            }
            let Some(stamp) = client_stamp(m, b.sync) else {
                return Ok(false);
            };
            let (acc, mag) = if imu_due {
                match (float3(&n.acc.get(node)?), float3(&n.mag.get(node)?)) {
                    (Some(a), Some(g)) => (a, g),
                    _ => return Ok(false),
                }
            } else {
                ([0.0; 3], [0.0; 3])
            };
            Some(Publish {
                imu_due,
                servo_due,
                stamp,
                acc,
                mag,
            })
        } else {
            None
        };
        self.decision = Decision::Busy(BusyTick {
            battery,
            step,
            publish,
        });
        Ok(true)
    }
}
