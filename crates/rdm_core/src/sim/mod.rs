//! Simulation-side models that run every simulated millisecond next to the plant: sensor
//! error models and the sensor-side encoding of what a simulated sensor sends. They mirror
//! the Python reference forms in `rdm.plant.sensors` / `rdm.protocol.leptrino` operation for
//! operation, so a run gives the same bytes with either. The plant bridge's state
//! (`bridge_state`), the plant's lazy forward pass (`plant_state`), the foot's contact anchor
//! (`foot_track`), the bridge's sampling schedule (`sample_schedule`) and the lockstep loop's node
//! schedule (`tick_schedule`) have this one form.

pub mod bridge_state;
pub mod contact_gate;
pub mod esc_duty;
pub mod fixed_decimals;
pub mod foot_track;
pub mod json_text;
pub mod leptrino_sensor;
pub mod leptrino_stream;
pub mod mcap_chunk;
pub mod normal_stream;
pub mod plant_state;
pub mod plate_contact;
pub mod python_float_repr;
pub mod resting_sleep;
pub mod rotor_plant;
pub mod sample_schedule;
pub mod sensor_noise;
pub mod tick_schedule;
