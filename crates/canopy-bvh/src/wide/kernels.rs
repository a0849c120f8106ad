//! The box test of a wide node: a ray against all `N` slot boxes at once, giving a mask of
//! the slots it enters and the entry distance of each. One scalar twin and SIMD kernels
//! (SSE2 for 4 lanes or two halves of 8, AVX2 and AVX-512 for 8) that perform the same
//! IEEE operations in the same order, so every kernel visits the same nodes.
//!
//! The slab test takes each axis's near and far planes by the sign of the ray direction
//! (its octant), so a node costs 6 subtractions, 6 multiplications and 6 min/max, with no
//! per-slot min/max of the two planes. The scalar twin, SSE2 and AVX2 pick the planes by
//! index once per ray; AVX-512 loads all six planes at fixed offsets and selects the
//! distances through mask registers keyed by the direction's signs, so that the walk
//! keeps no per-ray plane address in a general register. Every kernel computes a plane's distance as `(o - plane) * -inv` (exactly
//! `(plane - o) * inv`, zeros' signs included, and the form whose plane operand a SIMD
//! subtraction can take from memory). `min`/`max` are compare-and-select (`a < b ? a : b`),
//! which is exactly what `minps`/`maxps` compute, NaNs included. Empty slots have
//! `min = +inf`, `max = -inf` and are missed by every ray, so no slot count is needed.

use super::WideNode;
use crate::aabb::{fast_max, fast_min, FAR_SLACK};
use crate::Ray;

/// A ray prepared for slab tests against wide nodes.
#[derive(Clone, Copy, Debug)]
pub struct OctRay {
    pub o: [f32; 3],
    /// The reciprocal direction, negated.
    pub neg_inv: [f32; 3],
    /// Index into [`WideNode::bounds`] of the near plane of each axis (min or max).
    /// Always below 6: the SIMD kernels index planes with it unchecked.
    near: [usize; 3],
    /// The far plane of each axis, likewise below 6.
    far: [usize; 3],
    pub t_min: f32,
}

impl OctRay {
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        let inv = ray.inv_dir.to_array();
        // A ray running down an axis meets its max plane first.
        let down = [0, 1, 2].map(|a| inv[a].is_sign_negative() as usize);
        Self {
            o: ray.origin.to_array(),
            neg_inv: inv.map(|c| -c),
            near: [0, 1, 2].map(|a| a + 3 * down[a]),
            far: [0, 1, 2].map(|a| a + 3 - 3 * down[a]),
            t_min: ray.t_min,
        }
    }

    /// A pointer to plane `near[axis]` (or `far[axis]`) of `bounds`, in range by the
    /// invariant above.
    #[inline(always)]
    fn plane<const N: usize>(bounds: &[[f32; N]; 6], index: usize) -> *const f32 {
        debug_assert!(index < 6);
        // SAFETY: `index < 6` (the fields' invariant), so the pointer is in `bounds`.
        unsafe { bounds.as_ptr().add(index).cast::<f32>() }
    }
}

/// Tests a ray against every slot of an `N`-wide node.
pub trait NodeKernel<const N: usize> {
    type Ray: Copy;

    /// # Safety
    /// The kernel's instruction set must be available.
    unsafe fn prepare(ray: &OctRay) -> Self::Ray;

    /// Bit `i` of the mask is set when the ray enters slot `i` within `[t_min, t_max]`;
    /// `t[i]` is then the entry distance.
    ///
    /// # Safety
    /// The kernel's instruction set must be available.
    unsafe fn hit_mask(node: &WideNode<N>, ray: &Self::Ray, t_max: f32) -> (u32, [f32; N]);

    /// The slots of `mask` (entered, with entry distances `t`) farthest first, by
    /// [`order_key`]: a walk pushes all but the last and descends into the last.
    /// Positions from `mask.count_ones()` on hold some slot below `N`.
    ///
    /// # Safety
    /// The kernel's instruction set must be available.
    #[inline(always)]
    unsafe fn far_to_near(mask: u32, t: &[f32; N]) -> [u32; N] {
        far_to_near_scalar(mask, t)
    }
}

/// The key by which a walk orders the slots it enters, largest (farthest) first: the entry
/// distance as an integer in the float's total order, its 3 lowest bits replaced by the
/// slot. So slots within 8 ulps of one another come in slot order, and no two keys are
/// equal: every kernel orders them alike.
#[inline(always)]
pub(crate) fn order_key(t: f32, slot: usize) -> i32 {
    let bits = t.to_bits() as i32;
    // Negative floats order backwards as integers: flip their magnitude bits.
    let total = bits ^ (((bits >> 31) as u32) >> 1) as i32;
    (total & !7) | slot as i32
}

/// [`NodeKernel::far_to_near`] by insertion, for any width.
#[inline(always)]
pub(crate) fn far_to_near_scalar<const N: usize>(mask: u32, t: &[f32; N]) -> [u32; N] {
    let mut keys = [i32::MIN; N];
    let mut n = 0;
    let mut lanes = mask;
    while lanes != 0 {
        let i = lanes.trailing_zeros() as usize;
        lanes &= lanes - 1;
        let key = order_key(t[i], i);
        let mut j = n;
        while j > 0 && keys[j - 1] < key {
            keys[j] = keys[j - 1];
            j -= 1;
        }
        keys[j] = key;
        n += 1;
    }
    keys.map(|k| (k & 7) as u32)
}

/// The portable twin.
pub(crate) struct ScalarNode;

impl<const N: usize> NodeKernel<N> for ScalarNode {
    type Ray = OctRay;

    #[inline(always)]
    unsafe fn prepare(ray: &OctRay) -> OctRay {
        *ray
    }

    #[inline(always)]
    unsafe fn hit_mask(node: &WideNode<N>, r: &OctRay, t_max: f32) -> (u32, [f32; N]) {
        let b = &node.bounds;
        let mut mask = 0;
        let mut t = [0.0; N];
        for i in 0..N {
            let near = |a: usize| (r.o[a] - b[r.near[a]][i]) * r.neg_inv[a];
            let far = |a: usize| (r.o[a] - b[r.far[a]][i]) * r.neg_inv[a];
            let enter = fast_max(fast_max(near(0), near(1)), fast_max(near(2), r.t_min));
            let exit = fast_min(fast_min(far(0), far(1)), far(2)) * FAR_SLACK;
            let exit = fast_min(exit, t_max);
            if enter <= exit {
                mask |= 1 << i;
            }
            t[i] = enter;
        }
        (mask, t)
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) use x86::{Avx2Node, Avx512Node, Sse2Node};

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::*;
    use std::arch::x86_64::*;

    /// Four lanes of SSE2 (baseline x86-64); an 8-wide node as two halves.
    pub(crate) struct Sse2Node;

    #[derive(Clone, Copy)]
    pub(crate) struct Sse2Ray {
        o: [__m128; 3],
        neg_inv: [__m128; 3],
        near: [usize; 3],
        far: [usize; 3],
        t_min: __m128,
    }

    impl Sse2Node {
        /// Slots `offset..offset + 4` of a node whose planes are `b`.
        #[inline(always)]
        unsafe fn half<const N: usize>(
            b: &[[f32; N]; 6],
            offset: usize,
            r: &Sse2Ray,
            t_max: __m128,
        ) -> (u32, __m128) {
            // SAFETY: SSE2 is baseline; `offset + 4 <= N` and the lanes are 16-aligned
            // because nodes are 64-aligned and planes are multiples of 16 bytes.
            unsafe {
                let plane = |p: usize| _mm_load_ps(OctRay::plane(b, p).add(offset));
                let near =
                    |a: usize| _mm_mul_ps(_mm_sub_ps(r.o[a], plane(r.near[a])), r.neg_inv[a]);
                let far = |a: usize| _mm_mul_ps(_mm_sub_ps(r.o[a], plane(r.far[a])), r.neg_inv[a]);
                let enter = _mm_max_ps(_mm_max_ps(near(0), near(1)), _mm_max_ps(near(2), r.t_min));
                let exit = _mm_min_ps(_mm_min_ps(far(0), far(1)), far(2));
                let exit = _mm_min_ps(_mm_mul_ps(exit, _mm_set1_ps(FAR_SLACK)), t_max);
                (_mm_movemask_ps(_mm_cmple_ps(enter, exit)) as u32, enter)
            }
        }
    }

    macro_rules! sse2_prepare {
        ($ray:expr) => {{
            let r: &OctRay = $ray;
            Sse2Ray {
                o: r.o.map(|c| _mm_set1_ps(c)),
                neg_inv: r.neg_inv.map(|c| _mm_set1_ps(c)),
                near: r.near,
                far: r.far,
                t_min: _mm_set1_ps(r.t_min),
            }
        }};
    }

    impl NodeKernel<4> for Sse2Node {
        type Ray = Sse2Ray;

        #[inline(always)]
        unsafe fn prepare(ray: &OctRay) -> Sse2Ray {
            // SAFETY: SSE2 is baseline x86-64.
            unsafe { sse2_prepare!(ray) }
        }

        #[inline(always)]
        unsafe fn hit_mask(node: &WideNode<4>, r: &Sse2Ray, t_max: f32) -> (u32, [f32; 4]) {
            // SAFETY: SSE2 is baseline x86-64.
            unsafe {
                let (mask, enter) = Self::half(&node.bounds, 0, r, _mm_set1_ps(t_max));
                let mut t = [0.0; 4];
                _mm_storeu_ps(t.as_mut_ptr(), enter);
                (mask, t)
            }
        }
    }

    impl NodeKernel<8> for Sse2Node {
        type Ray = Sse2Ray;

        #[inline(always)]
        unsafe fn prepare(ray: &OctRay) -> Sse2Ray {
            // SAFETY: SSE2 is baseline x86-64.
            unsafe { sse2_prepare!(ray) }
        }

        #[inline(always)]
        unsafe fn hit_mask(node: &WideNode<8>, r: &Sse2Ray, t_max: f32) -> (u32, [f32; 8]) {
            // SAFETY: SSE2 is baseline x86-64.
            unsafe {
                let t_max = _mm_set1_ps(t_max);
                let (low, enter_low) = Self::half(&node.bounds, 0, r, t_max);
                let (high, enter_high) = Self::half(&node.bounds, 4, r, t_max);
                let mut t = [0.0; 8];
                _mm_storeu_ps(t.as_mut_ptr(), enter_low);
                _mm_storeu_ps(t.as_mut_ptr().add(4), enter_high);
                (low | high << 4, t)
            }
        }
    }

    /// Eight lanes of AVX2.
    pub(crate) struct Avx2Node;

    #[derive(Clone, Copy)]
    pub(crate) struct Avx2Ray {
        o: [__m256; 3],
        /// Also the AVX-512 test's blend key: its sign bit is set where the near plane is
        /// the min one.
        neg_inv: [__m256; 3],
        /// The AVX2 test's plane indices, as [`OctRay`]'s.
        near: [usize; 3],
        far: [usize; 3],
        t_min: __m256,
    }

    /// The AVX slab test of all eight slots: entry distances and exit distances.
    ///
    /// With `MASKS` (AVX-512), all six planes are loaded at fixed offsets and the near
    /// and far distances selected through mask registers (`vblendmps`, one micro-op; the
    /// masks made from the keys once per ray): the walk then keeps no plane address in a
    /// register. Without (AVX2), the planes are loaded by the ray's indices: the blends
    /// (`blendv`) measured 2-6% slower there, natively on an Intel Xeon (model 207).
    #[inline(always)]
    unsafe fn avx_enter_exit<const MASKS: bool>(
        node: &WideNode<8>,
        r: &Avx2Ray,
        t_max: f32,
    ) -> (__m256, __m256) {
        // SAFETY: called only where AVX is enabled (and AVX-512 with `MASKS`); planes are
        // 32-aligned (nodes are 64-aligned, planes 32 bytes).
        unsafe {
            let b = &node.bounds;
            let to_plane = |plane: *const f32, a: usize| {
                _mm256_mul_ps(_mm256_sub_ps(r.o[a], _mm256_load_ps(plane)), r.neg_inv[a])
            };
            let (near, far) = if MASKS {
                // The distances to an axis's min plane (`p = a`) and max plane
                // (`p = a + 3`). Written out, not `array::map`: its closure was compiled
                // apart, without AVX (so are the arrays below).
                let at = |p: usize, a: usize| to_plane(b[p].as_ptr(), a);
                let to_min = [at(0, 0), at(1, 1), at(2, 2)];
                let to_max = [at(3, 0), at(4, 1), at(5, 2)];
                // The min plane is near where the direction is not negative (`-inv` is).
                let select = |a: usize, if_clear: __m256, if_set: __m256| {
                    let key = _mm256_castps_si256(r.neg_inv[a]);
                    let set = _mm256_cmplt_epi32_mask(key, _mm256_setzero_si256());
                    _mm256_mask_blend_ps(set, if_clear, if_set)
                };
                let near = [
                    select(0, to_max[0], to_min[0]),
                    select(1, to_max[1], to_min[1]),
                    select(2, to_max[2], to_min[2]),
                ];
                let far = [
                    select(0, to_min[0], to_max[0]),
                    select(1, to_min[1], to_max[1]),
                    select(2, to_min[2], to_max[2]),
                ];
                (near, far)
            } else {
                let near = |a: usize| to_plane(OctRay::plane(b, r.near[a]), a);
                let far = |a: usize| to_plane(OctRay::plane(b, r.far[a]), a);
                ([near(0), near(1), near(2)], [far(0), far(1), far(2)])
            };
            let (near, far) = (|a: usize| near[a], |a: usize| far[a]);
            let enter = _mm256_max_ps(
                _mm256_max_ps(near(0), near(1)),
                _mm256_max_ps(near(2), r.t_min),
            );
            let exit = _mm256_min_ps(_mm256_min_ps(far(0), far(1)), far(2));
            let exit = _mm256_min_ps(
                _mm256_mul_ps(exit, _mm256_set1_ps(FAR_SLACK)),
                _mm256_set1_ps(t_max),
            );
            (enter, exit)
        }
    }

    /// [`NodeKernel::far_to_near`] of 8 slots in AVX2 registers: the keys of the entered
    /// slots (the others the least key) through a bitonic sorting network, no branches.
    #[inline(always)]
    unsafe fn avx2_far_to_near(mask: u32, t: &[f32; 8]) -> [u32; 8] {
        // SAFETY: called only where AVX2 is enabled.
        unsafe {
            let bits = _mm256_loadu_si256(t.as_ptr().cast());
            let flip = _mm256_srli_epi32::<1>(_mm256_srai_epi32::<31>(bits));
            let slots = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            let keys = _mm256_or_si256(
                _mm256_and_si256(_mm256_xor_si256(bits, flip), _mm256_set1_epi32(!7)),
                slots,
            );
            let lane_bit = _mm256_sllv_epi32(_mm256_set1_epi32(1), slots);
            let mask = _mm256_and_si256(_mm256_set1_epi32(mask as i32), lane_bit);
            let entered = _mm256_cmpeq_epi32(mask, lane_bit);
            let v = _mm256_blendv_epi8(_mm256_set1_epi32(i32::MIN), keys, entered);
            // Each stage compares every lane with its partner (`lane ^ j`) and keeps the
            // larger key where the blend's bit is set, the smaller elsewhere.
            macro_rules! stage {
                ($v:expr, $partner:expr, $larger:literal) => {{
                    let p = $partner;
                    _mm256_blend_epi32::<$larger>(_mm256_min_epi32($v, p), _mm256_max_epi32($v, p))
                }};
            }
            let v = stage!(v, _mm256_shuffle_epi32::<0xB1>(v), 0b1001_1001);
            let v = stage!(v, _mm256_shuffle_epi32::<0x4E>(v), 0b1100_0011);
            let v = stage!(v, _mm256_shuffle_epi32::<0xB1>(v), 0b1010_0101);
            let v = stage!(v, _mm256_permute2x128_si256::<0x01>(v, v), 0b0000_1111);
            let v = stage!(v, _mm256_shuffle_epi32::<0x4E>(v), 0b0011_0011);
            let v = stage!(v, _mm256_shuffle_epi32::<0xB1>(v), 0b0101_0101);
            let mut out = [0u32; 8];
            _mm256_storeu_si256(
                out.as_mut_ptr().cast(),
                _mm256_and_si256(v, _mm256_set1_epi32(7)),
            );
            out
        }
    }

    macro_rules! avx_prepare {
        ($ray:expr) => {{
            let r: &OctRay = $ray;
            Avx2Ray {
                o: r.o.map(|c| _mm256_set1_ps(c)),
                neg_inv: r.neg_inv.map(|c| _mm256_set1_ps(c)),
                near: r.near,
                far: r.far,
                t_min: _mm256_set1_ps(r.t_min),
            }
        }};
    }

    impl NodeKernel<8> for Avx2Node {
        type Ray = Avx2Ray;

        #[inline(always)]
        unsafe fn prepare(ray: &OctRay) -> Avx2Ray {
            // SAFETY: the caller guarantees AVX2.
            unsafe { avx_prepare!(ray) }
        }

        #[inline(always)]
        unsafe fn hit_mask(node: &WideNode<8>, r: &Avx2Ray, t_max: f32) -> (u32, [f32; 8]) {
            // SAFETY: the caller guarantees AVX2.
            unsafe {
                let (enter, exit) = avx_enter_exit::<false>(node, r, t_max);
                let hit = _mm256_cmp_ps::<_CMP_LE_OQ>(enter, exit);
                let mut t = [0.0; 8];
                _mm256_storeu_ps(t.as_mut_ptr(), enter);
                (_mm256_movemask_ps(hit) as u32, t)
            }
        }

        #[inline(always)]
        unsafe fn far_to_near(mask: u32, t: &[f32; 8]) -> [u32; 8] {
            // SAFETY: the caller guarantees AVX2.
            unsafe { avx2_far_to_near(mask, t) }
        }
    }

    /// Eight lanes of AVX-512 (VL): the same test, the compare straight into a mask
    /// register.
    pub(crate) struct Avx512Node;

    impl NodeKernel<8> for Avx512Node {
        type Ray = Avx2Ray;

        #[inline(always)]
        unsafe fn prepare(ray: &OctRay) -> Avx2Ray {
            // SAFETY: the caller guarantees AVX-512 (which implies AVX2).
            unsafe { avx_prepare!(ray) }
        }

        #[inline(always)]
        unsafe fn hit_mask(node: &WideNode<8>, r: &Avx2Ray, t_max: f32) -> (u32, [f32; 8]) {
            // SAFETY: the caller guarantees AVX-512 F and VL.
            unsafe {
                let (enter, exit) = avx_enter_exit::<true>(node, r, t_max);
                let mask = _mm256_cmp_ps_mask::<_CMP_LE_OQ>(enter, exit);
                let mut t = [0.0; 8];
                _mm256_storeu_ps(t.as_mut_ptr(), enter);
                (mask as u32, t)
            }
        }

        #[inline(always)]
        unsafe fn far_to_near(mask: u32, t: &[f32; 8]) -> [u32; 8] {
            // SAFETY: the caller guarantees AVX-512, which implies AVX2.
            unsafe { avx2_far_to_near(mask, t) }
        }
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use crate::Isa;

    fn far_to_near_in(isa: Isa, mask: u32, t: &[f32; 8]) -> [u32; 8] {
        // SAFETY: only instruction sets this CPU supports are asked for.
        unsafe {
            match isa {
                Isa::Scalar => <ScalarNode as NodeKernel<8>>::far_to_near(mask, t),
                Isa::Sse2 => <Sse2Node as NodeKernel<8>>::far_to_near(mask, t),
                Isa::Avx2 => <Avx2Node as NodeKernel<8>>::far_to_near(mask, t),
                Isa::Avx512 => <Avx512Node as NodeKernel<8>>::far_to_near(mask, t),
            }
        }
    }

    /// Entry distances with exact ties, ties within 8 ulps, signed zeros, negatives and
    /// infinities.
    fn distances(round: usize) -> [f32; 8] {
        const VALUES: [f32; 9] = [
            0.0,
            -0.0,
            1.0,
            -2.5,
            f32::INFINITY,
            f32::NEG_INFINITY,
            3.0,
            f32::from_bits(3.0f32.to_bits() + 3),
            f32::from_bits(3.0f32.to_bits() + 9),
        ];
        std::array::from_fn(|i| VALUES[(i * 7 + round * 5) % VALUES.len()])
    }

    /// Every kernel puts the entered slots in the order of their keys, largest first, for
    /// every mask of an 8-wide node: the same order, so every kernel visits the same nodes.
    #[test]
    fn every_kernel_orders_the_entered_slots_far_to_near_by_key() {
        for round in 0..9 {
            let t = distances(round);
            for mask in 1u32..256 {
                let mut expected: Vec<usize> = (0..8).filter(|&i| mask >> i & 1 != 0).collect();
                expected.sort_by_key(|&i| std::cmp::Reverse(order_key(t[i], i)));
                let n = expected.len();
                for isa in Isa::supported() {
                    let slots = far_to_near_in(isa, mask, &t).map(|s| s as usize);
                    assert_eq!(&slots[..n], &expected[..], "{isa}, mask {mask:#b}, t {t:?}");
                }
            }
        }
    }

    /// Keys order distances as `total_cmp` does where they lie 8 ulps or more apart, and
    /// by slot within 8 ulps; no two slots share a key.
    #[test]
    fn order_keys_follow_the_distances() {
        let t = [-3.0, -0.0, 0.0, 1e-30, 1.0, 1.0, 2.0, f32::INFINITY];
        for (i, &a) in t.iter().enumerate() {
            for (j, &b) in t.iter().enumerate().skip(i + 1) {
                let (ka, kb) = (order_key(a, i), order_key(b, j));
                assert_ne!(ka, kb);
                if a.total_cmp(&b).is_lt() && a.to_bits().abs_diff(b.to_bits()) >= 8 {
                    assert!(ka < kb, "{a} before {b}");
                }
            }
        }
        let near = f32::from_bits(1.0f32.to_bits() + 1);
        assert!(
            order_key(1.0, 5) > order_key(near, 2),
            "within 8 ulps the slot decides"
        );
    }
}
