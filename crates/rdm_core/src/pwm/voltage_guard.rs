//! The battery-voltage plausibility guard of the thrust -> PWM conversion (not in the
//! firmware; docs/spinal.md "Guards on the actuator path").

use super::PwmInfo;

/// A fully charged Li-Po cell, V: the reference voltage per cell that gives the cell count.
pub const CELL_FULL_V: f64 = 4.2;
/// Default lowest plausible cell voltage, V (Li-Po discharge cut-off).
pub const CELL_MIN_V: f64 = 3.0;
/// Default highest plausible cell voltage, V (a Li-HV cell's 4.35 V full charge plus 0.1 V).
pub const CELL_MAX_V: f64 = 4.45;
/// Most cells a [`VoltageGuard::CellWindow`] accepts.
pub const MAX_CELLS: u32 = 24;

/// Plausibility guard of the battery voltage the converter scales the thrust with (not in the
/// firmware, which uses any reading; `jsk-wire-protocols.md` sec. 3.6).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VoltageGuard {
    /// Firmware-exact: every finite, positive voltage selects the reference and the factor
    /// (a non-finite or non-positive one is ignored and counted).
    Off,
    /// A voltage outside `cells x [min_cell_v, max_cell_v]` is rejected, counted and replaced
    /// by the last good voltage (at first the first reference curve's voltage: factor 1).
    CellWindow {
        /// Battery cells; 0 derives them from the reference curves
        /// ([`cells_from_reference`]).
        cells: u32,
        /// Lowest plausible cell voltage, V.
        min_cell_v: f64,
        /// Highest plausible cell voltage, V.
        max_cell_v: f64,
    },
}

impl Default for VoltageGuard {
    fn default() -> Self {
        Self::CellWindow {
            cells: 0,
            min_cell_v: CELL_MIN_V,
            max_cell_v: CELL_MAX_V,
        }
    }
}

impl VoltageGuard {
    /// Checks the fields; names the one at fault.
    pub fn validate(&self) -> Result<(), &'static str> {
        if let Self::CellWindow {
            cells,
            min_cell_v,
            max_cell_v,
        } = *self
        {
            if cells > MAX_CELLS {
                return Err("voltage_guard.cells");
            }
            if !(min_cell_v.is_finite() && min_cell_v > 0.0) {
                return Err("voltage_guard.min_cell_v");
            }
            if !(max_cell_v.is_finite() && max_cell_v > min_cell_v) {
                return Err("voltage_guard.max_cell_v");
            }
        }
        Ok(())
    }

    /// The plausible voltage window `(low, high)` for these reference curves, V; `None` when
    /// the guard is off.
    pub fn window(&self, info: &PwmInfo) -> Option<(f64, f64)> {
        match *self {
            Self::Off => None,
            Self::CellWindow {
                cells,
                min_cell_v,
                max_cell_v,
            } => {
                let n = if cells == 0 {
                    cells_from_reference(info)
                } else {
                    cells
                };
                Some((f64::from(n) * min_cell_v, f64::from(n) * max_cell_v))
            }
        }
    }
}

/// The battery's cell count from the reference curves: `round(V_max / 4.2)`, at least 1.
///
/// ASSUMPTION: the highest reference voltage is a fully charged Li-Po battery (4.2 V per
/// cell), as in both `MotorInfo.yaml` examples of sec. 3.6 (25.2 V = 6S). The onboard node's
/// battery monitor derives its cell count the same way.
pub fn cells_from_reference(info: &PwmInfo) -> u32 {
    let top = info
        .curves()
        .iter()
        .map(|c| c.voltage)
        .fold(0.0_f64, f64::max);
    let cells = (top / CELL_FULL_V).round();
    if cells >= f64::from(MAX_CELLS) {
        MAX_CELLS
    } else if cells >= 1.0 {
        cells as u32
    } else {
        1
    }
}
