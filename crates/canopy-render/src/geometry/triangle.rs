use super::{max_abs, Surface, POINT_ERROR_ULPS};
use canopy_bvh::{Aabb, Ray};
use glam::{DVec3, Vec3};

/// A triangle, stored as its three vertices exactly as the mesh gives them: triangles
/// that share an edge then share its end points bit for bit, which the watertight test
/// needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    pub v: [Vec3; 3],
    /// Index into the scene's vertex-normal triples, or [`Triangle::FLAT`].
    pub normals: u32,
}

/// A ray prepared once for watertight triangle tests (Woop, Benthin and Wald,
/// "Watertight Ray/Triangle Intersection", JCGT 2013): the axis along which the ray runs
/// most steeply becomes z, and a shear maps the ray onto the z axis.
#[derive(Clone, Copy, Debug)]
pub struct ShearedRay {
    /// Axis indices: z is the dominant direction axis; x, y keep the winding.
    kx: usize,
    ky: usize,
    kz: usize,
    shear: Vec3,
}

impl ShearedRay {
    /// A placeholder for queries over scenes without triangles, where it is never read.
    pub const UNUSED: ShearedRay = ShearedRay {
        kx: 0,
        ky: 1,
        kz: 2,
        shear: Vec3::ZERO,
    };

    pub fn new(ray: &Ray) -> Self {
        let d = ray.dir;
        let kz = d.abs().max_position();
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Self {
            kx,
            ky,
            kz,
            shear: Vec3::new(d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]),
        }
    }
}

impl Triangle {
    /// `normals` value of a flat-shaded triangle.
    pub const FLAT: u32 = u32::MAX;

    pub fn new(v0: Vec3, v1: Vec3, v2: Vec3) -> Self {
        Self {
            v: [v0, v1, v2],
            normals: Self::FLAT,
        }
    }

    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(self.v)
    }

    pub fn area(&self) -> f32 {
        0.5 * (self.v[1] - self.v[0])
            .cross(self.v[2] - self.v[0])
            .length()
    }

    /// Distance and barycentric weights of the three vertices, if `ray` hits within its
    /// range. Watertight: a ray through an edge or vertex shared by triangles hits at least
    /// one of them; edge functions that come out exactly zero in single precision are
    /// recomputed in double precision, as the paper prescribes.
    #[inline]
    pub fn hit(&self, ray: &Ray, sheared: &ShearedRay) -> Option<(f32, [f32; 3])> {
        let ShearedRay { kx, ky, kz, shear } = *sheared;
        let [a, b, c] = self.v.map(|v| v - ray.origin);
        let (ax, ay) = (a[kx] - shear.x * a[kz], a[ky] - shear.y * a[kz]);
        let (bx, by) = (b[kx] - shear.x * b[kz], b[ky] - shear.y * b[kz]);
        let (cx, cy) = (c[kx] - shear.x * c[kz], c[ky] - shear.y * c[kz]);
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            let d =
                |p: f32, q: f32, r: f32, s: f32| (p as f64 * q as f64 - r as f64 * s as f64) as f32;
            u = d(cx, by, cy, bx);
            v = d(ax, cy, ay, cx);
            w = d(bx, ay, by, ax);
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let (az, bz, cz) = (shear.z * a[kz], shear.z * b[kz], shear.z * c[kz]);
        let t = (u * az + v * bz + w * cz) / det;
        (t >= ray.t_min && t <= ray.t_max).then(|| (t, [u / det, v / det, w / det]))
    }

    /// Hit distance, preparing the ray on the spot (for one-off tests; traversal prepares
    /// it once per ray and calls [`Triangle::hit`]).
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<f32> {
        self.hit(ray, &ShearedRay::new(ray)).map(|(t, _)| t)
    }

    pub fn surface(&self, ray: &Ray, vertex_normals: &[[Vec3; 3]]) -> Surface {
        // Recompute the weights for this one hit rather than carry them through traversal;
        // the point from weights is far more precise than o + t d.
        let (_, weights) = self
            .hit(ray, &ShearedRay::new(ray))
            .unwrap_or((0.0, [1.0 / 3.0; 3]));
        let p = (0..3)
            .fold(DVec3::ZERO, |p, i| {
                p + weights[i] as f64 * self.v[i].as_dvec3()
            })
            .as_vec3();
        let geometric_normal = (self.v[1] - self.v[0])
            .cross(self.v[2] - self.v[0])
            .normalize_or(Vec3::Y);
        let shading_normal = match vertex_normals.get(self.normals as usize) {
            Some(n) => {
                let interpolated = (0..3)
                    .fold(Vec3::ZERO, |s, i| s + weights[i] * n[i])
                    .normalize_or(geometric_normal);
                if interpolated.dot(geometric_normal) < 0.0 {
                    -interpolated
                } else {
                    interpolated
                }
            }
            None => geometric_normal,
        };
        Surface {
            p,
            geometric_normal,
            shading_normal,
            error: POINT_ERROR_ULPS
                * max_abs(self.v[0])
                    .max(max_abs(self.v[1]))
                    .max(max_abs(self.v[2])),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> Triangle {
        Triangle::new(Vec3::ZERO, Vec3::X, Vec3::Y)
    }

    fn ray(o: Vec3, d: Vec3) -> Ray {
        Ray::new(o, d, 0.0, f32::INFINITY)
    }

    #[test]
    fn hit_through_the_interior() {
        assert_eq!(
            tri().intersect(&ray(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z)),
            Some(1.0)
        );
    }

    #[test]
    fn back_side_is_hit_too() {
        assert_eq!(
            tri().intersect(&ray(Vec3::new(0.25, 0.25, -1.0), Vec3::Z)),
            Some(1.0)
        );
    }

    #[test]
    fn miss_outside_the_edges() {
        assert_eq!(
            tri().intersect(&ray(Vec3::new(0.75, 0.75, 1.0), -Vec3::Z)),
            None
        );
        assert_eq!(
            tri().intersect(&ray(Vec3::new(-0.1, 0.5, 1.0), -Vec3::Z)),
            None
        );
    }

    #[test]
    fn grazing_edge_and_vertex_hits_count() {
        // Exactly on the edge from (0,0) to (1,0), and exactly on a vertex.
        assert_eq!(
            tri().intersect(&ray(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z)),
            Some(1.0)
        );
        assert_eq!(
            tri().intersect(&ray(Vec3::new(1.0, 0.0, 1.0), -Vec3::Z)),
            Some(1.0)
        );
    }

    #[test]
    fn parallel_ray_misses() {
        assert_eq!(
            tri().intersect(&ray(Vec3::new(-1.0, 0.25, 0.0), Vec3::X)),
            None
        );
    }

    #[test]
    fn triangle_behind_the_origin_is_missed() {
        assert_eq!(
            tri().intersect(&ray(Vec3::new(0.25, 0.25, 1.0), Vec3::Z)),
            None
        );
    }

    #[test]
    fn t_range_limits_are_honoured() {
        let r = Ray::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, 0.0, 0.5);
        assert_eq!(tri().intersect(&r), None);
    }

    #[test]
    fn degenerate_triangle_is_never_hit() {
        let flat = Triangle::new(Vec3::ZERO, Vec3::X, 2.0 * Vec3::X);
        assert_eq!(
            flat.intersect(&ray(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z)),
            None
        );
    }

    #[test]
    fn weights_locate_the_hit_point() {
        let r = ray(Vec3::new(0.2, 0.3, 2.0), -Vec3::Z);
        let (t, w) = tri().hit(&r, &ShearedRay::new(&r)).unwrap();
        assert_eq!(t, 2.0);
        let p = w[0] * tri().v[0] + w[1] * tri().v[1] + w[2] * tri().v[2];
        assert!((p - Vec3::new(0.2, 0.3, 0.0)).length() < 1e-6);
    }

    #[test]
    fn smooth_normal_is_interpolated() {
        let mut t = tri();
        t.normals = 0;
        let normals = [[Vec3::Z, Vec3::new(1.0, 0.0, 1.0).normalize(), Vec3::Z]];
        let s = t.surface(&ray(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z), &normals);
        assert_eq!(s.geometric_normal, Vec3::Z);
        assert!(s.shading_normal.x > 0.1 && s.shading_normal.z > 0.5);
    }
}
