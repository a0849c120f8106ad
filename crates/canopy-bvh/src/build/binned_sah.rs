//! Top-down binned SAH builder (Wald, "On fast construction of SAH-based bounding volume
//! hierarchies", IEEE Symposium on Interactive Ray Tracing 2007).
//!
//! Each node bins its primitives' centroids into equal slots along each axis, evaluates
//! the SAH at every slot boundary and splits at the cheapest one, or makes a leaf when
//! that is cheaper and allowed. Large nodes use `params.bins` slots, small ones fewer
//! (4 + n/20, as Embree does): the per-node cost of clearing and sweeping bins, not the
//! primitives, dominates near the leaves.
//!
//! For speed the nodes reorder [`PrimRef`] records (box and index together, read in
//! order), bin indices come from one SIMD conversion, the partition has no branches, and
//! a node that no split could beat (its leaf costs no more than one traversal) is a leaf
//! before binning. On the 202k dragon these took the build from 78 to about 50 ms on one
//! thread, building the same tree (`examples/build_speed.rs` prints its SAH and a hash).

use super::box4::Box4;
use super::top_down::{self, Cut, Splitter};
use crate::{Aabb, BuildParams, Bvh2};
use glam::{Vec3, Vec3A, Vec4};
use rayon::prelude::*;

/// Most split candidates per axis (the arrays live on the stack, cleared per node).
pub(crate) const MAX_BINS: usize = 32;

/// Bin arrays of this size serve nodes that need at most this many bins.
const SMALL_BINS: usize = 8;

/// Nodes with at least this many primitives are binned in parallel, in chunks of this
/// size (the top of the tree, where there is no subtree parallelism yet).
const PARALLEL_BINNING: usize = 1 << 14;

/// Which bin a centroid falls in, on each axis: `lo + i / scale` starts bin `i`.
#[derive(Clone, Copy)]
struct Binning {
    lo: Vec3A,
    scale: Vec3A,
    last: Vec3A,
}

impl Binning {
    fn new(lo: Vec3A, scale: Vec3A, bins: usize) -> Self {
        Self {
            lo,
            scale,
            last: Vec3A::splat((bins - 1) as f32),
        }
    }

    /// The bin of centroid `c` on each axis (and a fourth lane to ignore). Binning and
    /// partitioning both ask this, so they always agree, even where rounding puts a
    /// centroid past the last bin or a degenerate axis makes a NaN (both go to the last
    /// bin: `min` returns its second operand for NaN).
    #[inline(always)]
    fn bins(&self, c: Vec3A) -> [i32; 4] {
        truncate(((c - self.lo) * self.scale).min(self.last).max(Vec3A::ZERO))
    }
}

/// Lanes of `x` (in `0..=i32::MAX`) truncated to integers: one instruction on x86-64,
/// the same numbers elsewhere (where the fourth lane is 0).
#[inline(always)]
fn truncate(x: Vec3A) -> [i32; 4] {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{__m128i, _mm_cvttps_epi32};
        // SAFETY: SSE2 is part of x86-64, so the instruction is always there; __m128i and
        // [i32; 4] are 16 plain bytes each.
        unsafe { std::mem::transmute::<__m128i, [i32; 4]>(_mm_cvttps_epi32(x.into())) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let [a, b, c] = x.to_array().map(|v| v as i32);
        [a, b, c, 0]
    }
}

/// The first three lanes of `v`, the fourth zeroed (one instruction on x86-64).
#[inline(always)]
fn xyz(v: Vec4) -> Vec3A {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_and_ps, _mm_castsi128_ps, _mm_set_epi32};
        // SAFETY: SSE2 is part of x86-64, so the instructions are always there.
        Vec3A::from(unsafe { _mm_and_ps(v.into(), _mm_castsi128_ps(_mm_set_epi32(0, -1, -1, -1))) })
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        Vec3A::from_vec4(v.with_w(0.0))
    }
}

/// Adds the bins of `b` to those of `a`, exactly (min, max and counts).
fn merge_bins<const B: usize>(a: &mut AxisBins<B>, b: &AxisBins<B>) {
    for (axis_a, axis_b) in a.iter_mut().zip(b) {
        for (x, y) in axis_a.iter_mut().zip(axis_b) {
            x.bounds = x.bounds.union(y.bounds);
            x.count += y.count;
        }
    }
}

/// A primitive as the builder moves it: its box, with the primitive's index in the
/// fourth lane of `min` (and zero in that of `max`). Nodes reorder these records rather
/// than indices into a box array, so binning and partitioning read memory in order.
#[derive(Clone, Copy)]
pub(crate) struct PrimRef {
    min: Vec4,
    max: Vec4,
}

impl PrimRef {
    fn new(prim: u32, b: &Aabb) -> Self {
        Self {
            min: b.min.extend(f32::from_bits(prim)),
            max: b.max.extend(0.0),
        }
    }

    #[inline(always)]
    fn prim(&self) -> u32 {
        self.min.w.to_bits()
    }

    /// The box; the fourth lanes are not looked at.
    #[inline(always)]
    fn bounds(&self) -> Box4 {
        Box4 {
            min: Vec3A::from_vec4(self.min),
            max: Vec3A::from_vec4(self.max),
        }
    }

    /// Twice the box's centre (`min + max`, the centre without its halving, which is exact
    /// and so changes no split); the origin on an axis where the box is empty (a NaN
    /// centre), so that centroid bounds stay finite. The index lane is zeroed first: as a
    /// float it is denormal, which some CPUs add slowly.
    #[inline(always)]
    fn centroid(&self) -> Vec3A {
        let c = xyz(self.min) + Vec3A::from_vec4(self.max);
        Vec3A::select(c.cmpeq(c), c, Vec3A::ZERO)
    }
}

#[derive(Clone, Copy)]
struct Bin {
    bounds: Box4,
    count: u32,
}

const EMPTY_BIN: Bin = Bin {
    bounds: Box4::EMPTY,
    count: 0,
};

/// The bins of all three axes, `B` slots each.
type AxisBins<const B: usize> = [[Bin; B]; 3];

const _: () = assert!(MAX_BINS.is_power_of_two() && SMALL_BINS.is_power_of_two());

/// The cheapest split found for a node: the axis, the first bin of the right side, the
/// binning that defines bins, and the two sides' bounds.
struct Split {
    axis: usize,
    bin: usize,
    binning: Binning,
    cost: f32,
    left: Aabb,
    right: Aabb,
}

pub(crate) fn build(boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    let refs = boxes
        .par_iter()
        .enumerate()
        .map(|(i, b)| PrimRef::new(i as u32, b))
        .collect();
    top_down::build(params, &BinnedSah { params }, refs)
}

struct BinnedSah<'a> {
    params: &'a BuildParams,
}

impl Splitter for BinnedSah<'_> {
    type Item = PrimRef;

    /// `centroids` are in [`PrimRef::centroid`]'s doubled units, as this splitter's cuts
    /// report them.
    fn split(
        &self,
        prims: &mut [PrimRef],
        bounds: Aabb,
        centroids: Option<Aabb>,
        must_split: bool,
    ) -> Option<Cut> {
        if !must_split && self.params.leaf_beats_any_split(prims.len()) {
            return None;
        }
        let leaf_cost = self.params.leaf_cost(prims.len());
        let centroids = centroids.map_or_else(|| centroid_bounds(prims), Box4::from);
        let split = self.find_split(prims, bounds, centroids)?;
        (split.cost < leaf_cost || must_split).then(|| {
            let (mid, left, right) = partition(prims, &split);
            Cut {
                mid,
                bounds: Some((split.left, split.right)),
                centroids: Some((left.aabb(), right.aabb())),
            }
        })
    }

    fn bounds(&self, prims: &[PrimRef]) -> Aabb {
        fold_large(prims, |b, p| b.union(p.bounds())).aabb()
    }

    fn prim(item: &PrimRef) -> u32 {
        item.prim()
    }
}

/// Folds `prims` into a box with `grow`, over chunks in parallel for large nodes.
fn fold_large(prims: &[PrimRef], grow: impl Fn(Box4, &PrimRef) -> Box4 + Sync) -> Box4 {
    let fold = |chunk: &[PrimRef]| chunk.iter().fold(Box4::EMPTY, &grow);
    if prims.len() >= 2 * PARALLEL_BINNING {
        prims
            .par_chunks(PARALLEL_BINNING)
            .map(fold)
            .reduce(|| Box4::EMPTY, Box4::union)
    } else {
        fold(prims)
    }
}

/// Bounds of the centroids of `prims`.
fn centroid_bounds(prims: &[PrimRef]) -> Box4 {
    fold_large(prims, |b, p| b.grow(p.centroid()))
}

/// Moves primitives left of the split to the front; returns how many there are and the
/// bounds of each side's centroids. Branch-free (Lomuto's scheme with a swap every step,
/// which keeps `prims[..left]` left and `prims[left..i]` right): deep in the tree the
/// sides of consecutive primitives are a coin toss, which a branch would mispredict.
fn partition(prims: &mut [PrimRef], split: &Split) -> (usize, Box4, Box4) {
    let (axis, bin) = (split.axis, split.bin as i32);
    // The centroid bounds of the right side, then of the left.
    let mut sides = [Box4::EMPTY; 2];
    let mut left_count = 0;
    for i in 0..prims.len() {
        let item = prims[i];
        let c = item.centroid();
        let goes_left = split.binning.bins(c)[axis] < bin;
        let side = &mut sides[goes_left as usize];
        *side = side.grow(c);
        prims[i] = prims[left_count];
        prims[left_count] = item;
        left_count += goes_left as usize;
    }
    (left_count, sides[1], sides[0])
}

/// Bins `prims` on all three axes at once into the slots of `out` that `binning` defines.
fn bin<const B: usize>(prims: &[PrimRef], binning: &Binning, out: &mut AxisBins<B>) {
    for p in prims {
        let b = p.bounds();
        let index = binning.bins(p.centroid());
        for (axis, axis_bins) in out.iter_mut().enumerate() {
            // Bin indices are below `bins` <= B, a power of two: the mask changes nothing
            // but spares a bounds check.
            let bin = &mut axis_bins[index[axis] as usize & (B - 1)];
            bin.bounds = bin.bounds.union(b);
            bin.count += 1;
        }
    }
}

/// [`bin`], over chunks in parallel for large nodes.
fn bin_all<const B: usize>(prims: &[PrimRef], binning: &Binning, out: &mut AxisBins<B>) {
    if prims.len() < 2 * PARALLEL_BINNING {
        return bin(prims, binning, out);
    }
    *out = prims
        .par_chunks(PARALLEL_BINNING)
        .map(|chunk| {
            let mut bins_of_chunk = [[EMPTY_BIN; B]; 3];
            bin(chunk, binning, &mut bins_of_chunk);
            bins_of_chunk
        })
        .reduce(
            || [[EMPTY_BIN; B]; 3],
            |mut a, b| {
                merge_bins(&mut a, &b);
                a
            },
        );
}

impl BinnedSah<'_> {
    /// Slots per axis for a node of `n` primitives.
    fn bins_for(&self, n: usize) -> usize {
        (self.params.bins as usize).min(4 + n / 20)
    }

    /// The cheapest SAH split over all axes, or `None` when all centroids coincide.
    fn find_split(&self, prims: &[PrimRef], bounds: Aabb, centroids: Box4) -> Option<Split> {
        let bins = self.bins_for(prims.len());
        if bins <= SMALL_BINS {
            self.find_split_in::<SMALL_BINS>(prims, bounds, centroids, bins)
        } else {
            self.find_split_in::<MAX_BINS>(prims, bounds, centroids, bins)
        }
    }

    /// [`Self::find_split`] with `bins` slots per axis in arrays of `B`.
    fn find_split_in<const B: usize>(
        &self,
        prims: &[PrimRef],
        bounds: Aabb,
        centroid_bounds: Box4,
        bins: usize,
    ) -> Option<Split> {
        let extent = Vec3::from(centroid_bounds.max - centroid_bounds.min);
        let lo = Vec3::from(centroid_bounds.min);
        let scale = Vec3::select(extent.cmpgt(Vec3::ZERO), bins as f32 / extent, Vec3::ZERO);
        let binning = Binning::new(lo.into(), scale.into(), bins);
        let mut axis_bins = [[EMPTY_BIN; B]; 3];
        bin_all(prims, &binning, &mut axis_bins);
        let inv_area = 1.0 / bounds.surface_area().max(f32::MIN_POSITIVE);
        let sah = &self.params.sah;
        let tests = |n: u32| self.params.leaf_tests(n as usize);
        // (cost, axis, first bin of the right side)
        let mut best: Option<(f32, usize, usize)> = None;
        for (axis, bin_array) in axis_bins.iter().enumerate() {
            if extent[axis] <= 0.0 {
                continue;
            }
            // Sweep from the right to record the right side of every boundary...
            let mut right_area = [0f32; B];
            let mut right_count = [0u32; B];
            let (mut acc, mut n) = (Box4::EMPTY, 0);
            for b in (1..bins).rev() {
                acc = acc.union(bin_array[b].bounds);
                n += bin_array[b].count;
                right_area[b] = acc.aabb().surface_area();
                right_count[b] = n;
            }
            // ...then from the left, pricing each boundary.
            let (mut acc, mut n) = (Box4::EMPTY, 0);
            for b in 1..bins {
                acc = acc.union(bin_array[b - 1].bounds);
                n += bin_array[b - 1].count;
                if n == 0 || right_count[b] == 0 {
                    continue;
                }
                let cost = sah.traversal
                    + sah.intersection
                        * inv_area
                        * (acc.aabb().surface_area() * tests(n)
                            + right_area[b] * tests(right_count[b]));
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, b));
                }
            }
        }
        let (cost, axis, bin) = best?;
        let side = |bins: &[Bin]| bins.iter().fold(Box4::EMPTY, |b, bin| b.union(bin.bounds));
        Some(Split {
            axis,
            bin,
            binning,
            cost,
            left: side(&axis_bins[axis][..bin]).aabb(),
            right: side(&axis_bins[axis][bin..bins]).aabb(),
        })
    }
}
