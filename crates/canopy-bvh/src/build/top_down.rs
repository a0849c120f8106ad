//! The driver shared by top-down builders: a splitter decides how to cut one node's
//! primitives, the driver makes leaves, enforces the leaf size and lays out nodes. The
//! splitter chooses what it reorders ([`Splitter::Item`]): primitive indices, or records
//! that carry each primitive's box so that its passes over a node read memory in order.
//!
//! Subtrees whose two halves are both large are built in parallel (rayon) into their own
//! node arrays, which are copied into one array once, at the end; everything else is built
//! serially from an explicit work list, so even a degenerate, very deep tree cannot
//! overflow the call stack.

use crate::{Aabb, BuildParams, Bvh2, Bvh2Node};
use rayon::prelude::*;

/// Below this many primitives on either side, a subtree is built on one thread. Low
/// enough that a mesh of a few thousand triangles is built on two threads (the 3.7k
/// bunny: 0.92 -> 0.55 ms on two cores; 4096 kept it on one), high enough that a join
/// costs little beside its halves' work (the 202k dragon: 35.2 -> 32.0 ms on two cores,
/// the same on one; AMD EPYC Zen 3).
const PARALLEL_THRESHOLD: usize = 512;

/// Cuts a node: reorders `prims` so that the left child's come first and says how many
/// there are, or `None` to make a leaf. `must_split` is set when the node holds more
/// primitives than a leaf may; the driver then splits at the middle if the splitter
/// declines or returns an empty side. `centroids` is the box of the primitives'
/// centroids when the parent's cut reported it (saving the splitter a pass).
pub(crate) trait Splitter: Sync {
    /// What stands for a primitive in the arrays the splitter reorders.
    type Item: Copy + Send + Sync;

    fn split(
        &self,
        prims: &mut [Self::Item],
        bounds: Aabb,
        centroids: Option<Aabb>,
        must_split: bool,
    ) -> Option<Cut>;

    /// The box around `prims`.
    fn bounds(&self, prims: &[Self::Item]) -> Aabb;

    /// The primitive an item stands for.
    fn prim(item: &Self::Item) -> u32;
}

/// [`Splitter::bounds`] of primitive indices into `boxes`.
pub(crate) fn bounds_of(boxes: &[Aabb], prims: &[u32]) -> Aabb {
    prims
        .iter()
        .fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize]))
}

/// Where a node is cut.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Cut {
    /// Primitives of the left child (they come first).
    pub mid: usize,
    /// The children's bounds when the splitter has them (binning does), which saves the
    /// driver a pass over the primitives.
    pub bounds: Option<(Aabb, Aabb)>,
    /// The children's centroid bounds when the splitter has them (its partition does),
    /// handed to the children's cuts.
    pub centroids: Option<(Aabb, Aabb)>,
}

impl Cut {
    pub fn at(mid: usize) -> Self {
        Self {
            mid,
            bounds: None,
            centroids: None,
        }
    }
}

/// What is known of a node before it is cut: its bounds, and maybe its centroids' bounds.
#[derive(Clone, Copy)]
struct Known {
    bounds: Aabb,
    centroids: Option<Aabb>,
}

/// Builds the tree over `items`, one per primitive, in the order the leaves will list
/// them once the splitter has reordered them.
pub(crate) fn build<S: Splitter>(
    params: &BuildParams,
    splitter: &S,
    mut items: Vec<S::Item>,
) -> Bvh2 {
    if items.is_empty() {
        return Bvh2::default();
    }
    let driver = Driver {
        max_leaf: params.max_leaf_size as usize,
        splitter,
    };
    let part = driver.subtree(&mut items, 0, None);
    let mut nodes = Vec::with_capacity(part.nodes());
    nodes.push(part.root());
    part.append_below(0, &mut nodes);
    Bvh2::from_parts(nodes, items.par_iter().map(S::prim).collect())
}

/// A subtree as the parallel recursion returns it: built on one thread, or two parts
/// joined under a root.
enum Part {
    Serial(Vec<Bvh2Node>),
    Joined {
        bounds: Aabb,
        nodes: usize,
        children: Box<(Part, Part)>,
    },
}

impl Part {
    fn nodes(&self) -> usize {
        match self {
            Part::Serial(nodes) => nodes.len(),
            Part::Joined { nodes, .. } => *nodes,
        }
    }

    /// The root node as it stands before its children are placed.
    fn root(&self) -> Bvh2Node {
        match self {
            Part::Serial(nodes) => nodes[0],
            Part::Joined { bounds, .. } => Bvh2Node::interior(*bounds, 0),
        }
    }

    /// Appends the nodes below the root to `out`, whose node `at` is this part's root,
    /// and points that root at its children. Siblings stay side by side, as in
    /// [`splice`]: a serial part keeps its own order, shifted.
    fn append_below(self, at: usize, out: &mut Vec<Bvh2Node>) {
        match self {
            Part::Serial(nodes) => {
                if nodes[0].is_leaf() {
                    return;
                }
                // Node i >= 1 of the part lands at base + i - 1.
                let base = out.len() as u32;
                let place = |node: Bvh2Node| match node.is_leaf() {
                    true => node,
                    false => Bvh2Node {
                        first: base + node.first - 1,
                        ..node
                    },
                };
                out[at] = place(nodes[0]);
                out.extend(nodes[1..].iter().map(|&n| place(n)));
            }
            Part::Joined { children, .. } => {
                let (left, right) = *children;
                let first = out.len();
                out[at].first = first as u32;
                out.push(left.root());
                out.push(right.root());
                left.append_below(first, out);
                right.append_below(first + 1, out);
            }
        }
    }
}

struct Driver<'a, S> {
    max_leaf: usize,
    splitter: &'a S,
}

impl<S: Splitter> Driver<'_, S> {
    /// Where to cut `prims`, or `None` for a leaf.
    fn cut(&self, prims: &mut [S::Item], known: Known) -> Option<Cut> {
        let count = prims.len();
        let must_split = count > self.max_leaf;
        match self
            .splitter
            .split(prims, known.bounds, known.centroids, must_split)
        {
            Some(cut) if cut.mid > 0 && cut.mid < count => Some(cut),
            _ if must_split => Some(Cut::at(count / 2)),
            _ => None,
        }
    }

    /// What is known of the children of `cut`: the splitter's bounds or computed ones,
    /// and the splitter's centroid bounds if it has them.
    fn children(&self, prims: &[S::Item], cut: &Cut) -> (Known, Known) {
        let (left, right) = cut.bounds.unwrap_or_else(|| {
            let (left, right) = prims.split_at(cut.mid);
            (self.splitter.bounds(left), self.splitter.bounds(right))
        });
        let (left_centroids, right_centroids) = match cut.centroids {
            Some((l, r)) => (Some(l), Some(r)),
            None => (None, None),
        };
        (
            Known {
                bounds: left,
                centroids: left_centroids,
            },
            Known {
                bounds: right,
                centroids: right_centroids,
            },
        )
    }

    /// Nodes of the subtree over `prims` (which start at `first` in the final index
    /// array), root first. `known` is what the caller knows of the subtree's root.
    fn subtree(&self, prims: &mut [S::Item], first: usize, known: Option<Known>) -> Part {
        let known = known.unwrap_or_else(|| Known {
            bounds: self.splitter.bounds(prims),
            centroids: None,
        });
        match self.cut(prims, known) {
            Some(cut)
                if cut.mid >= PARALLEL_THRESHOLD && prims.len() - cut.mid >= PARALLEL_THRESHOLD =>
            {
                let (left_known, right_known) = self.children(prims, &cut);
                let (left_prims, right_prims) = prims.split_at_mut(cut.mid);
                let (left, right) = rayon::join(
                    || self.subtree(left_prims, first, Some(left_known)),
                    || self.subtree(right_prims, first + cut.mid, Some(right_known)),
                );
                Part::Joined {
                    bounds: known.bounds,
                    nodes: 1 + left.nodes() + right.nodes(),
                    children: Box::new((left, right)),
                }
            }
            cut => Part::Serial(self.serial(prims, first, known.bounds, cut)),
        }
    }

    /// Builds a subtree on this thread; its root's cut is already decided.
    fn serial(
        &self,
        prims: &mut [S::Item],
        first: usize,
        bounds: Aabb,
        root_cut: Option<Cut>,
    ) -> Vec<Bvh2Node> {
        // A leaf holds at least one primitive, so there are fewer than 2n nodes.
        let mut nodes = Vec::with_capacity(2 * prims.len() - 1);
        nodes.push(Bvh2Node::leaf(bounds, first as u32, prims.len() as u32));
        // (node, start, end, bounds, cut) with start/end relative to `prims`.
        let mut work = vec![(0usize, 0usize, prims.len(), bounds, root_cut)];
        while let Some((node, start, end, bounds, cut)) = work.pop() {
            let Some(cut) = cut else {
                nodes[node] = Bvh2Node::leaf(bounds, (first + start) as u32, (end - start) as u32);
                continue;
            };
            let left = nodes.len();
            nodes[node] = Bvh2Node::interior(bounds, left as u32);
            let mid = start + cut.mid;
            let (left_known, right_known) = self.children(&prims[start..end], &cut);
            for (child, (s, e), known) in [
                (left, (start, mid), left_known),
                (left + 1, (mid, end), right_known),
            ] {
                let child_cut = self.cut(&mut prims[s..e], known);
                nodes.push(Bvh2Node::leaf(
                    known.bounds,
                    (first + s) as u32,
                    (e - s) as u32,
                ));
                work.push((child, s, e, known.bounds, child_cut));
            }
        }
        nodes
    }
}

/// Joins two subtrees under a new root: `[root, left root, right root, left rest, right
/// rest]`, renumbering child links. The right subtree's leaves move `right_prims` places
/// along the primitive indices (0 when they already point into the shared array).
pub(crate) fn splice(
    bounds: Aabb,
    left: Vec<Bvh2Node>,
    right: Vec<Bvh2Node>,
    right_prims: u32,
) -> Vec<Bvh2Node> {
    let left_rest = left.len() as u32 - 1;
    // Where node i of each subtree lands (its root goes to 1 or 2).
    let place_left = |i: u32| if i == 0 { 1 } else { 2 + i };
    let place_right = |i: u32| if i == 0 { 2 } else { 2 + left_rest + i };
    let mut nodes = vec![Bvh2Node::interior(bounds, 1); 3];
    nodes.resize(left.len() + right.len() + 1, nodes[0]);
    for (tree, place, prim_shift) in [
        (&left, &place_left as &dyn Fn(u32) -> u32, 0),
        (&right, &place_right, right_prims),
    ] {
        for (i, node) in tree.iter().enumerate() {
            let mut node = *node;
            node.first = match node.is_leaf() {
                true => node.first + prim_shift,
                false => place(node.first),
            };
            nodes[place(i as u32) as usize] = node;
        }
    }
    nodes
}
