//! `rdm._rdm`: thin pyo3 bindings of `rdm_core`. Each concept registers its own classes
//! and functions from its own file; no algorithm lives in this crate.

use pyo3::prelude::*;

mod attitude;
mod bench;
mod can_frame;
mod can_master;
mod capture_index;
mod contact_gate;
mod errors;
mod estimate;
mod finite_vector;
mod flight_axes;
mod foot_tracker;
mod gains;
mod json_log;
mod kernel;
mod leptrino_scan;
mod leptrino_sensor;
mod lqi;
mod model;
mod neuron_bank;
mod normal_stream;
mod option_flags;
mod perch;
mod planner;
mod plant_bridge;
mod plant_state;
mod plant_step;
mod plate_contact;
mod position;
mod qp;
mod resting_sleep;
mod rosserial;
mod rotor_arrays;
mod rotor_plant;
mod sample_schedule;
mod sensor_sim;
mod servo_goals;
mod spinal_commands;
mod spinal_mirror;
mod spinal_state;
mod stop_flag;
mod tick_counter;
mod untracked;

#[pymodule]
fn _rdm(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    model::register(m)?;
    estimate::register(m)?;
    attitude::register(m)?;
    lqi::register(m)?;
    position::register(m)?;
    flight_axes::register(m)?;
    finite_vector::register(m)?;
    perch::register(m)?;
    bench::register(m)?;
    qp::register(m)?;
    planner::register(m)?;
    plate_contact::register(m)?;
    foot_tracker::register(m)?;
    plant_state::register(m)?;
    plant_step::register(m)?;
    neuron_bank::register(m)?;
    sensor_sim::register(m)?;
    normal_stream::register(m)?;
    json_log::register(m)?;
    rotor_plant::register(m)?;
    resting_sleep::register(m)?;
    contact_gate::register(m)?;
    can_master::register(m)?;
    leptrino_scan::register(m)?;
    leptrino_sensor::register(m)?;
    capture_index::register(m)?;
    rosserial::register(m)?;
    kernel::register(m)?;
    stop_flag::register(m)?;
    tick_counter::register(m)?;
    spinal_mirror::register(m)?;
    spinal_state::register(m)?;
    spinal_commands::register(m)?;
    servo_goals::register(m)?;
    sample_schedule::register(m)?;
    plant_bridge::register(m)?;
    Ok(())
}
