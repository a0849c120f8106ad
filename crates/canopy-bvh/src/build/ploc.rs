//! Parallel Locally-Ordered Clustering (Meister and Bittner, "Parallel Locally-Ordered
//! Clustering for Bounding Volume Hierarchy Construction", IEEE TVCG 2018).
//!
//! Clusters start as the primitives in Morton order. Each round, every cluster finds its
//! nearest neighbour (smallest merged surface area) among the `radius` clusters on either
//! side of it, in parallel; mutual nearest neighbours merge, and the survivors keep their
//! order. Ties go to the lower position, which makes the cheapest pair always mutual, so
//! every round merges at least once.

use super::merge_tree::MergeTree;
use super::morton::{morton_codes, morton_order};
use crate::{Aabb, BuildParams, Bvh2};
use glam::Vec3A;
use rayon::prelude::*;

pub(crate) fn build(boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    let n = boxes.len();
    // A radius past the last cluster searches nothing more; clamping it keeps the
    // distance table at n * radius entries for any radius asked for.
    let radius = (params.ploc_radius.max(1) as usize).min(n.saturating_sub(1).max(1));
    let mut tree = MergeTree::new(n);
    let mut clusters: Vec<u32> = morton_order(&morton_codes(boxes));
    // Boxes of the live clusters, in list order (contiguous for the neighbour search).
    let mut bounds: Vec<Aabb> = clusters.iter().map(|&c| boxes[c as usize]).collect();
    let mut distances = Vec::new();
    while clusters.len() > 1 {
        let nearest = nearest_neighbours(&bounds, radius, &mut distances);
        let mut next_clusters = Vec::with_capacity(clusters.len());
        let mut next_bounds = Vec::with_capacity(clusters.len());
        for (i, &j) in nearest.iter().enumerate() {
            if nearest[j] != i {
                next_clusters.push(clusters[i]);
                next_bounds.push(bounds[i]);
            } else if i < j {
                next_clusters.push(tree.merge(clusters[i], clusters[j]));
                next_bounds.push(bounds[i].union(bounds[j]));
            }
        }
        clusters = next_clusters;
        bounds = next_bounds;
    }
    tree.into_bvh2(boxes, params)
}

/// For every cluster, the position of its nearest neighbour within `radius` positions.
/// Each pair's merged area is computed once, into `distances[i * radius + k - 1]` for the
/// pair (i, i + k), and read by both.
fn nearest_neighbours(bounds: &[Aabb], radius: usize, distances: &mut Vec<f32>) -> Vec<usize> {
    let n = bounds.len();
    distances.clear();
    distances.resize(n * radius, f32::INFINITY);
    let simd: Vec<SimdBox> = bounds.iter().map(SimdBox::from).collect();
    distances
        .par_chunks_mut(radius)
        .enumerate()
        .for_each(|(i, row)| {
            for (d, other) in row.iter_mut().zip(&simd[i + 1..]) {
                *d = simd[i].union_area(other);
            }
        });
    let distances = &*distances;
    (0..n)
        .into_par_iter()
        .map(|i| {
            // Candidates in increasing position, so that `<` keeps the lowest on a tie.
            let mut best = (f32::INFINITY, usize::MAX);
            for k in (1..=radius.min(i)).rev() {
                let d = distances[(i - k) * radius + k - 1];
                if d < best.0 {
                    best = (d, i - k);
                }
            }
            // Row i holds (i, i + k); entries past the end are infinite and never chosen.
            for (k, &d) in distances[i * radius..(i + 1) * radius].iter().enumerate() {
                if d < best.0 {
                    best = (d, i + k + 1);
                }
            }
            match best.1 {
                usize::MAX if i > 0 => i - 1, // every area infinite: any neighbour will do
                usize::MAX => 1,
                j => j,
            }
        })
        .collect()
}

/// A box in SIMD registers, for the hot merged-area computation.
struct SimdBox {
    min: Vec3A,
    max: Vec3A,
}

impl From<&Aabb> for SimdBox {
    fn from(b: &Aabb) -> Self {
        Self {
            min: b.min.into(),
            max: b.max.into(),
        }
    }
}

impl SimdBox {
    /// Surface area of the union of two boxes.
    #[inline(always)]
    fn union_area(&self, other: &SimdBox) -> f32 {
        let e = self.max.max(other.max) - self.min.min(other.min);
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }
}
