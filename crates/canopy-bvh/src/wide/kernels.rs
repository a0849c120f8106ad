//! The box test of a wide node: a ray against all `N` slot boxes at once, giving a mask of
//! the slots it enters and the entry distance of each. One scalar twin and SIMD kernels
//! (SSE2 for 4 lanes or two halves of 8, AVX2 and AVX-512 for 8) that perform the same
//! IEEE operations in the same order, so every kernel visits the same nodes.
//!
//! The slab test picks each axis's near and far planes by the sign of the ray direction
//! (its octant) once per ray, so a node costs 6 subtractions, 6 multiplications and 6
//! min/max, with no per-slot min/max of the two planes. `min`/`max` are compare-and-select
//! (`a < b ? a : b`), which is exactly what `minps`/`maxps` compute, NaNs included. Empty
//! slots have `min = +inf`, `max = -inf` and are missed by every ray, so no slot count is
//! needed.

use super::WideNode;
use crate::aabb::{fast_max, fast_min, FAR_SLACK};
use crate::Ray;

/// A ray prepared for slab tests against wide nodes.
#[derive(Clone, Copy, Debug)]
pub struct OctRay {
    pub o: [f32; 3],
    pub inv: [f32; 3],
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
            inv,
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
            let near = |a: usize| (b[r.near[a]][i] - r.o[a]) * r.inv[a];
            let far = |a: usize| (b[r.far[a]][i] - r.o[a]) * r.inv[a];
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
        inv: [__m128; 3],
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
                let near = |a: usize| _mm_mul_ps(_mm_sub_ps(plane(r.near[a]), r.o[a]), r.inv[a]);
                let far = |a: usize| _mm_mul_ps(_mm_sub_ps(plane(r.far[a]), r.o[a]), r.inv[a]);
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
                inv: r.inv.map(|c| _mm_set1_ps(c)),
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
        inv: [__m256; 3],
        near: [usize; 3],
        far: [usize; 3],
        t_min: __m256,
    }

    /// The AVX slab test of all eight slots: entry distances and exit distances.
    #[inline(always)]
    unsafe fn avx_enter_exit(node: &WideNode<8>, r: &Avx2Ray, t_max: f32) -> (__m256, __m256) {
        // SAFETY: called only where AVX is enabled; planes are 32-aligned (nodes are
        // 64-aligned, planes 32 bytes).
        unsafe {
            let b = &node.bounds;
            let plane = |p: usize| _mm256_load_ps(OctRay::plane(b, p));
            let near = |a: usize| _mm256_mul_ps(_mm256_sub_ps(plane(r.near[a]), r.o[a]), r.inv[a]);
            let far = |a: usize| _mm256_mul_ps(_mm256_sub_ps(plane(r.far[a]), r.o[a]), r.inv[a]);
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

    macro_rules! avx_prepare {
        ($ray:expr) => {{
            let r: &OctRay = $ray;
            Avx2Ray {
                o: r.o.map(|c| _mm256_set1_ps(c)),
                inv: r.inv.map(|c| _mm256_set1_ps(c)),
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
                let (enter, exit) = avx_enter_exit(node, r, t_max);
                let hit = _mm256_cmp_ps::<_CMP_LE_OQ>(enter, exit);
                let mut t = [0.0; 8];
                _mm256_storeu_ps(t.as_mut_ptr(), enter);
                (_mm256_movemask_ps(hit) as u32, t)
            }
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
                let (enter, exit) = avx_enter_exit(node, r, t_max);
                let mask = _mm256_cmp_ps_mask::<_CMP_LE_OQ>(enter, exit);
                let mut t = [0.0; 8];
                _mm256_storeu_ps(t.as_mut_ptr(), enter);
                (mask as u32, t)
            }
        }
    }
}
