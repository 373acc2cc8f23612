//! The tick `ready` accepted: the battery sample, the control step and the duty hand-over,
//! the `imu` and `servo/states` frames, then the CAN ms.

use pyo3::prelude::*;
use rdm_core::firmware::rosserial_frame::{imu_frame, ImuValues};
use rdm_core::MAX_ROTORS;

use super::flush::Duties;
use super::ready::{Decision, Publish, StepInput};
use super::{SpinalFast, SpinalTick};
use crate::can_master::{CanMaster, CanWire};
use crate::spinal_mirror::{clamp_duty, servo_states_frame_into, ServoFrame};

impl SpinalFast {
    /// The tick at `now` (requires `ready`).
    pub(crate) fn tick(&mut self, py: Python<'_>, now: f64) -> PyResult<SpinalTick> {
        let Some(p) = &mut self.plan else {
            return Err(pyo3::exceptions::PyRuntimeError::new_err(
                "kernel: Spinal tick without a plan",
            ));
        };
        let mut st = self.state.bind(py).try_borrow_mut()?;
        let s = &mut st.inner;
        let m = s.tick_begin(now);
        self.dirty = true;
        let decision = std::mem::replace(&mut self.decision, Decision::Idle);
        let boot = p.boot_state.is_some();
        let busy = match decision {
            Decision::Busy(busy) => Some(busy),
            Decision::Idle => None,
        };
        let no_plan =
            || pyo3::exceptions::PyRuntimeError::new_err("kernel: Spinal busy tick without plan");
        // In `tick`'s order: battery and control step, the CAN ms, the publications.
        if let Some(busy) = busy {
            let b = p.busy.as_mut().ok_or_else(no_plan)?;
            let d = &mut self.deferred;
            if busy.battery {
                // `ready` checked the sample is finite: the voltage takes it.
                s.battery_sample(m);
                d.battery_ms = Some(m);
                self.counts.batteries += 1;
            }
            if let Some(StepInput {
                motors,
                from_output,
            }) = busy.step
            {
                let core = b.core.as_ref().ok_or_else(|| {
                    pyo3::exceptions::PyRuntimeError::new_err("kernel: Spinal step without core")
                })?;
                let out =
                    core.bind(py)
                        .try_borrow_mut()?
                        .step_raw(s.now_s, &s.imu, s.step_voltage());
                s.next_control = s.next_control.map(|t| t + b.period);
                d.output = Some(out);
                b.output = Some(out);
                b.has_output = true;
                self.counts.steps += 1;
                let events = &out.control.events;
                if !events.is_empty() || events.dropped() > 0 {
                    self.counts.finish_step += 1;
                    return Ok(SpinalTick::FinishStep(m, true));
                }
                let mut duties = Duties {
                    values: [0.0; MAX_ROTORS],
                    n: motors,
                };
                for (v, &x) in duties.values.iter_mut().zip(out.control.duty.iter()) {
                    *v = if from_output {
                        clamp_duty(x, b.idle_duty)
                    } else {
                        b.idle_duty
                    };
                }
                d.duties = Some(duties);
                if boot {
                    // `_can` before the master runs hands no duties over.
                    d.duties_handed = false;
                } else {
                    let handed = self
                        .master
                        .bind(py)
                        .try_borrow_mut()?
                        .try_set_duty_slice(&duties.values[..motors]);
                    d.duties_handed = handed;
                    if !handed {
                        self.counts.finish_step += 1;
                        return Ok(SpinalTick::FinishStep(m, false));
                    }
                    d.handed = Some(duties);
                }
            }
        }
        s.can_ms = Some(m);
        let imu = s.imu;
        drop(st);
        if !Self::can_tick(
            &self.master,
            &self.wire,
            self.drain_at,
            p.boot_state,
            py,
            m,
            now,
        ) {
            return Ok(SpinalTick::Finish(m));
        }
        if let Some(Publish {
            imu_due,
            servo_due,
            stamp,
        }) = busy.and_then(|busy| busy.publish)
        {
            let b = p.busy.as_mut().ok_or_else(no_plan)?;
            let d = &mut self.deferred;
            self.tick_tx.clear();
            let mut used = 0usize;
            let cap = b.chunks.unwrap_or(0);
            let mut fits = |len: usize| -> bool {
                if len > b.output_size || b.chunk_bytes == 0 {
                    return false;
                }
                used += len.div_ceil(b.chunk_bytes);
                used <= cap
            };
            let mut imu_sent = false;
            if imu_due {
                let (Some(out), Some(topic)) = (b.output.as_ref(), b.imu_topic) else {
                    self.counts.finish_publish += 1;
                    return Ok(SpinalTick::FinishPublish(m));
                };
                let estimate = &out.estimate;
                let values = ImuValues {
                    acc: imu.acc,
                    gyro: estimate.angular_velocity.into(),
                    mag: imu.mag,
                    quaternion: estimate.quaternion,
                };
                match imu_frame(topic, stamp, &values) {
                    Some(f) if fits(f.len()) => {
                        self.tick_tx.extend_from_slice(&f);
                        imu_sent = true;
                    }
                    _ => {
                        self.counts.finish_publish += 1;
                        return Ok(SpinalTick::FinishPublish(m));
                    }
                }
            }
            let mut servo_sent = false;
            // Before the master runs no servo has reported: `states_frame` gives no
            // message (the publication's time is still taken).
            if servo_due && !boot {
                let (Some(core), Some(topic)) = (b.servo_core.as_ref(), b.servo_topic) else {
                    self.counts.finish_publish += 1;
                    return Ok(SpinalTick::FinishPublish(m));
                };
                let core = core.bind(py).try_borrow()?;
                match servo_states_frame_into(core.core_ref(), topic, stamp, &mut self.tick_tx) {
                    ServoFrame::Empty => {}
                    ServoFrame::Written(len) if fits(len) => servo_sent = true,
                    _ => {
                        self.counts.finish_publish += 1;
                        return Ok(SpinalTick::FinishPublish(m));
                    }
                }
            }
            if self.tx.len() + self.tick_tx.len() > b.max_pending {
                self.counts.finish_publish += 1;
                return Ok(SpinalTick::FinishPublish(m));
            }
            // Committed: _last_pub, _next_pub_ms, the TX counters, the bytes.
            if imu_due {
                b.imu_last = Some(m);
                d.imu_last = true;
            }
            if servo_due {
                b.servo_last = Some(m);
                d.servo_last = true;
            }
            let imu_next = b.imu_last.map_or(i64::MIN, |t| t + b.imu_period);
            let servo_next = b.servo_last.map_or(i64::MIN, |t| t + b.servo_period);
            self.state.bind(py).try_borrow_mut()?.inner.next_pub_ms =
                imu_next.min(servo_next).min(b.others_next);
            let sent = i64::from(imu_sent) + i64::from(servo_sent);
            d.frames += sent;
            d.imu_frames += i64::from(imu_sent);
            d.servo_frames += i64::from(servo_sent);
            self.counts.imu_frames += u64::from(imu_sent);
            self.counts.servo_frames += u64::from(servo_sent);
            self.tx.extend_from_slice(&self.tick_tx);
            if !self.tick_tx.is_empty() {
                // m is whole ms: m / 1000 rounds back to them in the index
                self.tx_marks.push((m as f64 / 1000.0, self.tx.len()));
            }
        }
        Ok(SpinalTick::Done)
    }

    /// The CAN ms (`tick_wire_steady`): the steady master's, or, before it first runs
    /// (`boot_state`), one that stays in that phase with no event and a short log (the
    /// master counts its frames and holds its events itself); false: the tick's result is
    /// for Python (`Finish`).
    fn can_tick(
        master: &Py<CanMaster>,
        wire: &Py<CanWire>,
        drain_at: usize,
        boot_state: Option<u8>,
        py: Python<'_>,
        m: i64,
        now: f64,
    ) -> bool {
        let mut master = master.bind(py).borrow_mut();
        let sent = master.tick_wire_steady(m, now, wire.bind(py), drain_at);
        match boot_state {
            None => sent >= 0,
            Some(phase) => {
                let (state, events, _, logged) = master.last_wire_tick();
                state == phase && events == 0 && logged < drain_at
            }
        }
    }
}
