//! The tree's view: a node of one of the structure's trees (the top one over the
//! instances, or a structure's own) and its children, each with its subtree's size and
//! share of the tree's SAH cost, so that a user can descend to where a builder spends its
//! cost, and from a leaf of the top tree into the trees of the structures it places.

use crate::protocol::{corners, NodeChild, NodeReport, TreeRef};
use canopy_bvh::view::{sah_contribution, Child, ChildKind, TreeView};
use canopy_bvh::{Instance, SahCosts, Tlas};
use canopy_render::accel::SceneBlas;

/// Node `index` of tree `tree` of `world` (see [`node_report`]).
pub fn world_node_report(
    world: &Tlas<SceneBlas>,
    tree: TreeRef,
    costs: &SahCosts,
    index: Option<usize>,
) -> Result<NodeReport, String> {
    let (view, instances) = match tree {
        TreeRef::Top => {
            let top = world
                .tree()
                .ok_or("the scene has no top tree (one instance)")?;
            (top.view(), Some(world.instances()))
        }
        TreeRef::Structure(n) => {
            let count = world.blases().len();
            let blas = world.blases().get(n as usize).ok_or_else(|| {
                format!(
                    "no structure {n}: the scene has {count} (0 to {})",
                    count - 1
                )
            })?;
            let own = blas
                .tree()
                .ok_or_else(|| format!("structure {n} has no tree"))?;
            (own.view(), None)
        }
    };
    let mut report = node_report(view, costs, index, instances)?;
    report.tree = tree;
    Ok(report)
}

/// Node `index` (an inner node's, as a report's child gives it; `None`: the root) and its
/// children, or why there is none such. `instances`: the tree is the top one, whose
/// leaves hold these instances.
pub fn node_report(
    view: &dyn TreeView,
    costs: &SahCosts,
    index: Option<usize>,
    instances: Option<&[Instance]>,
) -> Result<NodeReport, String> {
    let root = view.root().ok_or("the tree is empty")?;
    let node = match index {
        None => root,
        // Looked for from the root: an index from the page is never trusted.
        Some(i) => find_inner(view, root, i).ok_or_else(|| format!("no inner node {i}"))?,
    };
    let root_area = root.bounds.surface_area();
    let total = subtree(view, root, costs, root_area)
        .cost
        .max(f64::MIN_POSITIVE);
    let mut children = Vec::new();
    match node.kind {
        ChildKind::Inner(i) => view.children(i, &mut children),
        ChildKind::Leaf { .. } => {}
    }
    // The structures a leaf of the top tree places, each once.
    let structures = |c: &Child| -> Vec<u32> {
        let (Some(instances), ChildKind::Leaf { first, count }) = (instances, c.kind) else {
            return Vec::new();
        };
        let mut placed: Vec<u32> = view.prim_indices()[first..first + count]
            .iter()
            .map(|&k| instances[k as usize].blas)
            .collect();
        placed.sort_unstable();
        placed.dedup();
        placed
    };
    Ok(NodeReport {
        tree: TreeRef::default(),
        index,
        bounds: corners(&node.bounds),
        children: children
            .iter()
            .map(|&c| {
                let s = subtree(view, c, costs, root_area);
                NodeChild {
                    index: match c.kind {
                        ChildKind::Inner(i) => Some(i),
                        ChildKind::Leaf { .. } => None,
                    },
                    bounds: corners(&c.bounds),
                    primitives: s.primitives,
                    nodes: s.nodes,
                    leaves: s.leaves,
                    sah_share: (s.cost / total) as f32,
                    structures: structures(&c),
                }
            })
            .collect(),
    })
}

fn find_inner(view: &dyn TreeView, root: Child, index: usize) -> Option<Child> {
    let mut children = Vec::new();
    let mut stack = vec![root];
    while let Some(c) = stack.pop() {
        if let ChildKind::Inner(i) = c.kind {
            if i == index {
                return Some(c);
            }
            view.children(i, &mut children);
            stack.extend_from_slice(&children);
        }
    }
    None
}

#[derive(Default)]
struct Subtree {
    cost: f64,
    primitives: usize,
    nodes: usize,
    leaves: usize,
}

/// The SAH cost of `top`'s subtree (each box's [`sah_contribution`], as the whole tree's
/// statistics sum them), and its size.
fn subtree(view: &dyn TreeView, top: Child, costs: &SahCosts, root_area: f32) -> Subtree {
    let mut s = Subtree::default();
    let mut children = Vec::new();
    let mut stack = vec![top];
    while let Some(c) = stack.pop() {
        s.nodes += 1;
        s.cost += sah_contribution(&c, root_area, costs);
        match c.kind {
            ChildKind::Leaf { count, .. } => {
                s.leaves += 1;
                s.primitives += count;
            }
            ChildKind::Inner(i) => {
                view.children(i, &mut children);
                stack.extend_from_slice(&children);
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use canopy_bvh::{build, Aabb, BuildParams, Builder, BvhWidth, Tree};
    use glam::Vec3;

    fn tree(width: BvhWidth) -> Tree {
        let boxes: Vec<Aabb> = (0..200)
            .map(|i| {
                let p = Vec3::new((i % 7) as f32, (i / 7 % 5) as f32, (i / 35) as f32 * 1.5);
                Aabb::new(p, p + Vec3::splat(0.5))
            })
            .collect();
        let bvh = build(Builder::BinnedSah, &boxes, &BuildParams::default());
        Tree::new(bvh, width)
    }

    #[test]
    fn the_roots_children_share_out_the_whole_tree() {
        for width in BvhWidth::ALL {
            let tree = tree(width);
            let costs = SahCosts::default();
            let root = node_report(tree.view(), &costs, None, None).unwrap();
            let prims: usize = root.children.iter().map(|c| c.primitives).sum();
            assert_eq!(prims, 200);
            // Every inner node and leaf once, the root besides.
            let stats = tree.stats(&costs);
            let inner_and_leaves = match width {
                // Each node of a binary tree is a storage entry of its own.
                BvhWidth::Two => stats.nodes,
                // A wide tree's leaves live in their parents' slots.
                _ => stats.nodes + stats.leaves,
            };
            let nodes: usize = root.children.iter().map(|c| c.nodes).sum();
            assert_eq!(nodes + 1, inner_and_leaves, "{width:?}");
            // The children's shares and the root's own step make the whole.
            let shares: f32 = root.children.iter().map(|c| c.sah_share).sum();
            let root_step = costs.traversal / tree.stats(&costs).sah_cost;
            assert!(
                (shares + root_step - 1.0).abs() < 1e-4,
                "{width:?}: {shares} + {root_step}"
            );
            // Each child descends, to its own children.
            let inner = root.children.iter().find_map(|c| c.index).unwrap();
            let below = node_report(tree.view(), &costs, Some(inner), None).unwrap();
            assert!(!below.children.is_empty());
        }
    }

    #[test]
    fn an_index_that_is_no_inner_node_is_refused() {
        let tree = tree(BvhWidth::Eight);
        let costs = SahCosts::default();
        for index in [usize::MAX, 1 << 40, tree.stats(&costs).nodes + 5] {
            assert!(node_report(tree.view(), &costs, Some(index), None).is_err());
        }
    }
}
