//! URDF reading (kinematics and inertias only): links with `<inertial>`, revolute,
//! continuous and fixed joints. Geometry, meshes and other tags are ignored.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use roxmltree::{Document, Node};

use super::bounds::{bounded, Bound, ANGLE, AXIS, INERTIA, LENGTH, MASS};
use super::error::{DescriptionError, DescriptionErrorKind as Kind};

/// A URDF link: mass, centre of mass and inertia about it, both in the link frame.
#[derive(Clone, Debug)]
pub(crate) struct UrdfLink {
    pub name: String,
    pub mass: f64,
    pub com: Vector3<f64>,
    pub inertia: Matrix3<f64>,
}

/// A URDF joint; `axis` is `None` for fixed joints.
#[derive(Clone, Debug)]
pub(crate) struct UrdfJoint {
    pub name: String,
    pub parent: String,
    pub child: String,
    pub origin: Isometry3<f64>,
    pub axis: Option<Vector3<f64>>,
    pub lower: f64,
    pub upper: f64,
}

/// The parsed URDF.
#[derive(Clone, Debug)]
pub(crate) struct Urdf {
    pub links: Vec<UrdfLink>,
    pub joints: Vec<UrdfJoint>,
}

fn number(file: &str, field: &str, text: &str) -> Result<f64, DescriptionError> {
    let value: f64 = text.trim().parse().map_err(|_| {
        DescriptionError::new(
            file,
            field,
            Kind::Syntax,
            format!("'{text}' is not a number"),
        )
    })?;
    if !value.is_finite() {
        return Err(DescriptionError::new(
            file,
            field,
            Kind::NonFinite,
            format!("'{text}' is not finite"),
        ));
    }
    Ok(value)
}

/// A number within `bound` (see `model::bounds`).
fn bounded_number(
    file: &str,
    field: &str,
    text: &str,
    bound: Bound,
) -> Result<f64, DescriptionError> {
    let value = number(file, field, text)?;
    bounded(file, field, &[value], bound)?;
    Ok(value)
}

fn triple(
    file: &str,
    field: &str,
    text: &str,
    bound: Bound,
) -> Result<Vector3<f64>, DescriptionError> {
    let parts: Vec<&str> = text.split_whitespace().collect();
    if parts.len() != 3 {
        return Err(DescriptionError::new(
            file,
            field,
            Kind::Syntax,
            format!("expected 3 numbers, got '{text}'"),
        ));
    }
    Ok(Vector3::new(
        bounded_number(file, field, parts[0], bound)?,
        bounded_number(file, field, parts[1], bound)?,
        bounded_number(file, field, parts[2], bound)?,
    ))
}

fn attr<'a>(
    file: &str,
    field: &str,
    node: Node<'a, '_>,
    name: &str,
) -> Result<&'a str, DescriptionError> {
    node.attribute(name).ok_or_else(|| {
        DescriptionError::new(
            file,
            field,
            Kind::Missing,
            format!("missing attribute '{name}'"),
        )
    })
}

fn child<'a, 'i>(node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|c| c.has_tag_name(tag))
}

/// `<origin xyz rpy>` as an isometry (URDF: R = Rz(yaw) Ry(pitch) Rx(roll)); identity if absent.
fn origin(file: &str, field: &str, node: Node<'_, '_>) -> Result<Isometry3<f64>, DescriptionError> {
    let Some(o) = child(node, "origin") else {
        return Ok(Isometry3::identity());
    };
    let xyz = match o.attribute("xyz") {
        Some(t) => triple(file, &format!("{field}/<origin xyz>"), t, LENGTH)?,
        None => Vector3::zeros(),
    };
    let rpy = match o.attribute("rpy") {
        Some(t) => triple(file, &format!("{field}/<origin rpy>"), t, ANGLE)?,
        None => Vector3::zeros(),
    };
    let rotation = Rotation3::from_euler_angles(rpy.x, rpy.y, rpy.z);
    Ok(Isometry3::from_parts(
        Translation3::from(xyz),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

fn parse_link(file: &str, node: Node<'_, '_>) -> Result<UrdfLink, DescriptionError> {
    let name = attr(file, "<link>", node, "name")?.to_owned();
    let field = format!("link '{name}'");
    let Some(inertial) = child(node, "inertial") else {
        return Ok(UrdfLink {
            name,
            mass: 0.0,
            com: Vector3::zeros(),
            inertia: Matrix3::zeros(),
        });
    };
    let ifield = format!("{field} <inertial>");
    let mass_node = child(inertial, "mass")
        .ok_or_else(|| DescriptionError::new(file, &ifield, Kind::Missing, "missing <mass>"))?;
    let mfield = format!("{ifield}/<mass value>");
    let mass = number(file, &mfield, attr(file, &mfield, mass_node, "value")?)?;
    if mass < 0.0 {
        return Err(DescriptionError::new(
            file,
            mfield,
            Kind::NegativeMass,
            format!("negative mass {mass}"),
        ));
    }
    bounded(file, &mfield, &[mass], MASS)?;
    let frame = origin(file, &ifield, inertial)?;
    let inertia = match child(inertial, "inertia") {
        Some(i) => {
            let mut v = [0.0; 6];
            for (k, key) in ["ixx", "ixy", "ixz", "iyy", "iyz", "izz"]
                .iter()
                .enumerate()
            {
                let f = format!("{ifield}/<inertia {key}>");
                v[k] = bounded_number(file, &f, attr(file, &f, i, key)?, INERTIA)?;
            }
            Matrix3::new(v[0], v[1], v[2], v[1], v[3], v[4], v[2], v[4], v[5])
        }
        None => Matrix3::zeros(),
    };
    // Principal moments of a physical body are non-negative and obey the triangle inequality.
    let eig = inertia.symmetric_eigen().eigenvalues;
    let tol = 1e-12 * (1.0 + eig.abs().max());
    let (a, b, c) = (eig[0], eig[1], eig[2]);
    if eig.min() < -tol || a + b < c - tol || b + c < a - tol || a + c < b - tol {
        return Err(DescriptionError::new(
            file,
            format!("{ifield}/<inertia>"),
            Kind::NegativeMass,
            format!("not a physical inertia tensor (principal moments {a}, {b}, {c})"),
        ));
    }
    let rotation = frame.rotation.to_rotation_matrix();
    Ok(UrdfLink {
        name,
        mass,
        com: frame.translation.vector,
        inertia: rotation.matrix() * inertia * rotation.matrix().transpose(),
    })
}

fn parse_joint(file: &str, node: Node<'_, '_>) -> Result<UrdfJoint, DescriptionError> {
    let name = attr(file, "<joint>", node, "name")?.to_owned();
    let field = format!("joint '{name}'");
    let kind = attr(file, &field, node, "type")?;
    let link_of = |tag: &str| -> Result<String, DescriptionError> {
        let f = format!("{field}/<{tag}>");
        let n = child(node, tag).ok_or_else(|| {
            DescriptionError::new(file, &f, Kind::Missing, format!("missing <{tag}>"))
        })?;
        Ok(attr(file, &f, n, "link")?.to_owned())
    };
    let parent = link_of("parent")?;
    let child_link = link_of("child")?;
    let origin = origin(file, &field, node)?;
    let (axis, lower, upper) = match kind {
        "fixed" => (None, 0.0, 0.0),
        "revolute" | "continuous" => {
            let axis = match child(node, "axis").and_then(|a| a.attribute("xyz")) {
                Some(t) => triple(file, &format!("{field}/<axis xyz>"), t, AXIS)?,
                None => Vector3::x(), // URDF default axis
            };
            let norm = axis.norm();
            if norm < 1e-9 {
                return Err(DescriptionError::new(
                    file,
                    format!("{field}/<axis xyz>"),
                    Kind::InvalidValue,
                    "zero-length axis",
                ));
            }
            let (lower, upper) = if kind == "continuous" {
                (f64::NEG_INFINITY, f64::INFINITY)
            } else {
                let f = format!("{field}/<limit>");
                let l = child(node, "limit").ok_or_else(|| {
                    DescriptionError::new(file, &f, Kind::Missing, "revolute joint needs <limit>")
                })?;
                let lower = match l.attribute("lower") {
                    Some(t) => bounded_number(file, &format!("{f} lower"), t, ANGLE)?,
                    None => 0.0,
                };
                let upper = match l.attribute("upper") {
                    Some(t) => bounded_number(file, &format!("{f} upper"), t, ANGLE)?,
                    None => 0.0,
                };
                if lower > upper {
                    return Err(DescriptionError::new(
                        file,
                        f,
                        Kind::InvalidValue,
                        format!("lower {lower} > upper {upper}"),
                    ));
                }
                (lower, upper)
            };
            (Some(axis / norm), lower, upper)
        }
        other => {
            return Err(DescriptionError::new(
                file,
                format!("{field} type"),
                Kind::InvalidValue,
                format!("unsupported joint type '{other}' (revolute, continuous, fixed)"),
            ))
        }
    };
    Ok(UrdfJoint {
        name,
        parent,
        child: child_link,
        origin,
        axis,
        lower,
        upper,
    })
}

/// Deepest element nesting a URDF may have. Real descriptions nest about 5 deep
/// (robot/link/visual/geometry/mesh); the XML parser recurses per level, and a file nested
/// tens of thousands deep would overflow the stack.
pub const MAX_URDF_DEPTH: usize = 1000;

/// The deepest element nesting of XML `text` (a byte scan: comments, processing
/// instructions, CDATA and declarations skipped; quoted attribute values skipped). Stops
/// counting past `limit + 1`.
pub fn xml_element_depth(text: &str, limit: usize) -> usize {
    let b = text.as_bytes();
    let (mut i, mut depth, mut deepest) = (0usize, 0usize, 0usize);
    let skip_to = |from: usize, end: &[u8]| -> usize {
        b[from..]
            .windows(end.len())
            .position(|w| w == end)
            .map_or(b.len(), |p| from + p + end.len())
    };
    while i < b.len() {
        if b[i] != b'<' {
            i += 1;
            continue;
        }
        let rest = &b[i..];
        if rest.starts_with(b"<!--") {
            i = skip_to(i + 4, b"-->");
        } else if rest.starts_with(b"<![CDATA[") {
            i = skip_to(i + 9, b"]]>");
        } else if rest.starts_with(b"<?") {
            i = skip_to(i + 2, b"?>");
        } else if rest.starts_with(b"<!") {
            i = skip_to(i + 2, b">");
        } else if rest.starts_with(b"</") {
            depth = depth.saturating_sub(1);
            i = skip_to(i + 2, b">");
        } else {
            // an opening tag: find its end outside quoted attribute values
            let mut j = i + 1;
            let mut quote = 0u8;
            while j < b.len() {
                let c = b[j];
                if quote != 0 {
                    if c == quote {
                        quote = 0;
                    }
                } else if c == b'"' || c == b'\'' {
                    quote = c;
                } else if c == b'>' {
                    break;
                }
                j += 1;
            }
            let self_closing = j > i + 1 && j < b.len() && b[j - 1] == b'/';
            if !self_closing {
                depth += 1;
                deepest = deepest.max(depth);
                if deepest > limit {
                    return deepest;
                }
            }
            i = j + 1;
        }
    }
    deepest
}

/// Parse URDF text; `file` names the source in errors.
pub(crate) fn parse_urdf(file: &str, text: &str) -> Result<Urdf, DescriptionError> {
    if xml_element_depth(text, MAX_URDF_DEPTH) > MAX_URDF_DEPTH {
        return Err(DescriptionError::new(
            file,
            "",
            Kind::Syntax,
            format!("elements nested deeper than {MAX_URDF_DEPTH}"),
        ));
    }
    let doc = Document::parse(text).map_err(|e| {
        DescriptionError::new(file, "", Kind::Syntax, format!("malformed XML: {e}"))
    })?;
    let robot = doc.root_element();
    if !robot.has_tag_name("robot") {
        return Err(DescriptionError::new(
            file,
            "<robot>",
            Kind::Missing,
            "root element is not <robot>",
        ));
    }
    let mut links = Vec::new();
    let mut joints = Vec::new();
    for node in robot.children().filter(|n| n.is_element()) {
        if node.has_tag_name("link") {
            links.push(parse_link(file, node)?);
        } else if node.has_tag_name("joint") {
            joints.push(parse_joint(file, node)?);
        }
    }
    Ok(Urdf { links, joints })
}

#[cfg(test)]
mod depth_tests {
    use super::*;

    #[test]
    fn depth_counts_elements_and_skips_the_rest() {
        assert_eq!(xml_element_depth("<a><b/><c><d></d></c></a>", 100), 3);
        let tricky =
            "<?xml version='1.0'?><!-- <x><y><z> --><r a='<>' b=\"/>\"><![CDATA[<q><q>]]></r>";
        assert_eq!(xml_element_depth(tricky, 100), 1);
        let deep = "<a>".repeat(20_000) + &"</a>".repeat(20_000);
        assert_eq!(xml_element_depth(&deep, MAX_URDF_DEPTH), MAX_URDF_DEPTH + 1);
    }

    #[test]
    fn a_urdf_nested_20000_deep_is_refused_without_parsing() {
        let deep = format!(
            "<robot name='r'>{}{}</robot>",
            "<a>".repeat(20_000),
            "</a>".repeat(20_000)
        );
        let err = parse_urdf("deep.urdf", &deep).expect_err("refused");
        assert_eq!(err.kind, Kind::Syntax);
        assert!(
            err.message.contains("nested deeper than 1000"),
            "{}",
            err.message
        );
        let ok = format!(
            "<robot name='r'>{}{}</robot>",
            "<a>".repeat(900),
            "</a>".repeat(900)
        );
        assert!(xml_element_depth(&ok, MAX_URDF_DEPTH) == 901);
    }
}
