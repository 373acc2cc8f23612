//! Robot description loading (`rdm_core::model::RobotDescription::from_strs`): the URDF
//! (roxmltree) and the TOML (toml) readers and the checks behind them.
//!
//! Input: text with one macro, then split in two. The macro lets a short input stand for
//! a long, repetitive text (deep nesting, long lists): byte 0x00 followed by three bytes
//! `n_hi n_lo k` appends the last `k` bytes written `n` more times (the text is capped at
//! [`MAX_TEXT`] bytes). Byte 0x01 (not allowed in either format's text) separates the URDF
//! from the TOML; without it the whole text is the URDF and the TOML is empty. Invalid
//! UTF-8 is replaced (U+FFFD). `scripts/fuzz.sh` and the Python target `description` read
//! the same inputs (`fuzz/python/fuzz_targets/description.py` expands them the same way).
//!
//! Checks: a rejection names the file it is about (`fuzz.urdf` or `fuzz.toml`); an
//! accepted description holds finite numbers only (masses, centres of mass, inertias,
//! joint origins and limits, rotors, plate, friction, sensor ranges), its masses, lengths
//! and inertias are within the reader's physical bounds (`rdm_core::model::bounds`), and
//! its total mass is finite.
//!
//! The depth of a URDF is bounded by the reader (`MAX_URDF_DEPTH`) before roxmltree, whose
//! tokenizer recurses per level, sees it; the macro reaches that bound and past it.

use rdm_core::model::bounds::{MAX_INERTIA, MAX_LENGTH, MAX_MASS};
use rdm_core::model::RobotDescription;

/// Largest expanded text [bytes].
pub const MAX_TEXT: usize = 1 << 18;

/// The text an input stands for (see the module doc).
pub fn expand(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(data.len());
    let mut i = 0;
    while i < data.len() && out.len() < MAX_TEXT {
        if data[i] == 0 {
            let (Some(&hi), Some(&lo), Some(&k)) =
                (data.get(i + 1), data.get(i + 2), data.get(i + 3))
            else {
                break;
            };
            i += 4;
            let k = usize::from(k).min(out.len());
            if k == 0 {
                continue;
            }
            let start = out.len() - k;
            for _ in 0..usize::from(u16::from_be_bytes([hi, lo])) {
                if out.len() + k > MAX_TEXT {
                    break;
                }
                out.extend_from_within(start..start + k);
            }
        } else {
            out.push(data[i]);
            i += 1;
        }
    }
    out
}

/// The URDF and TOML texts of an input.
pub fn split(data: &[u8]) -> (String, String) {
    let text = expand(data);
    let (urdf, toml) = match text.iter().position(|&b| b == 1) {
        Some(k) => (&text[..k], &text[k + 1..]),
        None => (&text[..], &[][..]),
    };
    (
        String::from_utf8_lossy(urdf).into_owned(),
        String::from_utf8_lossy(toml).into_owned(),
    )
}

fn finite(what: &str, values: &[f64]) {
    assert!(
        values.iter().all(|v| v.is_finite()),
        "non-finite: {what} = {values:?} in an accepted description"
    );
}

fn within(what: &str, values: &[f64], bound: f64) {
    finite(what, values);
    assert!(
        values.iter().all(|v| v.abs() <= bound),
        "past the bound {bound}: {what} = {values:?} in an accepted description"
    );
}

/// Load the description `data` stands for; panics on a broken rule.
pub fn check(data: &[u8]) {
    let (urdf, toml) = split(data);
    let desc = match RobotDescription::from_strs(&urdf, &toml, "fuzz.urdf", "fuzz.toml") {
        Ok(desc) => desc,
        Err(e) => {
            let text = e.to_string();
            assert!(
                text.starts_with("fuzz.urdf") || text.starts_with("fuzz.toml"),
                "unnamed error: {text}"
            );
            return;
        }
    };
    for l in &desc.links {
        within("link mass", &[l.mass], MAX_MASS);
        within("link com", l.com.as_slice(), MAX_LENGTH);
        // the inertia about the com, turned into the link frame: entries up to 3x the bound
        within("link inertia", l.inertia.as_slice(), 3.0 * MAX_INERTIA);
    }
    for j in &desc.joints {
        within(
            "joint origin",
            j.origin.translation.vector.as_slice(),
            MAX_LENGTH,
        );
        finite("joint rotation", j.origin.rotation.coords.as_slice());
        finite("joint limits", &[j.lower, j.upper]);
        if let Some(axis) = j.axis {
            finite("joint axis", axis.as_slice());
        }
    }
    for r in &desc.rotors {
        finite("rotor offset", r.offset.as_slice());
        finite("rotor axis", r.axis.as_slice());
        finite(
            "rotor",
            &[
                r.spin,
                r.drag_to_thrust,
                r.thrust_min,
                r.thrust_max,
                r.diameter,
            ],
        );
    }
    for s in &desc.sensors {
        finite("sensor ranges", &s.force_range);
        finite("sensor ranges", &s.torque_range);
    }
    finite("plate", &desc.plate_size);
    finite("friction", &[desc.friction_xy, desc.friction_z]);
    finite("stall torque", &desc.stall_torque);
    finite("total mass", &[desc.total_mass()]);
}
