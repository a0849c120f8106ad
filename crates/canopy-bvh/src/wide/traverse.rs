//! Closest-hit and any-hit traversal of a wide BVH, written once over the node kernel
//! (the box test of all slots) and the leaf test (a closure per primitive, or triangle
//! packs plus the closure for other primitives). [`dispatch`] picks the kernels for an
//! instruction set and runs the query inside a function compiled for it.

use super::kernels::{NodeKernel, OctRay, ScalarNode};
use super::packet::{lane_mask, Lanes, PacketRays, PACKET};
use super::WideNode;
use crate::shapes::{intersect_box, ShapeRecord};
use crate::traverse::{TraversalCounter, TraversalStack};
use crate::triangle::{
    triangle_lanes, PackHits, PackKernel, PackRay, ScalarPack, TrianglePack, PACK_LANES, PAIR_LANES,
};
use crate::{Aabb, Hit, IntoHit, Isa, KnownShape, PrimHit, Ray};
use glam::Vec3;
use std::marker::PhantomData;

/// The closest-hit search state: the ray, its `t_max` shrunk to the best hit so far.
#[derive(Clone, Copy)]
pub(crate) struct Closest {
    pub ray: Ray,
    pub best: Option<Hit>,
}

impl Closest {
    /// Keeps `hit` if it comes before the best so far (ties to the lower index).
    #[inline(always)]
    fn offer(&mut self, hit: Hit) {
        if self.best.is_none_or(|b| hit.is_before(&b)) {
            self.ray.t_max = hit.t;
            self.best = Some(hit);
        }
    }
}

/// Tests the primitives of a leaf: `count` entries from position `first` of the tree's
/// leaf-ordered primitive array.
pub(crate) trait ClosestLeaves {
    /// The next leaves tested are for another ray (a packet's next lane): forget what
    /// was prepared for the last one.
    #[inline(always)]
    fn new_ray(&mut self) {}

    fn closest<C: TraversalCounter>(
        &mut self,
        first: u32,
        count: u32,
        search: &mut Closest,
        counter: &mut C,
    );

    /// [`ClosestLeaves::closest`] where the leaf's test holds no call, and `true`;
    /// otherwise `false`, having counted nothing and offered at most hits that
    /// [`ClosestLeaves::closest`] will offer again (offering a hit twice changes
    /// nothing). The walk tests leaves by this in a loop with no call, so that the
    /// compiler keeps the ray in registers through it (see [`closest_from`]).
    #[inline(always)]
    fn closest_without_call<C: TraversalCounter>(
        &mut self,
        first: u32,
        count: u32,
        search: &mut Closest,
        counter: &mut C,
    ) -> bool {
        self.closest(first, count, search, counter);
        true
    }
}

/// Leaves tested for the rays of a packet ([`super::packet`]).
pub(crate) trait PacketLeaves {
    /// Tests the leaf of `count` entries at `first` for the rays in `lanes`, each against
    /// its `t_max`, keeping its closest hit in `best` (and its `t_max` shrunk to it).
    fn closest_lanes(
        &mut self,
        first: u32,
        count: u32,
        lanes: Lanes,
        t_max: &mut [f32; PACKET],
        best: &mut [Option<Hit>; PACKET],
    );

    /// Walks one of the packet's rays on alone through the subtree `start` (once too few
    /// remain to share the nodes' tests): [`closest_from`] over these leaves tested ray
    /// by ray.
    ///
    /// # Safety
    /// As [`closest_from`].
    unsafe fn closest_alone<const N: usize, K: NodeKernel<N>>(
        &mut self,
        nodes: WalkNodes<'_, N>,
        start: (u32, u32),
        search: Closest,
        walk: &mut AloneWalk,
    ) -> Closest;

    /// Whether anything in the subtree `start` blocks `ray` ([`any_from`], as
    /// [`PacketLeaves::closest_alone`]): the caller's test blocks where it offers a hit.
    ///
    /// # Safety
    /// As [`closest_from`].
    unsafe fn any_alone<const N: usize, K: NodeKernel<N>>(
        &mut self,
        nodes: WalkNodes<'_, N>,
        start: (u32, u32),
        ray: &Ray,
        walk: &mut AloneWalk,
    ) -> bool;
}

/// What a packet's rays walking on alone share: their stacks.
pub(crate) struct AloneWalk {
    pub closest: ClosestStack,
    pub any: AnyStack,
}

impl AloneWalk {
    /// With room on both stacks for a walk of `nodes`.
    #[inline(always)]
    pub fn new<const N: usize>(nodes: WalkNodes<'_, N>) -> Self {
        Self {
            closest: nodes.stack(),
            any: nodes.stack(),
        }
    }
}

pub(crate) trait AnyLeaves {
    /// As [`ClosestLeaves::new_ray`].
    #[inline(always)]
    fn new_ray(&mut self) {}

    fn any(&mut self, first: u32, count: u32, ray: &Ray) -> bool;

    /// [`AnyLeaves::any`] where the leaf's test holds no call; otherwise `None` (see
    /// [`ClosestLeaves::closest_without_call`]).
    #[inline(always)]
    fn any_without_call(&mut self, first: u32, count: u32, ray: &Ray) -> Option<bool> {
        Some(self.any(first, count, ray))
    }
}

/// Leaves whose data can be fetched ahead of their test.
pub(crate) trait PrefetchLeaves {
    /// Where the leaf at position `first` starts in memory: an address to prefetch, never
    /// read through (made with wrapping arithmetic, so any `first` is sound).
    fn leaf_start(&self, first: u32) -> *const u8;
}

/// Starts loading `LINES` cache lines from `start` (a hint: it never faults and has no
/// effect on results).
#[inline(always)]
fn prefetch_lines<const LINES: usize>(start: *const u8) {
    #[cfg(target_arch = "x86_64")]
    for line in 0..LINES {
        // SAFETY: SSE is baseline x86-64, and a prefetch reads nothing the program sees.
        unsafe {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                start.wrapping_add(64 * line).cast(),
            )
        };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = start;
}

impl<F> PrefetchLeaves for ClosureLeaves<'_, F> {
    #[inline(always)]
    fn leaf_start(&self, first: u32) -> *const u8 {
        self.prims.as_ptr().wrapping_add(first as usize).cast()
    }
}

impl<T, F> PrefetchLeaves for PackedLeaves<'_, T, F> {
    #[inline(always)]
    fn leaf_start(&self, first: u32) -> *const u8 {
        // Leaves start on a pack.
        let pack = first as usize / PACK_LANES;
        self.packs.as_ptr().wrapping_add(pack).cast()
    }
}

/// Leaves whose primitives are all tested by the caller's closure.
pub(crate) struct ClosureLeaves<'a, F> {
    pub prims: &'a [u32],
    pub test: F,
}

impl<F, P> ClosestLeaves for ClosureLeaves<'_, F>
where
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
{
    #[inline(always)]
    fn closest<C: TraversalCounter>(&mut self, first: u32, count: u32, s: &mut Closest, c: &mut C) {
        let first = first as usize;
        for &prim in &self.prims[first..first + count as usize] {
            c.test_primitive();
            if let Some(hit) = (self.test)(prim, &s.ray) {
                s.offer(hit.into_hit(prim));
            }
        }
    }
}

impl<F: FnMut(u32, &Ray) -> bool> AnyLeaves for ClosureLeaves<'_, F> {
    #[inline(always)]
    fn any(&mut self, first: u32, count: u32, ray: &Ray) -> bool {
        let first = first as usize;
        self.prims[first..first + count as usize]
            .iter()
            .any(|&prim| (self.test)(prim, ray))
    }
}

/// Leaves whose shapes are stored beside them ([`super::BvhN::store_shapes`]) and
/// tested here; any other primitive goes to the caller's closure.
pub(crate) struct ShapeLeaves<'a, F> {
    pub prims: &'a [u32],
    /// The kept shape (or none) at each position of `prims`.
    pub shapes: &'a [ShapeRecord],
    pub test: F,
}

impl<F> PrefetchLeaves for ShapeLeaves<'_, F> {
    #[inline(always)]
    fn leaf_start(&self, first: u32) -> *const u8 {
        self.shapes.as_ptr().wrapping_add(first as usize).cast()
    }
}

impl<F, P> ClosestLeaves for ShapeLeaves<'_, F>
where
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
{
    #[inline(always)]
    fn closest<C: TraversalCounter>(&mut self, first: u32, count: u32, s: &mut Closest, c: &mut C) {
        let range = first as usize..(first + count) as usize;
        for (&prim, shape) in self.prims[range.clone()].iter().zip(&self.shapes[range]) {
            c.test_primitive();
            if shape.is_kept() {
                if let Some(t) = shape.intersect(&s.ray) {
                    s.offer(t.into_hit(prim));
                }
            } else if let Some(hit) = (self.test)(prim, &s.ray) {
                s.offer(hit.into_hit(prim));
            }
        }
    }
}

impl<F, P> PacketLeaves for ShapeLeaves<'_, F>
where
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
{
    /// Each kept shape against all the packet's rays at once; anything else one ray at a
    /// time.
    #[inline(always)]
    fn closest_lanes(
        &mut self,
        first: u32,
        count: u32,
        lanes: Lanes,
        t_max: &mut [f32; PACKET],
        best: &mut [Option<Hit>; PACKET],
    ) {
        for position in first as usize..(first + count) as usize {
            let prim = self.prims[position];
            let Some(shape) = self.shapes[position].0 else {
                // Kept for completeness: the tree sends packets here only where every
                // entry is kept (`BvhN::traces_packets`).
                let mut single = ClosureLeaves {
                    prims: self.prims,
                    test: &mut self.test,
                };
                lanes.each(&mut single, position as u32, 1, t_max, best);
                continue;
            };
            shape_packet(shape, prim, &lanes, t_max, best);
        }
    }

    #[inline(always)]
    unsafe fn closest_alone<const N: usize, K: NodeKernel<N>>(
        &mut self,
        nodes: WalkNodes<'_, N>,
        start: (u32, u32),
        search: Closest,
        walk: &mut AloneWalk,
    ) -> Closest {
        let mut single = ShapeLeaves {
            prims: self.prims,
            shapes: self.shapes,
            test: &mut self.test,
        };
        // SAFETY: the caller's guarantee.
        unsafe {
            closest_from::<N, K, _, _>(
                nodes,
                start,
                search,
                &mut single,
                &mut (),
                &mut walk.closest,
            )
        }
    }

    #[inline(always)]
    unsafe fn any_alone<const N: usize, K: NodeKernel<N>>(
        &mut self,
        nodes: WalkNodes<'_, N>,
        start: (u32, u32),
        ray: &Ray,
        walk: &mut AloneWalk,
    ) -> bool {
        let test = &mut self.test;
        let mut single = ShapeLeaves {
            prims: self.prims,
            shapes: self.shapes,
            test: |prim: u32, ray: &Ray| test(prim, ray).is_some(),
        };
        // SAFETY: the caller's guarantee.
        unsafe { any_from::<N, K, _>(nodes, start, ray, &mut single, &mut walk.any) }
    }
}

/// Keeps `hit` as `lane`'s closest if it comes before the best so far (ties to the lower
/// index), shrinking the lane's range to it.
#[inline(always)]
pub(crate) fn offer_lane(
    lane: usize,
    hit: Hit,
    t_max: &mut [f32; PACKET],
    best: &mut [Option<Hit>; PACKET],
) {
    if best[lane].is_none_or(|b| hit.is_before(&b)) {
        (t_max[lane], best[lane]) = (hit.t, Some(hit));
    }
}

/// Tests the kept shape of leaf entry `prim` against the rays in `lanes` at once, keeping
/// each ray's closest hit.
#[inline(always)]
pub(crate) fn shape_packet(
    shape: KnownShape,
    prim: u32,
    lanes: &Lanes,
    t_max: &mut [f32; PACKET],
    best: &mut [Option<Hit>; PACKET],
) {
    let t = match shape {
        KnownShape::Sphere { center, radius } => shape_lanes(center, radius, lanes.packet, t_max),
        KnownShape::Box(b) => box_lanes(b, lanes.packet, t_max),
    };
    let mut hit = [false; PACKET];
    for (hit, t) in hit.iter_mut().zip(&t) {
        *hit = !t.is_nan();
    }
    for lane in self::lanes(lane_mask(&hit) & lanes.active) {
        offer_lane(lane, t[lane].into_hit(prim), t_max, best);
    }
}

/// Distance to box `b` of every ray of `packet` (NaN where it misses or falls outside the
/// ray's range): [`crate::intersect_box`] lane by lane, so the same distances.
#[inline(always)]
fn box_lanes(b: Aabb, packet: &PacketRays, t_max: &[f32; PACKET]) -> [f32; PACKET] {
    let mut distance = [f32::NAN; PACKET];
    for (lane, distance) in distance.iter_mut().enumerate() {
        let origin = Vec3::from_array([0, 1, 2].map(|axis| packet.origin[axis][lane]));
        let inv_dir = Vec3::from_array([0, 1, 2].map(|axis| packet.inv[axis][lane]));
        let (t_min, t_max) = (packet.t_min[lane], t_max[lane]);
        if let Some(t) = intersect_box(b.min, b.max, origin, inv_dir, t_min, t_max) {
            *distance = t;
        }
    }
    distance
}

/// Distance to the sphere of every ray of `packet` (NaN where it misses or falls outside the
/// ray's range): [`crate::intersect_sphere`] lane by lane, the same operations in the same
/// order, so the same distances.
#[inline(always)]
fn shape_lanes(
    center: Vec3,
    radius: f32,
    packet: &PacketRays,
    t_max: &[f32; PACKET],
) -> [f32; PACKET] {
    let [cx, cy, cz] = center.to_array();
    let r2 = radius * radius;
    // A loop, not `array::from_fn`: its closure would be compiled apart, without the
    // dispatch's vector instructions.
    let mut distance = [f32::NAN; PACKET];
    for (lane, distance) in distance.iter_mut().enumerate() {
        let d = [0, 1, 2].map(|axis| packet.dir[axis][lane]);
        let o = [0, 1, 2].map(|axis| packet.origin[axis][lane]);
        let f = [o[0] - cx, o[1] - cy, o[2] - cz];
        let a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let b = -(f[0] * d[0] + f[1] * d[1] + f[2] * d[2]);
        let along = b / a;
        let to_line = [0, 1, 2].map(|axis| f[axis] + along * d[axis]);
        let line2 = to_line[0] * to_line[0] + to_line[1] * to_line[1] + to_line[2] * to_line[2];
        let discriminant = r2 - line2;
        let c = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]) - r2;
        let q = b + b.signum() * (a * discriminant).sqrt();
        let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (c / q, q / a) };
        let (near, far) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
        let in_range = |t: f32| t >= packet.t_min[lane] && t <= t_max[lane];
        let t = if in_range(near) {
            near
        } else if in_range(far) {
            far
        } else {
            f32::NAN
        };
        if discriminant >= 0.0 {
            *distance = t;
        }
    }
    distance
}

impl<F: FnMut(u32, &Ray) -> bool> AnyLeaves for ShapeLeaves<'_, F> {
    #[inline(always)]
    fn any(&mut self, first: u32, count: u32, ray: &Ray) -> bool {
        let range = first as usize..(first + count) as usize;
        for (&prim, shape) in self.prims[range.clone()].iter().zip(&self.shapes[range]) {
            let blocked = match shape.is_kept() {
                true => shape.intersect(ray).is_some(),
                false => (self.test)(prim, ray),
            };
            if blocked {
                return true;
            }
        }
        false
    }
}

/// Leaves stored as triangle packs: triangles by the pack kernel `T`, other primitives
/// by the caller's closure.
pub(crate) struct PackedLeaves<'a, T, F> {
    pub packs: &'a [TrianglePack],
    /// The ray prepared for pack tests, made at the first leaf: a ray that misses every
    /// leaf (most rays past a mesh's silhouette) never pays for it.
    pub ray: Option<PackRay>,
    /// Where closest-hit pack tests write their hits (see [`PackHits`]); any-hit tests
    /// use a scratch record of their own, which measured faster.
    pub hits: PackHits,
    pub test: F,
    pub kernel: PhantomData<T>,
}

impl<'a, T, F> PackedLeaves<'a, T, F> {
    /// Leaves of `packs`, nothing prepared yet.
    #[inline(always)]
    pub fn new(packs: &'a [TrianglePack], test: F) -> Self {
        Self {
            packs,
            ray: None,
            hits: PackHits::default(),
            test,
            kernel: PhantomData,
        }
    }

    /// A `match`, not `Option::get_or_insert_with`, which the compiler once left out of
    /// line: a call in the walk's loop.
    #[inline(always)]
    fn pack_ray(&mut self, ray: &Ray) -> PackRay {
        match self.ray {
            Some(pack_ray) => pack_ray,
            None => *self.ray.insert(PackRay::new(ray)),
        }
    }
}

/// The packs holding `count` leaf entries from position `first` (leaves start on a pack).
#[inline(always)]
pub(crate) fn leaf_packs(packs: &[TrianglePack], first: u32, count: u32) -> &[TrianglePack] {
    let start = first as usize / PACK_LANES;
    &packs[start..start + (count as usize).div_ceil(PACK_LANES)]
}

/// The set bits of `mask`, lowest first.
#[inline(always)]
pub(crate) fn lanes(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let lane = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            lane
        })
    })
}

/// A leaf's packs as pairs tested together (kernels with 8-lane pair tests) and the packs
/// left to test one at a time.
#[inline(always)]
fn pairs_and_rest<T: PackKernel>(
    packs: &[TrianglePack],
) -> (&[[TrianglePack; 2]], &[TrianglePack]) {
    if T::PAIRS {
        packs.as_chunks::<2>()
    } else {
        (&[], packs)
    }
}

/// The triangle lanes of `packs` hit within `[t_min, t_max]`: one pack by `T::test`, a
/// pair by `T::test_pair` (with `HITS`, hits go to `hits`, as those tests say).
///
/// # Safety
/// `T`'s instruction set must be available.
#[inline(always)]
unsafe fn test_packs<T: PackKernel, const HITS: bool, const PACKS: usize>(
    packs: &[TrianglePack; PACKS],
    ray: &PackRay,
    t_min: f32,
    t_max: f32,
    hits: &mut PackHits,
) -> u32 {
    // SAFETY: the caller guarantees the instruction set. `PACKS` is a constant, so the
    // branch is resolved at compile time.
    unsafe {
        match <&[TrianglePack; 2]>::try_from(packs.as_slice()) {
            Ok(pair) => T::test_pair::<HITS>(pair, ray, t_min, t_max, hits),
            Err(_) => T::test::<HITS>(&packs[0], ray, t_min, t_max, hits),
        }
    }
}

/// The kept-shape lanes (spheres and boxes) of `packs` that `ray` hits, as
/// [`test_packs`] gives triangle lanes: one pack by `T::shapes`, a pair by
/// `T::shape_pair`.
///
/// # Safety
/// As [`test_packs`].
#[inline(always)]
unsafe fn test_shapes<T: PackKernel, const PACKS: usize>(
    packs: &[TrianglePack; PACKS],
    ray: &Ray,
    t: &mut [f32; PAIR_LANES],
) -> u32 {
    // SAFETY: as in `test_packs`.
    unsafe {
        match <&[TrianglePack; 2]>::try_from(packs.as_slice()) {
            Ok(pair) => T::shape_pair(pair, ray, t),
            Err(_) => T::shapes(&packs[0], ray, t),
        }
    }
}

/// [`test_packs`] by [`PackKernel::test_unrefined`]: the lanes hit, and those left to
/// refine.
///
/// # Safety
/// As [`test_packs`].
#[inline(always)]
unsafe fn test_packs_unrefined<T: PackKernel, const HITS: bool, const PACKS: usize>(
    packs: &[TrianglePack; PACKS],
    ray: &PackRay,
    t_min: f32,
    t_max: f32,
    hits: &mut PackHits,
) -> (u32, u32) {
    // SAFETY: as in `test_packs`.
    unsafe {
        match <&[TrianglePack; 2]>::try_from(packs.as_slice()) {
            Ok(pair) => T::test_pair_unrefined::<HITS>(pair, ray, t_min, t_max, hits),
            Err(_) => T::test_unrefined::<HITS>(&packs[0], ray, t_min, t_max, hits),
        }
    }
}

impl<T, F, P> PackedLeaves<'_, T, F>
where
    T: PackKernel,
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
{
    /// Offers the hits of one pack or a pair tested together without a call: `false`
    /// where a lane is neither a triangle nor a kept shape, or is left to refine.
    #[inline(always)]
    fn closest_triangle_packs<const PACKS: usize>(
        &mut self,
        packs: &[TrianglePack; PACKS],
        pack_ray: &PackRay,
        s: &mut Closest,
    ) -> bool {
        // Packs of triangles alone (a mesh's) take the triangle test and nothing else.
        if packs.iter().any(|pack| pack.others != 0) {
            if packs
                .iter()
                .any(|pack| pack.others != (pack.spheres | pack.boxes))
            {
                return false;
            }
            let mut t = [0.0; PAIR_LANES];
            // SAFETY: `dispatch` runs this only where `T`'s instruction set exists.
            for lane in lanes(unsafe { test_shapes::<T, PACKS>(packs, &s.ray, &mut t) }) {
                let prim = packs[lane / PACK_LANES].prim[lane % PACK_LANES];
                s.offer(Hit::new(prim, PrimHit::from(t[lane])));
            }
            if triangle_lanes(packs) == 0 {
                return true;
            }
        }
        let hits = &mut self.hits;
        // SAFETY: `dispatch` runs this only where `T`'s instruction set exists.
        let (mask, refine) = unsafe {
            test_packs_unrefined::<T, true, PACKS>(
                packs,
                pack_ray,
                pack_ray.t_min,
                s.ray.t_max,
                hits,
            )
        };
        for lane in lanes(mask) {
            let prim = packs[lane / PACK_LANES].prim[lane % PACK_LANES];
            s.offer(Hit::new(prim, hits.lane(lane)));
        }
        refine == 0
    }

    /// Offers the hits of one pack or a pair tested together: triangles by the kernel,
    /// other primitives by the caller's closure.
    #[inline(always)]
    fn closest_packs<C: TraversalCounter, const PACKS: usize>(
        &mut self,
        packs: &[TrianglePack; PACKS],
        pack_ray: &PackRay,
        s: &mut Closest,
        c: &mut C,
    ) {
        let triangles = triangle_lanes(packs);
        if triangles != 0 {
            for _ in 0..triangles.count_ones() {
                c.test_primitive();
            }
            let hits = &mut self.hits;
            // SAFETY: `dispatch` runs this only where `T`'s instruction set exists.
            let mask = unsafe {
                test_packs::<T, true, PACKS>(packs, pack_ray, pack_ray.t_min, s.ray.t_max, hits)
            };
            for lane in lanes(mask) {
                let prim = packs[lane / PACK_LANES].prim[lane % PACK_LANES];
                s.offer(Hit::new(prim, hits.lane(lane)));
            }
        }
        for pack in packs {
            if pack.others != 0 {
                closest_others(pack, &mut self.test, s, c);
            }
        }
    }
}

/// Offers the hits of a pack's lanes that are not triangles: the shapes kept in their
/// lanes, the rest by the caller's closure. Out of line and cold: packed trees are built
/// over meshes of (nearly) only triangles, and inlined, its loop-invariant work (a
/// sphere test's `|d|²`) was hoisted into every ray's set-up.
#[cold]
#[inline(never)]
fn closest_others<F, P, C>(pack: &TrianglePack, test: &mut F, s: &mut Closest, c: &mut C)
where
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
    C: TraversalCounter,
{
    for lane in lanes(pack.others) {
        c.test_primitive();
        let prim = pack.prim[lane];
        let hit = match pack.kept(lane) {
            Some(shape) => shape.intersect(&s.ray).map(|t| t.into_hit(prim)),
            None => test(prim, &s.ray).map(|hit| hit.into_hit(prim)),
        };
        if let Some(hit) = hit {
            s.offer(hit);
        }
    }
}

impl<T, F, P> ClosestLeaves for PackedLeaves<'_, T, F>
where
    T: PackKernel,
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
{
    #[inline(always)]
    fn new_ray(&mut self) {
        self.ray = None;
    }

    #[inline(always)]
    fn closest<C: TraversalCounter>(&mut self, first: u32, count: u32, s: &mut Closest, c: &mut C) {
        let pack_ray = self.pack_ray(&s.ray);
        let (pairs, rest) = pairs_and_rest::<T>(leaf_packs(self.packs, first, count));
        for pair in pairs {
            self.closest_packs(pair, &pack_ray, s, c);
        }
        for pack in rest {
            self.closest_packs(std::array::from_ref(pack), &pack_ray, s, c);
        }
    }

    #[inline(always)]
    fn closest_without_call<C: TraversalCounter>(
        &mut self,
        first: u32,
        count: u32,
        s: &mut Closest,
        c: &mut C,
    ) -> bool {
        let packs = leaf_packs(self.packs, first, count);
        let pack_ray = self.pack_ray(&s.ray);
        let (pairs, rest) = pairs_and_rest::<T>(packs);
        for pair in pairs {
            if !self.closest_triangle_packs(pair, &pack_ray, s) {
                return false;
            }
        }
        for pack in rest {
            if !self.closest_triangle_packs(std::array::from_ref(pack), &pack_ray, s) {
                return false;
            }
        }
        for pack in packs {
            for _ in 0..(pack.triangles | pack.spheres | pack.boxes).count_ones() {
                c.test_primitive();
            }
        }
        true
    }
}

impl<T: PackKernel, F: FnMut(u32, &Ray) -> bool> PackedLeaves<'_, T, F> {
    /// Whether anything in one pack or a pair tested together blocks `ray`.
    #[inline(always)]
    fn any_packs<const PACKS: usize>(
        &mut self,
        packs: &[TrianglePack; PACKS],
        pack_ray: &PackRay,
        ray: &Ray,
        scratch: &mut PackHits,
    ) -> bool {
        // SAFETY: as above.
        if triangle_lanes(packs) != 0
            && unsafe {
                test_packs::<T, false, PACKS>(packs, pack_ray, ray.t_min, ray.t_max, scratch)
            } != 0
        {
            return true;
        }
        packs
            .iter()
            .any(|pack| pack.others != 0 && any_other(pack, &mut self.test, ray))
    }
}

/// Whether a pack's lanes that are not triangles block `ray` (see [`closest_others`]).
#[cold]
#[inline(never)]
fn any_other<F: FnMut(u32, &Ray) -> bool>(pack: &TrianglePack, test: &mut F, ray: &Ray) -> bool {
    lanes(pack.others).any(|lane| match pack.kept(lane) {
        Some(shape) => shape.intersect(ray).is_some(),
        None => test(pack.prim[lane], ray),
    })
}

impl<T: PackKernel, F: FnMut(u32, &Ray) -> bool> AnyLeaves for PackedLeaves<'_, T, F> {
    #[inline(always)]
    fn new_ray(&mut self) {
        self.ray = None;
    }

    #[inline(always)]
    fn any(&mut self, first: u32, count: u32, ray: &Ray) -> bool {
        let pack_ray = self.pack_ray(ray);
        let mut scratch = PackHits::default();
        let (pairs, rest) = pairs_and_rest::<T>(leaf_packs(self.packs, first, count));
        // Loops, not closures: a closure that holds an 8-lane test and is not inlined
        // would be compiled without AVX and call every intrinsic.
        for pair in pairs {
            if self.any_packs(pair, &pack_ray, ray, &mut scratch) {
                return true;
            }
        }
        for pack in rest {
            if self.any_packs(std::array::from_ref(pack), &pack_ray, ray, &mut scratch) {
                return true;
            }
        }
        false
    }

    #[inline(always)]
    fn any_without_call(&mut self, first: u32, count: u32, ray: &Ray) -> Option<bool> {
        let packs = leaf_packs(self.packs, first, count);
        let pack_ray = self.pack_ray(ray);
        let mut scratch = PackHits::default();
        let (pairs, rest) = pairs_and_rest::<T>(packs);
        // A lane hit is a blocker whether or not others are left to refine.
        let mut refine = 0;
        for pair in pairs {
            match any_triangle_packs::<T, 2>(pair, &pack_ray, ray, &mut scratch)? {
                (0, left) => refine |= left,
                _ => return Some(true),
            }
        }
        for pack in rest {
            let pack = std::array::from_ref(pack);
            match any_triangle_packs::<T, 1>(pack, &pack_ray, ray, &mut scratch)? {
                (0, left) => refine |= left,
                _ => return Some(true),
            }
        }
        (refine == 0).then_some(false)
    }
}

/// The lanes of one pack or a pair tested together that block `ray`, and those left to
/// refine, without a call; `None` where a lane is neither a triangle nor a kept shape.
#[inline(always)]
fn any_triangle_packs<T: PackKernel, const PACKS: usize>(
    packs: &[TrianglePack; PACKS],
    pack_ray: &PackRay,
    ray: &Ray,
    scratch: &mut PackHits,
) -> Option<(u32, u32)> {
    // Packs of triangles alone (a mesh's) take the triangle test and nothing else.
    if packs.iter().any(|pack| pack.others != 0) {
        if packs
            .iter()
            .any(|pack| pack.others != (pack.spheres | pack.boxes))
        {
            return None;
        }
        let mut t = [0.0; PAIR_LANES];
        // SAFETY: `dispatch` runs this only where `T`'s instruction set exists.
        let blocked = unsafe { test_shapes::<T, PACKS>(packs, ray, &mut t) };
        if blocked != 0 || triangle_lanes(packs) == 0 {
            return Some((blocked, 0));
        }
    }
    // SAFETY: `dispatch` runs this only where `T`'s instruction set exists.
    Some(unsafe {
        test_packs_unrefined::<T, false, PACKS>(packs, pack_ray, ray.t_min, ray.t_max, scratch)
    })
}

/// Leaves of an every-hit walk: [`any`] over leaves that never report a blocker, so
/// that every leaf whose box the ray's range passes through is tested, and each hit in
/// them goes to `found`, with the triangle's vertices where the leaf holds them (a
/// pack's lane, already in the cache: the caller need not fetch them from the mesh).
pub(crate) struct EveryHit<L, H> {
    pub leaves: L,
    /// Takes each hit as `found(ray, hit, vertices)`.
    pub found: H,
    /// Which ray of a batch is walked.
    pub ray: usize,
}

impl<L: PrefetchLeaves, H> PrefetchLeaves for EveryHit<L, H> {
    #[inline(always)]
    fn leaf_start(&self, first: u32) -> *const u8 {
        self.leaves.leaf_start(first)
    }
}

impl<F, P, H> AnyLeaves for EveryHit<ClosureLeaves<'_, F>, H>
where
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
    H: FnMut(usize, Hit, Option<[Vec3; 3]>),
{
    #[inline(always)]
    fn any(&mut self, first: u32, count: u32, ray: &Ray) -> bool {
        let leaves = &mut self.leaves;
        let first = first as usize;
        for &prim in &leaves.prims[first..first + count as usize] {
            if let Some(hit) = (leaves.test)(prim, ray) {
                (self.found)(self.ray, hit.into_hit(prim), None);
            }
        }
        false
    }
}

impl<F, P, H> AnyLeaves for EveryHit<ShapeLeaves<'_, F>, H>
where
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
    H: FnMut(usize, Hit, Option<[Vec3; 3]>),
{
    #[inline(always)]
    fn any(&mut self, first: u32, count: u32, ray: &Ray) -> bool {
        let leaves = &mut self.leaves;
        let range = first as usize..(first + count) as usize;
        for (&prim, shape) in leaves.prims[range.clone()]
            .iter()
            .zip(&leaves.shapes[range])
        {
            let hit = match shape.is_kept() {
                true => shape.intersect(ray).map(|t| t.into_hit(prim)),
                false => (leaves.test)(prim, ray).map(|hit| hit.into_hit(prim)),
            };
            if let Some(hit) = hit {
                (self.found)(self.ray, hit, None);
            }
        }
        false
    }
}

impl<T, F, P, H> EveryHit<PackedLeaves<'_, T, F>, H>
where
    T: PackKernel,
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
    H: FnMut(usize, Hit, Option<[Vec3; 3]>),
{
    /// Reports the hits in one pack or a pair tested together.
    #[inline(always)]
    fn every_in_packs<const PACKS: usize>(
        &mut self,
        packs: &[TrianglePack; PACKS],
        pack_ray: &PackRay,
        ray: &Ray,
    ) {
        let leaves = &mut self.leaves;
        if triangle_lanes(packs) != 0 {
            let hits = &mut leaves.hits;
            // SAFETY: `dispatch` runs this only where `T`'s instruction set exists.
            let mask = unsafe {
                test_packs::<T, true, PACKS>(packs, pack_ray, ray.t_min, ray.t_max, hits)
            };
            for lane in lanes(mask) {
                let (pack, in_pack) = (&packs[lane / PACK_LANES], lane % PACK_LANES);
                let hit = Hit::new(pack.prim[in_pack], hits.lane(lane));
                (self.found)(self.ray, hit, Some(pack.vertices(in_pack)));
            }
        }
        for pack in packs {
            if pack.others != 0 {
                every_other(pack, &mut leaves.test, ray, self.ray, &mut self.found);
            }
        }
    }
}

/// Reports the hits on a pack's lanes that are not triangles (see [`closest_others`]).
#[cold]
#[inline(never)]
fn every_other<F, P, H>(pack: &TrianglePack, test: &mut F, ray: &Ray, index: usize, found: &mut H)
where
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
    H: FnMut(usize, Hit, Option<[Vec3; 3]>),
{
    for lane in lanes(pack.others) {
        let prim = pack.prim[lane];
        let hit = match pack.kept(lane) {
            Some(shape) => shape.intersect(ray).map(|t| t.into_hit(prim)),
            None => test(prim, ray).map(|hit| hit.into_hit(prim)),
        };
        if let Some(hit) = hit {
            found(index, hit, None);
        }
    }
}

impl<T, F, P, H> AnyLeaves for EveryHit<PackedLeaves<'_, T, F>, H>
where
    T: PackKernel,
    F: FnMut(u32, &Ray) -> Option<P>,
    P: IntoHit,
    H: FnMut(usize, Hit, Option<[Vec3; 3]>),
{
    #[inline(always)]
    fn new_ray(&mut self) {
        self.leaves.ray = None;
    }

    #[inline(always)]
    fn any(&mut self, first: u32, count: u32, ray: &Ray) -> bool {
        let pack_ray = self.leaves.pack_ray(ray);
        let packs = self.leaves.packs;
        let (pairs, rest) = pairs_and_rest::<T>(leaf_packs(packs, first, count));
        // Loops, not closures, as in the any-hit test above.
        for pair in pairs {
            self.every_in_packs(pair, &pack_ray, ray);
        }
        for pack in rest {
            self.every_in_packs(std::array::from_ref(pack), &pack_ray, ray);
        }
        false
    }
}

/// A tree's nodes as a walk goes through them, with what every walk of them needs to
/// know: whether it prefetches stacked children and how many entries its stack must have
/// room for. Made by [`super::BvhN::walk_nodes`].
#[derive(Clone, Copy)]
pub(crate) struct WalkNodes<'a, const N: usize> {
    nodes: &'a [WideNode<N>],
    /// Whether to prefetch stacked children (`BvhN::prefetches`).
    prefetch: bool,
    /// The tree's [`super::BvhN::stack_room`].
    stack_room: usize,
}

impl<'a, const N: usize> WalkNodes<'a, N> {
    /// `stack_room` is [`super::BvhN::stack_room`] of the tree of `nodes`: walks make
    /// that much room before they start, and a push past it panics.
    pub fn new(nodes: &'a [WideNode<N>], prefetch: bool, stack_room: usize) -> Self {
        Self {
            nodes,
            prefetch,
            stack_room,
        }
    }

    /// A walk's stack with room for a walk of these nodes (so that its pushes never
    /// allocate: [`TraversalStack::push_in_room`]).
    #[inline(always)]
    pub fn stack<T: Copy>(self) -> TraversalStack<T> {
        TraversalStack::with_room(self.stack_room)
    }

    /// The node at index `child`, without a bounds check (a check and its branch on every
    /// node visit were about 5% of an incoherent ray's instructions).
    ///
    /// # Safety
    /// `child` must be 0 in a non-empty tree or an interior slot's child (`count == 0`):
    /// [`super::BvhN::from_bvh2`] writes every such index in range, and nothing else
    /// writes them (a refit changes boxes only).
    #[inline(always)]
    pub unsafe fn node(self, child: u32) -> &'a WideNode<N> {
        debug_assert!((child as usize) < self.nodes.len());
        // SAFETY: the caller's guarantee.
        unsafe { self.nodes.get_unchecked(child as usize) }
    }

    /// Starts loading a slot's node or leaf: it goes on the stack, and memory latency,
    /// not arithmetic, bounds incoherent rays in a large tree, so its loads overlap the
    /// work until it is popped. Trees that stay in the cache skip it (`prefetch` false).
    #[inline(always)]
    fn prefetch_child<L: PrefetchLeaves>(self, leaves: &L, child: u32, count: u32) {
        if !self.prefetch {
            return;
        }
        // A select, not a branch: whether an entered slot holds a node or a leaf is as
        // hard to predict as which slots a ray enters (a branch here mispredicted 0.8
        // times an incoherent ray). Four lines: a whole 8-wide node, or a leaf's first
        // pack and most of its second.
        let node = self
            .nodes
            .as_ptr()
            .wrapping_add(child as usize)
            .cast::<u8>();
        let start = if count == 0 {
            node
        } else {
            leaves.leaf_start(child)
        };
        prefetch_lines::<4>(start);
    }
}

/// A stack entry: a slot's `child` and `count` (see [`WideNode`]) and its entry distance.
pub(crate) type Entry = (u32, u32, f32);

/// A walk's stack of closest-hit entries, made once for a batch of rays (making one is
/// not free: about 30 instructions a ray, a tenth of a primary ray's).
pub(crate) type ClosestStack = TraversalStack<Entry>;

/// A walk's stack of any-hit entries (see [`ClosestStack`]).
pub(crate) type AnyStack = TraversalStack<(u32, u32)>;

/// Where a walk from the top starts: the root, as a slot's `child` and `count` would
/// name it (see [`WideNode`]).
pub(crate) const ROOT: (u32, u32) = (0, 0);

/// Closest hit, nearest child first. `nodes` is non-empty; `stack` is empty and left so.
///
/// # Safety
/// `K`'s instruction set must be available. `stack` must have room for a walk of
/// `nodes` (made by [`WalkNodes::stack`]), or the walk may panic.
#[inline(always)]
pub(crate) unsafe fn closest<const N: usize, K, L, C>(
    nodes: WalkNodes<'_, N>,
    ray: &Ray,
    leaves: &mut L,
    counter: &mut C,
    stack: &mut ClosestStack,
) -> Option<Hit>
where
    K: NodeKernel<N>,
    L: ClosestLeaves + PrefetchLeaves,
    C: TraversalCounter,
{
    // A NaN or degenerate ray would enter empty slots; it misses everything (see Ray).
    if !ray.is_traceable() {
        return None;
    }
    let search = Closest {
        ray: *ray,
        best: None,
    };
    // SAFETY: the caller's guarantee.
    unsafe { closest_from::<N, K, L, C>(nodes, ROOT, search, leaves, counter, stack) }.best
}

/// The closest-hit walk of `search`'s ray (traceable) through the subtree `start` (a
/// slot's `child` and `count`, or [`ROOT`]), nearest child first: `search` with the
/// closest hit found before its `t_max`, if that comes before its best. `stack` is
/// empty and left so. (By value, not by reference: the search then stays in registers.)
///
/// # Safety
/// `K`'s instruction set must be available; `start` is [`ROOT`] of a non-empty tree or
/// a slot of one of its nodes. `stack` must have room, as [`closest`] says.
#[inline(always)]
pub(crate) unsafe fn closest_from<const N: usize, K, L, C>(
    nodes: WalkNodes<'_, N>,
    start: (u32, u32),
    mut search: Closest,
    leaves: &mut L,
    counter: &mut C,
    stack: &mut ClosestStack,
) -> Closest
where
    K: NodeKernel<N>,
    L: ClosestLeaves + PrefetchLeaves,
    C: TraversalCounter,
{
    let oct = OctRay::new(&search.ray);
    // SAFETY: the caller guarantees the instruction set.
    let kray = unsafe { K::prepare(&oct) };
    let (mut child, mut count) = start;
    // Two loops: the inner one walks nodes and tests the leaves it can without a call;
    // a leaf that needs one (lanes that are not triangles, or to refine) leaves it for
    // the outer one. A call in the inner loop, even one rarely made, had the compiler
    // reload the ray's values from the stack at every node.
    loop {
        loop {
            counter.visit_node();
            if count > 0 {
                if !leaves.closest_without_call(child, count, &mut search, counter) {
                    break;
                }
            } else {
                // SAFETY: `child` is the root or an interior slot's child; the kernel's
                // instruction set is the caller's guarantee.
                let node = unsafe { nodes.node(child) };
                let (mask, t) = unsafe { K::hit_mask(node, &kray, search.ray.t_max) };
                if mask != 0 {
                    let first = mask.trailing_zeros() as usize;
                    let rest = mask & (mask - 1);
                    if rest == 0 {
                        // One slot entered (the common case deep in the tree): descend.
                        (child, count) = (node.child[first], node.count[first]);
                        continue;
                    }
                    if rest & (rest - 1) == 0 {
                        // Two: push the farther, descend into the nearer.
                        let second = rest.trailing_zeros() as usize;
                        let (near, far) = if t[second] < t[first] {
                            (second, first)
                        } else {
                            (first, second)
                        };
                        nodes.prefetch_child(leaves, node.child[far], node.count[far]);
                        stack.push_in_room((node.child[far], node.count[far], t[far]));
                        (child, count) = (node.child[near], node.count[near]);
                        continue;
                    }
                    // More: sort the entered slots far to near (the SIMD kernels through a
                    // sorting network, with no branch to mispredict), push all but the
                    // nearest and descend into it.
                    // SAFETY: the caller guarantees the instruction set.
                    let slots = unsafe { K::far_to_near(mask, &t) };
                    let n = mask.count_ones() as usize;
                    for &slot in &slots[..n - 1] {
                        let slot = slot as usize;
                        let entry = (node.child[slot], node.count[slot], t[slot]);
                        nodes.prefetch_child(leaves, entry.0, entry.1);
                        stack.push_in_room(entry);
                    }
                    let nearest = slots[n - 1] as usize;
                    (child, count) = (node.child[nearest], node.count[nearest]);
                    continue;
                }
            }
            match next_closest(stack, search.ray.t_max) {
                None => return search,
                Some(entry) => (child, count) = entry,
            }
        }
        rarely_taken();
        leaves.closest(child, count, &mut search, counter);
        match next_closest(stack, search.ray.t_max) {
            None => return search,
            Some(entry) => (child, count) = entry,
        }
    }
}

/// Tells the compiler that the path calling it is rarely taken, so that it keeps the
/// walk's values in registers elsewhere and spills them on this path (1-5% of an
/// occlusion walk's time measured on an Intel Xeon, model 207). `std::hint::cold_path`
/// exists from Rust 1.95, above the crate's MSRV; older compilers get no hint.
#[rustversion::since(1.95)]
#[inline(always)]
#[allow(clippy::incompatible_msrv)] // compiled only where it exists
fn rarely_taken() {
    std::hint::cold_path();
}

#[rustversion::before(1.95)]
#[inline(always)]
fn rarely_taken() {}

/// Pops the next subtree that can still hold a hit closer than (or as close as) `t_max`.
#[inline(always)]
fn next_closest(stack: &mut ClosestStack, t_max: f32) -> Option<(u32, u32)> {
    loop {
        match stack.pop()? {
            (child, count, t_entry) if t_entry <= t_max => return Some((child, count)),
            _ => {}
        }
    }
}

/// Whether anything blocks `ray`; stops at the first hit. `nodes` is non-empty; `stack`
/// is left empty.
///
/// # Safety
/// As [`closest`].
#[inline(always)]
pub(crate) unsafe fn any<const N: usize, K, L>(
    nodes: WalkNodes<'_, N>,
    ray: &Ray,
    leaves: &mut L,
    stack: &mut AnyStack,
) -> bool
where
    K: NodeKernel<N>,
    L: AnyLeaves + PrefetchLeaves,
{
    if !ray.is_traceable() {
        return false;
    }
    // SAFETY: the caller's guarantee.
    unsafe { any_from::<N, K, L>(nodes, ROOT, ray, leaves, stack) }
}

/// Whether anything in the subtree `start` (as [`closest_from`] takes it) blocks `ray`
/// (traceable); stops at the first hit. `stack` is left empty.
///
/// # Safety
/// As [`closest_from`].
#[inline(always)]
pub(crate) unsafe fn any_from<const N: usize, K, L>(
    nodes: WalkNodes<'_, N>,
    start: (u32, u32),
    ray: &Ray,
    leaves: &mut L,
    stack: &mut AnyStack,
) -> bool
where
    K: NodeKernel<N>,
    L: AnyLeaves + PrefetchLeaves,
{
    let oct = OctRay::new(ray);
    // SAFETY: the caller guarantees the instruction set.
    let kray = unsafe { K::prepare(&oct) };
    let (mut child, mut count) = start;
    // Two loops, as in `closest_from`.
    loop {
        loop {
            if count > 0 {
                match leaves.any_without_call(child, count, ray) {
                    Some(true) => {
                        stack.clear();
                        return true;
                    }
                    Some(false) => {}
                    None => break,
                }
            } else {
                // SAFETY: as in `closest_from`.
                let node = unsafe { nodes.node(child) };
                let (mask, t) = unsafe { K::hit_mask(node, &kray, ray.t_max) };
                if mask != 0 {
                    // Descend into an entered leaf if there is one, else the nearest
                    // entered slot; push the others. A leaf next to nodes is likely a large
                    // primitive (a floor, a wall) that the builder kept near the root: any
                    // hit ends the walk, and testing it first saved the lit dragon's camera
                    // rays more than half their occlusion walk.
                    let mut nearest = mask.trailing_zeros() as usize;
                    let mut rest = mask & (mask - 1);
                    while rest != 0 {
                        let i = rest.trailing_zeros() as usize;
                        rest &= rest - 1;
                        // Selects, not a branch: which of two slots comes first is a coin
                        // toss (as a branch, 1.7 mispredictions an incoherent ray).
                        let (leaf_i, leaf_n) = (node.count[i] > 0, node.count[nearest] > 0);
                        let goes_first =
                            (leaf_i & !leaf_n) | ((leaf_i == leaf_n) & (t[i] < t[nearest]));
                        let farther = std::hint::select_unpredictable(goes_first, nearest, i);
                        nearest = std::hint::select_unpredictable(goes_first, i, nearest);
                        nodes.prefetch_child(leaves, node.child[farther], node.count[farther]);
                        stack.push_in_room((node.child[farther], node.count[farther]));
                    }
                    (child, count) = (node.child[nearest], node.count[nearest]);
                    continue;
                }
            }
            match stack.pop() {
                None => return false,
                Some(entry) => (child, count) = entry,
            }
        }
        rarely_taken();
        if leaves.any(child, count, ray) {
            stack.clear();
            return true;
        }
        match stack.pop() {
            None => return false,
            Some(entry) => (child, count) = entry,
        }
    }
}

/// Closest hits of rays `0..count` (`ray(i)` makes ray `i`, `answer(i, hit)` takes its
/// hit), one by one through the same leaves and stack: what a batch shares is made once.
///
/// # Safety
/// `K`'s instruction set must be available.
#[inline(always)]
pub(crate) unsafe fn closest_each<const N: usize, K, L, C>(
    nodes: WalkNodes<'_, N>,
    count: usize,
    ray: impl FnMut(usize) -> Ray,
    mut answer: impl FnMut(usize, Option<Hit>),
    mut leaves: L,
    counter: &mut C,
) where
    K: NodeKernel<N>,
    L: ClosestLeaves + PrefetchLeaves,
    C: TraversalCounter,
{
    let mut stack: ClosestStack = nodes.stack();
    let mut rays = Upcoming::new(count, ray);
    for i in 0..count {
        let ray = rays.take(i);
        leaves.new_ray();
        // SAFETY: the caller guarantees the instruction set.
        let hit = unsafe { closest::<N, K, L, C>(nodes, ray, &mut leaves, counter, &mut stack) };
        answer(i, hit);
    }
}

/// A batch's rays made one ahead of the walk: ray `i + 1` is made before ray `i` is
/// traced. A caller's `ray(i)` that the compiler leaves out of line returns its ray
/// through memory, written in pieces; read at once by the walk, in wider loads, the loads
/// waited for the pieces (a failed store forward: 15–20 ns a ray, a quarter of a primary
/// ray's time). Made a walk earlier, the ray has long been written. The walk reads it
/// where it was made, in one of two slots: a copy out of the slot was itself written in
/// pieces and read across them at once (`Ray::is_traceable`'s loads).
struct Upcoming<R> {
    make: R,
    count: usize,
    slots: [Ray; 2],
}

impl<R: FnMut(usize) -> Ray> Upcoming<R> {
    #[inline(always)]
    fn new(count: usize, mut make: R) -> Self {
        // An empty batch never reads its placeholder.
        let placeholder = Ray::new(Vec3::ZERO, Vec3::X, 0.0, 0.0);
        let first = match count {
            0 => placeholder,
            _ => make(0),
        };
        Self {
            make,
            count,
            slots: [first, placeholder],
        }
    }

    /// Ray `i` (made at the call before), having made ray `i + 1`. Calls go in order.
    #[inline(always)]
    fn take(&mut self, i: usize) -> &Ray {
        if i + 1 < self.count {
            self.slots[(i + 1) & 1] = (self.make)(i + 1);
        }
        &self.slots[i & 1]
    }
}

/// Occlusion of rays `0..count`, as [`closest_each`].
///
/// # Safety
/// As [`closest_each`].
#[inline(always)]
pub(crate) unsafe fn any_each<const N: usize, K, L>(
    nodes: WalkNodes<'_, N>,
    count: usize,
    ray: impl FnMut(usize) -> Ray,
    mut answer: impl FnMut(usize, bool),
    mut leaves: L,
) where
    K: NodeKernel<N>,
    L: AnyLeaves + PrefetchLeaves,
{
    let mut stack: AnyStack = nodes.stack();
    let mut rays = Upcoming::new(count, ray);
    for i in 0..count {
        let ray = rays.take(i);
        leaves.new_ray();
        // SAFETY: the caller guarantees the instruction set.
        let blocked = unsafe { any::<N, K, L>(nodes, ray, &mut leaves, &mut stack) };
        answer(i, blocked);
    }
}

/// Every leaf that `ray` enters, each handed to `leaves` (whose answers are ignored:
/// nothing stops the walk), in no particular order: a walk for every hit along a ray
/// (counts and lists of crossings), which visits each entered node whatever it finds, so
/// that the order of children saves nothing. The entered slots are pushed without a
/// branch each (and fetched ahead, as [`any`] does), and the first of them entered at
/// once. Leaves are tested a few steps after they are reached ([`WaitingLeaves`]).
///
/// # Safety
/// As [`any`].
#[inline(always)]
pub(crate) unsafe fn every<const N: usize, K, L>(
    nodes: WalkNodes<'_, N>,
    ray: &Ray,
    leaves: &mut L,
    stack: &mut AnyStack,
) where
    K: NodeKernel<N>,
    L: AnyLeaves + PrefetchLeaves,
{
    if !ray.is_traceable() {
        return;
    }
    let oct = OctRay::new(ray);
    // SAFETY: the caller guarantees the instruction set.
    let kray = unsafe { K::prepare(&oct) };
    let (mut child, mut count) = ROOT;
    let mut waiting = WaitingLeaves::default();
    loop {
        if count > 0 {
            nodes.prefetch_child(leaves, child, count);
            if let Some((first, n)) = waiting.push((child, count)) {
                _ = leaves.any(first, n, ray);
            }
        } else {
            // SAFETY: as in `closest_from`.
            let node = unsafe { nodes.node(child) };
            let (mask, _) = unsafe { K::hit_mask(node, &kray, ray.t_max) };
            if mask != 0 {
                let first = mask.trailing_zeros() as usize;
                let rest = mask & (mask - 1);
                stack.push_masked::<N>(rest, |i| (node.child[i], node.count[i]));
                for i in lanes(rest) {
                    nodes.prefetch_child(leaves, node.child[i], node.count[i]);
                }
                (child, count) = (node.child[first], node.count[first]);
                // The slot entered at once is fetched too, and a leaf that waited is
                // tested while it loads.
                nodes.prefetch_child(leaves, child, count);
                if let Some((first, n)) = waiting.pop() {
                    _ = leaves.any(first, n, ray);
                }
                continue;
            }
        }
        match stack.pop() {
            None => break,
            Some(entry) => (child, count) = entry,
        }
    }
    while let Some((first, n)) = waiting.pop() {
        _ = leaves.any(first, n, ray);
    }
}

/// The leaves an every-hit walk ([`every`]) has reached but not yet tested, oldest first:
/// a leaf is fetched when it is reached and tested a few steps later, while the nodes
/// after it load, so that its cache misses and theirs overlap instead of following one
/// another. Nothing a leaf finds changes that walk, so the order of its tests is free.
/// (Four leaves: 3–6% off a count of the 202k dragon's crossings in Morton order, 19% in
/// random order, nothing in a tree that stays in the cache; eight did no better.)
#[derive(Default)]
struct WaitingLeaves {
    leaves: [(u32, u32); WaitingLeaves::ROOM],
    oldest: usize,
    len: usize,
}

impl WaitingLeaves {
    const ROOM: usize = 4;

    /// Queues `leaf`, handing back the oldest waiting leaf when the queue was full.
    #[inline(always)]
    fn push(&mut self, leaf: (u32, u32)) -> Option<(u32, u32)> {
        if self.len < Self::ROOM {
            self.leaves[(self.oldest + self.len) % Self::ROOM] = leaf;
            self.len += 1;
            return None;
        }
        let oldest = std::mem::replace(&mut self.leaves[self.oldest], leaf);
        self.oldest = (self.oldest + 1) % Self::ROOM;
        Some(oldest)
    }

    /// The oldest waiting leaf, taken off the queue.
    #[inline(always)]
    fn pop(&mut self) -> Option<(u32, u32)> {
        if self.len == 0 {
            return None;
        }
        let oldest = self.leaves[self.oldest];
        self.oldest = (self.oldest + 1) % Self::ROOM;
        self.len -= 1;
        Some(oldest)
    }
}

/// [`every`] for rays `0..count` (`ray(i)` makes ray `i`), one after another through the
/// same leaves and stack, the leaves told which ray they test ([`EveryHit::ray`]).
///
/// # Safety
/// As [`any`].
#[inline(always)]
pub(crate) unsafe fn every_each<const N: usize, K, L, H>(
    nodes: WalkNodes<'_, N>,
    count: usize,
    ray: impl FnMut(usize) -> Ray,
    leaves: &mut EveryHit<L, H>,
) where
    K: NodeKernel<N>,
    EveryHit<L, H>: AnyLeaves + PrefetchLeaves,
{
    let mut stack: AnyStack = nodes.stack();
    let mut rays = Upcoming::new(count, ray);
    for i in 0..count {
        let ray = rays.take(i);
        leaves.new_ray();
        leaves.ray = i;
        // SAFETY: the caller guarantees the instruction set.
        unsafe { every::<N, K, _>(nodes, ray, leaves, &mut stack) };
    }
}

/// A traversal to run with the kernels of one instruction set.
pub trait Query<const N: usize> {
    type Out;

    /// # Safety
    /// The instruction sets of `K` and `T` must be available.
    unsafe fn run<K: NodeKernel<N>, T: PackKernel>(self) -> Self::Out;
}

/// Widths that have SIMD kernels (4 and 8; public only as a bound, not to implement): picks the node and pack kernels for `isa` and runs the
/// query in a function compiled for that instruction set.
pub trait Dispatch<const N: usize> {
    /// `isa` must be supported by this CPU (checked where the tree's kernel is set).
    fn dispatch<Q: Query<N>>(isa: Isa, query: Q) -> Q::Out;
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::*;
    use crate::triangle::{Avx2Pack, Sse2Pack};
    use crate::wide::kernels::{Avx2Node, Avx512Node, Sse2Node};

    #[target_feature(enable = "avx2")]
    unsafe fn with_avx2<const N: usize, K: NodeKernel<N>, Q: Query<N>>(q: Q) -> Q::Out {
        // SAFETY: this function is only called when AVX2 is available.
        unsafe { q.run::<K, Avx2Pack>() }
    }

    #[target_feature(enable = "avx512f,avx512vl,avx2")]
    unsafe fn with_avx512<const N: usize, K: NodeKernel<N>, Q: Query<N>>(q: Q) -> Q::Out {
        // SAFETY: this function is only called when AVX-512 F/VL are available.
        unsafe { q.run::<K, Avx2Pack>() }
    }

    impl Dispatch<4> for WideNode<4> {
        #[inline]
        fn dispatch<Q: Query<4>>(isa: Isa, q: Q) -> Q::Out {
            // SAFETY: `isa` is supported (the tree's kernel is checked when set); SSE2
            // is baseline x86-64.
            unsafe {
                match isa {
                    Isa::Scalar => q.run::<ScalarNode, ScalarPack>(),
                    Isa::Sse2 => q.run::<Sse2Node, Sse2Pack>(),
                    Isa::Avx2 => with_avx2::<4, Sse2Node, Q>(q),
                    Isa::Avx512 => with_avx512::<4, Sse2Node, Q>(q),
                }
            }
        }
    }

    impl Dispatch<8> for WideNode<8> {
        #[inline]
        fn dispatch<Q: Query<8>>(isa: Isa, q: Q) -> Q::Out {
            // SAFETY: as above.
            unsafe {
                match isa {
                    Isa::Scalar => q.run::<ScalarNode, ScalarPack>(),
                    Isa::Sse2 => q.run::<Sse2Node, Sse2Pack>(),
                    Isa::Avx2 => with_avx2::<8, Avx2Node, Q>(q),
                    Isa::Avx512 => with_avx512::<8, Avx512Node, Q>(q),
                }
            }
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
macro_rules! scalar_dispatch {
    ($($n:literal),*) => {$(
        impl Dispatch<$n> for WideNode<$n> {
            #[inline]
            fn dispatch<Q: Query<$n>>(_isa: Isa, q: Q) -> Q::Out {
                // SAFETY: the scalar kernels need nothing.
                unsafe { q.run::<ScalarNode, ScalarPack>() }
            }
        }
    )*};
}

#[cfg(not(target_arch = "x86_64"))]
scalar_dispatch!(4, 8);

#[cfg(test)]
mod tests {
    use super::WaitingLeaves;

    #[test]
    fn waiting_leaves_come_back_oldest_first_and_none_is_lost() {
        let mut waiting = WaitingLeaves::default();
        let leaf = |i: u32| (i, i + 100);
        let mut handed_back = Vec::new();
        for i in 0..11 {
            handed_back.extend(waiting.push(leaf(i)));
        }
        // A full queue hands back its oldest leaf for each one pushed.
        assert_eq!(handed_back, (0..7).map(leaf).collect::<Vec<_>>());
        handed_back.extend(std::iter::from_fn(|| waiting.pop()));
        assert_eq!(handed_back, (0..11).map(leaf).collect::<Vec<_>>());
        assert_eq!(waiting.pop(), None);
        // Pops and pushes mixed: the queue stays first in, first out.
        waiting.push(leaf(20));
        waiting.push(leaf(21));
        assert_eq!(waiting.pop(), Some(leaf(20)));
        waiting.push(leaf(22));
        assert_eq!(waiting.pop(), Some(leaf(21)));
        assert_eq!(waiting.pop(), Some(leaf(22)));
        assert_eq!(waiting.pop(), None);
    }
}
