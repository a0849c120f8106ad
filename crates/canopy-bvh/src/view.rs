//! [`TreeView`]: what every layout shows to code that walks it, so that validation,
//! statistics (SAH) and the level walk used for pictures are written once, here, for the
//! binary tree and the wide trees alike (and for any layout added later).
//!
//! A tree, seen this way, is a root and inner nodes; every node has children, each with a
//! box, that are either inner nodes or leaves (ranges of the primitive indices). Levels
//! count boxes from the root's (level 0).

use crate::{Aabb, BvhError, SahCosts, TreeStats};

/// A child of a node (or the root), as a [`TreeView`] shows it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Child {
    pub bounds: Aabb,
    pub kind: ChildKind,
    /// The storage entry this child occupies, when it has one of its own (every node of a
    /// binary tree; a wide tree's inner nodes, but not its leaf slots). Validation checks
    /// that each entry is reached exactly once.
    pub slot: Option<usize>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChildKind {
    /// An inner node, by the index [`TreeView::children`] takes.
    Inner(usize),
    /// A leaf: `first..first + count` of [`TreeView::prim_indices`].
    Leaf { first: usize, count: usize },
}

/// A layout as a walk over boxes, children and leaf ranges.
pub trait TreeView: Sync {
    /// Storage entries (the layout's nodes, [`TreeStats::nodes`]), each of which must be
    /// reached exactly once from the root.
    fn slot_count(&self) -> usize;
    /// The root: an inner node, or a leaf (a tree of one leaf); `None` when empty.
    fn root(&self) -> Option<Child>;
    /// Replaces `out` with the children of inner node `node`.
    fn children(&self, node: usize, out: &mut Vec<Child>);
    fn prim_indices(&self) -> &[u32];
    /// Bytes the layout keeps: nodes, indices and any packed primitives.
    fn memory_bytes(&self) -> usize;
    /// Whether leaves may hold clipped references (see [`crate::Bvh2::has_spatial_splits`]).
    fn has_spatial_splits(&self) -> bool {
        false
    }
}

/// Checks the invariants every layout must keep: indices in range, every storage entry
/// reached exactly once, every primitive in exactly one leaf, every child inside its
/// parent's box and every box the tight union of its contents. With spatial splits, a
/// primitive is in at least one leaf and at most once in each, and a leaf box lies within
/// the union of its primitives' boxes (the parts it owns; that they cover each primitive
/// is for queries against brute force to show).
pub fn validate(view: &dyn TreeView, boxes: &[Aabb]) -> Result<(), BvhError> {
    let Some(root) = view.root() else {
        return match boxes.len() {
            0 => Ok(()),
            _ => Err(BvhError::PrimitiveCount { prim: 0, times: 0 }),
        };
    };
    let slots = view.slot_count();
    let indices = view.prim_indices();
    let mut reached = vec![false; slots];
    let mut times_seen = vec![0usize; boxes.len()];
    let clipped = view.has_spatial_splits();
    let mut children = Vec::new();
    // (the child, its parent's storage entry, for error messages)
    let mut stack = vec![(root, 0usize)];
    while let Some((child, parent)) = stack.pop() {
        let at = child.slot.unwrap_or(parent);
        if let Some(slot) = child.slot {
            let entry = reached.get_mut(slot).ok_or(BvhError::ChildOutOfRange {
                node: parent,
                child: slot,
                len: slots,
            })?;
            if std::mem::replace(entry, true) {
                // Entry 0 is the root's, so a child pointing there is out of range.
                return Err(if slot == 0 {
                    BvhError::ChildOutOfRange {
                        node: parent,
                        child: 0,
                        len: slots,
                    }
                } else {
                    BvhError::NodeShared { node: slot }
                });
            }
        }
        let contents = match child.kind {
            ChildKind::Leaf { first, count } => {
                let end = first + count;
                let prims = indices.get(first..end).ok_or(BvhError::LeafOutOfRange {
                    node: at,
                    first,
                    end,
                    len: indices.len(),
                })?;
                let mut bounds = Aabb::EMPTY;
                for (i, &prim) in prims.iter().enumerate() {
                    let seen =
                        times_seen
                            .get_mut(prim as usize)
                            .ok_or(BvhError::PrimitiveOutOfRange {
                                prim,
                                len: boxes.len(),
                            })?;
                    *seen += 1;
                    bounds = bounds.union(boxes[prim as usize]);
                    if clipped && prims[..i].contains(&prim) {
                        return Err(BvhError::PrimitiveCount { prim, times: 2 });
                    }
                }
                if clipped {
                    if !bounds.contains(&child.bounds) {
                        return Err(BvhError::LeafOutsidePrimitives { node: at });
                    }
                    continue;
                }
                bounds
            }
            ChildKind::Inner(node) => {
                view.children(node, &mut children);
                let mut bounds = Aabb::EMPTY;
                for grandchild in &children {
                    if !child.bounds.contains(&grandchild.bounds) {
                        return Err(BvhError::ChildOutsideParent {
                            node: at,
                            child: grandchild.slot.unwrap_or(at),
                        });
                    }
                    bounds = bounds.union(grandchild.bounds);
                    stack.push((*grandchild, at));
                }
                bounds
            }
        };
        if contents != child.bounds {
            return Err(BvhError::NotTight { node: at });
        }
    }
    let unreached = reached.iter().filter(|r| !**r).count();
    if unreached > 0 {
        return Err(BvhError::UnreachableNodes {
            unreached,
            len: slots,
        });
    }
    let wrong = |t: usize| t == 0 || (t > 1 && !clipped);
    if let Some((prim, &times)) = times_seen.iter().enumerate().find(|(_, &t)| wrong(t)) {
        return Err(BvhError::PrimitiveCount {
            prim: prim as u32,
            times,
        });
    }
    Ok(())
}

/// Shape and quality under the given SAH costs (of a valid tree: see [`validate`]): every inner box costs a traversal step
/// and every leaf box its primitives' tests, weighted by area relative to the root's.
/// Depth counts boxes from the root's to the deepest leaf's, both included.
pub fn stats(view: &dyn TreeView, costs: &SahCosts) -> TreeStats {
    let mut stats = TreeStats {
        nodes: view.slot_count(),
        memory_bytes: view.memory_bytes(),
        ..TreeStats::default()
    };
    let Some(root) = view.root() else {
        return stats;
    };
    let root_area = root.bounds.surface_area();
    let mut cost = 0.0f64;
    let mut children = Vec::new();
    let mut stack = vec![(root, 1usize)];
    while let Some((child, depth)) = stack.pop() {
        stats.max_depth = stats.max_depth.max(depth);
        cost += sah_contribution(&child, root_area, costs);
        match child.kind {
            ChildKind::Leaf { count, .. } => {
                stats.leaves += 1;
                stats.references += count;
                stats.max_leaf_size = stats.max_leaf_size.max(count);
            }
            ChildKind::Inner(node) => {
                view.children(node, &mut children);
                stack.extend(children.iter().map(|&c| (c, depth + 1)));
            }
        }
    }
    stats.sah_cost = cost as f32;
    stats
}

/// What one box adds to a tree's SAH cost ([`stats`]): an inner node's box a traversal
/// step, a leaf's its primitives' tests, weighted by its area relative to the root's
/// (`root_area`; every box counts in full where the root has no area).
pub fn sah_contribution(child: &Child, root_area: f32, costs: &SahCosts) -> f64 {
    let area = match root_area > 0.0 {
        true => (child.bounds.surface_area() / root_area) as f64,
        false => 1.0,
    };
    match child.kind {
        ChildKind::Leaf { count, .. } => area * count as f64 * costs.intersection as f64,
        ChildKind::Inner(_) => area * costs.traversal as f64,
    }
}

/// Every box whose level is in `first..=last` (the root's is level 0), with its level,
/// shallowest first; for pictures of the tree.
pub fn boxes_at_levels(view: &dyn TreeView, first: usize, last: usize) -> Vec<(Aabb, usize)> {
    let mut boxes = Vec::new();
    let Some(root) = view.root() else {
        return boxes;
    };
    let mut children = Vec::new();
    let mut stack = vec![(root, 0usize)];
    while let Some((child, level)) = stack.pop() {
        if level >= first {
            boxes.push((child.bounds, level));
        }
        if let (ChildKind::Inner(node), true) = (child.kind, level < last) {
            view.children(node, &mut children);
            stack.extend(children.iter().rev().map(|&c| (c, level + 1)));
        }
    }
    boxes.sort_by_key(|&(_, level)| level);
    boxes
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::{build, BuildParams, Builder, Bvh2, BvhWidth, Tree};
    use glam::Vec3;

    /// A few hundred overlapping boxes of four sizes, for layout tests.
    pub(crate) fn boxes(n: usize) -> Vec<Aabb> {
        (0..n)
            .map(|i| {
                let p = Vec3::new((i * 7 % 13) as f32, (i * 5 % 11) as f32, (i % 3) as f32);
                Aabb::new(p, p + Vec3::splat(0.5 + (i % 4) as f32 * 0.25))
            })
            .collect()
    }

    #[test]
    fn every_layout_of_a_tree_shows_the_same_leaves_and_root() {
        let boxes = boxes(300);
        let bvh = build(Builder::BinnedSah, &boxes, &BuildParams::default());
        let costs = SahCosts::default();
        let binary = Tree::new(bvh.clone(), BvhWidth::Two);
        let root = binary.boxes_at_levels(0, 0);
        for width in BvhWidth::ALL {
            let tree = Tree::new(bvh.clone(), width);
            tree.validate(&boxes).unwrap();
            let (a, b) = (binary.stats(&costs), tree.stats(&costs));
            assert_eq!(
                (a.leaves, a.max_leaf_size),
                (b.leaves, b.max_leaf_size),
                "{width}"
            );
            assert!(b.max_depth <= a.max_depth, "{width}");
            assert_eq!(tree.boxes_at_levels(0, 0), root, "{width}");
            // Levels come shallowest first and never below the last asked for.
            let levels: Vec<usize> = tree.boxes_at_levels(1, 3).iter().map(|b| b.1).collect();
            assert!(
                levels.windows(2).all(|w| w[0] <= w[1])
                    && levels.iter().all(|l| (1..=3).contains(l))
            );
        }
    }

    #[test]
    fn damaged_trees_are_errors_not_panics() {
        let boxes = boxes(40);
        let bvh = build(Builder::BinnedSah, &boxes, &BuildParams::default());
        let (nodes, indices) = (bvh.nodes().to_vec(), bvh.prim_indices().to_vec());
        let inner = nodes.iter().position(|n| !n.is_leaf()).unwrap();
        for bad_child in [0u32, nodes.len() as u32, u32::MAX - 1] {
            let mut damaged = nodes.clone();
            damaged[inner].first = bad_child;
            let tree = Bvh2::from_parts(damaged, indices.clone());
            assert!(tree.validate(&boxes).is_err(), "child {bad_child}");
        }
        let mut wide = crate::Bvh8::from_bvh2(&bvh);
        let slot = wide.nodes[0].count.iter().position(|&c| c == 0).unwrap();
        wide.nodes[0].child[slot] = 9999;
        assert!(matches!(
            validate(&wide, &boxes),
            Err(BvhError::ChildOutOfRange { child: 9999, .. })
        ));
        // Out-of-range children are shown as empty leaves, so walks do not index past
        // the nodes (a tree with cycles is only for `validate` to find).
        let _ = stats(&wide, &SahCosts::default());
        let _ = boxes_at_levels(&wide, 0, usize::MAX);
    }
}
