//! Whether the tick at `now` runs here: the idle ms (only the CAN ms), or a busy ms whose
//! battery sample, control step and publications are all on the kernel's paths.

use pyo3::prelude::*;
use rdm_core::firmware::rosserial_frame::client_stamp;
use rdm_core::firmware::spinal_state::{SpinalState, CONTROL_SLACK_S};
use rdm_core::MAX_ROTORS;

use super::SpinalFast;

/// What `ready` found the tick at `now` to be.
#[derive(Clone, Copy)]
pub(super) enum Decision {
    Idle,
    Busy(BusyTick),
}

#[derive(Clone, Copy)]
pub(super) struct BusyTick {
    /// The battery task runs (its sample is finite).
    pub(super) battery: bool,
    pub(super) step: Option<StepInput>,
    /// None: `_publish` is a no-op (not configured, no output yet) or not due.
    pub(super) publish: Option<Publish>,
}

/// A control step's input: the motor number (the IMU sample and the voltage are the
/// state's, the voltage after the tick's battery sample).
#[derive(Clone, Copy)]
pub(super) struct StepInput {
    pub(super) motors: usize,
    /// The duty list is the clamped controller output (`_duty_list`); false: `motors` idle
    /// duties (`_step_tail` before the CAN model is adopted: the master's motor number is
    /// not yet the controller's).
    pub(super) from_output: bool,
}

/// The publications of a tick: which are due, the stamp (the `imu` frame's acc and mag
/// are the state's IMU sample).
#[derive(Clone, Copy)]
pub(super) struct Publish {
    pub(super) imu_due: bool,
    pub(super) servo_due: bool,
    pub(super) stamp: (u32, u32),
}

impl SpinalFast {
    /// Whether the tick at `now` runs here (then `tick` does it).
    pub(crate) fn ready(&mut self, py: Python<'_>, now: f64) -> PyResult<bool> {
        self.ensure_loaded(py)?;
        let Some(p) = &self.plan else {
            return Ok(false);
        };
        let st = self.state.bind(py).try_borrow()?;
        let s = &st.inner;
        let (Some(last_ms), Some(can_ms), Some(next_control)) =
            (s.now_ms, s.can_ms, s.next_control)
        else {
            return Ok(false);
        };
        let m = SpinalState::ms_of(now);
        let (_, now_s) = s.clock_at(now);
        if !(m >= last_ms && p.idle_lo <= m && m < p.idle_hi && m == can_ms + 1) {
            return Ok(false);
        }
        let battery_due = m >= s.battery_due_ms;
        let control_due = now_s >= next_control - CONTROL_SLACK_S;
        let publish_due = p.publish_live && m >= s.next_pub_ms;
        if !battery_due && !control_due && !publish_due {
            self.decision = Decision::Idle;
            return Ok(true);
        }
        let Some(b) = &p.busy else {
            return Ok(false);
        };
        // The battery task: a finite sample (else the Python tick counts the rejection).
        if battery_due && s.battery_next().is_none() {
            return Ok(false);
        }
        // _control: exactly one step, on _step's fast path.
        let step = if control_due {
            let Some(core) = &b.core else {
                return Ok(false);
            };
            if now_s >= (next_control + b.period) - CONTROL_SLACK_S {
                return Ok(false); // a catch-up step follows: the Python tick
            }
            let motors = self.master.bind(py).try_borrow()?.core_ref().motor_number;
            let from_output = motors != 0 && motors == core.bind(py).try_borrow()?.motor_count();
            // The steady master: the controller's own duties only. During the boot
            // `_step_tail` gives `motors` idle duties when the numbers differ (no hand-over).
            if motors > MAX_ROTORS || (p.boot_state.is_none() && !from_output) {
                return Ok(false);
            }
            Some(StepInput {
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
                || b.chain.is_none()
            {
                return Ok(false);
            }
            let Some(stamp) = client_stamp(m, b.sync) else {
                return Ok(false);
            };
            Some(Publish {
                imu_due,
                servo_due,
                stamp,
            })
        } else {
            None
        };
        self.decision = Decision::Busy(BusyTick {
            battery: battery_due,
            step,
            publish,
        });
        Ok(true)
    }
}
