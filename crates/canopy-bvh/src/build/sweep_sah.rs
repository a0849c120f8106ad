//! Top-down SAH with a full sweep: every node sorts its primitives along each axis and
//! prices every split position between neighbours (MacDonald and Booth 1990; Wald et al.
//! 2007). The slowest top-down builder and the quality reference for the others.

use super::top_down::{self, Cut, Splitter};
use crate::{Aabb, BuildParams, Bvh2};
use glam::Vec3;

pub(crate) fn build(boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    let splitter = SweepSah {
        boxes,
        centroids: boxes.iter().map(Aabb::center).collect(),
        params,
    };
    top_down::build(params, &splitter, (0..boxes.len() as u32).collect())
}

struct SweepSah<'a> {
    boxes: &'a [Aabb],
    centroids: Vec<Vec3>,
    params: &'a BuildParams,
}

impl Splitter for SweepSah<'_> {
    type Item = u32;

    fn bounds(&self, prims: &[u32]) -> Aabb {
        top_down::bounds_of(self.boxes, prims)
    }

    fn prim(item: &u32) -> u32 {
        *item
    }

    fn split(
        &self,
        prims: &mut [u32],
        bounds: Aabb,
        _centroids: Option<Aabb>,
        must_split: bool,
    ) -> Option<Cut> {
        let n = prims.len();
        if n < 2 || (!must_split && self.params.leaf_beats_any_split(n)) {
            return None;
        }
        let leaf_cost = self.params.leaf_cost(n);
        let inv_area = 1.0 / bounds.surface_area().max(f32::MIN_POSITIVE);
        let sah = &self.params.sah;
        let mut best: Option<(f32, usize, Vec<u32>)> = None;
        let mut right_area = vec![0f32; n];
        for axis in 0..3 {
            let mut sorted = prims.to_vec();
            sorted.sort_unstable_by(|&a, &b| {
                let (ca, cb) = (
                    self.centroids[a as usize][axis],
                    self.centroids[b as usize][axis],
                );
                ca.total_cmp(&cb).then(a.cmp(&b))
            });
            // right_area[i]: area of the box of sorted[i..].
            let mut acc = Aabb::EMPTY;
            for i in (1..n).rev() {
                acc = acc.union(self.boxes[sorted[i] as usize]);
                right_area[i] = acc.surface_area();
            }
            let mut acc = Aabb::EMPTY;
            let mut axis_best: Option<(f32, usize)> = None;
            for i in 1..n {
                acc = acc.union(self.boxes[sorted[i - 1] as usize]);
                let cost = sah.traversal
                    + sah.intersection
                        * inv_area
                        * (acc.surface_area() * self.params.leaf_tests(i)
                            + right_area[i] * self.params.leaf_tests(n - i));
                if axis_best.is_none_or(|(c, _)| cost < c) {
                    axis_best = Some((cost, i));
                }
            }
            if let Some((cost, i)) = axis_best {
                if best.as_ref().is_none_or(|(c, _, _)| cost < *c) {
                    best = Some((cost, i, sorted));
                }
            }
        }
        let (cost, mid, sorted) = best?;
        (cost < leaf_cost || must_split).then(|| {
            prims.copy_from_slice(&sorted);
            Cut::at(mid)
        })
    }
}
