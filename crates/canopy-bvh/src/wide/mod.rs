//! Wide BVHs (4 or 8 children per node), collapsed from a [`Bvh2`] (Dammertz et al.,
//! "Shallow bounding volume hierarchies for fast SIMD ray tracing of incoherent rays",
//! 2008; Wald et al., "Getting rid of packets", 2008).
//!
//! Collapse is greedy by surface area: a wide node starts from a binary node's two
//! children and repeatedly opens the interior child with the largest surface area (the
//! one most rays would enter) until it has `N` children. Boxes are stored by plane, one
//! lane per slot, so that one SIMD box test covers a node ([`kernels`]). Leaves may hold
//! their triangles in packs of four ([`BvhN::pack_triangles`]) tested together.

mod frustum;
mod kernels;
mod pack_shapes;
mod packet;
mod packet_packs;
mod refit;
#[cfg(test)]
mod test_numbers;
mod traverse;

use crate::query::{Coherence, RayBatch};
use crate::shapes::ShapeRecord;
use crate::traverse::TraversalCounter;
use crate::triangle::{TrianglePack, TriangleTest, NO_PRIM, PACK_LANES};
use crate::view::{Child, ChildKind, TreeView};
use crate::{
    Aabb, Bvh2, BvhError, Hit, IntoHit, Isa, IsaError, KnownShape, Ray, SahCosts, TreeStats,
};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use packet::walk_packet;
use packet_packs::PackedPacketLeaves;
use rayon::prelude::*;
use std::marker::PhantomData;
use traverse::{
    any_each, closest_each, every_each, ClosureLeaves, EveryHit, PackedLeaves, Query, ShapeLeaves,
    WalkNodes,
};

#[cfg(target_arch = "x86_64")]
pub(crate) use pack_shapes::shape_lanes;
pub(crate) use pack_shapes::shapes_one_by_one;
pub use packet::PACKET;
pub(crate) use traverse::Dispatch;

/// Trees whose nodes and packs take more bytes than this are traversed with prefetches of
/// stacked children: about the size of a core's L2 cache, past which incoherent rays wait
/// on memory. Smaller trees stay in the cache, where prefetches only cost instructions.
pub const PREFETCH_ABOVE_BYTES: usize = 1 << 20;

/// `count` of a slot that holds nothing; its box is [`Aabb::EMPTY`].
pub const EMPTY_SLOT: u32 = u32::MAX;

/// A node of an `N`-wide BVH. Slot `i` is empty (`count == EMPTY_SLOT`), an interior
/// child (`count == 0`, node index `child`), or a leaf of `count` primitives starting at
/// position `child` of the primitive index array. Used slots come first.
///
/// Byte layout (`32 * N` bytes, 64-aligned): `bounds[plane][slot]` with planes min x,
/// min y, min z, max x, max y, max z (`24 * N` bytes), then `child` and `count`
/// (`4 * N` bytes each). Each plane is one SIMD register of `N` lanes.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WideNode<const N: usize> {
    pub bounds: [[f32; N]; 6],
    pub child: [u32; N],
    pub count: [u32; N],
}

macro_rules! pod_node {
    ($($n:literal),*) => {$(
        const _: () = assert!(std::mem::size_of::<WideNode<$n>>() == 32 * $n);
        const _: () = assert!(std::mem::align_of::<WideNode<$n>>() == 64);
        // SAFETY: only `f32`/`u32` arrays, no padding (asserted above), any bits valid.
        unsafe impl Zeroable for WideNode<$n> {}
        // SAFETY: as above.
        unsafe impl Pod for WideNode<$n> {}
    )*};
}
pod_node!(4, 8);

impl<const N: usize> WideNode<N> {
    fn empty() -> Self {
        let e = Aabb::EMPTY;
        Self {
            bounds: [e.min.x, e.min.y, e.min.z, e.max.x, e.max.y, e.max.z].map(|p| [p; N]),
            child: [0; N],
            count: [EMPTY_SLOT; N],
        }
    }

    /// Box of slot `i`.
    #[inline(always)]
    pub fn slot_bounds(&self, i: usize) -> Aabb {
        let b = &self.bounds;
        Aabb::new(
            Vec3::new(b[0][i], b[1][i], b[2][i]),
            Vec3::new(b[3][i], b[4][i], b[5][i]),
        )
    }

    fn set_slot(&mut self, i: usize, b: Aabb, child: u32, count: u32) {
        let planes = [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z];
        for (plane, value) in self.bounds.iter_mut().zip(planes) {
            plane[i] = value;
        }
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

/// An `N`-wide BVH: nodes (root first), the primitive index array leaves point into, and
/// optionally the same primitives as triangle packs; with the instruction set its
/// traversal kernels use.
#[derive(Clone, Debug, PartialEq)]
pub struct BvhN<const N: usize> {
    pub(crate) nodes: Vec<WideNode<N>>,
    prim_indices: Vec<u32>,
    /// Empty, or `packs[k]` holds positions `4k..4k + 4` of `prim_indices`.
    packs: Vec<TrianglePack>,
    /// Empty, or the kept shape (or none) at each position of `prim_indices`, in trees
    /// without triangle packs (whose lanes keep their shapes; see [`BvhN::store_shapes`]).
    shapes: Vec<ShapeRecord>,
    /// Whether `shapes` holds every leaf entry: no entry is left to the closure.
    every_shape_kept: bool,
    isa: Isa,
    /// The mode the packs' triangles are tested in.
    triangle_test: TriangleTest,
    /// Entries a walk's stack can hold at once ([`BvhN::stack_room`]).
    stack_room: usize,
    /// Taken from the binary tree (see [`Bvh2::has_spatial_splits`]).
    spatial_splits: bool,
}

/// [`BvhN::stack_room`] of `nodes`, whose children lie after their parents (as
/// [`BvhN::from_bvh2`] numbers them).
fn stack_room<const N: usize>(nodes: &[WideNode<N>]) -> usize {
    // Interior levels from the root down to each node, itself included.
    let mut levels = vec![0u32; nodes.len()];
    let mut deepest = 0;
    for (i, node) in nodes.iter().enumerate() {
        let level = levels[i] + 1;
        deepest = deepest.max(level);
        for slot in 0..N {
            if node.count[slot] == 0 {
                let child = node.child[slot] as usize;
                assert!(child > i, "a child before its parent");
                levels[child] = level;
            }
        }
    }
    (N - 1) * deepest as usize
}

pub type Bvh4 = BvhN<4>;
pub type Bvh8 = BvhN<8>;

impl<const N: usize> Default for BvhN<N> {
    fn default() -> Self {
        Self {
            nodes: Vec::new(),
            prim_indices: Vec::new(),
            packs: Vec::new(),
            shapes: Vec::new(),
            every_shape_kept: false,
            isa: Isa::best(),
            triangle_test: TriangleTest::Watertight,
            spatial_splits: false,
            stack_room: 0,
        }
    }
}

impl<const N: usize> BvhN<N> {
    /// Whether leaves hold triangle packs.
    pub fn has_triangle_packs(&self) -> bool {
        !self.packs.is_empty()
    }

    /// The instruction set the traversal kernels use.
    pub fn isa(&self) -> Isa {
        self.isa
    }

    /// Uses the kernels of `isa` (every twin gives the same answers; for tests and
    /// benchmarks). Fails if this CPU lacks it.
    pub fn set_isa(&mut self, isa: Isa) -> Result<(), IsaError> {
        if !isa.is_supported() {
            return Err(IsaError::Unsupported(isa));
        }
        self.isa = isa;
        Ok(())
    }

    /// The mode the triangle packs are tested in (watertight unless set).
    pub fn triangle_test(&self) -> TriangleTest {
        self.triangle_test
    }

    /// Tests the triangle packs in mode `test`. Primitives outside packs are the
    /// caller's closure's to test, in whatever mode it chooses.
    pub fn set_triangle_test(&mut self, test: TriangleTest) {
        self.triangle_test = test;
    }

    pub fn nodes(&self) -> &[WideNode<N>] {
        &self.nodes
    }

    /// Leaf-ordered primitive indices (with [`NO_PRIM`] padding between leaves when
    /// triangles are packed).
    pub fn prim_indices(&self) -> &[u32] {
        &self.prim_indices
    }
}

impl<const N: usize> BvhN<N> {
    /// Whether batches are traced in the order of their rays' origins ([`RayOrder`]):
    /// for trees larger than a core's cache ([`PREFETCH_ABOVE_BYTES`]), where rays that
    /// start near each other share the nodes and leaves they load. A tree that stays in
    /// the cache gains less than the reordering costs.
    pub fn orders_batches(&self) -> bool {
        self.prefetches()
    }

    /// Whether traversal prefetches stacked children ([`PREFETCH_ABOVE_BYTES`]).
    #[inline(always)]
    fn prefetches(&self) -> bool {
        std::mem::size_of_val(self.nodes.as_slice()) + std::mem::size_of_val(self.packs.as_slice())
            > PREFETCH_ABOVE_BYTES
    }

    /// Collapses a binary tree; the primitive order is kept. Traversal uses the best
    /// instruction set of this CPU.
    pub fn from_bvh2(bvh: &Bvh2) -> Self {
        let src = bvh.nodes();
        let mut wide = Self {
            prim_indices: bvh.prim_indices().to_vec(),
            spatial_splits: bvh.has_spatial_splits(),
            ..Self::default()
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
        // At most one wide node per binary interior node: room reserved but never
        // touched costs nothing, growing the array would copy it.
        wide.nodes.reserve_exact(src.len() / 2);
        wide.nodes.push(WideNode::empty());
        // (binary interior node, wide node to fill)
        let mut work = vec![(0usize, 0usize)];
        while let Some((binary, slot_node)) = work.pop() {
            let first = src[binary].first as usize;
            // Each slot's binary node, and its surface area if it can be opened.
            let openable = |c: usize| match src[c].is_leaf() {
                true => None,
                false => Some(src[c].bounds().surface_area()),
            };
            let mut slots = [0usize; N];
            let mut areas = [None; N];
            for (i, c) in [first, first + 1].into_iter().enumerate() {
                (slots[i], areas[i]) = (c, openable(c));
            }
            let mut len = 2;
            while len < N {
                // Open the interior child with the largest surface area (the last of
                // equals).
                let widest = (0..len)
                    .filter_map(|i| areas[i].map(|a| (i, a)))
                    .max_by(|a, b| a.1.total_cmp(&b.1));
                let Some((i, _)) = widest else { break };
                let grandchild = src[slots[i]].first as usize;
                (slots[i], areas[i]) = (grandchild, openable(grandchild));
                (slots[len], areas[len]) = (grandchild + 1, openable(grandchild + 1));
                len += 1;
            }
            let children = &slots[..len];
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
        wide.stack_room = stack_room(&wide.nodes);
        wide
    }

    /// Entries a walk's stack can hold at once: a node pushes at most `N - 1` of its
    /// slots, so `N - 1` for each interior level of the deepest path. Walks make this
    /// much room before they start ([`WalkNodes::stack`]).
    #[inline(always)]
    fn stack_room(&self) -> usize {
        self.stack_room
    }

    /// The nodes as walks go through them, with whether to prefetch and the stack room.
    #[inline(always)]
    fn walk_nodes(&self) -> WalkNodes<'_, N> {
        WalkNodes::new(&self.nodes, self.prefetches(), self.stack_room())
    }

    /// Stores the leaves' triangles in packs of four, tested together by SIMD kernels.
    /// `triangle(prim)` gives a primitive's vertices if it is a triangle; other
    /// primitives stay with the caller's closure. Each leaf then starts on a pack
    /// boundary with its triangles first (`prim_indices` gets [`NO_PRIM`] padding
    /// between leaves, never inside one).
    /// A tree without triangles is left as it is.
    pub fn pack_triangles(&mut self, triangle: impl Fn(u32) -> Option<[Vec3; 3]> + Sync) {
        self.pack(triangle, false);
    }

    /// Stores every leaf in packs as [`BvhN::pack_triangles`] does, a tree without
    /// triangles too: the spheres that [`BvhN::store_shapes`] then keeps in the packs'
    /// lanes are tested a pack or two at a time, in the walk's loop, as triangles are.
    pub fn pack_leaves(&mut self, triangle: impl Fn(u32) -> Option<[Vec3; 3]> + Sync) {
        self.pack(triangle, true);
    }

    fn pack(&mut self, triangle: impl Fn(u32) -> Option<[Vec3; 3]> + Sync, always: bool) {
        // Which primitives are triangles, asked in the caller's order, where lookups are
        // cheap; the leaf order scatters them into cache misses, so there each triangle
        // is looked up only once, for its vertices.
        let prims = self
            .prim_indices
            .iter()
            .max()
            .map_or(0, |&p| p as usize + 1);
        let is_triangle: Vec<bool> = (0..prims as u32)
            .into_par_iter()
            .map(|p| triangle(p).is_some())
            .collect();
        if self.nodes.is_empty() || !(always || is_triangle.contains(&true)) {
            return;
        }
        let is_triangle = |p: u32| is_triangle[p as usize];
        let mut order = Vec::with_capacity(self.prim_indices.len() * 2);
        for node in &mut self.nodes {
            for i in 0..N {
                let (first, count) = (node.child[i], node.count[i]);
                if count == 0 || count == EMPTY_SLOT {
                    continue;
                }
                // Each leaf starts on a pack, triangles first.
                order.resize(order.len().next_multiple_of(PACK_LANES), NO_PRIM);
                node.child[i] = order.len() as u32;
                let leaf = &self.prim_indices[first as usize..(first + count) as usize];
                order.extend(leaf.iter().filter(|&&p| is_triangle(p)));
                order.extend(leaf.iter().filter(|&&p| !is_triangle(p)));
            }
        }
        order.resize(order.len().next_multiple_of(PACK_LANES), NO_PRIM);
        self.packs = order
            .par_chunks_exact(PACK_LANES)
            .map(|lanes| {
                let mut pack = TrianglePack::EMPTY;
                for (lane, &prim) in lanes.iter().enumerate() {
                    if prim == NO_PRIM {
                        continue;
                    }
                    match is_triangle(prim).then(|| triangle(prim)).flatten() {
                        Some(v) => pack.set_triangle(lane, prim, v),
                        None => pack.set_other(lane, prim),
                    }
                }
                pack
            })
            .collect();
        self.prim_indices = order;
    }

    /// Keeps the leaves' spheres and boxes beside them, in leaf order (in their lanes of
    /// the triangle packs where there are packs), so that traversal tests them itself:
    /// testing one is then a load of its record, not a call of the caller's closure and a
    /// lookup of the primitive. `shape(prim)` gives a primitive as a [`KnownShape`] where its hit
    /// is that shape's; other primitives stay with the closure. A tree with none is left
    /// as it is. Call it after [`BvhN::pack_triangles`], and again after the shapes move.
    pub fn store_shapes(&mut self, shape: impl Fn(u32) -> Option<KnownShape> + Sync) {
        self.shapes = Vec::new();
        self.every_shape_kept = false;
        if !self.packs.is_empty() {
            // Beside triangles, a shape sits in its lane's unused vertex slots: a mesh
            // with a floor keeps one box, not a record for each of its triangles.
            self.packs.par_iter_mut().for_each(|pack| {
                let others = pack.others;
                for lane in (0..PACK_LANES).filter(|&lane| others & 1 << lane != 0) {
                    pack.set_kept(lane, shape(pack.prim[lane]));
                }
            });
            return;
        }
        let records: Vec<ShapeRecord> = self
            .prim_indices
            .par_iter()
            .map(|&p| ShapeRecord((p != NO_PRIM).then(|| shape(p)).flatten()))
            .collect();
        let kept = |(&p, record): (&u32, &ShapeRecord)| p == NO_PRIM || record.is_kept();
        self.every_shape_kept = self.prim_indices.iter().zip(&records).all(kept);
        if records.iter().any(ShapeRecord::is_kept) {
            self.shapes = records;
        }
    }

    /// Whether traversal tests some primitives itself as known shapes
    /// ([`BvhN::store_shapes`]).
    pub fn has_kept_shapes(&self) -> bool {
        !self.shapes.is_empty() || self.packs.iter().any(TrianglePack::keeps_shapes)
    }

    /// Whether the leaves are tested as [`ShapeLeaves`]: shapes kept, no triangle packs.
    #[inline(always)]
    fn has_shape_leaves(&self) -> bool {
        !self.shapes.is_empty() && self.packs.is_empty()
    }

    /// Whether coherent rays go in packets: the tree tests its leaves itself (every
    /// entry a kept shape, or triangles packed); a closure's leaves go ray by ray. In a
    /// packet, an entry left to the closure is tested lane by lane, each lane's ray copied
    /// out of the packet: the Cornell box's two turned blocks made its camera and shadow
    /// rays 1.06x slower in packets than one by one (AMD EPYC, Zen 3).
    #[inline(always)]
    fn traces_packets(&self) -> bool {
        (self.has_shape_leaves() && self.every_shape_kept) || !self.packs.is_empty()
    }

    /// One packet of `rays` through the tree (which [`BvhN::traces_packets`]): kept
    /// shapes and packed triangles tested for all its rays at once, anything else by
    /// `test`. Each ray goes to its closest hit, or with `ANY` stops at its first; returns
    /// each lane's hit and the lanes that stopped ([`packet::walk_packet`]).
    ///
    /// # Safety
    /// The instruction sets of `K` and `T` must be available.
    #[inline(always)]
    unsafe fn walk_packet<K, T, F, P, const ANY: bool>(
        &self,
        rays: &[Ray],
        test: F,
    ) -> ([Option<Hit>; PACKET], u32)
    where
        K: kernels::NodeKernel<N>,
        T: crate::triangle::PackKernel,
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
    {
        if self.nodes.is_empty() {
            return ([None; PACKET], 0);
        }
        let nodes = self.walk_nodes();
        // SAFETY (both): the caller guarantees the instruction sets.
        if self.packs.is_empty() {
            let mut leaves = ShapeLeaves {
                prims: &self.prim_indices,
                shapes: &self.shapes,
                test,
            };
            unsafe { walk_packet::<N, K, _, ANY>(nodes, rays, &mut leaves) }
        } else {
            let mut leaves = PackedPacketLeaves::<T, _>::new(&self.packs, self.triangle_test, test);
            unsafe { walk_packet::<N, K, _, ANY>(nodes, rays, &mut leaves) }
        }
    }

    /// Checks every primitive is in exactly one leaf, every slot box is the tight box of
    /// its contents, and every node is reached exactly once.
    pub fn validate(&self, boxes: &[Aabb]) -> Result<(), BvhError> {
        crate::view::validate(self, boxes)
    }

    /// Shape and quality of the tree under the given SAH costs; memory includes the
    /// triangle packs.
    pub fn stats(&self, costs: &SahCosts) -> TreeStats {
        crate::view::stats(self, costs)
    }
}

impl<const N: usize> TreeView for BvhN<N> {
    fn slot_count(&self) -> usize {
        self.nodes.len()
    }

    fn root(&self) -> Option<Child> {
        let root = self.nodes.first()?;
        Some(Child {
            bounds: (0..root.len()).fold(Aabb::EMPTY, |b, i| b.union(root.slot_bounds(i))),
            kind: ChildKind::Inner(0),
            slot: Some(0),
        })
    }

    fn children(&self, node: usize, out: &mut Vec<Child>) {
        let n = &self.nodes[node];
        out.clear();
        out.extend((0..n.len()).map(|i| {
            let (child, count) = (n.child[i] as usize, n.count[i] as usize);
            let bounds = n.slot_bounds(i);
            match count {
                0 if child < self.nodes.len() => Child {
                    bounds,
                    kind: ChildKind::Inner(child),
                    slot: Some(child),
                },
                // Out of range (a damaged tree): validation reports the slot.
                0 => Child {
                    bounds,
                    kind: ChildKind::Leaf { first: 0, count: 0 },
                    slot: Some(child),
                },
                _ => Child {
                    bounds,
                    kind: ChildKind::Leaf {
                        first: child,
                        count,
                    },
                    slot: None,
                },
            }
        }));
    }

    fn prim_indices(&self) -> &[u32] {
        &self.prim_indices
    }

    fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.prim_indices.as_slice())
            + std::mem::size_of_val(self.packs.as_slice())
            + std::mem::size_of_val(self.shapes.as_slice())
    }

    fn has_spatial_splits(&self) -> bool {
        self.spatial_splits
    }
}

impl<const N: usize> BvhN<N>
where
    WideNode<N>: Dispatch<N>,
{
    /// Closest hit; same contract as [`Bvh2::intersect`]. Triangles in packs are tested by
    /// canopy itself (see [`BvhN::pack_triangles`]); the closure tests the rest.
    #[inline]
    pub fn intersect<F, P>(&self, ray: &Ray, hit_prim: F) -> Option<Hit>
    where
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
    {
        self.intersect_counted(ray, hit_prim, &mut ())
    }

    /// [`BvhN::intersect`], reporting its work to `counter`.
    #[inline]
    pub fn intersect_counted<F, P, C>(&self, ray: &Ray, hit_prim: F, counter: &mut C) -> Option<Hit>
    where
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
        C: TraversalCounter,
    {
        let mut hit = None;
        self.closest_hits(
            RayBatch::new(1),
            |_| *ray,
            |_, h| hit = h,
            hit_prim,
            counter,
        );
        hit
    }

    /// Whether anything blocks `ray`; same contract as [`Bvh2::occluded`].
    #[inline]
    pub fn occluded<F>(&self, ray: &Ray, hit_prim: F) -> bool
    where
        F: FnMut(u32, &Ray) -> bool,
    {
        let mut blocked = false;
        self.any_hits(RayBatch::new(1), |_| *ray, |_, b| blocked = b, hit_prim);
        blocked
    }
}

impl<const N: usize> BvhN<N>
where
    WideNode<N>: Dispatch<N>,
{
    /// Every hit of `ray` within its range, each given to `found` as it is met (in no
    /// particular order; a primitive in several leaves, after spatial splits, once per
    /// leaf), with the triangle's vertices where its pack holds them. Triangles in packs
    /// are tested by canopy itself; the closure tests the rest.
    pub fn for_each_hit<F, P, H>(&self, ray: &Ray, hit_prim: F, mut found: H)
    where
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
        H: FnMut(Hit, Option<[Vec3; 3]>),
    {
        let rays = std::slice::from_ref(ray);
        self.for_each_hit_of(rays, hit_prim, |_, hit, vertices| found(hit, vertices))
    }

    /// [`BvhN::for_each_hit`] of each of `rays`, one ray after another, each hit given to
    /// `found(i, hit, vertices)` with its ray's index: the instruction set is chosen
    /// and the walk's stack made once for the batch.
    pub fn for_each_hit_of<F, P, H>(&self, rays: &[Ray], hit_prim: F, found: H)
    where
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
        H: FnMut(usize, Hit, Option<[Vec3; 3]>),
    {
        if self.nodes.is_empty() {
            return;
        }
        let query = EveryHitQuery {
            bvh: self,
            rays,
            test: hit_prim,
            found,
        };
        WideNode::<N>::dispatch(self.isa, query)
    }
}

impl<const N: usize> BvhN<N>
where
    WideNode<N>: Dispatch<N>,
{
    /// Closest hits of the batch's rays on this thread, as [`crate::Tree::closest_hits`]
    /// says: coherent batches in packets where the tree traces them and nothing is
    /// counted (packets report no per-ray work), others ray by ray.
    pub fn closest_hits<R, A, F, P, C>(
        &self,
        batch: RayBatch,
        ray: R,
        answer: A,
        hit_prim: F,
        counter: &mut C,
    ) where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
        C: TraversalCounter,
    {
        let count = batch.count;
        if batch.coherence == Coherence::Coherent && !C::COUNTS && self.traces_packets() {
            let packets =
                Batch::<N, _, _, _, ClosestInPackets>::new(self, count, ray, answer, hit_prim);
            return WideNode::<N>::dispatch(self.isa, packets);
        }
        let each = Batch::<N, _, _, _, ClosestOneByOne>::new(self, count, ray, answer, hit_prim)
            .counted(counter);
        WideNode::<N>::dispatch(self.isa, each)
    }

    /// Occlusion of the batch's rays on this thread, as [`BvhN::closest_hits`].
    pub fn any_hits<R, A, F>(&self, batch: RayBatch, ray: R, answer: A, hit_prim: F)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
        F: FnMut(u32, &Ray) -> bool,
    {
        let count = batch.count;
        if batch.coherence == Coherence::Coherent && self.traces_packets() {
            let packets =
                Batch::<N, _, _, _, AnyInPackets>::new(self, count, ray, answer, hit_prim);
            return WideNode::<N>::dispatch(self.isa, packets);
        }
        let each = Batch::<N, _, _, _, AnyOneByOne>::new(self, count, ray, answer, hit_prim);
        WideNode::<N>::dispatch(self.isa, each)
    }

    /// Closest hits of rays `0..count` on this thread ([`BvhN::closest_hits`] of an
    /// incoherent batch): `ray(i)` makes ray `i`, `answer(i, hit)` takes its hit, in order;
    /// the answers are those of [`BvhN::intersect`].
    pub fn intersect_each<R, A, F, P>(&self, count: usize, ray: R, answer: A, hit_prim: F)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
    {
        self.closest_hits(RayBatch::new(count), ray, answer, hit_prim, &mut ())
    }

    /// [`BvhN::intersect_each`] for coherent rays: rays that start near each other and
    /// run in similar directions (camera rays of neighbouring pixels). Trees that keep
    /// their shapes ([`BvhN::store_shapes`]) or pack their triangles trace them as
    /// packets of [`PACKET`] consecutive rays, each kept shape and each triangle tested
    /// against the packet's rays at once; others (whose leaves the closure tests) trace
    /// them one by one. The answers are the same.
    pub fn intersect_coherent<R, A, F, P>(&self, count: usize, ray: R, answer: A, hit_prim: F)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, Option<Hit>),
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
    {
        let batch = RayBatch::new(count).with(Coherence::Coherent);
        self.closest_hits(batch, ray, answer, hit_prim, &mut ())
    }

    /// Occlusion of rays `0..count` on this thread, as [`BvhN::intersect_each`].
    pub fn occluded_each<R, A, F>(&self, count: usize, ray: R, answer: A, hit_prim: F)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
        F: FnMut(u32, &Ray) -> bool,
    {
        self.any_hits(RayBatch::new(count), ray, answer, hit_prim)
    }

    /// [`BvhN::occluded_each`] for coherent rays (shadow rays from neighbouring points
    /// towards one light): packets of [`PACKET`] consecutive rays, as
    /// [`BvhN::intersect_coherent`] makes them, each ray leaving its packet at its first
    /// hit. The answers are the same.
    pub fn occluded_coherent<R, A, F>(&self, count: usize, ray: R, answer: A, hit_prim: F)
    where
        R: FnMut(usize) -> Ray,
        A: FnMut(usize, bool),
        F: FnMut(u32, &Ray) -> bool,
    {
        self.any_hits(
            RayBatch::new(count).with(Coherence::Coherent),
            ray,
            answer,
            hit_prim,
        )
    }
}

/// Rays `0..count` for one dispatch: `ray(i)` makes ray `i`, `answer(i, _)` takes its
/// answer, and `test` is the caller's test of the primitives the tree leaves to it. `Q`
/// names the query and how the rays go (one of the four kinds below).
struct Batch<'a, const N: usize, R, A, F, Q, C = ()> {
    bvh: &'a BvhN<N>,
    count: usize,
    ray: R,
    answer: A,
    test: F,
    /// Told of each node visit and primitive test (closest hits one by one).
    counter: C,
    query: PhantomData<Q>,
}

impl<'a, const N: usize, R, A, F, Q> Batch<'a, N, R, A, F, Q> {
    #[inline(always)]
    fn new(bvh: &'a BvhN<N>, count: usize, ray: R, answer: A, test: F) -> Self {
        Self {
            bvh,
            count,
            ray,
            answer,
            test,
            counter: (),
            query: PhantomData,
        }
    }

    /// The batch, reporting its work to `counter`.
    #[inline(always)]
    fn counted<C>(self, counter: C) -> Batch<'a, N, R, A, F, Q, C> {
        let Self {
            bvh,
            count,
            ray,
            answer,
            test,
            query,
            ..
        } = self;
        Batch {
            bvh,
            count,
            ray,
            answer,
            test,
            counter,
            query,
        }
    }
}

/// Runs `$body` with `$leaves` bound to the tree's leaves as its layout stores them — kept
/// shapes, triangle packs (tested by the pack kernel `$kernel`) or primitives the
/// caller's `$test` alone tests — so that each query is compiled once for each kind.
macro_rules! with_leaves {
    ($bvh:expr, $test:expr, $kernel:ty, |$leaves:ident| $body:expr) => {{
        let (bvh, test) = ($bvh, $test);
        if bvh.has_shape_leaves() {
            let $leaves = ShapeLeaves {
                prims: &bvh.prim_indices,
                shapes: &bvh.shapes,
                test,
            };
            $body
        } else if bvh.packs.is_empty() {
            let $leaves = ClosureLeaves {
                prims: &bvh.prim_indices,
                test,
            };
            $body
        } else if bvh.triangle_test == TriangleTest::Fast {
            let $leaves = PackedLeaves::<<$kernel as crate::triangle::PackKernel>::Fast, _>::new(
                &bvh.packs, test,
            );
            $body
        } else {
            let $leaves = PackedLeaves::<$kernel, _>::new(&bvh.packs, test);
            $body
        }
    }};
}

/// Closest hits, ray by ray ([`BvhN::intersect_each`]).
struct ClosestOneByOne;
/// Closest hits in packets ([`BvhN::intersect_coherent`]).
struct ClosestInPackets;
/// Occlusion, ray by ray ([`BvhN::occluded_each`]).
struct AnyOneByOne;
/// Occlusion in packets ([`BvhN::occluded_coherent`]).
struct AnyInPackets;

impl<const N: usize, R, A, F, P, C> Query<N> for Batch<'_, N, R, A, F, ClosestOneByOne, &mut C>
where
    R: FnMut(usize) -> Ray,
    A: FnMut(usize, Option<Hit>),
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
    C: TraversalCounter,
{
    type Out = ();

    #[inline(always)]
    unsafe fn run<K: kernels::NodeKernel<N>, T: crate::triangle::PackKernel>(self) {
        let Self {
            bvh,
            count,
            ray,
            mut answer,
            test,
            counter,
            ..
        } = self;
        if bvh.nodes.is_empty() {
            return (0..count).for_each(|i| answer(i, None));
        }
        let nodes = bvh.walk_nodes();
        // SAFETY: the caller guarantees the instruction sets.
        with_leaves!(bvh, test, T, |leaves| unsafe {
            closest_each::<N, K, _, _>(nodes, count, ray, answer, leaves, counter)
        })
    }
}

impl<const N: usize, R, A, F, P> Query<N> for Batch<'_, N, R, A, F, ClosestInPackets>
where
    R: FnMut(usize) -> Ray,
    A: FnMut(usize, Option<Hit>),
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
{
    type Out = ();

    #[inline(always)]
    unsafe fn run<K: kernels::NodeKernel<N>, T: crate::triangle::PackKernel>(mut self) {
        let bvh = self.bvh;
        let mut rays = [Ray::new(Vec3::ZERO, Vec3::X, 0.0, 0.0); PACKET];
        for start in (0..self.count).step_by(PACKET) {
            let rays = &mut rays[..PACKET.min(self.count - start)];
            for (lane, ray) in rays.iter_mut().enumerate() {
                *ray = (self.ray)(start + lane);
            }
            // SAFETY: the caller guarantees the instruction sets.
            let (hits, _) = unsafe { bvh.walk_packet::<K, T, _, _, false>(rays, &mut self.test) };
            for (lane, hit) in hits.into_iter().take(rays.len()).enumerate() {
                (self.answer)(start + lane, hit);
            }
        }
    }
}

impl<const N: usize, R, A, F> Query<N> for Batch<'_, N, R, A, F, AnyOneByOne>
where
    R: FnMut(usize) -> Ray,
    A: FnMut(usize, bool),
    F: FnMut(u32, &Ray) -> bool,
{
    type Out = ();

    #[inline(always)]
    unsafe fn run<K: kernels::NodeKernel<N>, T: crate::triangle::PackKernel>(self) {
        let Self {
            bvh,
            count,
            ray,
            mut answer,
            test,
            ..
        } = self;
        if bvh.nodes.is_empty() {
            return (0..count).for_each(|i| answer(i, false));
        }
        let nodes = bvh.walk_nodes();
        // SAFETY: the caller guarantees the instruction sets.
        with_leaves!(bvh, test, T, |leaves| unsafe {
            any_each::<N, K, _>(nodes, count, ray, answer, leaves)
        })
    }
}

impl<const N: usize, R, A, F> Query<N> for Batch<'_, N, R, A, F, AnyInPackets>
where
    R: FnMut(usize) -> Ray,
    A: FnMut(usize, bool),
    F: FnMut(u32, &Ray) -> bool,
{
    type Out = ();

    #[inline(always)]
    unsafe fn run<K: kernels::NodeKernel<N>, T: crate::triangle::PackKernel>(mut self) {
        let bvh = self.bvh;
        // The packet leaves offer hits: a blocker is one at the end of the ray's range,
        // and the lane stops there.
        let test = &mut self.test;
        let mut blocker = |prim: u32, ray: &Ray| test(prim, ray).then_some(ray.t_max);
        let mut rays = [Ray::new(Vec3::ZERO, Vec3::X, 0.0, 0.0); PACKET];
        for start in (0..self.count).step_by(PACKET) {
            let rays = &mut rays[..PACKET.min(self.count - start)];
            for (lane, ray) in rays.iter_mut().enumerate() {
                *ray = (self.ray)(start + lane);
            }
            // SAFETY: the caller guarantees the instruction sets.
            let (_, blocked) = unsafe { bvh.walk_packet::<K, T, _, _, true>(rays, &mut blocker) };
            for lane in 0..rays.len() {
                (self.answer)(start + lane, blocked >> lane & 1 == 1);
            }
        }
    }
}

struct EveryHitQuery<'a, const N: usize, F, H> {
    bvh: &'a BvhN<N>,
    rays: &'a [Ray],
    test: F,
    found: H,
}

impl<const N: usize, F, P, H> Query<N> for EveryHitQuery<'_, N, F, H>
where
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
    H: FnMut(usize, Hit, Option<[Vec3; 3]>),
{
    type Out = ();

    #[inline(always)]
    unsafe fn run<K: kernels::NodeKernel<N>, T: crate::triangle::PackKernel>(self) {
        let Self {
            bvh,
            rays,
            test,
            found,
        } = self;
        let nodes = bvh.walk_nodes();
        with_leaves!(bvh, test, T, |leaves| {
            let mut every = EveryHit {
                leaves,
                found,
                ray: 0,
            };
            // SAFETY: the caller guarantees the instruction sets.
            unsafe { every_each::<N, K, _, _>(nodes, rays.len(), |i| rays[i], &mut every) };
        })
    }
}
