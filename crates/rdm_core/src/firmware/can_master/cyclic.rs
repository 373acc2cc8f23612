//! The running 1 kHz schedule: at the start of each ms a queued board config (alone, then
//! a transmit pause), else on even ms the PWM broadcast and on odd ms the servo target
//! angles then currents to one Neuron, round-robin; the disconnect log and the config
//! re-requests after a REBOOT.

use super::{
    CanMaster, EventKind, BOARD_QUEUE, DISCONNECT_LOG_INTERVAL_MS, DISCONNECT_MS, PWM_MAX_MOTORS,
    REBOOT_REQUEST_MS, TX_PAUSE_MS,
};
use crate::firmware::neuron_frame::MAX_SERVO_NUM;
use crate::firmware::spinal_frame::{initial_config_request, pwm, servo_words};

impl CanMaster {
    pub(super) fn run(&mut self, t: i64) {
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
}
