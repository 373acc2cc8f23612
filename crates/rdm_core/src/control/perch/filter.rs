//! First-order IIR low-pass on the measured foot wrench (Sec. VII-B: 1 Hz cutoff).
//!
//! Discretised with the bilinear (Tustin) transform with the cutoff pre-warped, so the
//! discrete filter's -3 dB point is exactly the cutoff at any tick rate below Nyquist:
//! `K = tan(π f_c / f_s)`, `y_k = b0 x_k + b1 x_{k-1} - a1 y_{k-1}` with
//! `b0 = b1 = K / (1 + K)` and `a1 = (K - 1) / (K + 1)` (the same coefficients as
//! `scipy.signal.butter(1, f_c, fs=f_s)`).

/// Filter coefficients `(b0, b1, a1)` for cutoff `cutoff_hz` at `sample_hz`, or `None` when
/// the pair is unusable (non-finite, non-positive, or cutoff at/above Nyquist).
pub fn lowpass_coefficients(cutoff_hz: f64, sample_hz: f64) -> Option<(f64, f64, f64)> {
    let valid = cutoff_hz.is_finite()
        && sample_hz.is_finite()
        && cutoff_hz > 0.0
        && sample_hz > 0.0
        && cutoff_hz < 0.5 * sample_hz;
    if !valid {
        return None;
    }
    let k = (core::f64::consts::PI * cutoff_hz / sample_hz).tan();
    let b = k / (1.0 + k);
    Some((b, b, (k - 1.0) / (k + 1.0)))
}

/// Six-channel first-order low-pass for `[F_x, F_y, F_z, M_x, M_y, M_z]`. Allocation-free.
#[derive(Clone, Debug)]
pub struct WrenchFilter {
    b0: f64,
    b1: f64,
    a1: f64,
    last_input: [f64; 6],
    last_output: [f64; 6],
    primed: bool,
}

impl WrenchFilter {
    /// Filter with `cutoff_hz` at the tick rate `sample_hz` (paper: 1 Hz at 40 Hz).
    /// `None` when the pair is unusable (see [`lowpass_coefficients`]).
    pub fn new(cutoff_hz: f64, sample_hz: f64) -> Option<Self> {
        let (b0, b1, a1) = lowpass_coefficients(cutoff_hz, sample_hz)?;
        Some(Self {
            b0,
            b1,
            a1,
            last_input: [0.0; 6],
            last_output: [0.0; 6],
            primed: false,
        })
    }

    /// `(b0, b1, a1)` in scipy's `lfilter(b=[b0, b1], a=[1, a1])` convention.
    pub fn coefficients(&self) -> (f64, f64, f64) {
        (self.b0, self.b1, self.a1)
    }

    /// Forget the history: the next sample starts the filter in steady state at that sample
    /// (what `scipy.signal.lfilter_zi(b, a) * x0` does), so perching starts without a ramp.
    pub fn reset(&mut self) {
        self.primed = false;
    }

    /// Current output (zeros before the first sample).
    pub fn output(&self) -> [f64; 6] {
        self.last_output
    }

    /// Feed one sample. Returns `None` and leaves the state untouched if any entry is
    /// NaN/inf, so one bad sensor packet cannot poison the filter.
    pub fn update(&mut self, sample: &[f64; 6]) -> Option<[f64; 6]> {
        if sample.iter().any(|v| !v.is_finite()) {
            return None;
        }
        if !self.primed {
            self.last_input = *sample;
            self.last_output = *sample;
            self.primed = true;
            return Some(*sample);
        }
        for ((y, x_prev), x) in self
            .last_output
            .iter_mut()
            .zip(self.last_input.iter_mut())
            .zip(sample.iter())
        {
            *y = self.b0 * x + self.b1 * *x_prev - self.a1 * *y;
            *x_prev = *x;
        }
        Some(self.last_output)
    }
}
