//! Physical bounds on the numbers of a robot description, checked when it is loaded.
//!
//! Finite is not enough: a joint origin of `-1e308` m is finite, yet the products the model
//! forms with it (`m r^2` of the composite inertia, the centre of gravity) overflow, and
//! `evaluate` would return NaN or infinity. Every length, mass, inertia, angle, force and
//! torque of a description is therefore bounded to a range far outside any aerial robot and
//! far inside the double's: with these bounds the model's sums and products stay finite for
//! any tree a description file can hold.
//!
//! ASSUMPTION (not from the paper; listed in docs/model.md): the bounds below.

use super::config::TomlDescription;
use super::error::{DescriptionError, DescriptionErrorKind as Kind};

/// Largest magnitude of a length [m]: origins, centres of mass, rotor offsets, the drag
/// length c of eq. (9), rotor diameters, the foot plate. ASSUMPTION.
pub const MAX_LENGTH: f64 = 1e3;
/// Largest link mass [kg]; a mass is in `[0, MAX_MASS]` (0: a massless frame). ASSUMPTION.
pub const MAX_MASS: f64 = 1e4;
/// Largest magnitude of an inertia tensor entry [kg m^2]: a body of `MAX_MASS` all at
/// `MAX_LENGTH` from its centre. ASSUMPTION.
pub const MAX_INERTIA: f64 = MAX_MASS * MAX_LENGTH * MAX_LENGTH;
/// Largest magnitude of an angle [rad]: origin roll/pitch/yaw, revolute joint limits.
/// ASSUMPTION.
pub const MAX_ANGLE: f64 = 1e3;
/// Largest magnitude of an axis component (an axis is normalised; its norm must not
/// overflow). ASSUMPTION.
pub const MAX_AXIS: f64 = 1e3;
/// Largest force [N]: rotor thrust limits, force sensor ranges. ASSUMPTION.
pub const MAX_FORCE: f64 = 1e5;
/// Largest torque [N m]: servo stall torques, torque sensor ranges. ASSUMPTION.
pub const MAX_TORQUE: f64 = 1e5;
/// Largest friction coefficient. ASSUMPTION.
pub const MAX_FRICTION: f64 = 1e2;

/// What a bounded number is: the rule's name, its bound and unit.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Bound {
    pub what: &'static str,
    pub max: f64,
    pub unit: &'static str,
}

pub(crate) const LENGTH: Bound = Bound {
    what: "length",
    max: MAX_LENGTH,
    unit: " m",
};
pub(crate) const MASS: Bound = Bound {
    what: "mass",
    max: MAX_MASS,
    unit: " kg",
};
pub(crate) const INERTIA: Bound = Bound {
    what: "inertia",
    max: MAX_INERTIA,
    unit: " kg m^2",
};
pub(crate) const ANGLE: Bound = Bound {
    what: "angle",
    max: MAX_ANGLE,
    unit: " rad",
};
pub(crate) const AXIS: Bound = Bound {
    what: "axis component",
    max: MAX_AXIS,
    unit: "",
};
pub(crate) const FORCE: Bound = Bound {
    what: "force",
    max: MAX_FORCE,
    unit: " N",
};
pub(crate) const TORQUE: Bound = Bound {
    what: "torque",
    max: MAX_TORQUE,
    unit: " N m",
};
pub(crate) const FRICTION: Bound = Bound {
    what: "friction coefficient",
    max: MAX_FRICTION,
    unit: "",
};

/// Every value finite (else a `NonFinite` error naming `field`).
pub(crate) fn finite(file: &str, field: &str, values: &[f64]) -> Result<(), DescriptionError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(DescriptionError::new(
            file,
            field,
            Kind::NonFinite,
            "NaN or infinite value",
        ))
    }
}

/// Every value finite and within `|x| <= bound.max` (else an error naming `field` and the
/// rule).
pub(crate) fn bounded(
    file: &str,
    field: &str,
    values: &[f64],
    bound: Bound,
) -> Result<(), DescriptionError> {
    finite(file, field, values)?;
    match values.iter().find(|v| v.abs() > bound.max) {
        None => Ok(()),
        Some(v) => Err(DescriptionError::new(
            file,
            field,
            Kind::InvalidValue,
            format!(
                "{v:e} is outside the {} bound |x| <= {}{}",
                bound.what, bound.max, bound.unit
            ),
        )),
    }
}

/// Every number of the TOML half within its bound (the URDF reader bounds its own numbers
/// as it reads them); `tf` names the file in errors.
pub(crate) fn check_toml_numbers(tf: &str, cfg: &TomlDescription) -> Result<(), DescriptionError> {
    for (k, j) in cfg.joints.iter().enumerate() {
        let field = format!("joints[{k}] ('{}').stall_torque", j.name);
        bounded(tf, &field, &[j.stall_torque], TORQUE)?;
    }
    for (k, r) in cfg.rotors.iter().enumerate() {
        let field = format!("rotors[{k}] ('{}')", r.name);
        bounded(tf, &format!("{field}.offset"), &r.offset, LENGTH)?;
        bounded(tf, &format!("{field}.axis"), &r.axis, AXIS)?;
        let lengths = [r.drag_to_thrust, r.diameter];
        bounded(
            tf,
            &format!("{field}.drag_to_thrust/diameter"),
            &lengths,
            LENGTH,
        )?;
        let thrust = [r.thrust_min, r.thrust_max];
        bounded(
            tf,
            &format!("{field}.thrust_min/thrust_max"),
            &thrust,
            FORCE,
        )?;
    }
    let foot = &cfg.foot;
    bounded(tf, "foot.plate_size", &foot.plate_size, LENGTH)?;
    let friction = [foot.friction_xy, foot.friction_z];
    bounded(tf, "foot.friction_xy/friction_z", &friction, FRICTION)?;
    for (name, s) in &cfg.sensors {
        bounded(
            tf,
            &format!("sensors.{name}.force_range"),
            &s.force_range,
            FORCE,
        )?;
        bounded(
            tf,
            &format!("sensors.{name}.torque_range"),
            &s.torque_range,
            TORQUE,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_past_its_bound_is_named_with_the_rule() {
        assert!(bounded("f", "x", &[0.4, -1e3, 1e3], LENGTH).is_ok());
        let err = bounded("r.urdf", "joint 'a'/<origin xyz>", &[0.4, -1e308], LENGTH)
            .expect_err("refused");
        assert_eq!(err.kind, Kind::InvalidValue);
        assert_eq!(
            err.to_string(),
            "r.urdf: joint 'a'/<origin xyz>: -1e308 is outside the length bound |x| <= 1000 m"
        );
        let err = bounded("f", "x", &[f64::NAN], MASS).expect_err("refused");
        assert_eq!(err.kind, Kind::NonFinite);
    }

    const URDF: &str = include_str!("../../../../python/rdm/data/robots/rdm/rdm.urdf");
    const TOML: &str = include_str!("../../../../python/rdm/data/robots/rdm/rdm.toml");

    fn refusal(urdf: &str, toml: &str) -> String {
        let e = crate::model::RobotDescription::from_strs(urdf, toml, "x.urdf", "x.toml")
            .expect_err("refused");
        assert_eq!(e.kind, Kind::InvalidValue, "{e}");
        e.to_string()
    }

    #[test]
    fn numbers_past_the_bounds_are_refused_by_the_loader() {
        // fuzz/regressions/description/origin-1e308: a joint origin near the double's limit
        let urdf = URDF.replacen(
            "<origin xyz=\"0.4 0 0\" rpy=\"0 0 0\"/>\n    <axis xyz=\"1 0 0\"/>",
            "<origin xyz=\"0.4 -1e308 0\" rpy=\"0 0 0\"/>\n    <axis xyz=\"1 0 0\"/>",
            1,
        );
        assert_ne!(urdf, URDF);
        assert_eq!(
            refusal(&urdf, TOML),
            "x.urdf: joint 'alpha1'/<origin xyz>: -1e308 is outside the length bound |x| <= 1000 m"
        );
        let urdf = URDF.replacen("<mass value=\"0.35\"/>", "<mass value=\"2e4\"/>", 1);
        let text = refusal(&urdf, TOML);
        assert!(
            text.contains("link 'foot' <inertial>/<mass value>"),
            "{text}"
        );
        assert!(text.contains("mass bound |x| <= 10000 kg"), "{text}");
        let urdf = URDF.replacen("ixx=\"0.00076125\"", "ixx=\"1e300\"", 1);
        assert!(refusal(&urdf, TOML).contains("<inertia ixx>: 1e300 is outside the inertia bound"));
        let urdf = URDF.replacen("<axis xyz=\"1 0 0\"/>", "<axis xyz=\"1e308 1e308 0\"/>", 1);
        assert!(refusal(&urdf, TOML).contains("<axis xyz>: 1e308 is outside"));
        let toml = TOML.replacen(
            "offset = [0.0, 0.07, 0.03]",
            "offset = [0.0, 1e308, 0.03]",
            1,
        );
        assert_eq!(
            refusal(URDF, &toml),
            "x.toml: rotors[0] ('rotor1').offset: 1e308 is outside the length bound |x| <= 1000 m"
        );
        let toml = TOML.replacen("thrust_max = 20", "thrust_max = 1e6", 1);
        assert!(refusal(URDF, &toml).contains("thrust_min/thrust_max: 1e6 is outside the force"));
    }

    #[test]
    fn the_bounds_keep_the_model_products_finite() {
        // Composite inertia of a chain: sum of m r^2 with r up to (number of links) x
        // MAX_LENGTH; a million links at the bounds stay many orders below the double's.
        let links = 1e6;
        let r = links * MAX_LENGTH;
        assert!((links * (MAX_INERTIA + MAX_MASS * r * r)).is_finite());
        assert!(links * (MAX_INERTIA + MAX_MASS * r * r) < 1e40);
    }
}
