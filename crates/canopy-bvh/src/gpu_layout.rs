//! [`GpuBvh`]: the binary tree laid out for GPU traversal, derived from [`Bvh2`].
//!
//! Each node holds *both children's* boxes (Aila & Laine 2009), so one 64-byte read
//! decides which children a ray enters, and a leaf costs no node fetch of its own. Only
//! inner nodes of the binary tree become nodes here; the root is node 0.

use crate::aabb::SlabRay;
use crate::view::{Child, ChildKind, TreeView};
use crate::{Aabb, Bvh2, Hit, IntoHit, Ray, RefitError, TraversalCounter};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// `child` of an empty slot (the root of a one-leaf tree has one).
pub const GPU_EMPTY: u32 = u32::MAX;

/// A node of a [`GpuBvh`]: 64 bytes, `#[repr(C)]`, `Pod`; WGSL reads it as
/// `struct { lmin: vec3<f32>, left: u32, lmax: vec3<f32>, left_count: u32,
/// rmin: vec3<f32>, right: u32, rmax: vec3<f32>, right_count: u32 }`.
///
/// Byte layout: `left_min` (0..12), `left` (12..16), `left_max` (16..28), `left_count`
/// (28..32), `right_min` (32..44), `right` (44..48), `right_max` (48..60), `right_count`
/// (60..64). A child with `count > 0` is a leaf of `count` primitives from `first` in
/// the primitive indices; with `count == 0` it is the node `child`, or nothing when
/// `child == GPU_EMPTY` (its box is then empty).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GpuNode {
    pub left_min: Vec3,
    pub left: u32,
    pub left_max: Vec3,
    pub left_count: u32,
    pub right_min: Vec3,
    pub right: u32,
    pub right_max: Vec3,
    pub right_count: u32,
}

const _: () = assert!(std::mem::size_of::<GpuNode>() == 64);

impl GpuNode {
    /// Slot `i` (0 left, 1 right): box, child and count.
    pub fn slot(&self, i: usize) -> (Aabb, u32, u32) {
        match i {
            0 => (
                Aabb::new(self.left_min, self.left_max),
                self.left,
                self.left_count,
            ),
            _ => (
                Aabb::new(self.right_min, self.right_max),
                self.right,
                self.right_count,
            ),
        }
    }
}

/// A binary BVH with child boxes in the parent, ready to upload.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GpuBvh {
    nodes: Vec<GpuNode>,
    prim_indices: Vec<u32>,
    spatial_splits: bool,
}

impl GpuBvh {
    pub fn from_bvh2(bvh: &Bvh2) -> Self {
        let src = bvh.nodes();
        let mut out = Self {
            nodes: Vec::new(),
            prim_indices: bvh.prim_indices().to_vec(),
            spatial_splits: bvh.has_spatial_splits(),
        };
        let Some(root) = src.first() else {
            return out;
        };
        // Inner nodes keep their order (parents before children), numbered densely.
        let mut index = vec![GPU_EMPTY; src.len()];
        let mut next = 0;
        for (i, node) in src.iter().enumerate() {
            if !node.is_leaf() {
                index[i] = next;
                next += 1;
            }
        }
        let slot = |c: usize| {
            let n = &src[c];
            match n.is_leaf() {
                true => (n.bounds(), n.first, n.count),
                false => (n.bounds(), index[c], 0),
            }
        };
        let node = |left: (Aabb, u32, u32), right: (Aabb, u32, u32)| GpuNode {
            left_min: left.0.min,
            left: left.1,
            left_max: left.0.max,
            left_count: left.2,
            right_min: right.0.min,
            right: right.1,
            right_max: right.0.max,
            right_count: right.2,
        };
        if root.is_leaf() {
            out.nodes.push(node(slot(0), (Aabb::EMPTY, GPU_EMPTY, 0)));
            return out;
        }
        out.nodes = src
            .iter()
            .filter(|n| !n.is_leaf())
            .map(|n| {
                let c = n.first as usize;
                node(slot(c), slot(c + 1))
            })
            .collect();
        out
    }

    /// Recomputes every box from `boxes` (one per primitive), keeping the topology.
    /// Refuses a tree with spatial splits, whose leaf boxes are parts of primitives.
    pub fn refit(&mut self, boxes: &[Aabb]) -> Result<(), RefitError> {
        if self.spatial_splits {
            return Err(RefitError::SpatialSplits);
        }
        // Inner nodes keep the binary tree's order, children after parents, so a reverse
        // sweep sees children first.
        for i in (0..self.nodes.len()).rev() {
            let node = self.nodes[i];
            let slot = |(_, child, count): (Aabb, u32, u32)| match (child, count) {
                (GPU_EMPTY, 0) => Aabb::EMPTY,
                (_, 0) => {
                    let c = &self.nodes[child as usize];
                    c.slot(0).0.union(c.slot(1).0)
                }
                _ => self.prim_indices[child as usize..(child + count) as usize]
                    .iter()
                    .fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize])),
            };
            let (left, right) = (slot(node.slot(0)), slot(node.slot(1)));
            let n = &mut self.nodes[i];
            (n.left_min, n.left_max) = (left.min, left.max);
            (n.right_min, n.right_max) = (right.min, right.max);
        }
        Ok(())
    }

    pub fn nodes(&self) -> &[GpuNode] {
        &self.nodes
    }

    pub fn prim_indices(&self) -> &[u32] {
        &self.prim_indices
    }

    /// Closest hit, walking the tree exactly as the GPU kernel does (both child boxes per
    /// node, leaves tested on entry, the farther inner child stacked): the CPU twin the
    /// GPU's answers are checked against. Ties go to the lower primitive index.
    pub fn intersect<P: IntoHit>(
        &self,
        ray: &Ray,
        hit: impl FnMut(u32, &Ray) -> Option<P>,
    ) -> Option<Hit> {
        self.intersect_counted(ray, hit, &mut ())
    }

    /// [`GpuBvh::intersect`], reporting its work to `counter`.
    pub fn intersect_counted<P: IntoHit>(
        &self,
        ray: &Ray,
        mut hit: impl FnMut(u32, &Ray) -> Option<P>,
        counter: &mut impl TraversalCounter,
    ) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut ray = *ray;
        self.walk(&mut ray, counter, |prim, ray| {
            if let Some(h) = hit(prim, ray) {
                let h = h.into_hit(prim);
                if best.is_none_or(|b| h.is_before(&b)) {
                    best = Some(h);
                    ray.t_max = h.t;
                }
            }
            false
        });
        best
    }

    /// Whether anything blocks `ray` (the walk ends at the first hit).
    pub fn occluded(&self, ray: &Ray, mut hit: impl FnMut(u32, &Ray) -> bool) -> bool {
        let mut ray = *ray;
        self.walk(&mut ray, &mut (), |prim, ray| hit(prim, ray))
    }

    /// The kernel's walk: `test(prim, ray)` for every primitive of every leaf entered (it
    /// may shorten `ray.t_max`); stops and returns true when `test` does.
    fn walk(
        &self,
        ray: &mut Ray,
        counter: &mut impl TraversalCounter,
        mut test: impl FnMut(u32, &mut Ray) -> bool,
    ) -> bool {
        // A NaN or degenerate ray misses everything (see Ray).
        if self.nodes.is_empty() || !ray.is_traceable() {
            return false;
        }
        let mut stack = Vec::new();
        let mut node = 0usize;
        loop {
            counter.visit_node();
            let n = &self.nodes[node];
            let mut inner = [(f32::INFINITY, 0u32); 2];
            for (i, inner) in inner.iter_mut().enumerate() {
                let (bounds, child, count) = n.slot(i);
                // An empty box is not a miss for the slab test (-inf..inf): skip it.
                if count == 0 && child == GPU_EMPTY {
                    continue;
                }
                let t = SlabRay::new(ray).entry_or_inf(bounds.min, bounds.max);
                if t == f32::INFINITY {
                    continue;
                }
                if count == 0 {
                    *inner = (t, child);
                    continue;
                }
                for &prim in &self.prim_indices[child as usize..(child + count) as usize] {
                    counter.test_primitive();
                    if test(prim, ray) {
                        return true;
                    }
                }
            }
            let [(tl, l), (tr, r)] = inner;
            node = match (tl < f32::INFINITY, tr < f32::INFINITY) {
                (true, true) => {
                    let (near, far) = if tl <= tr { (l, r) } else { (r, l) };
                    stack.push(far);
                    near as usize
                }
                (true, false) => l as usize,
                (false, true) => r as usize,
                (false, false) => match stack.pop() {
                    Some(next) => next as usize,
                    None => return false,
                },
            };
        }
    }
}

impl TreeView for GpuBvh {
    fn slot_count(&self) -> usize {
        self.nodes.len()
    }

    fn root(&self) -> Option<Child> {
        let root = self.nodes.first()?;
        Some(Child {
            bounds: root.slot(0).0.union(root.slot(1).0),
            kind: ChildKind::Inner(0),
            slot: Some(0),
        })
    }

    fn children(&self, node: usize, out: &mut Vec<Child>) {
        let n = &self.nodes[node];
        out.clear();
        for i in 0..2 {
            let (bounds, child, count) = n.slot(i);
            out.push(match (count, child) {
                (0, GPU_EMPTY) => continue,
                (0, c) if (c as usize) < self.nodes.len() => Child {
                    bounds,
                    kind: ChildKind::Inner(c as usize),
                    slot: Some(c as usize),
                },
                // Out of range (a damaged tree): validation reports the slot.
                (0, c) => Child {
                    bounds,
                    kind: ChildKind::Leaf { first: 0, count: 0 },
                    slot: Some(c as usize),
                },
                (count, first) => Child {
                    bounds,
                    kind: ChildKind::Leaf {
                        first: first as usize,
                        count: count as usize,
                    },
                    slot: None,
                },
            });
        }
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
    use crate::view::tests::boxes;
    use crate::{build, BuildParams, Builder};

    #[test]
    fn the_gpu_layout_validates_and_answers_as_the_binary_tree_does() {
        for n in [1, 2, 5, 300] {
            let boxes = boxes(n);
            for builder in [Builder::BinnedSah, Builder::Sbvh, Builder::Lbvh] {
                let bvh = build(builder, &boxes, &BuildParams::default());
                let gpu = GpuBvh::from_bvh2(&bvh);
                gpu.validate_against(&boxes);
                let a = gpu.stats(&crate::SahCosts::default());
                let b = bvh.stats(&crate::SahCosts::default());
                assert_eq!((a.leaves, a.references), (b.leaves, b.references));
                let hit = |p: u32, r: &Ray| boxes[p as usize].ray_entry(r);
                for i in 0..200 {
                    let t = i as f32 * 0.37;
                    let origin = Vec3::new(-3.0, t % 12.0, (t * 1.7) % 4.0);
                    let target = Vec3::new(14.0, (t * 3.1) % 12.0, (t * 0.9) % 4.0);
                    let ray = Ray::new(origin, (target - origin).normalize(), 0.0, f32::INFINITY);
                    assert_eq!(
                        gpu.intersect(&ray, hit),
                        bvh.intersect(&ray, hit),
                        "{builder} x{n}"
                    );
                }
            }
        }
        assert_eq!(GpuBvh::from_bvh2(&Bvh2::default()).nodes().len(), 0);
    }

    impl GpuBvh {
        fn validate_against(&self, boxes: &[Aabb]) {
            crate::view::validate(self, boxes).unwrap();
        }

        fn stats(&self, costs: &crate::SahCosts) -> crate::TreeStats {
            crate::view::stats(self, costs)
        }
    }
}
