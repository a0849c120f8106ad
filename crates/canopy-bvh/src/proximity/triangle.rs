//! Point-against-triangle measures: the nearest point of a triangle, and the solid
//! angle a triangle subtends (the exact term of a winding number).

use glam::{DVec3, Vec3};

/// The point of triangle `v` nearest `query`, with its barycentric weights `(u, v)` of
/// vertices 1 and 2 (as ray hits report them).
///
/// Ericson's region test ("Real-Time Collision Detection", 5.1.5), computed relative to
/// the query point so that nearby points keep their precision. A degenerate triangle
/// (its vertices on one line or one point) is measured as its edges.
#[inline]
pub fn closest_point_on_triangle(query: Vec3, v: &[Vec3; 3]) -> (Vec3, [f32; 2]) {
    let (a, b, c) = (v[0] - query, v[1] - query, v[2] - query);
    let (ab, ac) = (b - a, c - a);
    // Each `dN` is an edge dotted with the vector from a vertex to the query point.
    let (d1, d2) = (-ab.dot(a), -ac.dot(a));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (v[0], [0.0, 0.0]);
    }
    let (d3, d4) = (-ab.dot(b), -ac.dot(b));
    if d3 >= 0.0 && d4 <= d3 {
        return (v[1], [1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let s = d1 / (d1 - d3);
        return (v[0] + s * (v[1] - v[0]), [s, 0.0]);
    }
    let (d5, d6) = (-ab.dot(c), -ac.dot(c));
    if d6 >= 0.0 && d5 <= d6 {
        return (v[2], [0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let s = d2 / (d2 - d6);
        return (v[0] + s * (v[2] - v[0]), [0.0, s]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let s = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (v[1] + s * (v[2] - v[1]), [1.0 - s, s]);
    }
    let sum = va + vb + vc;
    let proper = sum > 0.0 && sum.is_finite();
    if !proper {
        return closest_on_edges(query, v);
    }
    let (s, t) = (vb / sum, vc / sum);
    (v[0] + s * (v[1] - v[0]) + t * (v[2] - v[0]), [s, t])
}

/// The nearest point on the three edges of a (degenerate) triangle.
fn closest_on_edges(query: Vec3, v: &[Vec3; 3]) -> (Vec3, [f32; 2]) {
    let on_segment = |p: Vec3, q: Vec3| {
        let d = q - p;
        let len_sq = d.length_squared();
        let s = match len_sq > 0.0 {
            true => ((query - p).dot(d) / len_sq).clamp(0.0, 1.0),
            false => 0.0,
        };
        (p + s * d, s)
    };
    let (ab, s_ab) = on_segment(v[0], v[1]);
    let (bc, s_bc) = on_segment(v[1], v[2]);
    let (ca, s_ca) = on_segment(v[2], v[0]);
    [
        (ab, [s_ab, 0.0]),
        (bc, [1.0 - s_bc, s_bc]),
        (ca, [0.0, 1.0 - s_ca]),
    ]
    .into_iter()
    .min_by(|x, y| {
        let (dx, dy) = (x.0.distance_squared(query), y.0.distance_squared(query));
        dx.total_cmp(&dy)
    })
    .expect("three edges")
}

/// The signed solid angle triangle `v` subtends at `query` (Van Oosterom and Strackee,
/// 1983), in double precision: positive where `query` lies behind the triangle, on the
/// side away from its normal `(v1 - v0) x (v2 - v0)`. Over a closed surface whose normals
/// point out, the angles sum to 4π inside and 0 outside.
#[inline]
pub fn solid_angle(query: Vec3, v: &[Vec3; 3]) -> f64 {
    let q = query.as_dvec3();
    let rel = |p: Vec3| p.as_dvec3() - q;
    let (a, b, c): (DVec3, DVec3, DVec3) = (rel(v[0]), rel(v[1]), rel(v[2]));
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let numerator = a.dot(b.cross(c));
    let denominator = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    2.0 * numerator.atan2(denominator)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TRI: [Vec3; 3] = [Vec3::ZERO, Vec3::X, Vec3::Y];

    #[test]
    fn every_region_of_the_triangle() {
        let cases = [
            (
                Vec3::new(0.2, 0.3, 5.0),
                Vec3::new(0.2, 0.3, 0.0),
                [0.2, 0.3],
            ),
            (Vec3::new(-1.0, -1.0, 0.0), Vec3::ZERO, [0.0, 0.0]),
            (Vec3::new(2.0, -1.0, 1.0), Vec3::X, [1.0, 0.0]),
            (Vec3::new(-1.0, 2.0, 0.0), Vec3::Y, [0.0, 1.0]),
            (
                Vec3::new(0.5, -3.0, 0.0),
                Vec3::new(0.5, 0.0, 0.0),
                [0.5, 0.0],
            ),
            (
                Vec3::new(-3.0, 0.25, 0.0),
                Vec3::new(0.0, 0.25, 0.0),
                [0.0, 0.25],
            ),
            (
                Vec3::new(1.0, 1.0, -2.0),
                Vec3::new(0.5, 0.5, 0.0),
                [0.5, 0.5],
            ),
        ];
        for (query, point, uv) in cases {
            let (p, got) = closest_point_on_triangle(query, &TRI);
            assert!(p.distance(point) < 1e-6, "{query}: {p} != {point}");
            assert!((got[0] - uv[0]).abs() < 1e-6 && (got[1] - uv[1]).abs() < 1e-6);
            let at = TRI[0] + got[0] * (TRI[1] - TRI[0]) + got[1] * (TRI[2] - TRI[0]);
            assert!(at.distance(p) < 1e-6, "barycentrics name the point");
        }
    }

    #[test]
    fn a_degenerate_triangle_is_measured_as_its_edges() {
        let line = [Vec3::ZERO, Vec3::X, Vec3::new(2.0, 0.0, 0.0)];
        let (p, _) = closest_point_on_triangle(Vec3::new(1.5, 1.0, 0.0), &line);
        assert!(p.distance(Vec3::new(1.5, 0.0, 0.0)) < 1e-6, "{p}");
        let point = [Vec3::ONE; 3];
        let (p, _) = closest_point_on_triangle(Vec3::ZERO, &point);
        assert_eq!(p, Vec3::ONE);
    }

    #[test]
    fn solid_angles_of_a_closed_surface_sum_to_four_pi_inside_and_zero_outside() {
        // A tetrahedron with outward normals.
        let (a, b, c, d) = (Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z);
        let faces = [[a, c, b], [a, b, d], [a, d, c], [b, c, d]];
        let total = |q: Vec3| faces.iter().map(|f| solid_angle(q, f)).sum::<f64>();
        let four_pi = 4.0 * std::f64::consts::PI;
        assert!((total(Vec3::splat(0.1)) - four_pi).abs() < 1e-9);
        assert!(total(Vec3::splat(2.0)).abs() < 1e-9);
        assert!(total(Vec3::new(-0.5, 0.2, 0.1)).abs() < 1e-9);
    }
}
