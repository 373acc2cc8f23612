//! Bindings of `rdm_core::sim`: the per-sample sensor error models (IMU, 6-axis wrench) and
//! the Leptrino sample frame encoder, called by `rdm.plant.sensors` and
//! `rdm.nodes.leptrino_sensor` once per sample. The standard normals stay drawn by numpy on
//! the Python side (the seeded stream is numpy's); these only do the float work.

use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use rdm_core::sim::leptrino_stream::encode_force_frame;
use rdm_core::sim::sensor_noise::{ImuNoiseModel, WrenchNoiseModel};

/// A float array handed to Python.
type F64Array<'py> = Bound<'py, PyArray1<f64>>;
/// `(force, torque, saturated)` of a wrench sample.
type WrenchOut<'py> = (F64Array<'py>, F64Array<'py>, Bound<'py, PyArray1<bool>>);
/// `(gyro, accel, mag, saturated)` of an IMU sample.
type ImuOut<'py> = (F64Array<'py>, F64Array<'py>, F64Array<'py>, bool);

/// Wrench sensor error model (see `rdm_core::sim::sensor_noise::WrenchNoiseModel`).
#[pyclass(module = "rdm._rdm", frozen)]
struct WrenchNoiseCore {
    inner: WrenchNoiseModel,
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
        let s = self.inner.sample(&ideal, &normals);
        let (force, torque) = s.values.split_at(3);
        (
            PyArray1::from_slice(py, force),
            PyArray1::from_slice(py, torque),
            PyArray1::from_slice(py, &s.saturated),
        )
    }
}

/// IMU error model (see `rdm_core::sim::sensor_noise::ImuNoiseModel`).
#[pyclass(module = "rdm._rdm", frozen)]
struct ImuNoiseCore {
    inner: ImuNoiseModel,
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
        let s = self.inner.sample(&[gyro, accel, mag], &normals);
        (
            PyArray1::from_slice(py, &s.values[0]),
            PyArray1::from_slice(py, &s.values[1]),
            PyArray1::from_slice(py, &s.values[2]),
            s.saturated,
        )
    }
}

/// The Leptrino sample frame of a wrench, or None where the Python encoder raises
/// (non-finite wrench, int16 overflow, a byte field out of range).
#[pyfunction]
fn leptrino_force_frame<'py>(
    py: Python<'py>,
    wrench: [f64; 6],
    rated: [f64; 6],
    temperature: i64,
    status: i64,
    term_no: i64,
    result: i64,
) -> Option<Bound<'py, PyBytes>> {
    encode_force_frame(&wrench, &rated, temperature, status, term_no, result)
        .ok()
        .map(|f| PyBytes::new(py, f.as_bytes()))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<WrenchNoiseCore>()?;
    m.add_class::<ImuNoiseCore>()?;
    m.add_function(wrap_pyfunction!(leptrino_force_frame, m)?)?;
    Ok(())
}
