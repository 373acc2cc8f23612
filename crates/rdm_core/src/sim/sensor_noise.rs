//! IMU and 6-axis wrench error models: bias, white noise (standard normals drawn by the
//! caller), saturation and quantisation, per sample.
//!
//! Every value goes through the same IEEE operations, in the same order, as the Python
//! reference in `rdm.plant.sensors` (`x + b + std * e`, then the clip, then
//! `round_ties_even(v / lsb) * lsb` with the sign of a value that rounds to zero kept), so
//! both give bit-identical samples. NaN passes through the clip and the quantiser; inf is
//! clipped (to the range) or passed through (unclipped magnetometer).
//!
//! A finite value whose `v / lsb` overflows to inf, or an lsb of 0, gives the IEEE result
//! (inf or NaN): no panic, no error path.

/// `min(max(v, -limit), limit)` with Python's builtin `min`/`max` semantics: a NaN `v`
/// passes through (no comparison with NaN is true), ties keep `v`.
#[inline]
pub fn clip(v: f64, limit: f64) -> f64 {
    let lower = -limit;
    let m = if lower > v { lower } else { v };
    if limit < m {
        limit
    } else {
        m
    }
}

/// `round(v / lsb) * lsb` with ties to even; a value that rounds to zero keeps its sign
/// (as `numpy.round` does); non-finite values pass through unchanged.
#[inline]
pub fn quantize(v: f64, lsb: f64) -> f64 {
    if !v.is_finite() {
        return v;
    }
    let mut r = (v / lsb).round_ties_even();
    if r == 0.0 {
        r = 0.0f64.copysign(v);
    }
    r * lsb
}

/// Wrench sensor model: rated capacity per axis (Fx, Fy, Fz, Mx, My, Mz), constant bias,
/// noise `fraction * rated` per axis, resolution `rated / full_scale_counts` when quantising.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WrenchNoiseModel {
    /// Rated capacity per axis (the clip limit).
    pub rated: [f64; 6],
    /// Constant offset per axis.
    pub bias: [f64; 6],
    /// Noise standard deviation as a fraction of the rated capacity.
    pub noise_fraction: f64,
    /// Quantisation step per axis (`rated / full_scale_counts`), `None`: no quantisation.
    pub lsb: Option<[f64; 6]>,
}

/// One corrupted wrench sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WrenchSample {
    /// (Fx, Fy, Fz, Mx, My, Mz) after noise, clip and quantisation.
    pub values: [f64; 6],
    /// Per axis: `|value| >= rated` before the clip.
    pub saturated: [bool; 6],
}

impl WrenchNoiseModel {
    /// The model of a sensor with `rated` capacity; `full_scale_counts` raw counts span the
    /// rated capacity (Leptrino: 10000) when `quantize` is set.
    pub fn new(
        rated: [f64; 6],
        bias: [f64; 6],
        noise_fraction: f64,
        quantize: bool,
        full_scale_counts: f64,
    ) -> Self {
        let lsb = quantize.then(|| rated.map(|r| r / full_scale_counts));
        Self {
            rated,
            bias,
            noise_fraction,
            lsb,
        }
    }

    /// Corrupt one ideal sample with six standard normals.
    pub fn sample(&self, ideal: &[f64; 6], normals: &[f64; 6]) -> WrenchSample {
        let mut values = [0.0; 6];
        let mut saturated = [false; 6];
        for k in 0..6 {
            let r = self.rated[k];
            let v = ideal[k] + self.bias[k] + self.noise_fraction * r * normals[k];
            saturated[k] = v.abs() >= r;
            let v = clip(v, r);
            values[k] = match &self.lsb {
                Some(lsb) => quantize(v, lsb[k]),
                None => v,
            };
        }
        WrenchSample { values, saturated }
    }
}

/// IMU model: per-sensor bias and white-noise std (gyro, accelerometer, magnetometer), range
/// limits of gyro and accelerometer, quantisation steps of all three.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuNoiseModel {
    /// Constant bias of gyro, accelerometer, magnetometer (per axis).
    pub bias: [[f64; 3]; 3],
    /// White-noise std of gyro, accelerometer, magnetometer.
    pub std: [f64; 3],
    /// Clip limits of gyro and accelerometer (the magnetometer is not clipped).
    pub range: [f64; 2],
    /// Quantisation steps of gyro, accelerometer, magnetometer; `None`: no quantisation.
    pub lsb: Option<[f64; 3]>,
}

/// One corrupted IMU sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// Gyro, accelerometer, magnetometer after noise, clip and quantisation.
    pub values: [[f64; 3]; 3],
    /// Any gyro or accelerometer axis beyond its range before the clip.
    pub saturated: bool,
}

impl ImuNoiseModel {
    /// Corrupt one ideal sample (`ideal`: gyro, accelerometer, magnetometer) with nine
    /// standard normals (three per sensor, in that order).
    pub fn sample(&self, ideal: &[[f64; 3]; 3], normals: &[f64; 9]) -> ImuSample {
        let mut values = [[0.0; 3]; 3];
        for (s, out) in values.iter_mut().enumerate() {
            for (k, v) in out.iter_mut().enumerate() {
                *v = ideal[s][k] + self.bias[s][k] + self.std[s] * normals[3 * s + k];
            }
        }
        let saturated = values[0].iter().any(|v| v.abs() > self.range[0])
            || values[1].iter().any(|v| v.abs() > self.range[1]);
        for (s, limit) in self.range.iter().enumerate() {
            for v in values[s].iter_mut() {
                *v = clip(*v, *limit);
            }
        }
        if let Some(lsb) = &self.lsb {
            for (s, step) in lsb.iter().enumerate() {
                for v in values[s].iter_mut() {
                    *v = quantize(*v, *step);
                }
            }
        }
        ImuSample { values, saturated }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_keeps_nan_and_signed_zero() {
        assert!(clip(f64::NAN, 1.0).is_nan());
        assert_eq!(clip(f64::INFINITY, 2.0), 2.0);
        assert_eq!(clip(f64::NEG_INFINITY, 2.0), -2.0);
        assert!(clip(-0.0, 1.0).is_sign_negative());
        assert_eq!(clip(1.5, 1.0), 1.0);
    }

    #[test]
    fn quantize_ties_to_even_and_sign_of_zero() {
        assert_eq!(quantize(2.5, 1.0), 2.0);
        assert_eq!(quantize(3.5, 1.0), 4.0);
        assert_eq!(quantize(-2.5, 1.0), -2.0);
        let z = quantize(-0.2, 1.0);
        assert_eq!(z, 0.0);
        assert!(z.is_sign_negative());
        assert!(quantize(f64::NAN, 1.0).is_nan());
        assert_eq!(quantize(f64::NEG_INFINITY, 1.0), f64::NEG_INFINITY);
    }
}
