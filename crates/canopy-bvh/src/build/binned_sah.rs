//! Top-down binned SAH builder (Wald, "On fast construction of SAH-based bounding volume
//! hierarchies", IEEE Symposium on Interactive Ray Tracing 2007).
//!
//! Each node bins its primitives' centroids into equal slots along each axis, evaluates
//! the SAH at every slot boundary and splits at the cheapest one, or makes a leaf when
//! that is cheaper and allowed. Large nodes use `params.bins` slots, small ones fewer
//! (4 + n/20, as Embree does): the per-node cost of clearing and sweeping bins, not the
//! primitives, dominates near the leaves.

use super::box4::Box4;
use super::top_down::{self, Cut, Splitter};
use crate::{Aabb, BuildParams, Bvh2};
use glam::{Vec3, Vec3A};
use rayon::prelude::*;

/// Most split candidates per axis (the arrays live on the stack, cleared per node).
pub(crate) const MAX_BINS: usize = 32;

/// Bin arrays of this size serve nodes that need at most this many bins.
const SMALL_BINS: usize = 8;

/// Nodes with at least this many primitives are binned in parallel, in chunks of this
/// size (the top of the tree, where there is no subtree parallelism yet).
const PARALLEL_BINNING: usize = 1 << 14;

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

/// The cheapest split found for a node: the axis, the first bin of the right side, the
/// binning that defines bins (centroid `lo` on the axis and bins per unit length), and
/// the two sides' bounds.
struct Split {
    axis: usize,
    bin: usize,
    lo: f32,
    scale: f32,
    cost: f32,
    left: Aabb,
    right: Aabb,
}

pub(crate) fn build(boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    let splitter = BinnedSah {
        boxes: boxes
            .iter()
            .map(|b| Box4 {
                min: b.min.into(),
                max: b.max.into(),
            })
            .collect(),
        centroids: boxes.iter().map(centroid).collect(),
        params,
    };
    top_down::build(boxes, params, &splitter)
}

/// A box's centre; the origin for an empty box (whose centre is NaN), so that binning
/// and partitioning, which compare centroids differently, always agree.
fn centroid(b: &Aabb) -> Vec3A {
    if b.is_empty() {
        Vec3A::ZERO
    } else {
        b.center().into()
    }
}

struct BinnedSah<'a> {
    boxes: Vec<Box4>,
    centroids: Vec<Vec3A>,
    params: &'a BuildParams,
}

impl Splitter for BinnedSah<'_> {
    fn split(
        &self,
        prims: &mut [u32],
        bounds: Aabb,
        centroids: Option<Aabb>,
        must_split: bool,
    ) -> Option<Cut> {
        let leaf_cost = self.params.leaf_tests(prims.len()) * self.params.sah.intersection;
        let centroids = centroids.map_or_else(|| self.centroid_bounds(prims), Box4::from);
        let split = self.find_split(prims, bounds, centroids)?;
        (split.cost < leaf_cost || must_split).then(|| {
            let (mid, left, right) = self.partition(prims, &split);
            Cut {
                mid,
                bounds: Some((split.left, split.right)),
                centroids: Some((left.aabb(), right.aabb())),
            }
        })
    }
}

impl BinnedSah<'_> {
    /// Bounds of the centroids of `prims`, in parallel for large nodes.
    fn centroid_bounds(&self, prims: &[u32]) -> Box4 {
        let fold = |chunk: &[u32]| {
            chunk
                .iter()
                .fold(Box4::EMPTY, |b, &p| b.grow(self.centroids[p as usize]))
        };
        if prims.len() >= 2 * PARALLEL_BINNING {
            prims
                .par_chunks(PARALLEL_BINNING)
                .map(fold)
                .reduce(|| Box4::EMPTY, Box4::union)
        } else {
            fold(prims)
        }
    }

    /// Slots per axis for a node of `n` primitives.
    fn bins_for(&self, n: usize) -> usize {
        (self.params.bins as usize).min(4 + n / 20)
    }

    /// Bins `prims` on all three axes at once into `bins` slots of `out`, which are
    /// `lo + i / scale` wide.
    fn bin<const B: usize>(
        &self,
        prims: &[u32],
        lo: Vec3A,
        scale: Vec3A,
        bins: usize,
        out: &mut AxisBins<B>,
    ) {
        let last = glam::UVec3::splat(bins as u32 - 1);
        for &p in prims {
            let b = self.boxes[p as usize];
            // (c - lo) >= 0, so the float-to-int conversion truncates as `as usize` does.
            let index = ((self.centroids[p as usize] - lo) * scale)
                .as_uvec3()
                .min(last);
            for (axis, axis_bins) in out.iter_mut().enumerate() {
                let bin = &mut axis_bins[index[axis] as usize];
                bin.bounds = bin.bounds.union(b);
                bin.count += 1;
            }
        }
    }

    /// [`Self::bin`], over chunks in parallel for large nodes, merged exactly (min, max
    /// and counts).
    fn bin_all<const B: usize>(
        &self,
        prims: &[u32],
        lo: Vec3A,
        scale: Vec3A,
        bins: usize,
        out: &mut AxisBins<B>,
    ) {
        if prims.len() < 2 * PARALLEL_BINNING {
            return self.bin(prims, lo, scale, bins, out);
        }
        *out = prims
            .par_chunks(PARALLEL_BINNING)
            .map(|chunk| {
                let mut bins_of_chunk = [[EMPTY_BIN; B]; 3];
                self.bin(chunk, lo, scale, bins, &mut bins_of_chunk);
                bins_of_chunk
            })
            .reduce(
                || [[EMPTY_BIN; B]; 3],
                |mut a, b| {
                    for (axis_a, axis_b) in a.iter_mut().zip(&b) {
                        for (x, y) in axis_a.iter_mut().zip(axis_b) {
                            x.bounds = x.bounds.union(y.bounds);
                            x.count += y.count;
                        }
                    }
                    a
                },
            );
    }

    /// The cheapest SAH split over all axes, or `None` when all centroids coincide.
    fn find_split(&self, prims: &[u32], bounds: Aabb, centroids: Box4) -> Option<Split> {
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
        prims: &[u32],
        bounds: Aabb,
        centroid_bounds: Box4,
        bins: usize,
    ) -> Option<Split> {
        let extent = Vec3::from(centroid_bounds.max - centroid_bounds.min);
        let lo = Vec3::from(centroid_bounds.min);
        let scale = Vec3::select(extent.cmpgt(Vec3::ZERO), bins as f32 / extent, Vec3::ZERO);
        let mut axis_bins = [[EMPTY_BIN; B]; 3];
        self.bin_all(prims, lo.into(), scale.into(), bins, &mut axis_bins);
        let inv_area = 1.0 / bounds.surface_area().max(f32::MIN_POSITIVE);
        let sah = &self.params.sah;
        let mut best: Option<Split> = None;
        for (axis, bin_array) in axis_bins.iter().enumerate() {
            if extent[axis] <= 0.0 {
                continue;
            }
            // Sweep from the right to record the right side of every boundary...
            let mut right_bounds = [Box4::EMPTY; B];
            let mut right_count = [0u32; B];
            let (mut acc, mut n) = (Box4::EMPTY, 0);
            for b in (1..bins).rev() {
                acc = acc.union(bin_array[b].bounds);
                n += bin_array[b].count;
                right_bounds[b] = acc;
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
                let (left, right) = (acc.aabb(), right_bounds[b].aabb());
                let cost = sah.traversal
                    + sah.intersection
                        * inv_area
                        * (left.surface_area() * self.params.leaf_tests(n as usize)
                            + right.surface_area()
                                * self.params.leaf_tests(right_count[b] as usize));
                if best.as_ref().is_none_or(|s| cost < s.cost) {
                    best = Some(Split {
                        axis,
                        bin: b,
                        lo: lo[axis],
                        scale: scale[axis],
                        cost,
                        left,
                        right,
                    });
                }
            }
        }
        best
    }

    /// Moves primitives left of the split to the front (swapping from both ends, so
    /// each misplaced pair costs one swap); returns how many there are and the bounds of
    /// each side's centroids.
    fn partition(&self, prims: &mut [u32], split: &Split) -> (usize, Box4, Box4) {
        let axis = split.axis;
        // The bin index is trunc((c - lo) * scale) clamped to the last bin, and c >= lo,
        // so it lies left of `split.bin` exactly when (c - lo) * scale < split.bin.
        let threshold = split.bin as f32;
        let goes_left = |c: Vec3A| (c[axis] - split.lo) * split.scale < threshold;
        let (mut left, mut right) = (Box4::EMPTY, Box4::EMPTY);
        let (mut i, mut j) = (0, prims.len());
        loop {
            while i < j {
                let c = self.centroids[prims[i] as usize];
                if !goes_left(c) {
                    break;
                }
                left = left.grow(c);
                i += 1;
            }
            while i < j {
                let c = self.centroids[prims[j - 1] as usize];
                if goes_left(c) {
                    break;
                }
                right = right.grow(c);
                j -= 1;
            }
            if i >= j {
                return (i, left, right);
            }
            // prims[i] belongs right and prims[j - 1] left: swap them into place.
            prims.swap(i, j - 1);
            left = left.grow(self.centroids[prims[i] as usize]);
            right = right.grow(self.centroids[prims[j - 1] as usize]);
            i += 1;
            j -= 1;
        }
    }
}
