//! Wide BVHs (4 or 8 children per node), collapsed from a [`Bvh2`] (Dammertz et al.,
//! "Shallow bounding volume hierarchies for fast SIMD ray tracing of incoherent rays",
//! 2008; Wald et al., "Getting rid of packets", 2008).
//!
//! Collapse is greedy by surface area: a wide node starts from a binary node's two
//! children and repeatedly opens the interior child with the largest surface area (the
//! one most rays would enter) until it has `N` children. Boxes are stored per coordinate
//! (structure of arrays) so that a SIMD kernel can test all `N` at once; the traversal
//! here is the scalar twin.

use crate::aabb::SlabRay;
use crate::traverse::{TraversalCounter, TraversalStack};
use crate::{Aabb, Bvh2, BvhError, Hit, Ray, SahCosts, TreeStats};

/// `count` of a slot that holds nothing; its box is [`Aabb::EMPTY`].
pub const EMPTY_SLOT: u32 = u32::MAX;

/// A node of an `N`-wide BVH. Slot `i` is empty (`count == EMPTY_SLOT`), an interior
/// child (`count == 0`, node index `child`), or a leaf of `count` primitives starting at
/// `child` in the primitive index array. Used slots come first.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WideNode<const N: usize> {
    pub min_x: [f32; N],
    pub min_y: [f32; N],
    pub min_z: [f32; N],
    pub max_x: [f32; N],
    pub max_y: [f32; N],
    pub max_z: [f32; N],
    pub child: [u32; N],
    pub count: [u32; N],
}

impl<const N: usize> WideNode<N> {
    fn empty() -> Self {
        let e = Aabb::EMPTY;
        Self {
            min_x: [e.min.x; N],
            min_y: [e.min.y; N],
            min_z: [e.min.z; N],
            max_x: [e.max.x; N],
            max_y: [e.max.y; N],
            max_z: [e.max.z; N],
            child: [0; N],
            count: [EMPTY_SLOT; N],
        }
    }

    /// Box of slot `i`.
    #[inline(always)]
    pub fn slot_bounds(&self, i: usize) -> Aabb {
        Aabb::new(
            glam::Vec3::new(self.min_x[i], self.min_y[i], self.min_z[i]),
            glam::Vec3::new(self.max_x[i], self.max_y[i], self.max_z[i]),
        )
    }

    fn set_slot(&mut self, i: usize, b: Aabb, child: u32, count: u32) {
        (self.min_x[i], self.min_y[i], self.min_z[i]) = (b.min.x, b.min.y, b.min.z);
        (self.max_x[i], self.max_y[i], self.max_z[i]) = (b.max.x, b.max.y, b.max.z);
        self.child[i] = child;
        self.count[i] = count;
    }

    /// Number of used slots.
    #[inline(always)]
    pub fn len(&self) -> usize {
        self.count.iter().take_while(|&&c| c != EMPTY_SLOT).count()
    }

    pub fn is_empty(&self) -> bool {
        self.count[0] == EMPTY_SLOT
    }
}

/// An `N`-wide BVH: nodes (root first) and the primitive index array leaves point into.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BvhN<const N: usize> {
    nodes: Vec<WideNode<N>>,
    prim_indices: Vec<u32>,
}

pub type Bvh4 = BvhN<4>;
pub type Bvh8 = BvhN<8>;

impl<const N: usize> BvhN<N> {
    /// Collapses a binary tree; the primitive order is kept.
    pub fn from_bvh2(bvh: &Bvh2) -> Self {
        assert!(N >= 2, "a wide BVH has at least two children per node");
        let src = bvh.nodes();
        let mut wide = Self {
            nodes: Vec::new(),
            prim_indices: bvh.prim_indices().to_vec(),
        };
        let Some(root) = src.first() else {
            return wide;
        };
        if root.is_leaf() {
            let mut node = WideNode::empty();
            node.set_slot(0, root.bounds(), root.first, root.count);
            wide.nodes.push(node);
            return wide;
        }
        wide.nodes.push(WideNode::empty());
        // (binary interior node, wide node to fill)
        let mut work = vec![(0usize, 0usize)];
        while let Some((binary, slot_node)) = work.pop() {
            let first = src[binary].first as usize;
            let mut children = vec![first, first + 1];
            while children.len() < N {
                // Open the interior child with the largest surface area.
                let widest = children
                    .iter()
                    .enumerate()
                    .filter(|(_, &c)| !src[c].is_leaf())
                    .max_by(|a, b| {
                        src[*a.1]
                            .bounds()
                            .surface_area()
                            .total_cmp(&src[*b.1].bounds().surface_area())
                    });
                let Some((i, &c)) = widest else { break };
                let grandchild = src[c].first as usize;
                children[i] = grandchild;
                children.push(grandchild + 1);
            }
            let mut node = WideNode::empty();
            for (i, &c) in children.iter().enumerate() {
                let child = &src[c];
                if child.is_leaf() {
                    node.set_slot(i, child.bounds(), child.first, child.count);
                } else {
                    let index = wide.nodes.len();
                    wide.nodes.push(WideNode::empty());
                    node.set_slot(i, child.bounds(), index as u32, 0);
                    work.push((c, index));
                }
            }
            wide.nodes[slot_node] = node;
        }
        wide
    }

    pub fn nodes(&self) -> &[WideNode<N>] {
        &self.nodes
    }

    pub fn prim_indices(&self) -> &[u32] {
        &self.prim_indices
    }

    /// Closest hit; same contract as [`Bvh2::intersect`].
    #[inline]
    pub fn intersect<F>(&self, ray: &Ray, hit_prim: F) -> Option<Hit>
    where
        F: FnMut(u32, &Ray) -> Option<f32>,
    {
        self.intersect_counted(ray, hit_prim, &mut ())
    }

    /// [`BvhN::intersect`], reporting its work to `counter`.
    pub fn intersect_counted<F, C>(
        &self,
        ray: &Ray,
        mut hit_prim: F,
        counter: &mut C,
    ) -> Option<Hit>
    where
        F: FnMut(u32, &Ray) -> Option<f32>,
        C: TraversalCounter,
    {
        if self.nodes.is_empty() {
            return None;
        }
        let mut ray = *ray;
        let mut slab = SlabRay::new(&ray);
        let mut best: Option<Hit> = None;
        // Entries: (node or first primitive, count as in a slot, entry distance).
        let mut stack = TraversalStack::<(u32, u32, f32)>::new();
        stack.push((0, 0, 0.0));
        while let Some((index, count, t_entry)) = stack.pop() {
            if t_entry > ray.t_max {
                continue;
            }
            counter.visit_node();
            if count > 0 {
                // The same loop as `ClosestHitSearch::test_leaf`, kept inline: routing this
                // traversal through that type measured ~20% slower (the ray left registers).
                let first = index as usize;
                for &prim in &self.prim_indices[first..first + count as usize] {
                    counter.test_primitive();
                    if let Some(t) = hit_prim(prim, &ray) {
                        let hit = Hit { t, prim };
                        if best.is_none_or(|b| hit.is_before(&b)) {
                            ray.t_max = t;
                            slab.t_max = t;
                            best = Some(hit);
                        }
                    }
                }
                continue;
            }
            let node = &self.nodes[index as usize];
            // Hit slots, sorted far to near so that the nearest is popped first.
            let mut hits = [(0u32, 0u32, 0f32); N];
            let mut n_hits = 0;
            for i in 0..node.len() {
                let b = node.slot_bounds(i);
                let t = slab.entry_or_inf(b.min, b.max);
                if t != f32::INFINITY {
                    let mut j = n_hits;
                    while j > 0 && hits[j - 1].2 < t {
                        hits[j] = hits[j - 1];
                        j -= 1;
                    }
                    hits[j] = (node.child[i], node.count[i], t);
                    n_hits += 1;
                }
            }
            for &entry in &hits[..n_hits] {
                stack.push(entry);
            }
        }
        best
    }

    /// Whether anything blocks `ray`; same contract as [`Bvh2::occluded`].
    pub fn occluded<F>(&self, ray: &Ray, mut hit_prim: F) -> bool
    where
        F: FnMut(u32, &Ray) -> bool,
    {
        if self.nodes.is_empty() {
            return false;
        }
        let slab = SlabRay::new(ray);
        let mut stack = TraversalStack::<(u32, u32)>::new();
        stack.push((0, 0));
        while let Some((index, count)) = stack.pop() {
            if count > 0 {
                let first = index as usize;
                if self.prim_indices[first..first + count as usize]
                    .iter()
                    .any(|&p| hit_prim(p, ray))
                {
                    return true;
                }
                continue;
            }
            let node = &self.nodes[index as usize];
            for i in 0..node.len() {
                let b = node.slot_bounds(i);
                if slab.entry_or_inf(b.min, b.max) != f32::INFINITY {
                    stack.push((node.child[i], node.count[i]));
                }
            }
        }
        false
    }

    /// Checks every primitive is in exactly one leaf, every slot box is the tight box of
    /// its contents, and every node is reached exactly once.
    pub fn validate(&self, boxes: &[Aabb]) -> Result<(), BvhError> {
        if self.nodes.is_empty() {
            return match boxes.len() {
                0 => Ok(()),
                _ => Err(BvhError::PrimitiveCount { prim: 0, times: 0 }),
            };
        }
        let mut seen = vec![0usize; boxes.len()];
        let mut reached = vec![false; self.nodes.len()];
        reached[0] = true;
        let mut stack = vec![0usize];
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n];
            for i in 0..node.len() {
                let (child, count) = (node.child[i] as usize, node.count[i]);
                let contents = if count > 0 {
                    let end = child + count as usize;
                    let prims =
                        self.prim_indices
                            .get(child..end)
                            .ok_or(BvhError::LeafOutOfRange {
                                node: n,
                                first: child,
                                end,
                                len: self.prim_indices.len(),
                            })?;
                    let mut b = Aabb::EMPTY;
                    for &p in prims {
                        *seen
                            .get_mut(p as usize)
                            .ok_or(BvhError::PrimitiveOutOfRange {
                                prim: p,
                                len: boxes.len(),
                            })? += 1;
                        b = b.union(boxes[p as usize]);
                    }
                    b
                } else {
                    if child >= self.nodes.len() || child == 0 {
                        return Err(BvhError::ChildOutOfRange {
                            node: n,
                            child,
                            len: self.nodes.len(),
                        });
                    }
                    if std::mem::replace(&mut reached[child], true) {
                        return Err(BvhError::NodeShared { node: child });
                    }
                    stack.push(child);
                    let c = &self.nodes[child];
                    (0..c.len()).fold(Aabb::EMPTY, |b, j| b.union(c.slot_bounds(j)))
                };
                if contents != node.slot_bounds(i) {
                    return Err(BvhError::NotTight { node: n });
                }
            }
        }
        let unreached = reached.iter().filter(|r| !**r).count();
        if unreached > 0 {
            return Err(BvhError::UnreachableNodes {
                unreached,
                len: self.nodes.len(),
            });
        }
        if let Some((prim, &times)) = seen.iter().enumerate().find(|(_, &t)| t != 1) {
            return Err(BvhError::PrimitiveCount {
                prim: prim as u32,
                times,
            });
        }
        Ok(())
    }

    /// Shape and quality; the SAH charges one traversal step per wide node entered.
    pub fn stats(&self, costs: &SahCosts) -> TreeStats {
        let mut stats = TreeStats::sized(&self.nodes, &self.prim_indices);
        let Some(root) = self.nodes.first() else {
            return stats;
        };
        let root_box = (0..root.len()).fold(Aabb::EMPTY, |b, i| b.union(root.slot_bounds(i)));
        let root_area = root_box.surface_area();
        let relative = |b: Aabb| {
            if root_area > 0.0 {
                (b.surface_area() / root_area) as f64
            } else {
                1.0
            }
        };
        let mut cost = costs.traversal as f64;
        let mut stack = vec![(0usize, 1usize)];
        while let Some((n, depth)) = stack.pop() {
            stats.max_depth = stats.max_depth.max(depth);
            let node = &self.nodes[n];
            for i in 0..node.len() {
                let area = relative(node.slot_bounds(i));
                if node.count[i] > 0 {
                    stats.leaves += 1;
                    stats.max_leaf_size = stats.max_leaf_size.max(node.count[i] as usize);
                    cost += area * node.count[i] as f64 * costs.intersection as f64;
                } else {
                    cost += area * costs.traversal as f64;
                    stack.push((node.child[i] as usize, depth + 1));
                }
            }
        }
        stats.sah_cost = cost as f32;
        stats
    }
}
