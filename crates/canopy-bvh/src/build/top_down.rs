//! The driver shared by top-down builders: a splitter decides how to cut one node's
//! primitives, the driver makes leaves, enforces the leaf size and lays out nodes.
//!
//! Subtrees whose two halves are both large are built in parallel (rayon) into their own
//! node arrays and spliced together; everything else is built serially from an explicit
//! work list, so even a degenerate, very deep tree cannot overflow the call stack.

use crate::{Aabb, BuildParams, Bvh2, Bvh2Node};

/// Below this many primitives on either side, a subtree is built on one thread.
const PARALLEL_THRESHOLD: usize = 4096;

/// Cuts a node: reorders `prims` so that the left child's come first and says how many
/// there are, or `None` to make a leaf. `must_split` is set when the node holds more
/// primitives than a leaf may; the driver then splits at the middle if the splitter
/// declines or returns an empty side. `centroids` is the box of the primitives'
/// centroids when the parent's cut reported it (saving the splitter a pass).
pub(crate) trait Splitter: Sync {
    fn split(
        &self,
        prims: &mut [u32],
        bounds: Aabb,
        centroids: Option<Aabb>,
        must_split: bool,
    ) -> Option<Cut>;
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

pub(crate) fn build(boxes: &[Aabb], params: &BuildParams, splitter: &impl Splitter) -> Bvh2 {
    build_with_order(boxes, params, splitter, (0..boxes.len() as u32).collect())
}

/// As [`build`], starting from a given primitive order (for builders that sort first).
pub(crate) fn build_with_order(
    boxes: &[Aabb],
    params: &BuildParams,
    splitter: &impl Splitter,
    mut prim_indices: Vec<u32>,
) -> Bvh2 {
    if boxes.is_empty() {
        return Bvh2::default();
    }
    let driver = Driver {
        boxes,
        max_leaf: params.max_leaf_size as usize,
        splitter,
    };
    let nodes = driver.subtree(&mut prim_indices, 0, None);
    Bvh2::from_parts(nodes, prim_indices)
}

struct Driver<'a, S> {
    boxes: &'a [Aabb],
    max_leaf: usize,
    splitter: &'a S,
}

impl<S: Splitter> Driver<'_, S> {
    fn bounds(&self, prims: &[u32]) -> Aabb {
        prims
            .iter()
            .fold(Aabb::EMPTY, |b, &p| b.union(self.boxes[p as usize]))
    }

    /// Where to cut `prims`, or `None` for a leaf.
    fn cut(&self, prims: &mut [u32], known: Known) -> Option<Cut> {
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
    fn children(&self, prims: &[u32], cut: &Cut) -> (Known, Known) {
        let (left, right) = cut.bounds.unwrap_or_else(|| {
            let (left, right) = prims.split_at(cut.mid);
            (self.bounds(left), self.bounds(right))
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
    fn subtree(&self, prims: &mut [u32], first: usize, known: Option<Known>) -> Vec<Bvh2Node> {
        let known = known.unwrap_or_else(|| Known {
            bounds: self.bounds(prims),
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
                splice(known.bounds, left, right, 0)
            }
            cut => self.serial(prims, first, known.bounds, cut),
        }
    }

    /// Builds a subtree on this thread; its root's cut is already decided.
    fn serial(
        &self,
        prims: &mut [u32],
        first: usize,
        bounds: Aabb,
        root_cut: Option<Cut>,
    ) -> Vec<Bvh2Node> {
        let mut nodes = Vec::with_capacity(2 * prims.len() / self.max_leaf.max(1) + 1);
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
