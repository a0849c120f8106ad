//! Top-down binned SAH builder (Wald, "On fast construction of SAH-based bounding volume
//! hierarchies", IEEE Symposium on Interactive Ray Tracing 2007).
//!
//! Each node bins its primitives' centroids into `params.bins` equal slots along each
//! axis, evaluates the SAH at every slot boundary and splits at the cheapest one, or
//! makes a leaf when that is cheaper and allowed.

use super::top_down::{self, Splitter};
use crate::{Aabb, BuildParams, Bvh2};
use glam::Vec3;

#[derive(Clone, Copy)]
struct Bin {
    bounds: Aabb,
    count: u32,
}

const EMPTY_BIN: Bin = Bin {
    bounds: Aabb::EMPTY,
    count: 0,
};

/// The cheapest split found for a node: axis and the first bin of the right side.
struct Split {
    axis: usize,
    bin: usize,
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
        let leaf_cost = prims.len() as f32 * self.params.sah.intersection;
        let split = find_split(prims, self.boxes, &self.centroids, bounds, self.params)?;
        (split.cost < leaf_cost || must_split)
            .then(|| partition(prims, &self.centroids, &split, self.params.bins as usize))
    }
}

/// Bin index of a centroid along an axis, for a node whose centroid bounds start at `lo`
/// and have `scale = bins / extent`.
#[inline]
fn bin_of(c: f32, lo: f32, scale: f32, bins: usize) -> usize {
    (((c - lo) * scale) as usize).min(bins - 1)
}

/// The cheapest SAH split over all axes, or `None` when all centroids coincide.
fn find_split(
    prims: &[u32],
    boxes: &[Aabb],
    centroids: &[Vec3],
    bounds: Aabb,
    params: &BuildParams,
) -> Option<Split> {
    let bins = params.bins as usize;
    let centroid_bounds = Aabb::from_points(prims.iter().map(|&p| centroids[p as usize]));
    let extent = centroid_bounds.extent();
    let inv_area = 1.0 / bounds.surface_area().max(f32::MIN_POSITIVE);
    let mut best: Option<Split> = None;
    let mut bin_array = [EMPTY_BIN; 256];
    let mut right_area = [0f32; 256];
    let mut right_count = [0u32; 256];
    for axis in 0..3 {
        if extent[axis] <= 0.0 {
            continue;
        }
        let lo = centroid_bounds.min[axis];
        let scale = bins as f32 / extent[axis];
        let bin_array = &mut bin_array[..bins];
        bin_array.fill(EMPTY_BIN);
        for &p in prims {
            let bin = &mut bin_array[bin_of(centroids[p as usize][axis], lo, scale, bins)];
            bin.bounds = bin.bounds.union(boxes[p as usize]);
            bin.count += 1;
        }
        // Sweep from the right to record the right side of every boundary...
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
            let cost = params.sah.traversal
                + params.sah.intersection
                    * inv_area
                    * (acc.surface_area() * n as f32 + right_area[b] * right_count[b] as f32);
            if best.as_ref().is_none_or(|s| cost < s.cost) {
                best = Some(Split { axis, bin: b, cost });
            }
        }
    }
    best
}

/// Moves primitives left of the split to the front; returns how many there are.
fn partition(prims: &mut [u32], centroids: &[Vec3], split: &Split, bins: usize) -> usize {
    let centroid_bounds = Aabb::from_points(prims.iter().map(|&p| centroids[p as usize]));
    let lo = centroid_bounds.min[split.axis];
    let scale = bins as f32 / centroid_bounds.extent()[split.axis];
    let mut mid = 0;
    for i in 0..prims.len() {
        let c = centroids[prims[i] as usize][split.axis];
        if bin_of(c, lo, scale, bins) < split.bin {
            prims.swap(i, mid);
            mid += 1;
        }
    }
    mid
}
