//! Tree statistics: node and leaf counts, depth, SAH cost, memory.

use crate::{Bvh2, SahCosts};

/// Summary of a tree's shape and quality.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TreeStats {
    pub nodes: usize,
    pub leaves: usize,
    pub max_leaf_size: usize,
    pub max_depth: usize,
    /// SAH cost with the root's surface area normalised to 1.
    pub sah_cost: f32,
    /// Bytes of nodes plus primitive indices.
    pub memory_bytes: usize,
}

impl TreeStats {
    /// Node count and memory of a tree's arrays; the rest is filled in by a walk.
    pub(crate) fn sized<N>(nodes: &[N], prim_indices: &[u32]) -> Self {
        Self {
            nodes: nodes.len(),
            memory_bytes: std::mem::size_of_val(nodes) + std::mem::size_of_val(prim_indices),
            ..Self::default()
        }
    }

    pub fn mean_leaf_size(&self, primitives: usize) -> f32 {
        primitives as f32 / self.leaves.max(1) as f32
    }
}

impl Bvh2 {
    /// Shape and quality of the tree under the given SAH costs.
    pub fn stats(&self, costs: &SahCosts) -> TreeStats {
        let mut stats = TreeStats::sized(&self.nodes, &self.prim_indices);
        let Some(root) = self.nodes.first() else {
            return stats;
        };
        let root_area = root.bounds().surface_area();
        let inv_root_area = if root_area > 0.0 {
            1.0 / root_area
        } else {
            0.0
        };
        let mut cost = 0.0f64;
        let mut stack = vec![(0usize, 1usize)];
        while let Some((i, depth)) = stack.pop() {
            let node = &self.nodes[i];
            let area = if inv_root_area > 0.0 {
                (node.bounds().surface_area() * inv_root_area) as f64
            } else {
                1.0
            };
            stats.max_depth = stats.max_depth.max(depth);
            if node.is_leaf() {
                stats.leaves += 1;
                stats.max_leaf_size = stats.max_leaf_size.max(node.count as usize);
                cost += area * node.count as f64 * costs.intersection as f64;
            } else {
                cost += area * costs.traversal as f64;
                stack.push((node.first as usize, depth + 1));
                stack.push((node.first as usize + 1, depth + 1));
            }
        }
        stats.sah_cost = cost as f32;
        stats
    }
}
