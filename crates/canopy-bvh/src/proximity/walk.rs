//! Walks of any tree layout (through [`TreeView`]) for the queries that are not the
//! closest hit: the nearest primitive to a point, nearest child first and pruned by box
//! distance (a top-level tree's instances; a `Blas` walks its own point layout the same
//! way, [`super::PointTree::nearest`]).

use super::Nearest;
use crate::view::{Child, ChildKind, TreeView};
use crate::Aabb;
use glam::Vec3;

/// Squared distance from `point` to the box (0 inside; infinite for an empty box).
#[inline(always)]
pub(crate) fn box_distance_sq(bounds: &Aabb, point: Vec3) -> f32 {
    let outside = (bounds.min - point).max(point - bounds.max).max(Vec3::ZERO);
    outside.length_squared()
}

/// The best candidate so far: its squared distance (the measure compared and pruned by)
/// and what it is.
pub(crate) type Best = Option<(f32, Nearest)>;

/// Whether `candidate` (squared distance `d2`) beats `best`, or, with none yet, lies
/// within `limit_sq`. Equal distances go to the lower instance, then the lower
/// primitive, as brute force orders them.
#[inline(always)]
pub(crate) fn beats(d2: f32, candidate: &Nearest, best: &Best, limit_sq: f32) -> bool {
    match best {
        None => d2 <= limit_sq,
        Some((b2, b)) => {
            d2 < *b2 || (d2 == *b2 && (candidate.inst, candidate.prim) < (b.inst, b.prim))
        }
    }
}

/// The nearest primitive of the tree: `test(prim, best)` measures primitive `prim` and
/// returns it when it beats `best`. Boxes are in the tree's space around `query`, and a
/// box's distance times `stretch` (the least a placement lengthens any vector) bounds
/// the measure of everything inside it, so a box is skipped when even that bound loses.
pub(crate) fn nearest(
    view: &dyn TreeView,
    query: Vec3,
    stretch: f32,
    limit_sq: f32,
    mut test: impl FnMut(u32, &Best) -> Best,
) -> Best {
    let mut best: Best = None;
    let stretch_sq = stretch * stretch;
    let bound = |child: &Child| box_distance_sq(&child.bounds, query) * stretch_sq;
    let reach = |best: &Best| best.map_or(limit_sq, |(d2, _)| d2);
    let root = view.root()?;
    let mut stack: Vec<(f32, Child)> = Vec::with_capacity(64);
    let mut children = Vec::with_capacity(8);
    stack.push((bound(&root), root));
    while let Some((d2, child)) = stack.pop() {
        // Equal bounds are kept: a tie may still go to a lower index.
        if d2 > reach(&best) {
            continue;
        }
        match child.kind {
            ChildKind::Leaf { first, count } => {
                for &prim in &view.prim_indices()[first..first + count] {
                    if let Some(found) = test(prim, &best) {
                        best = Some(found);
                    }
                }
            }
            ChildKind::Inner(node) => {
                view.children(node, &mut children);
                let first = stack.len();
                let within = reach(&best);
                stack.extend(
                    children
                        .iter()
                        .map(|c| (bound(c), *c))
                        .filter(|(d2, _)| *d2 <= within),
                );
                // Farthest first onto the stack, so the nearest is taken next.
                stack[first..].sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
            }
        }
    }
    best
}
