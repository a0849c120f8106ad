//! The output of bottom-up builders: a binary merge tree over the primitives, turned into
//! a [`Bvh2`] with leaves chosen by the SAH.
//!
//! Ids `0..n` are the primitives; id `n + k` is the k-th merge, of `merges[k]`. The
//! conversion collapses every subtree that is cheaper (by the SAH) as one leaf, and that
//! fits in one, into a leaf: bottom-up builders make one-primitive leaves, which are
//! rarely the best.

use crate::{Aabb, BuildParams, Bvh2, Bvh2Node};

pub(crate) struct MergeTree {
    pub prims: usize,
    pub merges: Vec<[u32; 2]>,
}

impl MergeTree {
    pub fn new(prims: usize) -> Self {
        Self {
            prims,
            merges: Vec::with_capacity(prims.saturating_sub(1)),
        }
    }

    /// Records the merge of two clusters and returns the new cluster's id.
    pub fn merge(&mut self, a: u32, b: u32) -> u32 {
        self.merges.push([a, b]);
        (self.prims + self.merges.len() - 1) as u32
    }

    fn children(&self, id: u32) -> Option<[u32; 2]> {
        (id as usize >= self.prims).then(|| self.merges[id as usize - self.prims])
    }

    /// The tree as a [`Bvh2`]; the root is the last merge (or the only primitive).
    pub fn into_bvh2(self, boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
        let n = self.prims;
        if n == 0 {
            return Bvh2::default();
        }
        assert_eq!(
            self.merges.len(),
            n - 1,
            "a merge tree over n primitives has n - 1 merges"
        );
        let root = (2 * n - 2) as u32;
        let total = 2 * n - 1;
        let mut bounds = vec![Aabb::EMPTY; total];
        let mut count = vec![1u32; total];
        // Cost of the subtree as the builder made it, or as one leaf where that is cheaper.
        let mut cost = vec![0f32; total];
        let mut as_leaf = vec![true; total];
        let sah = params.sah;
        for (id, b) in boxes.iter().enumerate() {
            bounds[id] = *b;
            cost[id] = b.surface_area() * sah.intersection;
        }
        // Children are always merged before their parent, so id order is bottom-up.
        for (k, &[a, b]) in self.merges.iter().enumerate() {
            let (a, b, id) = (a as usize, b as usize, n + k);
            bounds[id] = bounds[a].union(bounds[b]);
            count[id] = count[a] + count[b];
            let area = bounds[id].surface_area();
            let split_cost = area * sah.traversal + cost[a] + cost[b];
            let leaf_cost = area * count[id] as f32 * sah.intersection;
            as_leaf[id] = count[id] <= params.max_leaf_size && leaf_cost <= split_cost;
            cost[id] = if as_leaf[id] { leaf_cost } else { split_cost };
        }

        let mut nodes = Vec::with_capacity(total);
        let mut prim_indices = Vec::with_capacity(n);
        nodes.push(Bvh2Node::leaf(Aabb::EMPTY, 0, 1));
        let mut work = vec![(root, 0usize)];
        let mut subtree = Vec::new();
        while let Some((id, slot)) = work.pop() {
            let b = bounds[id as usize];
            if as_leaf[id as usize] {
                let first = prim_indices.len() as u32;
                subtree.push(id);
                while let Some(i) = subtree.pop() {
                    match self.children(i) {
                        Some([l, r]) => subtree.extend([r, l]),
                        None => prim_indices.push(i),
                    }
                }
                nodes[slot] = Bvh2Node::leaf(b, first, count[id as usize]);
            } else {
                let [l, r] = self.children(id).expect("only merges are split");
                let left = nodes.len();
                nodes.push(Bvh2Node::leaf(Aabb::EMPTY, 0, 1));
                nodes.push(Bvh2Node::leaf(Aabb::EMPTY, 0, 1));
                nodes[slot] = Bvh2Node::interior(b, left as u32);
                work.push((r, left + 1));
                work.push((l, left));
            }
        }
        Bvh2::from_parts(nodes, prim_indices)
    }
}
