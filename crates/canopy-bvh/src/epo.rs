//! Effective parallel overlap (EPO; Aila, Karras & Laine, "On Quality Metrics of Bounding
//! Volume Hierarchies", HPG 2013): the SAH assumes a ray that enters a node's box finds
//! nothing else there, so it mispredicts the cost of trees whose boxes overlap. EPO
//! charges every node (inner or leaf, at its SAH cost) for the surface of *other*
//! subtrees' geometry inside its box, relative to the total surface:
//!
//! `EPO = Σ_n C(n) · A((S \ Q(n)) ∩ box(n)) / A(S)`
//!
//! `S` is all geometry, `Q(n)` the geometry under `n`. The library knows boxes only, so
//! the caller says how much surface of a primitive lies inside a box
//! ([`triangle_area_in_box`] for triangles). Written once against [`TreeView`], so every
//! layout has it.

use crate::view::{Child, ChildKind, TreeView};
use crate::{Aabb, SahCosts, NO_PRIM};
use glam::Vec3;
use rayon::prelude::*;

/// EPO of the tree in `view`. `area_inside(prim, box)` is the surface area of primitive
/// `prim` inside `box`. Work is about one box query per node, in parallel.
pub fn epo(
    view: &dyn TreeView,
    costs: &SahCosts,
    area_inside: impl Fn(u32, &Aabb) -> f32 + Sync,
) -> f32 {
    let Some(root) = view.root() else {
        return 0.0;
    };
    // Each primitive once, though spatial splits may reference it from several leaves.
    let mut prims: Vec<u32> = view
        .prim_indices()
        .iter()
        .copied()
        .filter(|&p| p != NO_PRIM)
        .collect();
    prims.par_sort_unstable();
    prims.dedup();
    let total: f64 = prims
        .par_iter()
        .map(|&p| area_inside(p, &root.bounds) as f64)
        .sum();
    if total <= 0.0 {
        return 0.0;
    }
    let nodes = all_nodes(view, root);
    let charged: f64 = nodes
        .par_iter()
        .map(|node| {
            let cost = match node.kind {
                ChildKind::Leaf { count, .. } => costs.intersection as f64 * count as f64,
                ChildKind::Inner(_) => costs.traversal as f64,
            };
            cost * foreign_area(view, root, node, &area_inside)
        })
        .sum();
    (charged / total) as f32
}

/// Every node of the tree, root included.
fn all_nodes(view: &dyn TreeView, root: Child) -> Vec<Child> {
    let mut nodes = vec![root];
    let mut children = Vec::new();
    let mut next = 0;
    while next < nodes.len() {
        if let ChildKind::Inner(node) = nodes[next].kind {
            view.children(node, &mut children);
            nodes.extend_from_slice(&children);
        }
        next += 1;
    }
    nodes
}

/// Surface of the geometry not under `node` that lies inside its box.
fn foreign_area(
    view: &dyn TreeView,
    root: Child,
    node: &Child,
    area_inside: &impl Fn(u32, &Aabb) -> f32,
) -> f64 {
    let region = node.bounds;
    let prims = view.prim_indices();
    let mut area = 0.0f64;
    let mut children = Vec::new();
    let mut stack = vec![root];
    while let Some(other) = stack.pop() {
        if other.kind == node.kind || !overlap(&other.bounds, &region) {
            continue;
        }
        match other.kind {
            ChildKind::Leaf { first, count } => {
                // A leaf owns the part of its primitives inside its box: all of them,
                // unless spatial splits clipped them.
                let owned = region.intersection(other.bounds);
                // (Leaves of packed layouts pad their last pack with NO_PRIM.)
                for &p in prims[first..first + count]
                    .iter()
                    .filter(|&&p| p != NO_PRIM)
                {
                    area += area_inside(p, &owned) as f64;
                }
            }
            ChildKind::Inner(inner) => {
                view.children(inner, &mut children);
                stack.extend_from_slice(&children);
            }
        }
    }
    area
}

fn overlap(a: &Aabb, b: &Aabb) -> bool {
    a.min.cmple(b.max).all() && b.min.cmple(a.max).all()
}

/// Surface area of the triangle `v` inside box `b`: the triangle clipped against the six
/// planes of the box (Sutherland–Hodgman), then the clipped polygon's area.
pub fn triangle_area_in_box(v: &[Vec3; 3], b: &Aabb) -> f32 {
    // A triangle clipped by six planes has at most 9 corners.
    let mut poly = [Vec3::ZERO; 9];
    let mut scratch = [Vec3::ZERO; 9];
    poly[..3].copy_from_slice(v);
    let mut n = 3;
    for axis in 0..3 {
        for (bound, keep_below) in [(b.min[axis], false), (b.max[axis], true)] {
            let inside = |p: Vec3| {
                if keep_below {
                    p[axis] <= bound
                } else {
                    p[axis] >= bound
                }
            };
            let mut m = 0;
            for i in 0..n {
                let (p, q) = (poly[i], poly[(i + 1) % n]);
                let (p_in, q_in) = (inside(p), inside(q));
                if p_in {
                    scratch[m] = p;
                    m += 1;
                }
                if p_in != q_in {
                    let t = (bound - p[axis]) / (q[axis] - p[axis]);
                    let mut crossing = p + t * (q - p);
                    crossing[axis] = bound;
                    scratch[m] = crossing;
                    m += 1;
                }
            }
            n = m;
            poly[..n].copy_from_slice(&scratch[..n]);
            if n < 3 {
                return 0.0;
            }
        }
    }
    let mut twice_area = Vec3::ZERO;
    for i in 1..n - 1 {
        twice_area += (poly[i] - poly[0]).cross(poly[i + 1] - poly[0]);
    }
    0.5 * twice_area.length()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{build, BuildParams, Builder, Bvh2};

    fn unit_triangle() -> [Vec3; 3] {
        [Vec3::ZERO, Vec3::X, Vec3::Y]
    }

    #[test]
    fn triangle_area_in_boxes() {
        let t = unit_triangle();
        let everything = Aabb::new(Vec3::splat(-1.0), Vec3::splat(2.0));
        assert!((triangle_area_in_box(&t, &everything) - 0.5).abs() < 1e-6);
        // The square [0, 0.5]² holds a 0.5 x 0.5 corner of it, all under the hypotenuse.
        let corner = Aabb::new(Vec3::new(0.0, 0.0, -1.0), Vec3::new(0.5, 0.5, 1.0));
        assert!((triangle_area_in_box(&t, &corner) - 0.25).abs() < 1e-6);
        // x >= 0.5 keeps the small triangle (0.5,0)-(1,0)-(0.5,0.5): area 1/8.
        let right = Aabb::new(Vec3::new(0.5, -1.0, -1.0), Vec3::splat(2.0));
        assert!((triangle_area_in_box(&t, &right) - 0.125).abs() < 1e-6);
        let beside = Aabb::new(Vec3::splat(3.0), Vec3::splat(4.0));
        assert_eq!(triangle_area_in_box(&t, &beside), 0.0);
        // A box thinner than the triangle's plane offset misses it.
        let above = Aabb::new(Vec3::new(-1.0, -1.0, 0.1), Vec3::splat(2.0));
        assert_eq!(triangle_area_in_box(&t, &above), 0.0);
    }

    /// Triangles of a row of unit squares along x, each square two triangles.
    fn strip(n: usize, y: f32) -> Vec<[Vec3; 3]> {
        (0..n)
            .flat_map(|i| {
                let x = i as f32;
                [
                    [
                        Vec3::new(x, y, 0.0),
                        Vec3::new(x + 1.0, y, 0.0),
                        Vec3::new(x, y + 1.0, 0.0),
                    ],
                    [
                        Vec3::new(x + 1.0, y, 0.0),
                        Vec3::new(x + 1.0, y + 1.0, 0.0),
                        Vec3::new(x, y + 1.0, 0.0),
                    ],
                ]
            })
            .collect()
    }

    fn epo_of(bvh: &Bvh2, tris: &[[Vec3; 3]]) -> f32 {
        epo(bvh, &SahCosts::default(), |p, b| {
            triangle_area_in_box(&tris[p as usize], b)
        })
    }

    #[test]
    fn disjoint_nodes_have_no_overlap_and_overlapping_ones_do() {
        // Two strips far apart: a tree that keeps them apart has boxes that only hold
        // their own triangles, apart from the shared-edge slivers inside leaf boxes.
        let mut tris = strip(8, 0.0);
        tris.extend(strip(8, 10.0));
        let boxes: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(*t)).collect();
        let good = build(Builder::SweepSah, &boxes, &BuildParams::default());
        // The same triangles split badly: alternate triangles in two halves, so both
        // halves' boxes cover everything.
        let order: Vec<u32> = (0..tris.len() as u32)
            .step_by(2)
            .chain((1..tris.len() as u32).step_by(2))
            .collect();
        let half = order.len() / 2;
        let bad = two_leaves(&boxes, &order[..half], &order[half..]);
        let (good_epo, bad_epo) = (epo_of(&good, &tris), epo_of(&bad, &tris));
        assert!(
            good_epo >= 0.0 && bad_epo > good_epo,
            "{good_epo} vs {bad_epo}"
        );
        // In the bad tree each half's box holds the other half entirely: each leaf pays
        // its count x intersection cost x the other half's share (1/2) of the area, and
        // the root pays nothing (everything is under it).
        let c = SahCosts::default();
        let expected = 2.0 * (half as f32 * c.intersection) * 0.5;
        assert!(
            (bad_epo - expected).abs() < 1e-3 * expected,
            "{bad_epo} vs {expected}"
        );
    }

    #[test]
    fn clipped_references_count_only_the_part_their_leaf_owns() {
        // Two long triangles crossing like an X, cut at x = 5 into two leaves that each
        // reference both: each leaf's box holds the other leaf's pieces only on the
        // plane they share, so nothing overlaps (counting whole triangles, each box
        // would hold half of both).
        let tris = vec![
            [
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(10.0, 10.0, 0.0),
                Vec3::new(10.0, 10.2, 0.0),
            ],
            [
                Vec3::new(0.0, 10.0, 0.0),
                Vec3::new(10.0, 0.0, 0.0),
                Vec3::new(10.0, 0.2, 0.0),
            ],
        ];
        let boxes: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(*t)).collect();
        let all = boxes[0].union(boxes[1]);
        let (left, right) = crate::split_box(all, 0, 5.0);
        let mut bvh = Bvh2::from_parts(
            vec![
                crate::Bvh2Node::interior(all, 1),
                crate::Bvh2Node::leaf(left, 0, 2),
                crate::Bvh2Node::leaf(right, 2, 2),
            ],
            vec![0, 1, 0, 1],
        );
        bvh.spatial_splits = true;
        bvh.validate(&boxes).unwrap();
        let clipped = epo_of(&bvh, &tris);
        assert!(clipped.abs() < 1e-4, "{clipped}");
        // The best tree without spatial splits, a triangle per leaf: each leaf's box
        // holds nearly all of the other triangle.
        let unclipped = epo_of(&two_leaves(&boxes, &[0], &[1]), &tris);
        assert!(unclipped > 0.95, "{unclipped}");
    }

    /// A root over two leaves holding the given primitives.
    fn two_leaves(boxes: &[Aabb], left: &[u32], right: &[u32]) -> Bvh2 {
        let union = |ps: &[u32]| {
            ps.iter()
                .fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize]))
        };
        let (l, r) = (union(left), union(right));
        let nodes = vec![
            crate::Bvh2Node::interior(l.union(r), 1),
            crate::Bvh2Node::leaf(l, 0, left.len() as u32),
            crate::Bvh2Node::leaf(r, left.len() as u32, right.len() as u32),
        ];
        Bvh2::from_parts(nodes, left.iter().chain(right).copied().collect())
    }
}
