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
use rayon::prelude::*;

pub(crate) fn build(boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    let n = boxes.len();
    let radius = params.ploc_radius.max(1) as usize;
    let mut tree = MergeTree::new(n);
    let mut bounds: Vec<Aabb> = boxes.to_vec();
    bounds.reserve(n.saturating_sub(1));
    let mut clusters: Vec<u32> = morton_order(&morton_codes(boxes));
    while clusters.len() > 1 {
        let nearest: Vec<usize> = (0..clusters.len())
            .into_par_iter()
            .map(|i| {
                let b = bounds[clusters[i] as usize];
                let lo = i.saturating_sub(radius);
                let hi = (i + radius).min(clusters.len() - 1);
                let mut best = (f32::INFINITY, usize::MAX);
                for j in (lo..=hi).filter(|&j| j != i) {
                    let cost = b.union(bounds[clusters[j] as usize]).surface_area();
                    if cost < best.0 || best.1 == usize::MAX {
                        best = (cost, j);
                    }
                }
                best.1
            })
            .collect();
        let mut next = Vec::with_capacity(clusters.len());
        for (i, &j) in nearest.iter().enumerate() {
            if nearest[j] != i {
                next.push(clusters[i]);
            } else if i < j {
                let (a, b) = (clusters[i], clusters[j]);
                let merged = tree.merge(a, b);
                bounds.push(bounds[a as usize].union(bounds[b as usize]));
                next.push(merged);
            }
        }
        clusters = next;
    }
    tree.into_bvh2(boxes, params)
}
