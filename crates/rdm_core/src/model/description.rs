//! `RobotDescription`: URDF kinematics/inertias plus the TOML extras, validated and
//! arranged for allocation-free evaluation (joints in topological order, ancestor lists).

use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Vector3};

use super::bounds::check_toml_numbers;
use super::config::TomlDescription;
use super::error::{DescriptionError, DescriptionErrorKind as Kind};
use super::rules;
use super::urdf::parse_urdf;

/// A rigid link: mass, centre of mass and inertia about it (link frame).
#[derive(Clone, Debug)]
pub struct Link {
    pub name: String,
    pub mass: f64,
    pub com: Vector3<f64>,
    pub inertia: Matrix3<f64>,
    /// Index of the joint whose child this link is (`None` for the root link).
    pub parent_joint: Option<usize>,
}

/// A joint; `axis` is `None` for fixed joints, `q_index` its position in `q`.
#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    pub parent_link: usize,
    pub child_link: usize,
    /// Child frame in the parent frame at zero angle.
    pub origin: Isometry3<f64>,
    /// Unit rotation axis in the child frame (URDF convention).
    pub axis: Option<Vector3<f64>>,
    pub lower: f64,
    pub upper: f64,
    pub q_index: Option<usize>,
}

/// A rotor: thrust `lambda * axis` (parent link frame) at `offset`, drag torque
/// `-c sigma lambda axis` (eq. 9).
#[derive(Clone, Debug)]
pub struct Rotor {
    pub name: String,
    pub link: usize,
    pub offset: Vector3<f64>,
    pub axis: Vector3<f64>,
    /// sigma_i = +-1.
    pub spin: f64,
    /// c of eq. (9) [N m per N].
    pub drag_to_thrust: f64,
    pub thrust_min: f64,
    pub thrust_max: f64,
    pub diameter: f64,
}

/// A dual-rotor vectoring apparatus (roll alpha, then pitch beta).
#[derive(Clone, Debug)]
pub struct VectoringUnit {
    pub name: String,
    /// `q` index of the roll joint alpha_i.
    pub roll_q: usize,
    /// `q` index of the pitch joint beta_i.
    pub pitch_q: usize,
    /// Link the roll joint is mounted on (frame L_i of eq. 36).
    pub parent_link: usize,
    /// Rotor indices carried by this unit.
    pub rotors: Vec<usize>,
}

/// A force/torque sensor and its rated ranges.
#[derive(Clone, Debug)]
pub struct WrenchSensor {
    pub name: String,
    pub link: usize,
    pub model: String,
    pub force_range: [f64; 3],
    pub torque_range: [f64; 3],
}

/// A complete, validated robot description.
#[derive(Clone, Debug)]
pub struct RobotDescription {
    pub name: String,
    pub links: Vec<Link>,
    /// Joints in topological order (a parent's joint before its children's).
    pub joints: Vec<Joint>,
    /// Index of the root link (the base whose pose is given).
    pub root_link: usize,
    /// Joint names in `q` order.
    pub joint_order: Vec<String>,
    /// For each `q` index: the joint index.
    pub q_joint: Vec<usize>,
    /// For each `q` index: servo stall torque [N m].
    pub stall_torque: Vec<f64>,
    /// For each `q` index: servo model name, if the TOML gives one.
    pub servo: Vec<Option<String>>,
    /// URDF file name the TOML refers to (relative to the TOML), if given.
    pub urdf_file: Option<String>,
    pub rotors: Vec<Rotor>,
    pub units: Vec<VectoringUnit>,
    /// Named frames (TOML `[frames]`) -> link index; always holds `foot` and `end_effector`.
    pub named_frames: Vec<(String, usize)>,
    pub foot_link: usize,
    pub end_effector_link: usize,
    /// Foot plate size x, y [m].
    pub plate_size: [f64; 2],
    pub friction_xy: f64,
    pub friction_z: f64,
    pub sensors: Vec<WrenchSensor>,
    /// For each link: `q` indices of the movable joints between the root and the link.
    pub ancestors: Vec<Vec<usize>>,
}

impl RobotDescription {
    /// Load from a URDF file and a TOML file; errors name the file and field.
    pub fn from_files(urdf: &Path, toml: &Path) -> Result<Self, DescriptionError> {
        let read = |p: &Path| {
            std::fs::read_to_string(p).map_err(|e| {
                DescriptionError::new(&p.display().to_string(), "", Kind::Io, e.to_string())
            })
        };
        let urdf_text = read(urdf)?;
        let toml_text = read(toml)?;
        Self::from_strs(
            &urdf_text,
            &toml_text,
            &urdf.display().to_string(),
            &toml.display().to_string(),
        )
    }

    /// Build from URDF and TOML text; `urdf_name`/`toml_name` name the sources in errors.
    pub fn from_strs(
        urdf_text: &str,
        toml_text: &str,
        urdf_name: &str,
        toml_name: &str,
    ) -> Result<Self, DescriptionError> {
        let urdf = parse_urdf(urdf_name, urdf_text)?;
        let cfg: TomlDescription = toml::from_str(toml_text).map_err(|e| {
            DescriptionError::new(toml_name, "", Kind::Syntax, e.to_string().trim().to_owned())
        })?;
        let (uf, tf) = (urdf_name, toml_name);
        check_toml_numbers(tf, &cfg)?;

        // Links and the tree structure.
        let mut links: Vec<Link> = Vec::with_capacity(urdf.links.len());
        for l in &urdf.links {
            if links.iter().any(|o| o.name == l.name) {
                return Err(DescriptionError::new(
                    uf,
                    format!("link '{}'", l.name),
                    Kind::Structure,
                    "duplicate link name",
                ));
            }
            links.push(Link {
                name: l.name.clone(),
                mass: l.mass,
                com: l.com,
                inertia: l.inertia,
                parent_joint: None,
            });
        }
        let link_index = |name: &str| urdf.links.iter().position(|l| l.name == name);
        let mut raw = Vec::with_capacity(urdf.joints.len());
        for j in &urdf.joints {
            let field = format!("joint '{}'", j.name);
            if urdf.joints.iter().filter(|o| o.name == j.name).count() > 1 {
                return Err(DescriptionError::new(
                    uf,
                    field,
                    Kind::Structure,
                    "duplicate joint name",
                ));
            }
            let parent = link_index(&j.parent).ok_or_else(|| {
                DescriptionError::new(
                    uf,
                    format!("{field}/<parent>"),
                    Kind::UnknownReference,
                    format!("unknown link '{}'", j.parent),
                )
            })?;
            let child = link_index(&j.child).ok_or_else(|| {
                DescriptionError::new(
                    uf,
                    format!("{field}/<child>"),
                    Kind::UnknownReference,
                    format!("unknown link '{}'", j.child),
                )
            })?;
            raw.push((parent, child));
        }
        for (ji, &(_, child)) in raw.iter().enumerate() {
            if links[child].parent_joint.is_some() {
                return Err(DescriptionError::new(
                    uf,
                    format!("link '{}'", links[child].name),
                    Kind::Structure,
                    "link is the child of two joints",
                ));
            }
            links[child].parent_joint = Some(ji);
        }
        let roots: Vec<usize> = (0..links.len())
            .filter(|&i| links[i].parent_joint.is_none())
            .collect();
        if roots.len() != 1 {
            return Err(DescriptionError::new(
                uf,
                "<robot>",
                Kind::Structure,
                format!("expected exactly one root link, found {}", roots.len()),
            ));
        }
        let root_link = roots[0];
        let masses: Vec<f64> = links.iter().map(|l| l.mass).collect();
        rules::check_total_mass(uf, &masses)?;

        // Topological order of joints (breadth first from the root).
        let mut order: Vec<usize> = Vec::with_capacity(raw.len());
        let mut frontier = vec![root_link];
        while let Some(link) = frontier.pop() {
            for (ji, &(parent, child)) in raw.iter().enumerate() {
                if parent == link {
                    order.push(ji);
                    frontier.push(child);
                }
            }
            if order.len() > raw.len() {
                break;
            }
        }
        if order.len() != raw.len() {
            return Err(DescriptionError::new(
                uf,
                "<robot>",
                Kind::Structure,
                "joints do not form a tree rooted at one link (cycle or detached part)",
            ));
        }
        let mut new_index = vec![0usize; raw.len()];
        for (new, &old) in order.iter().enumerate() {
            new_index[old] = new;
        }
        for link in &mut links {
            link.parent_joint = link.parent_joint.map(|j| new_index[j]);
        }

        // Joint order from the TOML; every movable URDF joint must be listed exactly once.
        let mut joints: Vec<Joint> = order
            .iter()
            .map(|&old| {
                let j = &urdf.joints[old];
                Joint {
                    name: j.name.clone(),
                    parent_link: raw[old].0,
                    child_link: raw[old].1,
                    origin: j.origin,
                    axis: j.axis,
                    lower: j.lower,
                    upper: j.upper,
                    q_index: None,
                }
            })
            .collect();
        let mut q_joint = Vec::with_capacity(cfg.joint_order.len());
        for (qi, name) in cfg.joint_order.iter().enumerate() {
            let field = format!("joint_order[{qi}]");
            let ji = joints.iter().position(|j| &j.name == name).ok_or_else(|| {
                DescriptionError::new(
                    tf,
                    &field,
                    Kind::UnknownReference,
                    format!("joint '{name}' is missing from {uf}"),
                )
            })?;
            if joints[ji].axis.is_none() {
                return Err(DescriptionError::new(
                    tf,
                    field,
                    Kind::InvalidValue,
                    format!("joint '{name}' is fixed in {uf}"),
                ));
            }
            if joints[ji].q_index.is_some() {
                return Err(DescriptionError::new(
                    tf,
                    field,
                    Kind::Structure,
                    format!("joint '{name}' listed twice"),
                ));
            }
            joints[ji].q_index = Some(qi);
            q_joint.push(ji);
        }
        if let Some(j) = joints
            .iter()
            .find(|j| j.axis.is_some() && j.q_index.is_none())
        {
            return Err(DescriptionError::new(
                tf,
                "joint_order",
                Kind::Missing,
                format!("movable joint '{}' of {uf} is not listed", j.name),
            ));
        }

        // Stall torques.
        let mut stall_torque = vec![f64::NAN; q_joint.len()];
        let mut servo = vec![None; q_joint.len()];
        for (k, j) in cfg.joints.iter().enumerate() {
            let field = format!("joints[{k}] ('{}')", j.name);
            let qi = cfg
                .joint_order
                .iter()
                .position(|n| n == &j.name)
                .ok_or_else(|| {
                    DescriptionError::new(
                        tf,
                        &field,
                        Kind::UnknownReference,
                        "joint not in joint_order",
                    )
                })?;
            if j.stall_torque <= 0.0 {
                return Err(DescriptionError::new(
                    tf,
                    format!("{field}.stall_torque"),
                    Kind::InvalidValue,
                    "must be positive",
                ));
            }
            stall_torque[qi] = j.stall_torque;
            servo[qi].clone_from(&j.servo);
        }
        if let Some(qi) = stall_torque.iter().position(|t| t.is_nan()) {
            return Err(DescriptionError::new(
                tf,
                "joints",
                Kind::Missing,
                format!(
                    "no [[joints]] entry (stall_torque) for '{}'",
                    cfg.joint_order[qi]
                ),
            ));
        }

        // Rotors.
        let mut rotors = Vec::with_capacity(cfg.rotors.len());
        for (k, r) in cfg.rotors.iter().enumerate() {
            let field = format!("rotors[{k}] ('{}')", r.name);
            let link = link_index(&r.parent).ok_or_else(|| {
                DescriptionError::new(
                    tf,
                    format!("{field}.parent"),
                    Kind::UnknownReference,
                    format!("unknown link '{}' (not in {uf})", r.parent),
                )
            })?;
            let axis = Vector3::from(r.axis);
            if axis.norm() < 1e-9 {
                return Err(DescriptionError::new(
                    tf,
                    format!("{field}.axis"),
                    Kind::InvalidValue,
                    "zero-length axis",
                ));
            }
            if r.spin != 1 && r.spin != -1 {
                return Err(DescriptionError::new(
                    tf,
                    format!("{field}.spin"),
                    Kind::InvalidValue,
                    format!("spin must be +1 or -1, got {}", r.spin),
                ));
            }
            if r.thrust_min < 0.0 || r.thrust_min > r.thrust_max {
                return Err(DescriptionError::new(
                    tf,
                    format!("{field}.thrust_min"),
                    Kind::InvalidValue,
                    format!(
                        "need 0 <= thrust_min <= thrust_max, got {} and {}",
                        r.thrust_min, r.thrust_max
                    ),
                ));
            }
            if r.drag_to_thrust < 0.0 || r.diameter <= 0.0 {
                return Err(DescriptionError::new(
                    tf,
                    &field,
                    Kind::InvalidValue,
                    "drag_to_thrust must be >= 0 and diameter > 0",
                ));
            }
            if rotors.iter().any(|o: &Rotor| o.name == r.name) {
                return Err(DescriptionError::new(
                    tf,
                    field,
                    Kind::Structure,
                    "duplicate rotor name",
                ));
            }
            rotors.push(Rotor {
                name: r.name.clone(),
                link,
                offset: Vector3::from(r.offset),
                axis: axis / axis.norm(),
                spin: f64::from(r.spin),
                drag_to_thrust: r.drag_to_thrust,
                thrust_min: r.thrust_min,
                thrust_max: r.thrust_max,
                diameter: r.diameter,
            });
        }

        // Vectoring apparatuses.
        let q_of = |field: &str, name: &str| {
            cfg.joint_order
                .iter()
                .position(|n| n == name)
                .ok_or_else(|| {
                    DescriptionError::new(
                        tf,
                        field,
                        Kind::UnknownReference,
                        format!("joint '{name}' not in joint_order"),
                    )
                })
        };
        let mut units = Vec::with_capacity(cfg.vectoring_units.len());
        for (k, u) in cfg.vectoring_units.iter().enumerate() {
            let field = format!("vectoring_units[{k}] ('{}')", u.name);
            rules::check_unit_joints(tf, &field, &u.roll_joint, &u.pitch_joint)?;
            let roll_q = q_of(&format!("{field}.roll_joint"), &u.roll_joint)?;
            let pitch_q = q_of(&format!("{field}.pitch_joint"), &u.pitch_joint)?;
            let mut unit_rotors = Vec::with_capacity(u.rotors.len());
            for name in &u.rotors {
                let ri = rotors.iter().position(|r| &r.name == name).ok_or_else(|| {
                    DescriptionError::new(
                        tf,
                        format!("{field}.rotors"),
                        Kind::UnknownReference,
                        format!("unknown rotor '{name}'"),
                    )
                })?;
                unit_rotors.push(ri);
            }
            units.push(VectoringUnit {
                name: u.name.clone(),
                roll_q,
                pitch_q,
                parent_link: joints[q_joint[roll_q]].parent_link,
                rotors: unit_rotors,
            });
        }

        // Named frames, foot plate, sensors.
        let mut named_frames = Vec::with_capacity(cfg.frames.len());
        for (name, link) in &cfg.frames {
            let li = link_index(link).ok_or_else(|| {
                DescriptionError::new(
                    tf,
                    format!("frames.{name}"),
                    Kind::UnknownReference,
                    format!("unknown link '{link}' (not in {uf})"),
                )
            })?;
            named_frames.push((name.clone(), li));
        }
        let named = |name: &str| {
            named_frames
                .iter()
                .find(|(n, _)| n == name)
                .map(|&(_, l)| l)
                .ok_or_else(|| {
                    DescriptionError::new(
                        tf,
                        format!("frames.{name}"),
                        Kind::Missing,
                        "required frame",
                    )
                })
        };
        let foot_link = named("foot")?;
        let end_effector_link = named("end_effector")?;
        let foot = &cfg.foot;
        if foot.plate_size.iter().any(|&s| s < 0.0)
            || foot.friction_xy < 0.0
            || foot.friction_z < 0.0
        {
            return Err(DescriptionError::new(
                tf,
                "foot",
                Kind::InvalidValue,
                "plate size and friction coefficients must be >= 0",
            ));
        }
        let mut sensors = Vec::with_capacity(cfg.sensors.len());
        for (name, s) in &cfg.sensors {
            let field = format!("sensors.{name}");
            rules::check_sensor_model(tf, &field, &s.model)?;
            let link = match named_frames.iter().find(|(n, _)| n == &s.frame) {
                Some(&(_, l)) => l,
                None => link_index(&s.frame).ok_or_else(|| {
                    DescriptionError::new(
                        tf,
                        format!("{field}.frame"),
                        Kind::UnknownReference,
                        format!("unknown frame '{}'", s.frame),
                    )
                })?,
            };
            sensors.push(WrenchSensor {
                name: name.clone(),
                link,
                model: s.model.clone(),
                force_range: s.force_range,
                torque_range: s.torque_range,
            });
        }

        // Movable ancestors of every link.
        let mut ancestors = vec![Vec::new(); links.len()];
        for j in &joints {
            let mut list = ancestors[j.parent_link].clone();
            if let Some(qi) = j.q_index {
                list.push(qi);
            }
            ancestors[j.child_link] = list;
        }

        Ok(Self {
            name: cfg.name,
            links,
            joints,
            root_link,
            joint_order: cfg.joint_order,
            q_joint,
            stall_torque,
            servo,
            urdf_file: cfg.urdf,
            rotors,
            units,
            named_frames,
            foot_link,
            end_effector_link,
            plate_size: foot.plate_size,
            friction_xy: foot.friction_xy,
            friction_z: foot.friction_z,
            sensors,
            ancestors,
        })
    }

    /// Number of entries of `q`.
    pub fn n_q(&self) -> usize {
        self.q_joint.len()
    }

    /// Number of rotors.
    pub fn n_rotors(&self) -> usize {
        self.rotors.len()
    }

    /// Total mass [kg].
    pub fn total_mass(&self) -> f64 {
        self.links.iter().map(|l| l.mass).sum()
    }

    /// Position limits (lower, upper) of each `q` entry.
    pub fn joint_limits(&self) -> Vec<(f64, f64)> {
        self.q_joint
            .iter()
            .map(|&j| (self.joints[j].lower, self.joints[j].upper))
            .collect()
    }
}
