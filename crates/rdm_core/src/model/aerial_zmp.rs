//! Aerial ZMP (Appendix A, eq. 73) and the aerial support polygon (ASP, eq. 1): the convex
//! hull of the rotor positions projected on the world's horizontal plane.

use nalgebra::Vector2;

use super::description::RobotDescription;
use super::error::{check_input, ModelError};
use super::workspace::ModelWorkspace;

/// Hulls whose area is below this [m^2] count as degenerate (a segment or a point).
const DEGENERATE_AREA: f64 = 1e-10;

/// Aerial ZMP and its position relative to the aerial support polygon.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AerialZmp {
    /// p_AZMP,xy in the world frame [m].
    pub point: Vector2<f64>,
    /// Signed distance to the polygon boundary [m]: positive inside, negative outside.
    /// For a degenerate polygon (rotors collinear or coincident: no interior) it is minus
    /// the distance to the segment/point, so never positive.
    pub margin: f64,
    /// Strictly inside (margin > 0); always false for a degenerate polygon.
    pub inside: bool,
    /// The polygon has no interior (fewer than three non-collinear rotor projections).
    pub degenerate: bool,
}

fn cross(o: &Vector2<f64>, a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
}

fn segment_distance(p: &Vector2<f64>, a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).norm()
}

/// Convex hull (counter-clockwise, collinear points dropped) of `points` into `hull`;
/// `points` is sorted in place. Allocation-free while `hull` has capacity `2 n`.
fn convex_hull(points: &mut [Vector2<f64>], hull: &mut Vec<Vector2<f64>>) {
    hull.clear();
    points.sort_unstable_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    // Andrew's monotone chain: lower hull, then upper hull.
    for p in points.iter() {
        while hull.len() >= 2 && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(*p);
    }
    let lower = hull.len() + 1;
    for p in points.iter().rev().skip(1) {
        while hull.len() >= lower && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(*p);
    }
    if hull.len() > 1 {
        hull.pop(); // last point repeats the first
    }
}

/// Signed margin of `p` w.r.t. the convex hull of `points` (see [`AerialZmp::margin`]).
/// `points` is reordered; `hull` is a scratch buffer. Returns (margin, degenerate).
pub fn support_margin(
    points: &mut [Vector2<f64>],
    p: &Vector2<f64>,
    hull: &mut Vec<Vector2<f64>>,
) -> (f64, bool) {
    if points.is_empty() {
        return (f64::NEG_INFINITY, true);
    }
    convex_hull(points, hull);
    let n = hull.len();
    let area2: f64 = (0..n)
        .map(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum();
    if n < 3 || area2.abs() * 0.5 < DEGENERATE_AREA {
        // No interior: distance to the segment (or point) spanned by the rotors.
        let (mut lo, mut hi) = (points[0], points[0]);
        let dir = if n >= 2 {
            hull[1] - hull[0]
        } else {
            Vector2::x()
        };
        for q in points.iter() {
            if (q - lo).dot(&dir) < 0.0 {
                lo = *q;
            }
            if (q - hi).dot(&dir) > 0.0 {
                hi = *q;
            }
        }
        return (-segment_distance(p, &lo, &hi), true);
    }
    let mut inside = true;
    let mut to_edge = f64::INFINITY;
    for i in 0..n {
        let (a, b) = (hull[i], hull[(i + 1) % n]);
        if cross(&a, &b, p) < 0.0 {
            inside = false;
        }
        to_edge = to_edge.min(segment_distance(p, &a, &b));
    }
    (if inside { to_edge } else { -to_edge }, false)
}

impl RobotDescription {
    /// Steady-state aerial ZMP: eq. (73) with thrusts that cancel the roll and pitch
    /// moments about the CoG while lifting vertically reduces to the CoG's projection
    /// (Sec. II-A-1). Margin w.r.t. the ASP of the current rotor positions.
    pub fn aerial_zmp(&self, ws: &mut ModelWorkspace) -> Result<AerialZmp, ModelError> {
        if !ws.evaluated {
            return Err(ModelError::NotEvaluated);
        }
        let point = Vector2::new(ws.cog.x, ws.cog.y);
        Ok(self.zmp_margin(ws, point))
    }

    /// Eq. (73) for given rotor thrusts: the F_z-weighted mean of the rotor xy positions
    /// (world). `None` when the total vertical thrust is not positive.
    pub fn aerial_zmp_from_thrusts(
        &self,
        ws: &mut ModelWorkspace,
        thrusts: &[f64],
    ) -> Result<Option<AerialZmp>, ModelError> {
        if !ws.evaluated {
            return Err(ModelError::NotEvaluated);
        }
        check_input("thrusts", thrusts, self.n_rotors())?;
        let mut weight = 0.0;
        let mut sum = Vector2::zeros();
        for (i, &t) in thrusts.iter().enumerate() {
            let fz = t * ws.rotor_direction[i].z;
            weight += fz;
            sum += fz * ws.rotor_position[i].xy();
        }
        if weight <= 1e-12 {
            return Ok(None);
        }
        Ok(Some(self.zmp_margin(ws, sum / weight)))
    }

    fn zmp_margin(&self, ws: &mut ModelWorkspace, point: Vector2<f64>) -> AerialZmp {
        for (dst, p) in ws.projected.iter_mut().zip(&ws.rotor_position) {
            *dst = p.xy();
        }
        let (margin, degenerate) = support_margin(&mut ws.projected, &point, &mut ws.hull);
        AerialZmp {
            point,
            margin,
            inside: !degenerate && margin > 0.0,
            degenerate,
        }
    }
}
