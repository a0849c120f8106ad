//! The report's top-down builders (its Algorithm 1): sort the primitives once by a key,
//! then split every node at the median of its range, recursively, until a node is small
//! enough to be a leaf. The key is either one coordinate of the centroid ("sort by x") or
//! the centroid's Morton code.

use super::morton::{morton_codes, morton_order};
use super::top_down::{self, Cut, Splitter};
use crate::{Aabb, BuildParams, Bvh2};

/// Halves every node that holds more primitives than a leaf may.
struct MedianSplit<'a> {
    boxes: &'a [Aabb],
}

impl Splitter for MedianSplit<'_> {
    type Item = u32;

    fn split(
        &self,
        prims: &mut [u32],
        _bounds: Aabb,
        _centroids: Option<Aabb>,
        must_split: bool,
    ) -> Option<Cut> {
        must_split.then_some(Cut::at(prims.len() / 2))
    }

    fn bounds(&self, prims: &[u32]) -> Aabb {
        top_down::bounds_of(self.boxes, prims)
    }

    fn prim(item: &u32) -> u32 {
        *item
    }
}

/// Sorted by one centroid coordinate (`axis` 0, 1 or 2), split at the median.
pub(crate) fn build_sort_axis(boxes: &[Aabb], params: &BuildParams, axis: usize) -> Bvh2 {
    let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
    order.sort_unstable_by(|&a, &b| {
        let (ca, cb) = (
            boxes[a as usize].center()[axis],
            boxes[b as usize].center()[axis],
        );
        ca.total_cmp(&cb).then(a.cmp(&b))
    });
    top_down::build(params, &MedianSplit { boxes }, order)
}

/// Sorted by Morton code of the centroid, split at the median.
pub(crate) fn build_morton_median(boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    let order = morton_order(&morton_codes(boxes));
    top_down::build(params, &MedianSplit { boxes }, order)
}
