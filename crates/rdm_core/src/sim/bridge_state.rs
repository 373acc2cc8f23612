//! The plant bridge's state between its milliseconds: the servo targets and rotor duties it
//! last commanded, the battery voltage it last applied, and how many ticks found the plant
//! at another time than the tick's. One form: `rdm.nodes.plant_bridge.PlantBridge` and the
//! lockstep kernel both tick the one `_rdm.PlantBridgeCore` that holds it.

/// The plant bridge's state (see the module doc). Allocates only in [`BridgeState::new`].
#[derive(Debug, Clone, PartialEq)]
pub struct BridgeState {
    /// Servo targets (rad) per plant joint, as last commanded.
    pub targets: Vec<f64>,
    /// Rotor duties per plant rotor, as last commanded (0.5: stopped).
    pub duties: Vec<f64>,
    half_period: f64,
    time_mismatches: u64,
    voltage: Option<f64>,
    fixed_battery: Option<f64>,
}

impl BridgeState {
    /// Targets start at `targets` (rad), `rotors` duties at 0.5; a tick is `period` s.
    pub fn new(targets: &[f64], rotors: usize, period: f64) -> Self {
        BridgeState {
            targets: targets.to_vec(),
            duties: vec![0.5; rotors],
            half_period: 0.5 * period,
            time_mismatches: 0,
            voltage: None,
            fixed_battery: None,
        }
    }

    /// Count a tick at `now` that finds the plant at `plant_time` more than half a period
    /// away.
    pub fn check_time(&mut self, plant_time: f64, now: f64) {
        if (plant_time - now).abs() > self.half_period {
            self.time_mismatches += 1;
        }
    }

    /// Ticks that found the plant at another time.
    pub fn time_mismatches(&self) -> u64 {
        self.time_mismatches
    }

    /// The battery is a constant `volts` (Some) or a function of time (None) from now on.
    pub fn set_fixed_battery(&mut self, volts: Option<f64>) {
        self.fixed_battery = volts;
    }

    /// Take `volts` as the voltage of this tick; true if it differs from the last applied
    /// (the caller applies it to the plant and the sinks and re-commands the duties).
    pub fn apply_voltage(&mut self, volts: f64) -> bool {
        if self.voltage == Some(volts) {
            return false;
        }
        self.voltage = Some(volts);
        true
    }

    /// The last voltage applied (None before the first tick).
    pub fn voltage(&self) -> Option<f64> {
        self.voltage
    }

    /// True when the battery is a constant already applied: a tick leaves the voltage as
    /// it is.
    pub fn battery_steady(&self) -> bool {
        self.fixed_battery.is_some() && self.fixed_battery == self.voltage
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_mismatch_beyond_half_a_period_only() {
        let mut s = BridgeState::new(&[0.0], 1, 0.001);
        s.check_time(0.0104, 0.010); // 0.4 ms: within half a period
        assert_eq!(s.time_mismatches(), 0);
        s.check_time(0.0106, 0.010);
        s.check_time(0.0094, 0.010);
        assert_eq!(s.time_mismatches(), 2);
    }

    #[test]
    fn battery_steady_once_the_constant_is_applied() {
        let mut s = BridgeState::new(&[], 2, 0.001);
        assert_eq!(s.duties, vec![0.5, 0.5]);
        s.set_fixed_battery(Some(23.0));
        assert!(!s.battery_steady());
        assert!(s.apply_voltage(23.0));
        assert!(!s.apply_voltage(23.0));
        assert!(s.battery_steady());
        s.set_fixed_battery(None);
        assert!(!s.battery_steady());
        s.set_fixed_battery(Some(24.0));
        assert!(!s.battery_steady());
        assert!(s.apply_voltage(24.0));
        assert_eq!(s.voltage(), Some(24.0));
        assert!(s.battery_steady());
    }
}
