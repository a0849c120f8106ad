//! Approximate Agglomerative Clustering (Gu, He, Fatahalian and Blelloch, "Efficient
//! BVH Construction via Approximate Agglomerative Clustering", HPG 2013).
//!
//! Primitives sorted by Morton code are split top-down by code bit until at most
//! `delta` remain; then, on the way back up, each range greedily merges the clusters of
//! its two halves down to `f(n) = delta^(1/2 + epsilon) / 2 * n^(1/2 - epsilon)` of them,
//! and the root merges what is left into one. Only small sets are ever searched, so the
//! cost is near-linear while the tree stays close to the full greedy one.

use super::merge_tree::MergeTree;
use super::morton::{morton_codes, morton_order};
use crate::{Aabb, BuildParams, Bvh2};

/// The paper's "AAC-HQ" settings.
const DELTA: usize = 20;
const EPSILON: f32 = 0.1;

pub(crate) fn build(boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    let n = boxes.len();
    let codes = morton_codes(boxes);
    let order = morton_order(&codes);
    let sorted: Vec<u64> = order.iter().map(|&i| codes[i as usize]).collect();
    let mut builder = Aac {
        tree: MergeTree::new(n),
        bounds: boxes.to_vec(),
        sorted,
        order,
    };
    if n > 0 {
        let clusters = builder.range(0, n, 62);
        builder.combine(clusters, 1);
    }
    builder.tree.into_bvh2(boxes, params)
}

/// How many clusters a range of `n` primitives hands up.
fn reduction(n: usize) -> usize {
    let c = (DELTA as f32).powf(0.5 + EPSILON) / 2.0;
    ((c * (n as f32).powf(0.5 - EPSILON)).ceil() as usize).max(1)
}

struct Aac {
    tree: MergeTree,
    bounds: Vec<Aabb>,
    sorted: Vec<u64>,
    order: Vec<u32>,
}

impl Aac {
    /// Clusters of the sorted primitives `start..end`, whose codes agree above `bit`.
    fn range(&mut self, start: usize, end: usize, bit: i32) -> Vec<u32> {
        let n = end - start;
        if n <= DELTA {
            let clusters = self.order[start..end].to_vec();
            return self.combine(clusters, reduction(DELTA));
        }
        // First position whose code has `bit` set; codes are sorted, so it splits them.
        let mid = if bit >= 0 {
            start + self.sorted[start..end].partition_point(|&c| c & (1 << bit) == 0)
        } else {
            start + n / 2
        };
        if mid == start || mid == end {
            return self.range(start, end, bit - 1);
        }
        let mut clusters = self.range(start, mid, bit - 1);
        clusters.extend(self.range(mid, end, bit - 1));
        self.combine(clusters, reduction(n))
    }

    fn cost(&self, a: u32, b: u32) -> f32 {
        self.bounds[a as usize]
            .union(self.bounds[b as usize])
            .surface_area()
    }

    /// Nearest other cluster of `clusters[i]`: (area of the union, position).
    fn nearest(&self, clusters: &[u32], i: usize) -> (f32, usize) {
        let mut best = (f32::INFINITY, usize::MAX);
        for (j, &c) in clusters.iter().enumerate() {
            if j != i {
                let cost = self.cost(clusters[i], c);
                if cost < best.0 || best.1 == usize::MAX {
                    best = (cost, j);
                }
            }
        }
        best
    }

    /// Greedily merges the closest pair until at most `target` clusters remain.
    fn combine(&mut self, mut clusters: Vec<u32>, target: usize) -> Vec<u32> {
        if clusters.len() <= target {
            return clusters;
        }
        let mut nearest: Vec<(f32, usize)> = (0..clusters.len())
            .map(|i| self.nearest(&clusters, i))
            .collect();
        while clusters.len() > target {
            let (i, &(_, j)) = nearest
                .iter()
                .enumerate()
                .min_by(|a, b| a.1 .0.total_cmp(&b.1 .0))
                .expect("at least two clusters");
            let (a, b) = (clusters[i], clusters[j]);
            let merged = self.tree.merge(a, b);
            self.bounds
                .push(self.bounds[a as usize].union(self.bounds[b as usize]));
            // The merged cluster takes i's place; the last cluster moves into j's.
            let last = clusters.len() - 1;
            clusters[i] = merged;
            clusters.swap_remove(j);
            nearest.swap_remove(j);
            let renumber = |p: usize| if p == last { j } else { p };
            let merged_at = renumber(i);
            for k in (0..clusters.len()).filter(|&k| k != merged_at) {
                let (cost, p) = nearest[k];
                if p == i || p == j {
                    // Its neighbour is gone (merged clusters are never nearer): search again.
                    nearest[k] = self.nearest(&clusters, k);
                } else {
                    nearest[k].1 = renumber(p);
                    let to_merged = self.cost(clusters[k], merged);
                    if to_merged < cost {
                        nearest[k] = (to_merged, merged_at);
                    }
                }
            }
            nearest[merged_at] = self.nearest(&clusters, merged_at);
        }
        clusters
    }
}
