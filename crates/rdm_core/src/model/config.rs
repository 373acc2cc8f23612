//! The TOML half of a robot description: what URDF cannot hold (rotors, servo stall
//! torques, joint order, named frames, foot plate, friction placeholders, wrench sensors).

use std::collections::BTreeMap;

use serde::Deserialize;

/// Top level of the TOML file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TomlDescription {
    pub name: String,
    /// URDF file name, relative to the TOML file (informational for `from_strs`).
    #[serde(default)]
    pub urdf: Option<String>,
    /// Order of `q` in every API.
    pub joint_order: Vec<String>,
    /// Named frames -> URDF link names; `foot` and `end_effector` are required.
    pub frames: BTreeMap<String, String>,
    pub foot: TomlFoot,
    #[serde(default)]
    pub vectoring_units: Vec<TomlUnit>,
    #[serde(default)]
    pub sensors: BTreeMap<String, TomlSensor>,
    pub joints: Vec<TomlJoint>,
    pub rotors: Vec<TomlRotor>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TomlFoot {
    pub plate_size: [f64; 2],
    pub friction_xy: f64,
    pub friction_z: f64,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TomlUnit {
    pub name: String,
    pub roll_joint: String,
    pub pitch_joint: String,
    pub rotors: Vec<String>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TomlSensor {
    pub frame: String,
    pub model: String,
    pub force_range: [f64; 3],
    pub torque_range: [f64; 3],
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TomlJoint {
    pub name: String,
    #[serde(default)]
    pub servo: Option<String>,
    pub stall_torque: f64,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TomlRotor {
    pub name: String,
    pub parent: String,
    pub offset: [f64; 3],
    pub axis: [f64; 3],
    pub spin: i32,
    pub drag_to_thrust: f64,
    pub thrust_min: f64,
    pub thrust_max: f64,
    pub diameter: f64,
}
