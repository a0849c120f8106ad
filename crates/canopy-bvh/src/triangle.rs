//! Triangles, the one primitive canopy-bvh intersects itself: the watertight ray/triangle
//! test (Woop, Benthin and Wald, "Watertight Ray/Triangle Intersection", JCGT 2013), and
//! packs of four triangles stored by lanes in a wide tree's leaves.
//!
//! The scalar test and the 4-lane kernels perform the same IEEE operations in the same
//! order (no fused multiply-add), so every kernel returns bit-identical hits.

use crate::{PrimHit, Ray};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// A ray prepared once for watertight triangle tests: the axis along which the ray runs
/// most steeply becomes z, and a shear maps the ray onto the z axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShearedRay {
    /// Axis indices: z is the dominant direction axis; x, y keep the winding.
    pub kx: usize,
    pub ky: usize,
    pub kz: usize,
    pub shear: Vec3,
}

impl ShearedRay {
    /// A placeholder for queries over scenes without triangles, where it is never read.
    pub const UNUSED: ShearedRay = ShearedRay {
        kx: 0,
        ky: 1,
        kz: 2,
        shear: Vec3::ZERO,
    };

    #[inline]
    pub fn new(ray: &Ray) -> Self {
        // x and y follow z cyclically, swapped when the ray runs down z to keep the
        // winding: `AXES[kz][runs down z]`.
        const AXES: [[[usize; 2]; 2]; 3] = [[[1, 2], [2, 1]], [[2, 0], [0, 2]], [[0, 1], [1, 0]]];
        let d = ray.dir.to_array();
        let a = ray.dir.abs();
        // The first axis of largest magnitude (as `Vec3::max_position`), by selects
        // rather than branches: ray directions are random, branches on them mispredict.
        let y_wins = a.y > a.x;
        let largest = if y_wins { a.y } else { a.x };
        let kz = if a.z > largest { 2 } else { y_wins as usize };
        let dz = d[kz];
        let [kx, ky] = AXES[kz][(dz < 0.0) as usize];
        Self {
            kx,
            ky,
            kz,
            shear: Vec3::new(d[kx] / dz, d[ky] / dz, 1.0 / dz),
        }
    }
}

/// The closest hit of `ray` on the triangle `v` within `[t_min, t_max]`, with the
/// barycentric weights of `v[1]` (`u`) and `v[2]` (`v`).
///
/// Watertight: a ray through an edge or vertex shared by triangles hits at least one of
/// them; edge functions that come out exactly zero in single precision are recomputed in
/// double precision, as the paper prescribes. Both sides of a triangle are hit.
#[inline]
pub fn intersect_triangle(v: &[Vec3; 3], ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit> {
    let o = ray.origin;
    let rel = |p: Vec3| [p.x - o.x, p.y - o.y, p.z - o.z];
    let (a, b, c) = (rel(v[0]), rel(v[1]), rel(v[2]));
    let s = sheared;
    let edges = EdgeInput {
        a: [a[s.kx], a[s.ky], a[s.kz]],
        b: [b[s.kx], b[s.ky], b[s.kz]],
        c: [c[s.kx], c[s.ky], c[s.kz]],
    };
    edges.hit(s.shear, ray.t_min, ray.t_max)
}

/// One triangle's vertices relative to the ray origin, axes permuted to (kx, ky, kz).
struct EdgeInput {
    a: [f32; 3],
    b: [f32; 3],
    c: [f32; 3],
}

impl EdgeInput {
    /// The scalar core that the SIMD kernels mirror operation for operation.
    #[inline(always)]
    fn hit(&self, shear: Vec3, t_min: f32, t_max: f32) -> Option<PrimHit> {
        let (a, b, c) = (self.a, self.b, self.c);
        let (ax, ay) = (a[0] - shear.x * a[2], a[1] - shear.y * a[2]);
        let (bx, by) = (b[0] - shear.x * b[2], b[1] - shear.y * b[2]);
        let (cx, cy) = (c[0] - shear.x * c[2], c[1] - shear.y * c[2]);
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
        let (az, bz, cz) = (shear.z * a[2], shear.z * b[2], shear.z * c[2]);
        let t = (u * az + v * bz + w * cz) / det;
        (t >= t_min && t <= t_max).then(|| PrimHit {
            t,
            u: v / det,
            v: w / det,
        })
    }
}

/// Lanes per triangle pack.
pub const PACK_LANES: usize = 4;

/// `prim` of a lane that holds nothing.
pub const NO_PRIM: u32 = u32::MAX;

/// Four primitives of a leaf, stored by lanes so that one SIMD test covers the triangles
/// among them. Lanes that are not triangles (other primitives, tested by the caller's
/// closure, or padding) hold NaN vertices, which no ray hits.
///
/// Byte layout (176 bytes, 16-aligned): `v[vertex][axis][lane]` (0..144), `prim` (144..160),
/// `triangles` (160..164), `others` (164..168), padding (168..176).
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct TrianglePack {
    pub v: [[[f32; PACK_LANES]; 3]; 3],
    /// Primitive index of each lane, or [`NO_PRIM`].
    pub prim: [u32; PACK_LANES],
    /// Bit `i` set: lane `i` is a triangle.
    pub triangles: u32,
    /// Bit `i` set: lane `i` is another primitive, tested by the caller.
    pub others: u32,
    _pad: [u32; 2],
}

const _: () = assert!(std::mem::size_of::<TrianglePack>() == 176);
const _: () = assert!(std::mem::align_of::<TrianglePack>() == 16);

impl TrianglePack {
    pub const EMPTY: TrianglePack = TrianglePack {
        v: [[[f32::NAN; PACK_LANES]; 3]; 3],
        prim: [NO_PRIM; PACK_LANES],
        triangles: 0,
        others: 0,
        _pad: [0; 2],
    };

    pub fn set_triangle(&mut self, lane: usize, prim: u32, v: [Vec3; 3]) {
        for (vertex, p) in v.iter().enumerate() {
            for axis in 0..3 {
                self.v[vertex][axis][lane] = p[axis];
            }
        }
        self.prim[lane] = prim;
        self.triangles |= 1 << lane;
    }

    pub fn set_other(&mut self, lane: usize, prim: u32) {
        self.prim[lane] = prim;
        self.others |= 1 << lane;
    }

    fn lane_edges(&self, lane: usize, ray: &PackRay) -> EdgeInput {
        let rel = |vertex: usize| {
            let p = &self.v[vertex];
            [
                p[ray.k[0]][lane] - ray.o[0],
                p[ray.k[1]][lane] - ray.o[1],
                p[ray.k[2]][lane] - ray.o[2],
            ]
        };
        EdgeInput {
            a: rel(0),
            b: rel(1),
            c: rel(2),
        }
    }
}

/// A ray prepared for pack tests: the sheared ray's axes and the origin in that order.
#[derive(Clone, Copy, Debug)]
pub struct PackRay {
    k: [usize; 3],
    o: [f32; 3],
    shear: Vec3,
}

impl PackRay {
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        let s = ShearedRay::new(ray);
        let o = ray.origin;
        Self {
            k: [s.kx, s.ky, s.kz],
            o: [o[s.kx], o[s.ky], o[s.kz]],
            shear: s.shear,
        }
    }
}

/// Distance and barycentrics of each lane of one pack, valid in the lanes of the mask
/// that [`PackKernel::test`] returns. The caller owns it and passes it to every test, so
/// a pack that is missed (most are) writes nothing, and the mask comes back in a register:
/// returning the whole record by value made each test store it in pieces and reload it
/// whole, a load no store can forward, which stalled every pack test.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, Default)]
pub struct PackHits {
    pub t: [f32; PACK_LANES],
    pub u: [f32; PACK_LANES],
    pub v: [f32; PACK_LANES],
}

impl PackHits {
    fn set(&mut self, lane: usize, hit: PrimHit) {
        self.t[lane] = hit.t;
        self.u[lane] = hit.u;
        self.v[lane] = hit.v;
    }

    /// The hit in `lane`, which must be in the mask of the last test.
    #[inline(always)]
    pub fn lane(&self, lane: usize) -> PrimHit {
        PrimHit {
            t: self.t[lane],
            u: self.u[lane],
            v: self.v[lane],
        }
    }

    /// Tests the `lanes` of `pack` one by one in the scalar core, adding their hits;
    /// returns the lanes hit.
    #[inline(always)]
    fn add_scalar_lanes(
        &mut self,
        pack: &TrianglePack,
        ray: &PackRay,
        mut lanes: u32,
        t_min: f32,
        t_max: f32,
    ) -> u32 {
        let mut mask = 0;
        while lanes != 0 {
            let lane = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            if let Some(hit) = pack.lane_edges(lane, ray).hit(ray.shear, t_min, t_max) {
                self.set(lane, hit);
                mask |= 1 << lane;
            }
        }
        mask
    }
}

/// A 4-lane triangle test: [`Scalar`] or [`Sse2`], identical in every bit.
pub trait PackKernel {
    /// The pack's triangle lanes hit within `[t_min, t_max]` (bit `i` for lane `i`).
    /// With `HITS`, their hits are written to `hits` (other lanes are left as they were);
    /// without (any-hit queries), `hits` is scratch space.
    ///
    /// # Safety
    /// The kernel's instruction set must be available.
    unsafe fn test<const HITS: bool>(
        pack: &TrianglePack,
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> u32;
}

/// The portable twin: the scalar core lane by lane.
pub(crate) struct ScalarPack;

impl PackKernel for ScalarPack {
    #[inline(always)]
    unsafe fn test<const HITS: bool>(
        pack: &TrianglePack,
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> u32 {
        hits.add_scalar_lanes(pack, ray, pack.triangles, t_min, t_max)
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) use sse2::Sse2Pack;

#[cfg(target_arch = "x86_64")]
mod sse2 {
    use super::*;
    use std::arch::x86_64::*;

    /// The SSE2 kernel (baseline x86-64): the scalar core on four lanes at once. Lanes
    /// whose edge functions come out exactly zero go to the scalar core, which redoes
    /// them in double precision.
    pub(crate) struct Sse2Pack;

    impl PackKernel for Sse2Pack {
        #[inline(always)]
        unsafe fn test<const HITS: bool>(
            pack: &TrianglePack,
            ray: &PackRay,
            t_min: f32,
            t_max: f32,
            hits: &mut PackHits,
        ) -> u32 {
            // SAFETY (whole block): SSE2 is part of x86-64; loads are from 16-aligned
            // `[f32; 4]` arrays.
            unsafe {
                let load =
                    |vertex: usize, axis: usize| _mm_load_ps(pack.v[vertex][ray.k[axis]].as_ptr());
                let [ox, oy, oz] = ray.o.map(|c| _mm_set1_ps(c));
                let sx = _mm_set1_ps(ray.shear.x);
                let sy = _mm_set1_ps(ray.shear.y);
                let sz = _mm_set1_ps(ray.shear.z);
                let rel = |vertex: usize| {
                    (
                        _mm_sub_ps(load(vertex, 0), ox),
                        _mm_sub_ps(load(vertex, 1), oy),
                        _mm_sub_ps(load(vertex, 2), oz),
                    )
                };
                let (a0, a1, a2) = rel(0);
                let (b0, b1, b2) = rel(1);
                let (c0, c1, c2) = rel(2);
                let shear_xy = |p0: __m128, p1: __m128, p2: __m128| {
                    (
                        _mm_sub_ps(p0, _mm_mul_ps(sx, p2)),
                        _mm_sub_ps(p1, _mm_mul_ps(sy, p2)),
                    )
                };
                let (ax, ay) = shear_xy(a0, a1, a2);
                let (bx, by) = shear_xy(b0, b1, b2);
                let (cx, cy) = shear_xy(c0, c1, c2);
                let u = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
                let v = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
                let w = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
                let zero = _mm_setzero_ps();
                let any_zero = _mm_or_ps(
                    _mm_or_ps(_mm_cmpeq_ps(u, zero), _mm_cmpeq_ps(v, zero)),
                    _mm_cmpeq_ps(w, zero),
                );
                let negative = _mm_or_ps(
                    _mm_or_ps(_mm_cmplt_ps(u, zero), _mm_cmplt_ps(v, zero)),
                    _mm_cmplt_ps(w, zero),
                );
                let positive = _mm_or_ps(
                    _mm_or_ps(_mm_cmpgt_ps(u, zero), _mm_cmpgt_ps(v, zero)),
                    _mm_cmpgt_ps(w, zero),
                );
                let lanes = pack.triangles;
                let redo = _mm_movemask_ps(any_zero) as u32 & lanes;
                // Inside: no edge function of each sign (or all zero, sent to `redo`).
                let straddles = _mm_movemask_ps(_mm_and_ps(negative, positive)) as u32;
                let inside = lanes & !straddles & !redo;
                let mut mask = 0;
                // Most packs a ray reaches it misses: skip the division unless a lane
                // is inside all three edges.
                if inside != 0 {
                    let det = _mm_add_ps(_mm_add_ps(u, v), w);
                    let det_ok = _mm_and_ps(
                        _mm_cmpneq_ps(det, zero),
                        _mm_cmpeq_ps(_mm_sub_ps(det, det), zero),
                    );
                    let t = _mm_div_ps(
                        _mm_add_ps(
                            _mm_add_ps(
                                _mm_mul_ps(u, _mm_mul_ps(sz, a2)),
                                _mm_mul_ps(v, _mm_mul_ps(sz, b2)),
                            ),
                            _mm_mul_ps(w, _mm_mul_ps(sz, c2)),
                        ),
                        det,
                    );
                    let in_range = _mm_and_ps(
                        _mm_cmpge_ps(t, _mm_set1_ps(t_min)),
                        _mm_cmple_ps(t, _mm_set1_ps(t_max)),
                    );
                    mask = _mm_movemask_ps(_mm_and_ps(det_ok, in_range)) as u32 & inside;
                    if HITS && mask != 0 {
                        _mm_storeu_ps(hits.t.as_mut_ptr(), t);
                        _mm_storeu_ps(hits.u.as_mut_ptr(), _mm_div_ps(v, det));
                        _mm_storeu_ps(hits.v.as_mut_ptr(), _mm_div_ps(w, det));
                    }
                }
                // Lanes with an exactly-zero edge function go to the scalar core's
                // f64 fallback.
                if redo != 0 {
                    mask |= hits.add_scalar_lanes(pack, ray, redo, t_min, t_max);
                }
                mask
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> [Vec3; 3] {
        [Vec3::ZERO, Vec3::X, Vec3::Y]
    }

    fn hit(o: Vec3, d: Vec3, t_max: f32) -> Option<PrimHit> {
        let ray = Ray::new(o, d, 0.0, t_max);
        intersect_triangle(&tri(), &ray, &ShearedRay::new(&ray))
    }

    #[test]
    fn interior_hit_with_barycentrics() {
        let h = hit(Vec3::new(0.25, 0.5, 1.0), -Vec3::Z, f32::INFINITY).unwrap();
        assert_eq!((h.t, h.u, h.v), (1.0, 0.25, 0.5));
    }

    #[test]
    fn misses_outside_and_beyond_t_max() {
        assert_eq!(
            hit(Vec3::new(0.75, 0.75, 1.0), -Vec3::Z, f32::INFINITY),
            None
        );
        assert_eq!(hit(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, 0.5), None);
    }

    #[test]
    fn edges_and_vertices_count_as_hits() {
        assert!(hit(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z, f32::INFINITY).is_some());
        assert!(hit(Vec3::new(1.0, 0.0, 1.0), -Vec3::Z, f32::INFINITY).is_some());
    }

    /// A pack of the triangle in every lane but one, which is left empty.
    fn pack() -> TrianglePack {
        let mut p = TrianglePack::EMPTY;
        for lane in 0..3 {
            let shift = Vec3::new(0.0, 0.0, lane as f32);
            p.set_triangle(lane, lane as u32, tri().map(|v| v - shift));
        }
        p
    }

    fn kernels_agree(ray: &Ray) {
        let pr = PackRay::new(ray);
        let mut scalar = PackHits::default();
        let scalar_mask =
            unsafe { ScalarPack::test::<true>(&pack(), &pr, ray.t_min, ray.t_max, &mut scalar) };
        for lane in 0..PACK_LANES {
            let shift = Vec3::new(0.0, 0.0, lane as f32);
            let expect = (lane < 3)
                .then(|| intersect_triangle(&tri().map(|v| v - shift), ray, &ShearedRay::new(ray)))
                .flatten();
            let got = (scalar_mask & (1 << lane) != 0).then(|| scalar.lane(lane));
            assert_eq!(got, expect, "lane {lane}");
        }
        #[cfg(target_arch = "x86_64")]
        {
            let mut simd = PackHits::default();
            let simd_mask =
                unsafe { Sse2Pack::test::<true>(&pack(), &pr, ray.t_min, ray.t_max, &mut simd) };
            assert_eq!(simd_mask, scalar_mask);
            for lane in 0..PACK_LANES {
                if scalar_mask & (1 << lane) != 0 {
                    assert_eq!(simd.t[lane].to_bits(), scalar.t[lane].to_bits());
                    assert_eq!(simd.u[lane].to_bits(), scalar.u[lane].to_bits());
                    assert_eq!(simd.v[lane].to_bits(), scalar.v[lane].to_bits());
                }
            }
        }
    }

    #[test]
    fn pack_kernels_match_the_scalar_test_lane_by_lane() {
        let rays = [
            Ray::new(Vec3::new(0.2, 0.3, 5.0), -Vec3::Z, 0.0, f32::INFINITY),
            Ray::new(Vec3::new(0.2, 0.3, 5.0), -Vec3::Z, 0.0, 5.5),
            Ray::new(Vec3::new(0.5, 0.0, 5.0), -Vec3::Z, 0.0, f32::INFINITY),
            Ray::new(
                Vec3::new(0.0, 0.0, -5.0),
                Vec3::new(0.01, 0.02, 1.0),
                0.0,
                f32::INFINITY,
            ),
            Ray::new(Vec3::new(-1.0, 0.25, -1.0), Vec3::X, 0.0, f32::INFINITY),
        ];
        for ray in &rays {
            kernels_agree(ray);
        }
    }
}
