//! The one binary tree format that every builder produces.

use crate::view::{Child, ChildKind, TreeView};
use crate::Aabb;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use thiserror::Error;

/// A node of a [`Bvh2`]: 32 bytes, `#[repr(C)]` and `Pod`, so a node array uploads to a
/// GPU as is.
///
/// Byte layout: `min: [f32; 3]` (0..12), `first: u32` (12..16), `max: [f32; 3]` (16..28),
/// `count: u32` (28..32).
///
/// `count == 0`: an interior node whose children are nodes `first` and `first + 1`.
/// `count > 0`: a leaf of `count` primitives at `prim_indices[first..first + count]`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Bvh2Node {
    pub min: Vec3,
    pub first: u32,
    pub max: Vec3,
    pub count: u32,
}

const _: () = assert!(std::mem::size_of::<Bvh2Node>() == 32);
const _: () = assert!(std::mem::align_of::<Bvh2Node>() == 4);

impl Bvh2Node {
    #[inline]
    pub fn leaf(bounds: Aabb, first: u32, count: u32) -> Self {
        debug_assert!(count > 0);
        Self {
            min: bounds.min,
            first,
            max: bounds.max,
            count,
        }
    }

    #[inline]
    pub fn interior(bounds: Aabb, first_child: u32) -> Self {
        Self {
            min: bounds.min,
            first: first_child,
            max: bounds.max,
            count: 0,
        }
    }

    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }

    #[inline]
    pub fn bounds(&self) -> Aabb {
        Aabb::new(self.min, self.max)
    }
}

/// A binary BVH: a flat node array (root at index 0, siblings adjacent) and the
/// permutation of primitive indices that leaves point into.
///
/// An empty input gives a tree with no nodes, which every query answers with a miss.
///
/// A tree built with spatial splits (`sbvh`) may reference a primitive from several
/// leaves, each leaf box holding only the part of it that leaf owns: see
/// [`Bvh2::has_spatial_splits`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bvh2 {
    pub(crate) nodes: Vec<Bvh2Node>,
    pub(crate) prim_indices: Vec<u32>,
    /// Leaves may hold clipped references (see [`Bvh2::has_spatial_splits`]).
    pub(crate) spatial_splits: bool,
}

/// Why [`Bvh2::refit`] refused a tree.
#[derive(Debug, Error, PartialEq)]
pub enum RefitError {
    #[error(
        "cannot refit a tree with spatial splits: its leaves hold clipped parts of primitives, \
         which whole-primitive boxes would loosen; rebuild it instead"
    )]
    SpatialSplits,
}

/// What [`Bvh2::validate`] found wrong with a tree.
#[derive(Debug, Error, PartialEq)]
pub enum BvhError {
    #[error("node {node}: child index {child} is out of range ({len} nodes)")]
    ChildOutOfRange {
        node: usize,
        child: usize,
        len: usize,
    },
    #[error("node {node}: leaf range {first}..{end} exceeds {len} primitive indices")]
    LeafOutOfRange {
        node: usize,
        first: usize,
        end: usize,
        len: usize,
    },
    #[error("node {node} is reached more than once")]
    NodeShared { node: usize },
    #[error("{unreached} of {len} nodes are not reachable from the root")]
    UnreachableNodes { unreached: usize, len: usize },
    #[error("primitive {prim} appears {times} times in leaves (expected once)")]
    PrimitiveCount { prim: u32, times: usize },
    #[error("primitive index {prim} is out of range ({len} primitives)")]
    PrimitiveOutOfRange { prim: u32, len: usize },
    #[error("node {node}: box is not the tight union of its contents")]
    NotTight { node: usize },
    #[error("node {node}: leaf box reaches outside its primitives' boxes")]
    LeafOutsidePrimitives { node: usize },
    #[error("node {node}: child {child} is not inside its parent's box")]
    ChildOutsideParent { node: usize, child: usize },
}

impl Bvh2 {
    /// Assembles a tree from parts; call [`Bvh2::validate`] if they come from outside.
    pub fn from_parts(nodes: Vec<Bvh2Node>, prim_indices: Vec<u32>) -> Self {
        Self {
            nodes,
            prim_indices,
            spatial_splits: false,
        }
    }

    /// Whether leaves may hold clipped references: a primitive may appear in several
    /// leaves, and a leaf box need only cover the part of each primitive it owns. Such a
    /// tree is traced like any other, but [`Bvh2::refit`] refuses it and
    /// [`Bvh2::validate`] checks the weaker invariants.
    pub fn has_spatial_splits(&self) -> bool {
        self.spatial_splits
    }

    pub fn nodes(&self) -> &[Bvh2Node] {
        &self.nodes
    }

    pub fn prim_indices(&self) -> &[u32] {
        &self.prim_indices
    }

    /// Box of the whole tree (empty for an empty tree).
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, Bvh2Node::bounds)
    }

    /// The primitive indices of a leaf.
    #[inline]
    pub fn leaf_prims(&self, node: &Bvh2Node) -> &[u32] {
        let first = node.first as usize;
        &self.prim_indices[first..first + node.count as usize]
    }

    /// Recomputes every box bottom-up from the primitive boxes, keeping the topology.
    /// Refuses a tree with spatial splits, whose leaf boxes are not primitive boxes.
    pub fn refit(&mut self, boxes: &[Aabb]) -> Result<(), RefitError> {
        if self.spatial_splits {
            return Err(RefitError::SpatialSplits);
        }
        // Children always have larger indices than their parent, so a reverse sweep
        // visits children first.
        for i in (0..self.nodes.len()).rev() {
            let node = self.nodes[i];
            let bounds = if node.is_leaf() {
                self.leaf_prims(&node)
                    .iter()
                    .fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize]))
            } else {
                let c = node.first as usize;
                self.nodes[c].bounds().union(self.nodes[c + 1].bounds())
            };
            self.nodes[i].min = bounds.min;
            self.nodes[i].max = bounds.max;
        }
        Ok(())
    }

    /// Checks the invariants every builder must keep: indices in range, every node reached
    /// exactly once, every primitive in exactly one leaf, every child inside its parent
    /// and every box the tight union of its contents. With spatial splits a primitive
    /// may be in several leaves (at most once in each), and a leaf box need only lie
    /// within its primitives' boxes.
    pub fn validate(&self, boxes: &[Aabb]) -> Result<(), BvhError> {
        crate::view::validate(self, boxes)
    }

    /// Shape and quality of the tree under the given SAH costs.
    pub fn stats(&self, costs: &crate::SahCosts) -> crate::TreeStats {
        crate::view::stats(self, costs)
    }

    /// A node as a child: its box, and what it is.
    fn as_child(&self, index: usize) -> Child {
        match self.nodes.get(index) {
            Some(node) => Child {
                bounds: node.bounds(),
                kind: if node.is_leaf() {
                    ChildKind::Leaf {
                        first: node.first as usize,
                        count: node.count as usize,
                    }
                } else {
                    ChildKind::Inner(index)
                },
                slot: Some(index),
            },
            // Out of range (a damaged tree): validation reports the slot.
            None => Child {
                bounds: Aabb::EMPTY,
                kind: ChildKind::Leaf { first: 0, count: 0 },
                slot: Some(index),
            },
        }
    }
}

impl TreeView for Bvh2 {
    fn slot_count(&self) -> usize {
        self.nodes.len()
    }

    fn root(&self) -> Option<Child> {
        (!self.nodes.is_empty()).then(|| self.as_child(0))
    }

    fn children(&self, node: usize, out: &mut Vec<Child>) {
        let first = self.nodes[node].first as usize;
        out.clear();
        out.extend([first, first + 1].map(|c| self.as_child(c)));
    }

    fn prim_indices(&self) -> &[u32] {
        &self.prim_indices
    }

    fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.prim_indices.as_slice())
    }

    fn has_spatial_splits(&self) -> bool {
        self.spatial_splits
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boxes() -> Vec<Aabb> {
        vec![
            Aabb::new(Vec3::ZERO, Vec3::ONE),
            Aabb::new(Vec3::splat(2.0), Vec3::splat(3.0)),
        ]
    }

    fn two_leaf_tree() -> Bvh2 {
        let b = boxes();
        Bvh2::from_parts(
            vec![
                Bvh2Node::interior(b[0].union(b[1]), 1),
                Bvh2Node::leaf(b[0], 0, 1),
                Bvh2Node::leaf(b[1], 1, 1),
            ],
            vec![0, 1],
        )
    }

    #[test]
    fn node_is_32_bytes() {
        assert_eq!(std::mem::size_of::<Bvh2Node>(), 32);
    }

    #[test]
    fn hand_built_tree_validates() {
        assert_eq!(two_leaf_tree().validate(&boxes()), Ok(()));
    }

    #[test]
    fn loose_box_is_rejected() {
        let mut t = two_leaf_tree();
        t.nodes[0].max = Vec3::splat(4.0);
        assert_eq!(t.validate(&boxes()), Err(BvhError::NotTight { node: 0 }));
    }

    #[test]
    fn duplicated_primitive_is_rejected() {
        let mut t = two_leaf_tree();
        t.prim_indices = vec![0, 0];
        t.nodes[0].max = Vec3::ONE;
        t.nodes[2].min = Vec3::ZERO;
        t.nodes[2].max = Vec3::ONE;
        assert!(matches!(
            t.validate(&boxes()),
            Err(BvhError::PrimitiveCount { .. })
        ));
    }

    #[test]
    fn refit_restores_tight_boxes() {
        let mut t = two_leaf_tree();
        t.nodes[0].max = Vec3::splat(9.0);
        t.nodes[1].min = Vec3::splat(-9.0);
        t.refit(&boxes()).unwrap();
        assert_eq!(t, two_leaf_tree());
    }

    #[test]
    fn refit_refuses_a_tree_with_spatial_splits() {
        let mut t = two_leaf_tree();
        t.spatial_splits = true;
        let before = t.clone();
        assert_eq!(t.refit(&boxes()), Err(RefitError::SpatialSplits));
        assert_eq!(t, before);
    }
}
