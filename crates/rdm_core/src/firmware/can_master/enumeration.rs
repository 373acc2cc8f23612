//! Start-up (fact sheet sec. 2.5-2.7): wait the boot delay, broadcast ENUM_REQUEST and
//! collect responses, then per Neuron an INITIAL_CONFIG_REQUEST, then IMU init per Neuron,
//! then infer the `uav_model` and start running.

use super::{
    CanMaster, EventKind, MasterState, NeuronEntry, CONFIG_WAIT_MS, DRAGON, ENUM_WAIT_MS, HYDRUS,
    HYDRUS_XI, IMU_INIT_MS, PWM_MAX_MOTORS,
};
use crate::firmware::spinal_frame::{enum_request, initial_config_request};

impl CanMaster {
    pub(super) fn step(&mut self, t: i64) {
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
}
