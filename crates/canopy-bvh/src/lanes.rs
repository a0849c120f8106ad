//! One SIMD register of floats, one primitive of a [`TrianglePack`] per lane: the
//! operations the pack tests (triangles in `triangle`, spheres and boxes in `wide::pack_shapes`)
//! need, written once for SSE2's 4 lanes (one pack) and AVX's 8 (two packs).

use crate::triangle::{TrianglePack, PAIR_LANES};
use std::arch::x86_64::*;

/// A SIMD register of floats, one primitive per lane, holding one pack (4 lanes, SSE2)
/// or two (8 lanes, AVX): the operations the pack tests need, so that each test is
/// written once for both.
///
/// # Safety
/// The methods use the register's instruction set (SSE2 is baseline x86-64; the
/// 8-lane one runs only inside functions compiled for AVX2).
pub(crate) trait Lanes: Copy {
    /// Lanes per register: one pack's, or two packs'.
    const PACKS: usize;
    unsafe fn splat(x: f32) -> Self;
    /// Coordinate `axis` of `vertex` of the first `PACKS` packs.
    unsafe fn load(packs: &[TrianglePack], vertex: usize, axis: usize) -> Self;
    unsafe fn add(self, b: Self) -> Self;
    unsafe fn sub(self, b: Self) -> Self;
    unsafe fn mul(self, b: Self) -> Self;
    unsafe fn div(self, b: Self) -> Self;
    unsafe fn sqrt(self) -> Self;
    unsafe fn and(self, b: Self) -> Self;
    /// `self & !b`, bit by bit.
    unsafe fn and_not(self, b: Self) -> Self;
    unsafe fn or(self, b: Self) -> Self;
    unsafe fn xor(self, b: Self) -> Self;
    unsafe fn eq(self, b: Self) -> Self;
    unsafe fn ne(self, b: Self) -> Self;
    unsafe fn lt(self, b: Self) -> Self;
    unsafe fn gt(self, b: Self) -> Self;
    unsafe fn ge(self, b: Self) -> Self;
    unsafe fn le(self, b: Self) -> Self;
    unsafe fn mask(self) -> u32;
    unsafe fn store(self, to: &mut [f32; PAIR_LANES]);

    /// `a` in the lanes where `self` (a comparison's result) is set, else `b`.
    #[inline(always)]
    unsafe fn select(self, a: Self, b: Self) -> Self {
        // SAFETY: as the trait says.
        unsafe { a.and(self).or(b.and_not(self)) }
    }
}

/// Binary operations of a `Lanes` impl, each one intrinsic.
macro_rules! binary_ops {
    ($($name:ident: $op:expr;)*) => {$(
        #[inline(always)]
        unsafe fn $name(self, b: Self) -> Self {
            // SAFETY: as the trait says.
            unsafe { $op(self, b) }
        }
    )*};
}

impl Lanes for __m128 {
    const PACKS: usize = 1;

    #[inline(always)]
    unsafe fn splat(x: f32) -> Self {
        // SAFETY: SSE2 is baseline x86-64.
        unsafe { _mm_set1_ps(x) }
    }

    #[inline(always)]
    unsafe fn sqrt(self) -> Self {
        // SAFETY: SSE2 is baseline x86-64.
        unsafe { _mm_sqrt_ps(self) }
    }

    #[inline(always)]
    unsafe fn and_not(self, b: Self) -> Self {
        // SAFETY: SSE2 is baseline x86-64.
        unsafe { _mm_andnot_ps(b, self) }
    }

    #[inline(always)]
    unsafe fn load(packs: &[TrianglePack], vertex: usize, axis: usize) -> Self {
        // SAFETY: SSE2 is baseline; the lanes are a 16-aligned `[f32; 4]`.
        unsafe { _mm_load_ps(packs[0].v[vertex][axis].as_ptr()) }
    }

    binary_ops! {
        add: _mm_add_ps; sub: _mm_sub_ps; mul: _mm_mul_ps; div: _mm_div_ps;
        and: _mm_and_ps; or: _mm_or_ps; xor: _mm_xor_ps;
        eq: _mm_cmpeq_ps; ne: _mm_cmpneq_ps; lt: _mm_cmplt_ps; gt: _mm_cmpgt_ps;
        ge: _mm_cmpge_ps; le: _mm_cmple_ps;
    }

    #[inline(always)]
    unsafe fn mask(self) -> u32 {
        // SAFETY: SSE2 is baseline x86-64.
        unsafe { _mm_movemask_ps(self) as u32 }
    }

    #[inline(always)]
    unsafe fn store(self, to: &mut [f32; PAIR_LANES]) {
        // SAFETY: SSE2 is baseline; four floats fit in `to`.
        unsafe { _mm_storeu_ps(to.as_mut_ptr(), self) }
    }
}

impl Lanes for __m256 {
    const PACKS: usize = 2;

    #[inline(always)]
    unsafe fn splat(x: f32) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_set1_ps(x) }
    }

    #[inline(always)]
    unsafe fn sqrt(self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_sqrt_ps(self) }
    }

    #[inline(always)]
    unsafe fn and_not(self, b: Self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_andnot_ps(b, self) }
    }

    #[inline(always)]
    unsafe fn load(packs: &[TrianglePack], vertex: usize, axis: usize) -> Self {
        // SAFETY: the caller guarantees AVX and two packs; lanes are 16-aligned.
        unsafe {
            let low = _mm_load_ps(packs[0].v[vertex][axis].as_ptr());
            let high = _mm_load_ps(packs[1].v[vertex][axis].as_ptr());
            _mm256_set_m128(high, low)
        }
    }

    // The comparisons are those of the SSE2 intrinsics: ordered, except `ne`.
    binary_ops! {
        add: _mm256_add_ps; sub: _mm256_sub_ps; mul: _mm256_mul_ps; div: _mm256_div_ps;
        and: _mm256_and_ps; or: _mm256_or_ps; xor: _mm256_xor_ps;
        eq: _mm256_cmp_ps::<_CMP_EQ_OQ>; ne: _mm256_cmp_ps::<_CMP_NEQ_UQ>;
        lt: _mm256_cmp_ps::<_CMP_LT_OQ>; gt: _mm256_cmp_ps::<_CMP_GT_OQ>;
        ge: _mm256_cmp_ps::<_CMP_GE_OQ>; le: _mm256_cmp_ps::<_CMP_LE_OQ>;
    }

    #[inline(always)]
    unsafe fn mask(self) -> u32 {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_movemask_ps(self) as u32 }
    }

    #[inline(always)]
    unsafe fn store(self, to: &mut [f32; PAIR_LANES]) {
        // SAFETY: the caller guarantees AVX; eight floats fit in `to`.
        unsafe { _mm256_storeu_ps(to.as_mut_ptr(), self) }
    }
}
