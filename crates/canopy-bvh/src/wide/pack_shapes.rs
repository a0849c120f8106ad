//! Shapes kept in a triangle pack's lanes ([`TrianglePack::set_kept`]: spheres and
//! axis-aligned boxes) tested together, one lane per shape, inside the walk's loop: a
//! sphere beside a mesh, or the floor and light boxes beside it, no longer send their leaf
//! out of the loop to a call (paper-3 and paper-5 render 6% faster), and a field of
//! spheres is packed four to a pack as a mesh's triangles are (at the speed of the scalar
//! tests it replaces: its leaves are mostly one pack).
//!
//! Each lane performs [`crate::intersect_sphere`]'s or [`crate::intersect_box`]'s
//! operations in their order (no fused multiply-add; glam's `min` and `max` are the
//! compare-and-selects written here), so each gives the distance the single test gives,
//! bit for bit: in SSE2 lanes (one pack), AVX lanes (two packs) or one by one (the
//! scalar twin), as the pack kernel ([`crate::triangle::PackKernel::shapes`]) says.
//! Written with intrinsics: the compiler left the sphere roots' stage of a plain-array
//! version scalar, with branches.

use crate::triangle::{TrianglePack, PACK_LANES, PAIR_LANES};
use crate::Ray;

/// The kept-shape lanes of `packs` (one pack, or a pair tested together) that `ray` hits
/// within `[t_min, t_max]`, pack `i`'s lane `l` as bit `i * PACK_LANES + l`, with the
/// distance of each hit lane in `t`: the scalar twin, lane by lane.
#[inline(always)]
pub(crate) fn shapes_one_by_one(
    packs: &[TrianglePack],
    ray: &Ray,
    t: &mut [f32; PAIR_LANES],
) -> u32 {
    let mut hit = 0;
    for (i, pack) in packs.iter().enumerate() {
        let mut lanes = pack.spheres | pack.boxes;
        while lanes != 0 {
            let lane = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            if let Some(distance) = pack.kept(lane).and_then(|shape| shape.intersect(ray)) {
                t[i * PACK_LANES + lane] = distance;
                hit |= 1 << (i * PACK_LANES + lane);
            }
        }
    }
    hit
}

#[cfg(target_arch = "x86_64")]
pub(crate) use simd::shape_lanes;

#[cfg(target_arch = "x86_64")]
mod simd {
    use super::*;
    use crate::lanes::Lanes;

    /// [`shapes_one_by_one`] of the first `V::PACKS` packs in SIMD lanes, distances from
    /// lane 0 of `t`.
    ///
    /// # Safety
    /// `V`'s instruction set must be available.
    #[inline(always)]
    pub(crate) unsafe fn shape_lanes<V: Lanes>(
        packs: &[TrianglePack],
        ray: &Ray,
        t: &mut [f32; PAIR_LANES],
    ) -> u32 {
        let (mut spheres, mut boxes) = (0, 0);
        for (i, pack) in packs[..V::PACKS].iter().enumerate() {
            spheres |= pack.spheres << (i * PACK_LANES);
            boxes |= pack.boxes << (i * PACK_LANES);
        }
        // SAFETY (both): the caller guarantees `V`'s instruction set.
        let mut hit = 0;
        if spheres != 0 {
            hit = unsafe { sphere_lanes::<V>(packs, ray, spheres, t) };
        }
        if boxes != 0 {
            let mut box_t = [0.0; PAIR_LANES];
            let box_hit = unsafe { box_lanes::<V>(packs, ray, boxes, &mut box_t) };
            let mut lanes = box_hit;
            while lanes != 0 {
                let lane = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                t[lane] = box_t[lane];
            }
            hit |= box_hit;
        }
        hit
    }

    /// The sphere lanes (`spheres`) hit, [`crate::intersect_sphere`] in every lane.
    #[inline(always)]
    unsafe fn sphere_lanes<V: Lanes>(
        packs: &[TrianglePack],
        ray: &Ray,
        spheres: u32,
        t: &mut [f32; PAIR_LANES],
    ) -> u32 {
        // SAFETY (whole block): the caller guarantees `V`'s instruction set.
        unsafe {
            let [dx, dy, dz] = ray.dir.to_array();
            let [ox, oy, oz] = ray.origin.to_array();
            let a = dx * dx + dy * dy + dz * dz;
            let (vdx, vdy, vdz, va) = (V::splat(dx), V::splat(dy), V::splat(dz), V::splat(a));
            let fx = V::splat(ox).sub(V::load(packs, 0, 0));
            let fy = V::splat(oy).sub(V::load(packs, 0, 1));
            let fz = V::splat(oz).sub(V::load(packs, 0, 2));
            let sign = V::splat(-0.0);
            let b = fx.mul(vdx).add(fy.mul(vdy)).add(fz.mul(vdz)).xor(sign);
            let along = b.div(va);
            let lx = fx.add(along.mul(vdx));
            let ly = fy.add(along.mul(vdy));
            let lz = fz.add(along.mul(vdz));
            let radius = V::load(packs, 1, 0);
            let r2 = radius.mul(radius);
            let discriminant = r2.sub(lx.mul(lx).add(ly.mul(ly)).add(lz.mul(lz)));
            let zero = V::splat(0.0);
            // Most spheres of a ray's leaves it passes by: the roots only where one is met.
            let met = spheres & !discriminant.lt(zero).mask();
            if met == 0 {
                return 0;
            }
            let c = fx.mul(fx).add(fy.mul(fy)).add(fz.mul(fz)).sub(r2);
            // `b.signum() * root` is the root with b's sign (a NaN `b` makes `q` NaN).
            let root = va.mul(discriminant).sqrt();
            let q = b.add(root.or(b.and(sign)));
            let q_zero = q.eq(zero);
            let t0 = c.div(q).and_not(q_zero);
            let t1 = q.div(va).and_not(q_zero);
            let ordered = t0.le(t1);
            let near = ordered.select(t0, t1);
            let far = ordered.select(t1, t0);
            in_range(near, far, ray, t) & met
        }
    }

    /// The box lanes (`boxes`) hit, [`crate::intersect_box`] with the ray's own origin
    /// and inverse direction in every lane.
    #[inline(always)]
    unsafe fn box_lanes<V: Lanes>(
        packs: &[TrianglePack],
        ray: &Ray,
        boxes: u32,
        t: &mut [f32; PAIR_LANES],
    ) -> u32 {
        // SAFETY (whole block): the caller guarantees `V`'s instruction set.
        unsafe {
            let (x0, x1) = slab::<V>(packs, ray, 0);
            let (y0, y1) = slab::<V>(packs, ray, 1);
            let (z0, z1) = slab::<V>(packs, ray, 2);
            // glam's `max_element` and `min_element`: `max(x, max(y, z))`, each a
            // compare and select.
            let enter_yz = y0.gt(z0).select(y0, z0);
            let enter = x0.gt(enter_yz).select(x0, enter_yz);
            let exit_yz = y1.lt(z1).select(y1, z1);
            let exit = x1.lt(exit_yz).select(x1, exit_yz);
            let passes = boxes & !enter.gt(exit).mask();
            if passes == 0 {
                return 0;
            }
            in_range(enter, exit, ray, t) & passes
        }
    }

    /// The entry and exit distances of every lane's box along `axis`: glam's `min` and
    /// `max` (`a < b ? a : b`, `a > b ? a : b`) of the distances to its two planes.
    #[inline(always)]
    unsafe fn slab<V: Lanes>(packs: &[TrianglePack], ray: &Ray, axis: usize) -> (V, V) {
        // SAFETY (whole block): the caller guarantees `V`'s instruction set.
        unsafe {
            let o = V::splat(ray.origin.to_array()[axis]);
            let inv = V::splat(ray.inv_dir.to_array()[axis]);
            let t0 = V::load(packs, 0, axis).sub(o).mul(inv);
            let t1 = V::load(packs, 1, axis).sub(o).mul(inv);
            (t0.lt(t1).select(t0, t1), t0.gt(t1).select(t0, t1))
        }
    }

    /// `near` where it lies in the ray's range, else `far` where that does, written to `t`;
    /// the lanes of either.
    #[inline(always)]
    unsafe fn in_range<V: Lanes>(near: V, far: V, ray: &Ray, t: &mut [f32; PAIR_LANES]) -> u32 {
        // SAFETY (whole block): the caller guarantees `V`'s instruction set.
        unsafe {
            let (t_min, t_max) = (V::splat(ray.t_min), V::splat(ray.t_max));
            let near_in = near.ge(t_min).and(near.le(t_max));
            let far_in = far.ge(t_min).and(far.le(t_max));
            near_in.select(near, far).store(t);
            near_in.or(far_in).mask()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::triangle::{PackKernel, ScalarPack};
    use crate::{Aabb, KnownShape};
    use glam::Vec3;

    use crate::wide::test_numbers::Numbers;

    /// Two packs: five spheres (huge and near, tiny, one of radius zero), two boxes (one
    /// flat, as a quad light is) and a lane that keeps nothing.
    fn packs(n: &mut Numbers) -> [TrianglePack; 2] {
        let mut packs = [TrianglePack::EMPTY; 2];
        for lane in 0..PAIR_LANES {
            let pack = &mut packs[lane / PACK_LANES];
            let l = lane % PACK_LANES;
            pack.set_other(l, lane as u32);
            let radius = match lane {
                0 => 1000.0,
                1 => 1e-3,
                2 => 0.0,
                _ => 0.1 + n.next(),
            };
            let center = n.vec(3.0)
                + if lane == 0 {
                    Vec3::Y * -1000.5
                } else {
                    Vec3::ZERO
                };
            let corner = n.vec(3.0);
            let size = n.vec(2.0).abs()
                * if lane == 7 {
                    Vec3::new(1.0, 0.0, 1.0)
                } else {
                    Vec3::ONE
                };
            let shape = match lane {
                5 => None,
                6 | 7 => Some(KnownShape::Box(Aabb::new(corner, corner + size))),
                _ => Some(KnownShape::Sphere { center, radius }),
            };
            pack.set_kept(l, shape);
        }
        packs
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn avx2_pair(packs: &[TrianglePack; 2], ray: &Ray, t: &mut [f32; PAIR_LANES]) -> u32 {
        // SAFETY: compiled for AVX2, run only where it was detected.
        unsafe { crate::triangle::Avx2Pack::<true>::shape_pair(packs, ray, t) }
    }

    /// Each kernel's hits and distances (`name`, mask, distances).
    fn every_kernel(packs: &[TrianglePack; 2], ray: &Ray) -> Vec<(&'static str, u32, [f32; 8])> {
        let mut out = Vec::new();
        let mut run = |name, test: &dyn Fn(&mut [f32; PAIR_LANES]) -> u32| {
            let mut t = [f32::NAN; PAIR_LANES];
            let mask = test(&mut t);
            out.push((name, mask, t));
        };
        // SAFETY (all): the kernels' instruction sets exist (AVX2 is asked first).
        run("scalar pair", &|t| unsafe {
            ScalarPack::<true>::shape_pair(packs, ray, t)
        });
        run("scalar one", &|t| unsafe {
            ScalarPack::<true>::shapes(&packs[0], ray, t)
        });
        #[cfg(target_arch = "x86_64")]
        {
            use crate::triangle::Sse2Pack;
            run("sse2 pair", &|t| unsafe {
                Sse2Pack::<true>::shape_pair(packs, ray, t)
            });
            run("sse2 one", &|t| unsafe {
                Sse2Pack::<true>::shapes(&packs[0], ray, t)
            });
            if std::arch::is_x86_feature_detected!("avx2") {
                run("avx2 pair", &|t| unsafe { avx2_pair(packs, ray, t) });
            }
        }
        out
    }

    /// Every kernel gives each lane the single test's answer (sphere or box), bit for bit: rays from
    /// outside and inside, towards and away, at grazing angles, with short and long
    /// ranges, with unnormalised directions, and along an axis.
    #[test]
    fn every_kernel_gives_the_single_shape_tests_bit_for_bit() {
        let mut n = Numbers(0x9e37_79b9_7f4a_7c15);
        let mut hits = 0;
        for round in 0..4000 {
            let packs = packs(&mut n);
            let origin = n.vec(4.0);
            let mut dir = match round % 4 {
                0 => Vec3::X * (0.5 + n.next()),
                _ => n.vec(1.0) * (0.1 + 10.0 * n.next()),
            };
            if dir == Vec3::ZERO {
                dir = Vec3::Z;
            }
            let t_min = if round % 3 == 0 { 1e-3 } else { 0.0 };
            let t_max = if round % 5 == 0 { 0.5 } else { f32::INFINITY };
            let ray = Ray::new(origin, dir, t_min, t_max);
            let expected: Vec<Option<f32>> = (0..PAIR_LANES)
                .map(|lane| {
                    let kept = packs[lane / PACK_LANES].kept(lane % PACK_LANES);
                    kept.and_then(|shape| shape.intersect(&ray))
                })
                .collect();
            hits += expected.iter().flatten().count();
            for (kernel, mask, t) in every_kernel(&packs, &ray) {
                let lanes = if kernel.ends_with("one") {
                    PACK_LANES
                } else {
                    PAIR_LANES
                };
                assert_eq!(mask >> lanes, 0, "{kernel} reports its own lanes only");
                for (lane, expected) in expected.iter().enumerate().take(lanes) {
                    let got = (mask >> lane & 1 != 0).then(|| t[lane]);
                    assert_eq!(
                        got.map(f32::to_bits),
                        expected.map(f32::to_bits),
                        "{kernel}, lane {lane}, ray {ray:?}"
                    );
                }
            }
        }
        assert!(hits > 2000, "the rays meet the spheres often ({hits} hits)");
    }
}
