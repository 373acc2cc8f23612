//! Whole-description rules the per-field checks cannot see: a robot that has mass, a
//! vectoring unit turned by two different joints, a wrench sensor of a known model.

use super::error::{DescriptionError, DescriptionErrorKind as Kind};

/// Wrench sensor models a description may name: the Leptrino sensors the link layer
/// decodes (`rdm.protocol.leptrino.MODELS`) and the paper's spelling of the end-effector
/// sensor, `CFS018CA201` (Sec. VI-B; the same ratings as `CFS018CA201U`).
pub const KNOWN_WRENCH_SENSORS: [&str; 5] = [
    "CFS034CA301U",
    "CFS018CA201U",
    "CFS018CA201",
    "PFS055YA501U6",
    "PFS080YS102U6",
];

/// The sum of the link masses must be above 0 (every quantity of the model divides by it).
pub(crate) fn check_total_mass(urdf_file: &str, masses: &[f64]) -> Result<(), DescriptionError> {
    let total: f64 = masses.iter().sum();
    if total > 0.0 {
        Ok(())
    } else {
        Err(DescriptionError::new(
            urdf_file,
            "<robot> <link>/<inertial>/<mass value>",
            Kind::InvalidValue,
            format!("total mass {total} kg: the link masses must sum to more than 0"),
        ))
    }
}

/// A vectoring unit's roll and pitch are two joints (eqs. 33-34 turn two axes).
pub(crate) fn check_unit_joints(
    toml_file: &str,
    field: &str,
    roll_joint: &str,
    pitch_joint: &str,
) -> Result<(), DescriptionError> {
    if roll_joint == pitch_joint {
        return Err(DescriptionError::new(
            toml_file,
            format!("{field}.pitch_joint"),
            Kind::InvalidValue,
            format!("joint '{pitch_joint}' is also the roll_joint: the two must differ"),
        ));
    }
    Ok(())
}

/// A sensor's `model` is one of [`KNOWN_WRENCH_SENSORS`].
pub(crate) fn check_sensor_model(
    toml_file: &str,
    field: &str,
    model: &str,
) -> Result<(), DescriptionError> {
    if KNOWN_WRENCH_SENSORS.contains(&model) {
        return Ok(());
    }
    Err(DescriptionError::new(
        toml_file,
        format!("{field}.model"),
        Kind::UnknownReference,
        format!(
            "unknown sensor model '{model}' (known: {})",
            KNOWN_WRENCH_SENSORS.join(", ")
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::super::{DescriptionErrorKind, RobotDescription};

    const URDF: &str = include_str!("../../../../python/rdm/data/robots/rdm/rdm.urdf");
    const TOML: &str = include_str!("../../../../python/rdm/data/robots/rdm/rdm.toml");

    fn refusal(urdf: &str, toml: &str) -> (DescriptionErrorKind, String) {
        let e = RobotDescription::from_strs(urdf, toml, "x.urdf", "x.toml").unwrap_err();
        (e.kind.clone(), e.to_string())
    }

    #[test]
    fn a_robot_without_mass_is_refused() {
        let mut urdf = String::new();
        for (k, part) in URDF.split("<mass value=\"").enumerate() {
            if k == 0 {
                urdf.push_str(part);
            } else {
                let rest = &part[part.find('"').unwrap()..];
                urdf.push_str("<mass value=\"0");
                urdf.push_str(rest);
            }
        }
        let (kind, text) = refusal(&urdf, TOML);
        assert_eq!(kind, DescriptionErrorKind::InvalidValue);
        assert!(text.starts_with("x.urdf: <robot>"), "{text}");
        assert!(text.contains("must sum to more than 0"), "{text}");
    }

    #[test]
    fn a_unit_turned_twice_by_one_joint_is_refused() {
        let toml = TOML.replacen("pitch_joint = \"beta1\"", "pitch_joint = \"alpha1\"", 1);
        assert_ne!(toml, TOML);
        let (kind, text) = refusal(URDF, &toml);
        assert_eq!(kind, DescriptionErrorKind::InvalidValue);
        assert!(
            text.starts_with("x.toml: vectoring_units[0] ('foot_unit').pitch_joint: "),
            "{text}"
        );
        assert!(text.contains("must differ"), "{text}");
    }

    #[test]
    fn an_unknown_sensor_model_is_refused() {
        let toml = TOML.replacen("model = \"CFS034CA301U\"", "model = \"XYZ\"", 1);
        assert_ne!(toml, TOML);
        let (kind, text) = refusal(URDF, &toml);
        assert_eq!(kind, DescriptionErrorKind::UnknownReference);
        assert!(
            text.starts_with("x.toml: sensors.foot_wrench.model: unknown sensor model 'XYZ'"),
            "{text}"
        );
    }
}
