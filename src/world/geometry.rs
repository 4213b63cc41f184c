//! 2D geometry on the floor plane: points, and rays against wall segments and
//! circles (balls, robots). Lengths in mm.

use super::Segment;

/// A 2D point or vector in mm: `[x, y]`.
pub type Point2 = [f64; 2];

/// The z component of the cross product of `a` and `b`.
#[inline]
pub fn cross(a: Point2, b: Point2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Ray o + t·d against segment s: t if it hits.
#[inline]
pub fn ray_segment(o: Point2, d: Point2, s: &Segment) -> Option<f64> {
    let e = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
    let den = cross(d, e);
    if den.abs() < 1e-12 {
        return None;
    }
    let ao = [s.a[0] - o[0], s.a[1] - o[1]];
    let t = cross(ao, e) / den;
    let u = cross(ao, d) / den;
    (t >= 0.0 && (-1e-9..=1.0 + 1e-9).contains(&u)).then_some(t)
}

/// Ray o + t·d (d unit) against a circle: the nearest t ≥ 0 if it hits.
#[inline]
pub fn ray_circle(o: Point2, d: Point2, c: Point2, r: f64) -> Option<f64> {
    let oc = [o[0] - c[0], o[1] - c[1]];
    let b = oc[0] * d[0] + oc[1] * d[1];
    let cc = oc[0] * oc[0] + oc[1] * oc[1] - r * r;
    if cc <= 0.0 {
        return Some(0.0); // inside
    }
    let disc = b * b - cc;
    if disc < 0.0 || b > 0.0 {
        return None;
    }
    Some(-b - disc.sqrt())
}

/// The point of segment s nearest to p.
#[inline]
pub fn closest_on_segment(p: Point2, s: &Segment) -> Point2 {
    closest_on(p, s.a, s.b)
}

/// The point of the segment a-b nearest to p.
#[inline]
pub fn closest_on(p: Point2, a: Point2, b: Point2) -> Point2 {
    let e = [b[0] - a[0], b[1] - a[1]];
    let l2 = e[0] * e[0] + e[1] * e[1];
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * e[0] + (p[1] - a[1]) * e[1]) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    [a[0] + t * e[0], a[1] + t * e[1]]
}

/// The distance between two points.
#[inline]
pub fn distance(a: Point2, b: Point2) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}
