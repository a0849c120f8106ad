//! Top-down binned SAH builder (Wald, "On fast construction of SAH-based bounding volume
//! hierarchies", IEEE Symposium on Interactive Ray Tracing 2007).
//!
//! Each node bins its primitives' centroids into `params.bins` equal slots along each
//! axis, evaluates the SAH at every slot boundary and splits at the cheapest one, or
//! makes a leaf when that is cheaper and allowed.

use super::top_down::{self, Splitter};
use crate::{Aabb, BuildParams, Bvh2};
use glam::Vec3;

/// Most split candidates per axis (the arrays live on the stack, cleared per node).
pub(crate) const MAX_BINS: usize = 32;

#[derive(Clone, Copy)]
struct Bin {
    bounds: Aabb,
    count: u32,
}

const EMPTY_BIN: Bin = Bin {
    bounds: Aabb::EMPTY,
    count: 0,
};

/// The cheapest split found for a node: the axis, the first bin of the right side, and
/// the binning that defines bins (centroid `lo` on the axis and bins per unit length).
struct Split {
    axis: usize,
    bin: usize,
    lo: f32,
    scale: f32,
    cost: f32,
}

pub(crate) fn build(boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    let splitter = BinnedSah {
        boxes,
        centroids: boxes.iter().map(Aabb::center).collect(),
        params,
    };
    top_down::build(boxes, params, &splitter)
}

struct BinnedSah<'a> {
    boxes: &'a [Aabb],
    centroids: Vec<Vec3>,
    params: &'a BuildParams,
}

impl Splitter for BinnedSah<'_> {
    fn split(&self, prims: &mut [u32], bounds: Aabb, must_split: bool) -> Option<usize> {
        let leaf_cost = self.params.leaf_tests(prims.len()) * self.params.sah.intersection;
        let split = self.find_split(prims, bounds)?;
        (split.cost < leaf_cost || must_split).then(|| self.partition(prims, &split))
    }
}

impl BinnedSah<'_> {
    /// Bin index of a centroid coordinate.
    #[inline]
    fn bin_of(&self, c: f32, lo: f32, scale: f32) -> usize {
        (((c - lo) * scale) as usize).min(self.params.bins as usize - 1)
    }

    /// The cheapest SAH split over all axes, or `None` when all centroids coincide.
    fn find_split(&self, prims: &[u32], bounds: Aabb) -> Option<Split> {
        let bins = self.params.bins as usize;
        let centroid_bounds = Aabb::from_points(prims.iter().map(|&p| self.centroids[p as usize]));
        let extent = centroid_bounds.extent();
        let lo = centroid_bounds.min;
        let scale = Vec3::select(extent.cmpgt(Vec3::ZERO), bins as f32 / extent, Vec3::ZERO);
        // Bin all three axes in one pass over the primitives.
        let mut axis_bins = [[EMPTY_BIN; MAX_BINS]; 3];
        for &p in prims {
            let c = self.centroids[p as usize];
            let b = self.boxes[p as usize];
            for (axis, bins_of_axis) in axis_bins.iter_mut().enumerate() {
                let bin = &mut bins_of_axis[self.bin_of(c[axis], lo[axis], scale[axis])];
                bin.bounds = bin.bounds.union(b);
                bin.count += 1;
            }
        }
        let inv_area = 1.0 / bounds.surface_area().max(f32::MIN_POSITIVE);
        let sah = &self.params.sah;
        let mut best: Option<Split> = None;
        for (axis, bin_array) in axis_bins.iter().enumerate() {
            if extent[axis] <= 0.0 {
                continue;
            }
            // Sweep from the right to record the right side of every boundary...
            let mut right_area = [0f32; MAX_BINS];
            let mut right_count = [0u32; MAX_BINS];
            let (mut acc, mut n) = (Aabb::EMPTY, 0);
            for b in (1..bins).rev() {
                acc = acc.union(bin_array[b].bounds);
                n += bin_array[b].count;
                right_area[b] = acc.surface_area();
                right_count[b] = n;
            }
            // ...then from the left, pricing each boundary.
            let (mut acc, mut n) = (Aabb::EMPTY, 0);
            for b in 1..bins {
                acc = acc.union(bin_array[b - 1].bounds);
                n += bin_array[b - 1].count;
                if n == 0 || right_count[b] == 0 {
                    continue;
                }
                let cost = sah.traversal
                    + sah.intersection
                        * inv_area
                        * (acc.surface_area() * self.params.leaf_tests(n as usize)
                            + right_area[b] * self.params.leaf_tests(right_count[b] as usize));
                if best.as_ref().is_none_or(|s| cost < s.cost) {
                    best = Some(Split {
                        axis,
                        bin: b,
                        lo: lo[axis],
                        scale: scale[axis],
                        cost,
                    });
                }
            }
        }
        best
    }

    /// Moves primitives left of the split to the front; returns how many there are.
    fn partition(&self, prims: &mut [u32], split: &Split) -> usize {
        let mut mid = 0;
        for i in 0..prims.len() {
            let c = self.centroids[prims[i] as usize][split.axis];
            if self.bin_of(c, split.lo, split.scale) < split.bin {
                prims.swap(i, mid);
                mid += 1;
            }
        }
        mid
    }
}
