//! Collision geometry of eq. (67): capsules and spheres, their closest points and the
//! signed clearance between them (negative: penetration).

use nalgebra::Vector3;

/// Closest points of segments p1-q1 and p2-q2 (Ericson, Real-Time Collision Detection,
/// 5.1.9). Degenerate segments are handled as points.
pub fn closest_points_segments(
    p1: &Vector3<f64>,
    q1: &Vector3<f64>,
    p2: &Vector3<f64>,
    q2: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = d1.dot(&d1);
    let e = d2.dot(&d2);
    let f = d2.dot(&r);
    let eps = 1e-12;
    let (s, t);
    if a <= eps && e <= eps {
        return (*p1, *p2);
    }
    if a <= eps {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(&r);
        if e <= eps {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s0 = if denom > eps {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t0 = 0.0;
                s0 = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t0 = 1.0;
                s0 = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = s0;
            t = t0;
        }
    }
    (p1 + d1 * s, p2 + d2 * t)
}

/// A shape placed in the world: a segment (a == b for a sphere) and a radius.
#[derive(Clone, Copy, Debug)]
pub struct PlacedShape {
    pub a: Vector3<f64>,
    pub b: Vector3<f64>,
    pub radius: f64,
}

/// Clearance between two placed shapes (distance of the swept segments minus radii).
pub fn clearance(s1: &PlacedShape, s2: &PlacedShape) -> f64 {
    let (c1, c2) = closest_points_segments(&s1.a, &s1.b, &s2.a, &s2.b);
    (c1 - c2).norm() - s1.radius - s2.radius
}

/// Clearance of a shape below the plane z = `ceiling`.
pub fn ceiling_clearance(s: &PlacedShape, ceiling: f64) -> f64 {
    ceiling - s.a.z.max(s.b.z) - s.radius
}
