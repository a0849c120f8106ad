//! Tree statistics: node and leaf counts, depth, SAH cost, memory (computed for every
//! layout by [`crate::view::stats`]).

/// Summary of a tree's shape and quality.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TreeStats {
    pub nodes: usize,
    pub leaves: usize,
    pub max_leaf_size: usize,
    /// Primitive references in leaves: the primitives, plus the duplicates spatial splits
    /// made.
    pub references: usize,
    /// Boxes from the root's to the deepest leaf's, both included.
    pub max_depth: usize,
    /// SAH cost with the root's surface area normalised to 1.
    pub sah_cost: f32,
    /// Bytes of nodes, primitive indices and packed triangles.
    pub memory_bytes: usize,
}

impl TreeStats {
    pub fn mean_leaf_size(&self) -> f32 {
        self.references as f32 / self.leaves.max(1) as f32
    }
}
