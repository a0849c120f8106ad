//! A dynamic box tree over the live clusters of agglomerative clustering: insert and
//! remove in O(depth), and a branch-and-bound search for the cluster whose union with a
//! query box has the smallest surface area. Insertion picks the sibling greedily by area
//! growth (as in Box2D's b2DynamicTree); no rebalancing, which the search does not need.

use crate::Aabb;

const NONE: u32 = u32::MAX;

#[derive(Clone, Copy)]
struct Node {
    bounds: Aabb,
    parent: u32,
    /// `[NONE, cluster]` for a leaf.
    children: [u32; 2],
}

impl Node {
    fn is_leaf(&self) -> bool {
        self.children[0] == NONE
    }
}

pub(super) struct DynamicTree {
    nodes: Vec<Node>,
    free: Vec<u32>,
    root: u32,
}

/// Smallest area of `query` grown to reach any point of `node`: a lower bound on the
/// area of `query`'s union with anything inside `node`.
#[inline]
fn area_lower_bound(query: &Aabb, node: &Aabb) -> f32 {
    Aabb::new(query.min.min(node.max), query.max.max(node.min)).surface_area()
}

impl DynamicTree {
    pub fn with_capacity(clusters: usize) -> Self {
        Self {
            nodes: Vec::with_capacity(2 * clusters),
            free: Vec::new(),
            root: NONE,
        }
    }

    fn allocate(&mut self, node: Node) -> u32 {
        match self.free.pop() {
            Some(i) => {
                self.nodes[i as usize] = node;
                i
            }
            None => {
                self.nodes.push(node);
                self.nodes.len() as u32 - 1
            }
        }
    }

    /// Adds a cluster; returns its leaf, for [`DynamicTree::remove`].
    pub fn insert(&mut self, cluster: u32, bounds: Aabb) -> u32 {
        let leaf = self.allocate(Node {
            bounds,
            parent: NONE,
            children: [NONE, cluster],
        });
        if self.root == NONE {
            self.root = leaf;
            return leaf;
        }
        // Walk down to the sibling whose pairing grows the tree's area least.
        let mut index = self.root;
        while !self.nodes[index as usize].is_leaf() {
            let node = self.nodes[index as usize];
            let area = node.bounds.surface_area();
            let combined = node.bounds.union(bounds).surface_area();
            let pair_here = 2.0 * combined;
            let inherited = 2.0 * (combined - area);
            let descend = |child: u32| {
                let c = &self.nodes[child as usize];
                let grown = c.bounds.union(bounds).surface_area();
                inherited
                    + if c.is_leaf() {
                        grown
                    } else {
                        grown - c.bounds.surface_area()
                    }
            };
            let (cost0, cost1) = (descend(node.children[0]), descend(node.children[1]));
            if pair_here < cost0 && pair_here < cost1 {
                break;
            }
            index = if cost0 <= cost1 {
                node.children[0]
            } else {
                node.children[1]
            };
        }
        let sibling = index;
        let old_parent = self.nodes[sibling as usize].parent;
        let parent = self.allocate(Node {
            bounds: self.nodes[sibling as usize].bounds.union(bounds),
            parent: old_parent,
            children: [sibling, leaf],
        });
        self.nodes[sibling as usize].parent = parent;
        self.nodes[leaf as usize].parent = parent;
        if old_parent == NONE {
            self.root = parent;
        } else {
            let c = &mut self.nodes[old_parent as usize].children;
            let slot = if c[0] == sibling { 0 } else { 1 };
            c[slot] = parent;
        }
        self.refit_from(old_parent);
        leaf
    }

    pub fn remove(&mut self, leaf: u32) {
        let parent = self.nodes[leaf as usize].parent;
        self.free.push(leaf);
        if parent == NONE {
            self.root = NONE;
            return;
        }
        let p = self.nodes[parent as usize];
        let sibling = if p.children[0] == leaf {
            p.children[1]
        } else {
            p.children[0]
        };
        self.free.push(parent);
        self.nodes[sibling as usize].parent = p.parent;
        if p.parent == NONE {
            self.root = sibling;
        } else {
            let c = &mut self.nodes[p.parent as usize].children;
            let slot = if c[0] == parent { 0 } else { 1 };
            c[slot] = sibling;
            self.refit_from(p.parent);
        }
    }

    fn refit_from(&mut self, mut index: u32) {
        while index != NONE {
            let [a, b] = self.nodes[index as usize].children;
            self.nodes[index as usize].bounds = self.nodes[a as usize]
                .bounds
                .union(self.nodes[b as usize].bounds);
            index = self.nodes[index as usize].parent;
        }
    }

    /// The live cluster other than `exclude` whose union with `query` has the least
    /// surface area, with that area; ties go to the lower cluster id. `stack` is scratch
    /// space, reused between calls.
    pub fn nearest(&self, query: &Aabb, exclude: u32, stack: &mut Vec<(u32, f32)>) -> (f32, u32) {
        let mut best = (f32::INFINITY, u32::MAX);
        stack.clear();
        if self.root != NONE {
            stack.push((self.root, 0.0));
        }
        while let Some((index, bound)) = stack.pop() {
            if bound > best.0 {
                continue;
            }
            let node = &self.nodes[index as usize];
            if node.is_leaf() {
                let cluster = node.children[1];
                if cluster != exclude {
                    let cost = query.union(node.bounds).surface_area();
                    if cost < best.0 || (cost == best.0 && cluster < best.1) {
                        best = (cost, cluster);
                    }
                }
                continue;
            }
            let [a, b] = node.children;
            let (la, lb) = (
                area_lower_bound(query, &self.nodes[a as usize].bounds),
                area_lower_bound(query, &self.nodes[b as usize].bounds),
            );
            // Push the farther child first so that the nearer one is searched first.
            let (near, far) = if la <= lb {
                ((a, la), (b, lb))
            } else {
                ((b, lb), (a, la))
            };
            for (child, child_bound) in [far, near] {
                if child_bound <= best.0 {
                    stack.push((child, child_bound));
                }
            }
        }
        best
    }
}
