//! Leaves of triangle packs tested for a packet's rays: each triangle against all the
//! packet's rays at once (one lane per ray) rather than each ray against a pack's
//! triangles, so a leaf costs one test per triangle for the whole packet.
//!
//! The test is the watertight one ([`crate::triangle`]), operation for operation: the
//! rays of a packet are sheared as the single-ray test shears them, and where they all
//! run most steeply along the same axis, the same way (camera rays of neighbouring
//! pixels nearly always do), a triangle's permuted vertices are shared by every lane.
//! Each ray then gets the distance and barycentrics the pack kernels give it, bit for
//! bit. A packet whose rays are sheared differently tests its leaves ray by ray.

use super::kernels::NodeKernel;
use super::packet::{lane_mask, Lanes, PACKET};
use super::traverse::{
    any_from, closest_from, lanes, leaf_packs, offer_lane, shape_packet, AloneWalk, Closest,
    PackedLeaves, PacketLeaves, WalkNodes,
};
use crate::triangle::{PackKernel, ShearedRay, TrianglePack, TriangleTest, PACK_LANES};
use crate::{Hit, IntoHit, PrimHit, Ray};
use std::marker::PhantomData;

/// A packet's rays prepared for triangle tests, all sheared along the same axes.
pub(crate) struct PacketShear {
    /// The axes (kx, ky, kz) every lane is sheared along.
    k: [usize; 3],
    /// Each lane's origin, axes in that order.
    o: [[f32; PACKET]; 3],
    /// Each lane's shear ([`ShearedRay::shear`]), x, y and z.
    shear: [[f32; PACKET]; 3],
    test: TriangleTest,
}

impl PacketShear {
    /// The shears of the traceable rays among `rays`; `None` where they are not all
    /// sheared along the same axes. Other lanes hold zeros and are never tested.
    fn new(rays: &[Ray], test: TriangleTest) -> Option<Self> {
        let mut axes = None;
        let mut packet = Self {
            k: [0, 1, 2],
            o: [[0.0; PACKET]; 3],
            shear: [[0.0; PACKET]; 3],
            test,
        };
        for (lane, ray) in rays.iter().enumerate().filter(|(_, r)| r.is_traceable()) {
            let s = ShearedRay::new(ray);
            let k = [s.kx, s.ky, s.kz];
            // The axes compared as one number: compared as arrays, they were stored in
            // 8-byte pieces and read back 16 bytes at once, a store forward that fails
            // (half of this function's samples).
            let code = s.kx | s.ky << 2 | s.kz << 4;
            if axes.get_or_insert((k, code)).1 != code {
                return None;
            }
            let origin = ray.origin.to_array();
            for (axis, &k) in k.iter().enumerate() {
                packet.o[axis][lane] = origin[k];
            }
            for (axis, shear) in s.shear.to_array().into_iter().enumerate() {
                packet.shear[axis][lane] = shear;
            }
        }
        packet.k = axes?.0;
        Some(packet)
    }

    /// The lanes of `active` whose rays hit the triangle `v` (vertex, then axis) within
    /// `[t_min, t_max]`, each lane's hit written to `hits`: `EdgeInput::hit` of the
    /// single-ray test, lane by lane.
    #[inline(always)]
    fn hit_lanes(
        &self,
        v: [[f32; 3]; 3],
        active: u32,
        t_min: &[f32; PACKET],
        t_max: &[f32; PACKET],
        hits: &mut LaneHits,
    ) -> u32 {
        // No `[T; N]::map` here: outside release builds it is left out of line, outside
        // the dispatch's AVX2 function, and packets ran at a third of single rays' speed.
        let [kx, ky, kz] = self.k;
        let permute = |p: [f32; 3]| [p[kx], p[ky], p[kz]];
        let permuted = [permute(v[0]), permute(v[1]), permute(v[2])];
        // The sheared 2D vertices of `lane`, and each vertex's distance along z.
        let sheared = |lane: usize| {
            let [sx, sy] = [self.shear[0][lane], self.shear[1][lane]];
            let shear = |p: [f32; 3]| {
                let rel = [
                    p[0] - self.o[0][lane],
                    p[1] - self.o[1][lane],
                    p[2] - self.o[2][lane],
                ];
                [rel[0] - sx * rel[2], rel[1] - sy * rel[2], rel[2]]
            };
            [shear(permuted[0]), shear(permuted[1]), shear(permuted[2])]
        };
        let mut edges = [[0.0f32; PACKET]; 3];
        let mut zero = [false; PACKET];
        for lane in 0..PACKET {
            let [a, b, c] = sheared(lane);
            let u = c[0] * b[1] - c[1] * b[0];
            let v = a[0] * c[1] - a[1] * c[0];
            let w = b[0] * a[1] - b[1] * a[0];
            (edges[0][lane], edges[1][lane], edges[2][lane]) = (u, v, w);
            zero[lane] = self.test.refines_zeros() && (u == 0.0 || v == 0.0 || w == 0.0);
        }
        // Edge functions exactly zero in single precision, again in double (rare; never
        // in the fast mode).
        for lane in lanes(lane_mask(&zero) & active) {
            let [a, b, c] = sheared(lane);
            let d =
                |p: f32, q: f32, r: f32, s: f32| (p as f64 * q as f64 - r as f64 * s as f64) as f32;
            edges[0][lane] = d(c[0], b[1], c[1], b[0]);
            edges[1][lane] = d(a[0], c[1], a[1], c[0]);
            edges[2][lane] = d(b[0], a[1], b[1], a[0]);
        }
        let mut hit = [false; PACKET];
        let mut det = [0.0f32; PACKET];
        for lane in 0..PACKET {
            let [u, v, w] = [edges[0][lane], edges[1][lane], edges[2][lane]];
            let outside = (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0);
            let d = u + v + w;
            let sz = self.shear[2][lane];
            let along = |p: [f32; 3]| sz * (p[2] - self.o[2][lane]);
            let z = [along(permuted[0]), along(permuted[1]), along(permuted[2])];
            let t = (u * z[0] + v * z[1] + w * z[2]) / d;
            hit[lane] =
                !outside && d != 0.0 && d.is_finite() && t >= t_min[lane] && t <= t_max[lane];
            (det[lane], hits.t[lane]) = (d, t);
        }
        let mask = lane_mask(&hit) & active;
        for lane in lanes(mask) {
            hits.u[lane] = edges[1][lane] / det[lane];
            hits.v[lane] = edges[2][lane] / det[lane];
        }
        mask
    }
}

/// Each lane's hit of the last triangle tested, valid in the lanes it returned.
struct LaneHits {
    t: [f32; PACKET],
    u: [f32; PACKET],
    v: [f32; PACKET],
}

/// Leaves stored as triangle packs ([`PackedLeaves`]), tested for a packet's rays.
pub(crate) struct PackedPacketLeaves<'a, T, F> {
    pub packs: &'a [TrianglePack],
    pub triangle_test: TriangleTest,
    pub test: F,
    /// The packet's shears, made at its first leaf: `Some(None)` where they differ.
    shear: Option<Option<PacketShear>>,
    kernel: PhantomData<T>,
}

impl<'a, T, F> PackedPacketLeaves<'a, T, F> {
    pub fn new(packs: &'a [TrianglePack], triangle_test: TriangleTest, test: F) -> Self {
        Self {
            packs,
            triangle_test,
            test,
            shear: None,
            kernel: PhantomData,
        }
    }
}

impl<T, F, P> PacketLeaves for PackedPacketLeaves<'_, T, F>
where
    T: PackKernel,
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
{
    #[inline(always)]
    fn closest_lanes(
        &mut self,
        first: u32,
        count: u32,
        group: Lanes,
        t_max: &mut [f32; PACKET],
        best: &mut [Option<Hit>; PACKET],
    ) {
        let packs = leaf_packs(self.packs, first, count);
        // A leaf of spheres alone (a field of spheres packed) needs no shears.
        let triangles = packs.iter().any(|pack| pack.triangles != 0);
        let shear = match triangles {
            true => self
                .shear
                .get_or_insert_with(|| PacketShear::new(group.rays, self.triangle_test))
                .as_ref(),
            false => None,
        };
        if triangles && shear.is_none() {
            // Rays sheared differently: the single-ray pack test, one lane at a time.
            let (packs, test) = (self.packs, &mut self.test);
            match self.triangle_test {
                TriangleTest::Watertight => {
                    let mut single = PackedLeaves::<T, _>::new(packs, test);
                    group.each(&mut single, first, count, t_max, best);
                }
                TriangleTest::Fast => {
                    let mut single = PackedLeaves::<T::Fast, _>::new(packs, test);
                    group.each(&mut single, first, count, t_max, best);
                }
            }
            return;
        };
        let mut hits = LaneHits {
            t: [0.0; PACKET],
            u: [0.0; PACKET],
            v: [0.0; PACKET],
        };
        for pack in packs {
            if let Some(shear) = shear {
                for lane in lanes(pack.triangles) {
                    let corner = |v: &[[f32; PACK_LANES]; 3]| [v[0][lane], v[1][lane], v[2][lane]];
                    let v = [corner(&pack.v[0]), corner(&pack.v[1]), corner(&pack.v[2])];
                    let hit =
                        shear.hit_lanes(v, group.active, &group.packet.t_min, t_max, &mut hits);
                    for ray in lanes(hit) {
                        let prim_hit = PrimHit {
                            t: hits.t[ray],
                            u: hits.u[ray],
                            v: hits.v[ray],
                        };
                        offer_lane(ray, Hit::new(pack.prim[lane], prim_hit), t_max, best);
                    }
                }
            }
            for lane in lanes(pack.others) {
                let prim = pack.prim[lane];
                match pack.kept(lane) {
                    Some(shape) => shape_packet(shape, prim, &group, t_max, best),
                    None => {
                        for ray in lanes(group.active) {
                            let single = Ray {
                                t_max: t_max[ray],
                                ..group.rays[ray]
                            };
                            if let Some(hit) = (self.test)(prim, &single) {
                                offer_lane(ray, hit.into_hit(prim), t_max, best);
                            }
                        }
                    }
                }
            }
        }
    }
    #[inline(always)]
    unsafe fn closest_alone<const N: usize, K: NodeKernel<N>>(
        &mut self,
        nodes: WalkNodes<'_, N>,
        start: (u32, u32),
        search: Closest,
        walk: &mut AloneWalk,
    ) -> Closest {
        let (packs, test) = (self.packs, &mut self.test);
        let (stack, counter) = (&mut walk.closest, &mut ());
        // SAFETY: the caller's guarantee; the pack kernels share the node kernel's
        // instruction set.
        unsafe {
            match self.triangle_test {
                TriangleTest::Watertight => {
                    let mut single = PackedLeaves::<T, _>::new(packs, test);
                    closest_from::<N, K, _, _>(nodes, start, search, &mut single, counter, stack)
                }
                TriangleTest::Fast => {
                    let mut single = PackedLeaves::<T::Fast, _>::new(packs, test);
                    closest_from::<N, K, _, _>(nodes, start, search, &mut single, counter, stack)
                }
            }
        }
    }

    #[inline(always)]
    unsafe fn any_alone<const N: usize, K: NodeKernel<N>>(
        &mut self,
        nodes: WalkNodes<'_, N>,
        start: (u32, u32),
        ray: &Ray,
        walk: &mut AloneWalk,
    ) -> bool {
        let (packs, test) = (self.packs, &mut self.test);
        let blocks = |prim: u32, ray: &Ray| test(prim, ray).is_some();
        let stack = &mut walk.any;
        // SAFETY: as in `closest_alone`.
        unsafe {
            match self.triangle_test {
                TriangleTest::Watertight => {
                    let mut single = PackedLeaves::<T, _>::new(packs, blocks);
                    any_from::<N, K, _>(nodes, start, ray, &mut single, stack)
                }
                TriangleTest::Fast => {
                    let mut single = PackedLeaves::<T::Fast, _>::new(packs, blocks);
                    any_from::<N, K, _>(nodes, start, ray, &mut single, stack)
                }
            }
        }
    }
}
