//! The host's commands to the master: motor duties, servo goal position, torque and
//! current words, board-config requests (queued, sent alone by the cyclic schedule).

use super::{
    BoardRequest, CanMaster, MasterError, ServoEntry, BOARD_QUEUE, WORD_VALUE_MAX, WORD_VALUE_MIN,
};
use crate::firmware::neuron_frame::CanFrame;

impl CanMaster {
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
        if payload.len() > 8 || can_id > crate::firmware::neuron_frame::MAX_STD_ID {
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
}
