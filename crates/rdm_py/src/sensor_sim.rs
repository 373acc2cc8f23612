//! Bindings of `rdm_core::sim`: the per-sample sensor error models (IMU, 6-axis wrench),
//! called by `rdm.plant.sensors` once per sample. The standard normals stay drawn by numpy on
//! the Python side (the seeded stream is numpy's); these only do the float work.

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rdm_core::sim::sensor_noise::{ImuNoiseModel, ImuSample, WrenchNoiseModel, WrenchSample};

/// A float array handed to Python.
type F64Array<'py> = Bound<'py, PyArray1<f64>>;
/// `(force, torque, saturated)` of a wrench sample.
type WrenchOut<'py> = (F64Array<'py>, F64Array<'py>, Bound<'py, PyArray1<bool>>);
/// `(gyro, accel, mag, saturated)` of an IMU sample.
type ImuOut<'py> = (F64Array<'py>, F64Array<'py>, F64Array<'py>, bool);

/// `N` consecutive values of `data` from `adr`, or a ValueError naming `what`.
fn values_at<const N: usize>(data: &[f64], adr: usize, what: &str) -> PyResult<[f64; N]> {
    adr.checked_add(N)
        .and_then(|end| data.get(adr..end))
        .and_then(|s| <[f64; N]>::try_from(s).ok())
        .ok_or_else(|| {
            PyValueError::new_err(format!(
                "{what}: address {adr} + {N} outside sensordata of {} values",
                data.len()
            ))
        })
}

/// The values of a (possibly strided) 1-D float array as a slice, copied only if strided.
fn with_slice<R>(data: &PyReadonlyArray1<'_, f64>, f: impl FnOnce(&[f64]) -> R) -> R {
    match data.as_slice() {
        Ok(s) => f(s),
        Err(_) => f(&data.as_array().to_vec()),
    }
}

/// Wrench sensor error model (see `rdm_core::sim::sensor_noise::WrenchNoiseModel`).
#[pyclass(module = "rdm._rdm", frozen)]
pub(crate) struct WrenchNoiseCore {
    pub(crate) inner: WrenchNoiseModel,
}

#[pymethods]
impl WrenchNoiseCore {
    #[new]
    fn new(
        rated: [f64; 6],
        bias: [f64; 6],
        noise_fraction: f64,
        quantize: bool,
        full_scale_counts: f64,
    ) -> Self {
        Self {
            inner: WrenchNoiseModel::new(rated, bias, noise_fraction, quantize, full_scale_counts),
        }
    }

    /// ``(force, torque, saturated)`` arrays of one ideal sample (6 floats) and 6 normals.
    fn sample<'py>(&self, py: Python<'py>, ideal: [f64; 6], normals: [f64; 6]) -> WrenchOut<'py> {
        wrench_out(py, &self.inner.sample(&ideal, &normals))
    }

    /// :meth:`sample` of the ideal force (3 values at ``force_adr``) and torque (3 at
    /// ``torque_adr``) read straight from MuJoCo's ``sensordata``.
    fn sample_at<'py>(
        &self,
        py: Python<'py>,
        sensordata: PyReadonlyArray1<'py, f64>,
        force_adr: usize,
        torque_adr: usize,
        normals: [f64; 6],
    ) -> PyResult<WrenchOut<'py>> {
        let ideal = with_slice(&sensordata, |sd| -> PyResult<[f64; 6]> {
            let f: [f64; 3] = values_at(sd, force_adr, "force_adr")?;
            let t: [f64; 3] = values_at(sd, torque_adr, "torque_adr")?;
            Ok([f[0], f[1], f[2], t[0], t[1], t[2]])
        })?;
        Ok(wrench_out(py, &self.inner.sample(&ideal, &normals)))
    }

    /// The noisy (Fx, Fy, Fz, Mx, My, Mz) of :meth:`sample_at` as one tuple of floats (no
    /// arrays, no saturation flags): the 1 kHz foot-sensor read that goes straight to the
    /// Leptrino mirror (``LeptrinoSensorNode.set_wrench_values``).
    fn sample_values_at(
        &self,
        sensordata: PyReadonlyArray1<'_, f64>,
        force_adr: usize,
        torque_adr: usize,
        normals: [f64; 6],
    ) -> PyResult<(f64, f64, f64, f64, f64, f64)> {
        let ideal = with_slice(&sensordata, |sd| -> PyResult<[f64; 6]> {
            let f: [f64; 3] = values_at(sd, force_adr, "force_adr")?;
            let t: [f64; 3] = values_at(sd, torque_adr, "torque_adr")?;
            Ok([f[0], f[1], f[2], t[0], t[1], t[2]])
        })?;
        let v = self.inner.sample(&ideal, &normals).values;
        Ok((v[0], v[1], v[2], v[3], v[4], v[5]))
    }
}

fn wrench_out<'py>(py: Python<'py>, s: &WrenchSample) -> WrenchOut<'py> {
    let (force, torque) = s.values.split_at(3);
    (
        PyArray1::from_slice(py, force),
        PyArray1::from_slice(py, torque),
        PyArray1::from_slice(py, &s.saturated),
    )
}

fn imu_out<'py>(py: Python<'py>, s: &ImuSample) -> ImuOut<'py> {
    (
        PyArray1::from_slice(py, &s.values[0]),
        PyArray1::from_slice(py, &s.values[1]),
        PyArray1::from_slice(py, &s.values[2]),
        s.saturated,
    )
}

/// IMU error model (see `rdm_core::sim::sensor_noise::ImuNoiseModel`).
#[pyclass(module = "rdm._rdm", frozen)]
pub(crate) struct ImuNoiseCore {
    pub(crate) inner: ImuNoiseModel,
}

#[pymethods]
impl ImuNoiseCore {
    /// ``lsb``: quantisation steps (gyro, accel, mag) or None.
    #[new]
    fn new(
        gyro_bias: [f64; 3],
        accel_bias: [f64; 3],
        mag_bias: [f64; 3],
        std: [f64; 3],
        range: [f64; 2],
        lsb: Option<[f64; 3]>,
    ) -> Self {
        Self {
            inner: ImuNoiseModel {
                bias: [gyro_bias, accel_bias, mag_bias],
                std,
                range,
                lsb,
            },
        }
    }

    /// ``(gyro, accel, mag, saturated)`` of one ideal sample and 9 normals.
    fn sample<'py>(
        &self,
        py: Python<'py>,
        gyro: [f64; 3],
        accel: [f64; 3],
        mag: [f64; 3],
        normals: [f64; 9],
    ) -> ImuOut<'py> {
        imu_out(py, &self.inner.sample(&[gyro, accel, mag], &normals))
    }

    /// :meth:`sample` of gyro, accelerometer and magnetometer values (3 each) read straight
    /// from MuJoCo's ``sensordata`` at their addresses.
    fn sample_at<'py>(
        &self,
        py: Python<'py>,
        sensordata: PyReadonlyArray1<'py, f64>,
        gyro_adr: usize,
        accel_adr: usize,
        mag_adr: usize,
        normals: [f64; 9],
    ) -> PyResult<ImuOut<'py>> {
        let ideal = with_slice(&sensordata, |sd| -> PyResult<[[f64; 3]; 3]> {
            Ok([
                values_at(sd, gyro_adr, "gyro_adr")?,
                values_at(sd, accel_adr, "accel_adr")?,
                values_at(sd, mag_adr, "mag_adr")?,
            ])
        })?;
        Ok(imu_out(py, &self.inner.sample(&ideal, &normals)))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<WrenchNoiseCore>()?;
    m.add_class::<ImuNoiseCore>()?;
    Ok(())
}
