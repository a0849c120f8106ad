//! Triangles, the one primitive canopy-bvh intersects itself: the watertight ray/triangle
//! test (Woop, Benthin and Wald, "Watertight Ray/Triangle Intersection", JCGT 2013), and
//! packs of four triangles stored by lanes in a wide tree's leaves.
//!
//! The scalar test and the SIMD kernels (4 lanes: one pack; 8 lanes: two packs of a leaf
//! at once) perform the same IEEE operations in the same order (no fused multiply-add), so
//! every kernel returns bit-identical hits, in either [`TriangleTest`] mode.

use crate::{Aabb, KnownShape, PrimHit, Ray};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// How a triangle test treats a ray that passes within rounding of an edge or a vertex:
/// where an edge function comes out exactly zero in single precision.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TriangleTest {
    /// Watertight (Woop, Benthin and Wald 2013): exactly-zero edge functions are computed
    /// again in double precision, so a ray through a shared edge or vertex hits the
    /// triangles the exact signs give, and never misses all of them.
    #[default]
    Watertight,
    /// The same test without the double-precision step: an exactly-zero edge function
    /// counts as inside. Still closed (a ray through a shared edge or vertex hits at least
    /// one triangle there) but where the exact signs would send it to one triangle it may
    /// hit several, at distances that differ in the last bits. Fewer instructions a pack
    /// test; the trade Embree makes by default (its robust mode is the watertight one).
    Fast,
}

impl TriangleTest {
    /// Whether exactly-zero edge functions are refined in double precision.
    #[inline(always)]
    pub fn refines_zeros(self) -> bool {
        self == TriangleTest::Watertight
    }

    /// The mode's name where users and records spell it: `watertight` or `fast`.
    pub fn name(self) -> &'static str {
        match self {
            TriangleTest::Watertight => "watertight",
            TriangleTest::Fast => "fast",
        }
    }
}

/// A ray prepared once for triangle tests: the axis along which the ray runs most
/// steeply becomes z, and a shear maps the ray onto the z axis; with the [`TriangleTest`]
/// mode its tests use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShearedRay {
    /// Axis indices: z is the dominant direction axis; x, y keep the winding.
    pub kx: usize,
    pub ky: usize,
    pub kz: usize,
    pub shear: Vec3,
    pub test: TriangleTest,
}

impl ShearedRay {
    /// A placeholder for queries over scenes without triangles, where it is never read.
    pub const UNUSED: ShearedRay = ShearedRay {
        kx: 0,
        ky: 1,
        kz: 2,
        shear: Vec3::ZERO,
        test: TriangleTest::Watertight,
    };

    /// `ray` prepared for the watertight test.
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        Self::with_test(ray, TriangleTest::Watertight)
    }

    /// `ray` prepared for tests in mode `test`. Always inlined: made at a walk's first
    /// leaf, out of line it was a call in the walk's loop.
    #[inline(always)]
    pub fn with_test(ray: &Ray, test: TriangleTest) -> Self {
        // x and y follow z cyclically, swapped when the ray runs down z to keep the
        // winding: `AXES[kz][runs down z]`.
        const AXES: [[[usize; 2]; 2]; 3] = [[[1, 2], [2, 1]], [[2, 0], [0, 2]], [[0, 1], [1, 0]]];
        let d = ray.dir.to_array();
        let a = ray.dir.abs();
        // The first axis of largest magnitude (as `Vec3::max_position`), by selects
        // rather than branches: ray directions are random, branches on them mispredict.
        let y_wins = a.y > a.x;
        let largest = if y_wins { a.y } else { a.x };
        let kz = if a.z > largest { 2 } else { y_wins as usize };
        let dz = d[kz];
        let [kx, ky] = AXES[kz][(dz < 0.0) as usize];
        Self {
            kx,
            ky,
            kz,
            shear: Vec3::new(d[kx] / dz, d[ky] / dz, 1.0 / dz),
            test,
        }
    }
}

/// The closest hit of `ray` on the triangle `v` within `[t_min, t_max]`, with the
/// barycentric weights of `v[1]` (`u`) and `v[2]` (`v`).
///
/// Watertight: a ray through an edge or vertex shared by triangles hits at least one of
/// them. In `sheared`'s [`TriangleTest::Watertight`] mode, edge functions that come out
/// exactly zero in single precision are recomputed in double precision, as the paper
/// prescribes; [`TriangleTest::Fast`] takes them as they are. Both sides of a triangle
/// are hit.
#[inline]
pub fn intersect_triangle(v: &[Vec3; 3], ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit> {
    EdgeInput::new(v, ray, sheared).hit(sheared.shear, sheared.test, ray.t_min, ray.t_max)
}

/// One triangle's vertices relative to the ray origin, axes permuted to (kx, ky, kz).
struct EdgeInput {
    a: [f32; 3],
    b: [f32; 3],
    c: [f32; 3],
}

/// The triangle seen along the ray: its vertices sheared onto the plane across the ray
/// (the ray at the origin), and the edge functions, each the weight of one vertex: `u`
/// of `a` (edge b-c), `v` of `b` (edge c-a), `w` of `c` (edge a-b).
struct Projected {
    xy: [[f32; 2]; 3],
    uvw: [f32; 3],
}

impl EdgeInput {
    #[inline(always)]
    fn new(v: &[Vec3; 3], ray: &Ray, s: &ShearedRay) -> Self {
        let o = ray.origin;
        let rel = |p: Vec3| [p.x - o.x, p.y - o.y, p.z - o.z];
        let (a, b, c) = (rel(v[0]), rel(v[1]), rel(v[2]));
        Self {
            a: [a[s.kx], a[s.ky], a[s.kz]],
            b: [b[s.kx], b[s.ky], b[s.kz]],
            c: [c[s.kx], c[s.ky], c[s.kz]],
        }
    }

    /// The projection and edge functions as the test in mode `test` computes them.
    #[inline(always)]
    fn project(&self, shear: Vec3, test: TriangleTest) -> Projected {
        let (a, b, c) = (self.a, self.b, self.c);
        let (ax, ay) = (a[0] - shear.x * a[2], a[1] - shear.y * a[2]);
        let (bx, by) = (b[0] - shear.x * b[2], b[1] - shear.y * b[2]);
        let (cx, cy) = (c[0] - shear.x * c[2], c[1] - shear.y * c[2]);
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if test.refines_zeros() && (u == 0.0 || v == 0.0 || w == 0.0) {
            let d =
                |p: f32, q: f32, r: f32, s: f32| (p as f64 * q as f64 - r as f64 * s as f64) as f32;
            u = d(cx, by, cy, bx);
            v = d(ax, cy, ay, cx);
            w = d(bx, ay, by, ax);
        }
        Projected {
            xy: [[ax, ay], [bx, by], [cx, cy]],
            uvw: [u, v, w],
        }
    }

    /// The scalar core that the SIMD kernels mirror operation for operation.
    #[inline(always)]
    fn hit(&self, shear: Vec3, test: TriangleTest, t_min: f32, t_max: f32) -> Option<PrimHit> {
        self.hit_projected(&self.project(shear, test), shear, t_min, t_max)
    }

    /// [`EdgeInput::hit`] from the projection already made.
    #[inline(always)]
    fn hit_projected(&self, p: &Projected, shear: Vec3, t_min: f32, t_max: f32) -> Option<PrimHit> {
        let [u, v, w] = p.uvw;
        let (a, b, c) = (self.a, self.b, self.c);
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let (az, bz, cz) = (shear.z * a[2], shear.z * b[2], shear.z * c[2]);
        let t = (u * az + v * bz + w * cz) / det;
        (t >= t_min && t <= t_max).then(|| PrimHit {
            t,
            u: v / det,
            v: w / det,
        })
    }
}

impl Projected {
    /// Whether the ray, moved off every edge and vertex by an infinitesimal step, still
    /// passes through the triangle (see [`crosses_triangle`]).
    #[inline]
    fn crossed(&self) -> bool {
        let [a, b, c] = self.xy;
        let [u, v, w] = self.uvw;
        // Each edge function is `p1.x * p2.y - p1.y * p2.x` of its edge's two vertices.
        let signs = [
            displaced_sign(u, c, b),
            displaced_sign(v, a, c),
            displaced_sign(w, b, a),
        ];
        signs[0] != 0 && signs[0] == signs[1] && signs[1] == signs[2]
    }
}

/// The sign of the edge function `f = p1.x * p2.y - p1.y * p2.x` at the point
/// `(e, e * e)` for an infinitesimal `e > 0` instead of at the origin: `f + e (p1.y -
/// p2.y) + e² (p2.x - p1.x)`. Where `f` is exactly zero the sign is that of the first
/// non-zero term, and each is a difference of two floats, whose sign rounding never
/// changes. The edge's other triangle computes the same terms negated, so the displaced
/// ray passes through exactly one of them.
#[inline(always)]
fn displaced_sign(f: f32, p1: [f32; 2], p2: [f32; 2]) -> i8 {
    let sign = |x: f32| (x > 0.0) as i8 - (x < 0.0) as i8;
    [f, p1[1] - p2[1], p2[0] - p1[0]]
        .into_iter()
        .map(sign)
        .find(|&s| s != 0)
        .unwrap_or(0)
}

/// [`intersect_triangle`], counting each crossing of a surface once: where the ray passes
/// exactly through an edge or a vertex (an edge function exactly zero, the case the
/// watertight test gives to every triangle that shares it), only the triangles that the
/// ray moved by an infinitesimal step off the edge would hit count, the tie rule of
/// symbolic perturbation (Edelsbrunner and Mücke, "Simulation of Simplicity", 1990). A
/// ray through a closed surface's edge or vertex then meets it twice, once in and once
/// out, as a ray that misses them does; one that only grazes an edge meets it twice or
/// not at all. Elsewhere the answer is `intersect_triangle`'s, bit for bit.
#[inline]
pub fn crosses_triangle(v: &[Vec3; 3], ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit> {
    crossing(v, ray, sheared).map(|(hit, _)| hit)
}

/// The hit of a crossing ([`crosses_triangle`]) and the projection it was decided on.
#[inline(always)]
fn crossing(v: &[Vec3; 3], ray: &Ray, sheared: &ShearedRay) -> Option<(PrimHit, Projected)> {
    // Deciding ties needs the exact signs, whatever mode `sheared` was made for.
    let edges = EdgeInput::new(v, ray, sheared);
    let projected = edges.project(sheared.shear, TriangleTest::Watertight);
    let hit = edges.hit_projected(&projected, sheared.shear, ray.t_min, ray.t_max)?;
    projected.crossed().then_some((hit, projected))
}

/// +1 where `ray` crosses the triangle `v` ([`crosses_triangle`]'s crossings) leaving
/// through its front (the side `(v1 - v0) x (v2 - v0)` faces), -1 where it enters there,
/// 0 where it does not cross. Summed along a ray from a point to infinity, it is the
/// winding number of a closed surface at that point, exactly.
#[inline]
pub(crate) fn signed_crossing(v: &[Vec3; 3], ray: &Ray, sheared: &ShearedRay) -> i32 {
    // The edge functions' sum is negative for a ray that runs along the normal.
    match crossing(v, ray, sheared) {
        None => 0,
        Some((_, projected)) if projected.uvw.iter().sum::<f32>() < 0.0 => 1,
        Some(_) => -1,
    }
}

/// Lanes per triangle pack.
pub const PACK_LANES: usize = 4;

/// `prim` of a lane that holds nothing.
pub const NO_PRIM: u32 = u32::MAX;

/// Four primitives of a leaf, stored by lanes so that one SIMD test covers the triangles
/// among them. Lanes that are not triangles hold NaN vertices (padding, and primitives
/// tested by the caller's closure) or a kept shape in the vertex slots (see
/// [`TrianglePack::set_kept`]); the triangle tests look at `triangles`' lanes only.
///
/// Byte layout (176 bytes, 16-aligned): `v[vertex][axis][lane]` (0..144), `prim` (144..160),
/// `triangles` (160..164), `others` (164..168), `spheres` (168..172), `boxes` (172..176).
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct TrianglePack {
    pub v: [[[f32; PACK_LANES]; 3]; 3],
    /// Primitive index of each lane, or [`NO_PRIM`].
    pub prim: [u32; PACK_LANES],
    /// Bit `i` set: lane `i` is a triangle.
    pub triangles: u32,
    /// Bit `i` set: lane `i` is another primitive: a kept sphere or box, else tested by
    /// the caller.
    pub others: u32,
    /// Bit `i` set: lane `i` is a kept sphere, its centre in `v[0]` and radius in
    /// `v[1][0]`.
    pub spheres: u32,
    /// Bit `i` set: lane `i` is a kept axis-aligned box, its corners in `v[0]` and `v[1]`.
    pub boxes: u32,
}

const _: () = assert!(std::mem::size_of::<TrianglePack>() == 176);
const _: () = assert!(std::mem::align_of::<TrianglePack>() == 16);

impl TrianglePack {
    pub const EMPTY: TrianglePack = TrianglePack {
        v: [[[f32::NAN; PACK_LANES]; 3]; 3],
        prim: [NO_PRIM; PACK_LANES],
        triangles: 0,
        others: 0,
        spheres: 0,
        boxes: 0,
    };

    pub fn set_triangle(&mut self, lane: usize, prim: u32, v: [Vec3; 3]) {
        for (vertex, p) in v.iter().enumerate() {
            for axis in 0..3 {
                self.v[vertex][axis][lane] = p[axis];
            }
        }
        self.prim[lane] = prim;
        self.triangles |= 1 << lane;
    }

    /// The vertices of triangle lane `lane`.
    #[inline(always)]
    pub fn vertices(&self, lane: usize) -> [Vec3; 3] {
        self.v
            .map(|p| Vec3::new(p[0][lane], p[1][lane], p[2][lane]))
    }

    pub fn set_other(&mut self, lane: usize, prim: u32) {
        self.prim[lane] = prim;
        self.others |= 1 << lane;
    }

    /// Keeps `shape` in other-primitive lane `lane`'s vertex slots (or, given `None`,
    /// leaves the lane to the caller's closure again), so that traversal tests it from the
    /// pack it has loaded anyway: no array beside the packs, no call.
    pub fn set_kept(&mut self, lane: usize, shape: Option<KnownShape>) {
        debug_assert!(
            self.others & 1 << lane != 0,
            "lane {lane} is not another primitive"
        );
        let bit = 1 << lane;
        (self.spheres, self.boxes) = (self.spheres & !bit, self.boxes & !bit);
        let mut put = |vertex: usize, p: Vec3| {
            for axis in 0..3 {
                self.v[vertex][axis][lane] = p[axis];
            }
        };
        match shape {
            Some(KnownShape::Sphere { center, radius }) => {
                put(0, center);
                put(1, Vec3::new(radius, f32::NAN, f32::NAN));
                self.spheres |= bit;
            }
            Some(KnownShape::Box(b)) => {
                put(0, b.min);
                put(1, b.max);
                self.boxes |= bit;
            }
            None => {
                put(0, Vec3::NAN);
                put(1, Vec3::NAN);
            }
        }
    }

    /// The shape kept in lane `lane` ([`TrianglePack::set_kept`]), if any.
    #[inline(always)]
    pub fn kept(&self, lane: usize) -> Option<KnownShape> {
        let at = |vertex: usize| {
            let p = &self.v[vertex];
            Vec3::new(p[0][lane], p[1][lane], p[2][lane])
        };
        if self.spheres & 1 << lane != 0 {
            let (center, radius) = (at(0), self.v[1][0][lane]);
            Some(KnownShape::Sphere { center, radius })
        } else if self.boxes & 1 << lane != 0 {
            Some(KnownShape::Box(Aabb::new(at(0), at(1))))
        } else {
            None
        }
    }

    /// Whether some lane keeps a shape.
    pub fn keeps_shapes(&self) -> bool {
        self.spheres | self.boxes != 0
    }

    fn lane_edges(&self, lane: usize, ray: &PackRay) -> EdgeInput {
        let rel = |vertex: usize| {
            let p = &self.v[vertex];
            [
                p[ray.k[0]][lane] - ray.o[0],
                p[ray.k[1]][lane] - ray.o[1],
                p[ray.k[2]][lane] - ray.o[2],
            ]
        };
        EdgeInput {
            a: rel(0),
            b: rel(1),
            c: rel(2),
        }
    }
}

/// A ray prepared for pack tests: the sheared ray's axes and the origin in that order.
/// (The test's mode is the kernel's: [`PackKernel::TEST`].)
#[derive(Clone, Copy, Debug)]
pub struct PackRay {
    k: [usize; 3],
    o: [f32; 3],
    shear: Vec3,
    /// The ray's `t_min`, which no hit changes. Closest-hit walks read it here and only
    /// `t_max` from their search: the two side by side were read as one 8-byte load, which
    /// could not be forwarded from the 4-byte store of a hit just found in the pack before
    /// (a stall on which a tenth of the walk's time was spent, the lit dragon's camera rays
    /// on AMD Zen 3).
    pub t_min: f32,
}

impl PackRay {
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        let s = ShearedRay::new(ray);
        // An array, not `Vec3`: glam indexes a `Vec3` with a `match`, whose branches on
        // the ray's axes mispredicted about once a ray.
        let o = ray.origin.to_array();
        Self {
            k: [s.kx, s.ky, s.kz],
            o: [o[s.kx], o[s.ky], o[s.kz]],
            shear: s.shear,
            t_min: ray.t_min,
        }
    }
}

/// The triangle lanes of consecutive packs as one mask: pack `i`'s lane `l` is bit
/// `i * PACK_LANES + l` (one pack, or a pair tested together).
#[inline(always)]
pub(crate) fn triangle_lanes(packs: &[TrianglePack]) -> u32 {
    let mut lanes = 0;
    for (i, pack) in packs.iter().enumerate() {
        lanes |= pack.triangles << (i * PACK_LANES);
    }
    lanes
}

/// Lanes of a [`PackHits`]: two packs, tested together by the 8-lane kernel.
pub const PAIR_LANES: usize = 2 * PACK_LANES;

/// Distance and barycentrics of each lane of one pack (lanes 0..4) or of a pair of packs
/// (lanes 0..8, the second pack's in 4..8), valid in the lanes of the mask that
/// [`PackKernel::test`] or [`PackKernel::test_pair`] returns. The caller owns it and passes
/// it to every test, so a pack that is missed (most are) writes nothing, and the mask comes
/// back in a register: returning the whole record by value made each test store it in
/// pieces and reload it whole, a load no store can forward, which stalled every pack test.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, Default)]
pub struct PackHits {
    pub t: [f32; PAIR_LANES],
    pub u: [f32; PAIR_LANES],
    pub v: [f32; PAIR_LANES],
}

impl PackHits {
    fn set(&mut self, lane: usize, hit: PrimHit) {
        self.t[lane] = hit.t;
        self.u[lane] = hit.u;
        self.v[lane] = hit.v;
    }

    /// The hit in `lane`, which must be in the mask of the last test.
    #[inline(always)]
    pub fn lane(&self, lane: usize) -> PrimHit {
        PrimHit {
            t: self.t[lane],
            u: self.u[lane],
            v: self.v[lane],
        }
    }

    /// Tests the `lanes` of `pack` one by one in the scalar core in mode `test`, adding
    /// their hits at lanes `base + lane`; returns the lanes hit (bit `lane`, not shifted
    /// by `base`).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn add_scalar_lanes(
        &mut self,
        pack: &TrianglePack,
        base: usize,
        ray: &PackRay,
        test: TriangleTest,
        mut lanes: u32,
        t_min: f32,
        t_max: f32,
    ) -> u32 {
        let mut mask = 0;
        while lanes != 0 {
            let lane = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            let edges = pack.lane_edges(lane, ray);
            if let Some(hit) = edges.hit(ray.shear, test, t_min, t_max) {
                self.set(base + lane, hit);
                mask |= 1 << lane;
            }
        }
        mask
    }
}

/// A triangle test of one pack (4 lanes) or a pair of packs (8 lanes) in one
/// [`TriangleTest`] mode: [`ScalarPack`], [`Sse2Pack`] or [`Avx2Pack`], identical in every
/// bit. The mode is part of the kernel's type, so that the fast one carries no trace of
/// the watertight one's refinement, not even a branch.
pub trait PackKernel {
    /// Whether [`PackKernel::test_pair`] costs about one pack test (8-lane registers), so
    /// a leaf's packs are best tested two at a time.
    const PAIRS: bool;

    /// The mode this kernel tests in.
    const TEST: TriangleTest;

    /// The same kernel in the fast mode.
    type Fast: PackKernel;

    /// The pack's triangle lanes hit within `[t_min, t_max]` (bit `i` for lane `i`).
    /// With `HITS`, their hits are written to lanes 0..4 of `hits` (other lanes are left
    /// as they were); without (any-hit queries), `hits` is scratch space.
    ///
    /// # Safety
    /// The kernel's instruction set must be available.
    unsafe fn test<const HITS: bool>(
        pack: &TrianglePack,
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> u32;

    /// [`PackKernel::test`] of two packs, the second's lanes as bits and hit lanes 4..8.
    ///
    /// # Safety
    /// As [`PackKernel::test`].
    unsafe fn test_pair<const HITS: bool>(
        packs: &[TrianglePack; 2],
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> u32;

    /// [`PackKernel::test`] with no call in it: the lanes that the watertight mode would
    /// refine in the scalar core (an exactly-zero edge function) are left out of the hits
    /// and returned second, for the caller to test again with [`PackKernel::test`]. A
    /// walk whose loop holds no call keeps its values in registers (see
    /// `wide::traverse`). Kernels without SIMD test fully (and may call).
    ///
    /// # Safety
    /// As [`PackKernel::test`].
    #[inline(always)]
    unsafe fn test_unrefined<const HITS: bool>(
        pack: &TrianglePack,
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> (u32, u32) {
        // SAFETY: the caller's guarantee.
        (
            unsafe { Self::test::<HITS>(pack, ray, t_min, t_max, hits) },
            0,
        )
    }

    /// [`PackKernel::test_unrefined`] of two packs, as [`PackKernel::test_pair`].
    ///
    /// # Safety
    /// As [`PackKernel::test`].
    #[inline(always)]
    unsafe fn test_pair_unrefined<const HITS: bool>(
        packs: &[TrianglePack; 2],
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> (u32, u32) {
        // SAFETY: the caller's guarantee.
        (
            unsafe { Self::test_pair::<HITS>(packs, ray, t_min, t_max, hits) },
            0,
        )
    }

    /// The pack's kept-shape lanes (spheres and boxes) that `ray` hits within its range
    /// (bit `i` for lane `i`), each hit's distance at its lane of `t` (see
    /// `wide::pack_shapes`).
    ///
    /// # Safety
    /// As [`PackKernel::test`].
    #[inline(always)]
    unsafe fn shapes(pack: &TrianglePack, ray: &Ray, t: &mut [f32; PAIR_LANES]) -> u32 {
        crate::wide::shapes_one_by_one(std::slice::from_ref(pack), ray, t)
    }

    /// [`PackKernel::shapes`] of two packs, the second's lanes as bits and distances
    /// 4..8.
    ///
    /// # Safety
    /// As [`PackKernel::test`].
    #[inline(always)]
    unsafe fn shape_pair(packs: &[TrianglePack; 2], ray: &Ray, t: &mut [f32; PAIR_LANES]) -> u32 {
        crate::wide::shapes_one_by_one(packs, ray, t)
    }
}

/// The mode a kernel's `REFINES` parameter stands for.
const fn mode(refines: bool) -> TriangleTest {
    match refines {
        true => TriangleTest::Watertight,
        false => TriangleTest::Fast,
    }
}

/// The portable twin: the scalar core lane by lane; `REFINES`: the watertight mode.
pub(crate) struct ScalarPack<const REFINES: bool = true>;

impl<const REFINES: bool> PackKernel for ScalarPack<REFINES> {
    const PAIRS: bool = false;
    const TEST: TriangleTest = mode(REFINES);
    type Fast = ScalarPack<false>;

    #[inline(always)]
    unsafe fn test<const HITS: bool>(
        pack: &TrianglePack,
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> u32 {
        hits.add_scalar_lanes(pack, 0, ray, Self::TEST, pack.triangles, t_min, t_max)
    }

    #[inline(always)]
    unsafe fn test_pair<const HITS: bool>(
        packs: &[TrianglePack; 2],
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> u32 {
        let [low, high] = packs;
        let (test, lanes) = (Self::TEST, PACK_LANES);
        let low = hits.add_scalar_lanes(low, 0, ray, test, low.triangles, t_min, t_max);
        let high = hits.add_scalar_lanes(high, lanes, ray, test, high.triangles, t_min, t_max);
        low | high << PACK_LANES
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) use simd::{Avx2Pack, Sse2Pack};

#[cfg(target_arch = "x86_64")]
mod simd {
    use super::*;
    use crate::lanes::Lanes;
    use std::arch::x86_64::*;

    /// The pack test on `V::PACKS` packs: the scalar core's operations in every lane;
    /// the lanes hit, and those left to refine. In the watertight mode, lanes whose edge
    /// functions come out exactly zero go to the scalar core, which redoes them in double
    /// precision; with `DEFERS`, they are returned instead (and the test holds no call).
    #[inline(always)]
    unsafe fn test_lanes<V: Lanes, const HITS: bool, const REFINES: bool, const DEFERS: bool>(
        packs: &[TrianglePack],
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> (u32, u32) {
        // SAFETY (whole block): the caller guarantees `V`'s instruction set.
        unsafe {
            // No closures here: a closure is not inlined for sure, and one compiled
            // without AVX would take 8-lane registers through memory and call every
            // intrinsic.
            let [ox, oy, oz] = [V::splat(ray.o[0]), V::splat(ray.o[1]), V::splat(ray.o[2])];
            let sx = V::splat(ray.shear.x);
            let sy = V::splat(ray.shear.y);
            let sz = V::splat(ray.shear.z);
            let [k0, k1, k2] = ray.k;
            let a0 = V::load(packs, 0, k0).sub(ox);
            let a1 = V::load(packs, 0, k1).sub(oy);
            let a2 = V::load(packs, 0, k2).sub(oz);
            let b0 = V::load(packs, 1, k0).sub(ox);
            let b1 = V::load(packs, 1, k1).sub(oy);
            let b2 = V::load(packs, 1, k2).sub(oz);
            let c0 = V::load(packs, 2, k0).sub(ox);
            let c1 = V::load(packs, 2, k1).sub(oy);
            let c2 = V::load(packs, 2, k2).sub(oz);
            let (ax, ay) = (a0.sub(sx.mul(a2)), a1.sub(sy.mul(a2)));
            let (bx, by) = (b0.sub(sx.mul(b2)), b1.sub(sy.mul(b2)));
            let (cx, cy) = (c0.sub(sx.mul(c2)), c1.sub(sy.mul(c2)));
            let u = cx.mul(by).sub(cy.mul(bx));
            let v = ax.mul(cy).sub(ay.mul(cx));
            let w = bx.mul(ay).sub(by.mul(ax));
            let zero = V::splat(0.0);
            let negative = u.lt(zero).or(v.lt(zero)).or(w.lt(zero));
            let positive = u.gt(zero).or(v.gt(zero)).or(w.gt(zero));
            let lanes = triangle_lanes(&packs[..V::PACKS]);
            let redo = match REFINES {
                true => u.eq(zero).or(v.eq(zero)).or(w.eq(zero)).mask() & lanes,
                false => 0,
            };
            // Inside: no edge function of each sign (in the fast mode, zero counts as
            // either; in the watertight one, lanes with a zero go to `redo`).
            let straddles = negative.and(positive).mask();
            let inside = lanes & !straddles & !redo;
            let mut mask = 0;
            // Most packs a ray reaches it misses: skip the division unless a lane is
            // inside all three edges.
            if inside != 0 {
                let det = u.add(v).add(w);
                let det_ok = det.ne(zero).and(det.sub(det).eq(zero));
                let t = u
                    .mul(sz.mul(a2))
                    .add(v.mul(sz.mul(b2)))
                    .add(w.mul(sz.mul(c2)))
                    .div(det);
                let in_range = t.ge(V::splat(t_min)).and(t.le(V::splat(t_max)));
                mask = det_ok.and(in_range).mask() & inside;
                if HITS && mask != 0 {
                    t.store(&mut hits.t);
                    v.div(det).store(&mut hits.u);
                    w.div(det).store(&mut hits.v);
                }
            }
            if DEFERS {
                return (mask, redo);
            }
            // Lanes with an exactly-zero edge function go to the scalar core's f64
            // fallback (rare: one branch skips it).
            if redo != 0 {
                for (i, pack) in packs[..V::PACKS].iter().enumerate() {
                    let base = i * PACK_LANES;
                    let lanes = (redo >> base) & ((1 << PACK_LANES) - 1);
                    if lanes != 0 {
                        let test = TriangleTest::Watertight;
                        let hit = hits.add_scalar_lanes(pack, base, ray, test, lanes, t_min, t_max);
                        mask |= hit << base;
                    }
                }
            }
            (mask, 0)
        }
    }

    /// The SSE2 kernel (baseline x86-64): four lanes, one pack at a time; `REFINES`: the
    /// watertight mode.
    pub(crate) struct Sse2Pack<const REFINES: bool = true>;

    /// One pack in SSE2 lanes ([`test_lanes`]).
    #[inline(always)]
    fn sse2_one<const HITS: bool, const REFINES: bool, const DEFERS: bool>(
        pack: &TrianglePack,
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> (u32, u32) {
        let pack = std::slice::from_ref(pack);
        // SAFETY: SSE2 is baseline x86-64.
        unsafe { test_lanes::<__m128, HITS, REFINES, DEFERS>(pack, ray, t_min, t_max, hits) }
    }

    /// Two packs in SSE2 lanes, one after the other: the second pack's hits land in
    /// lanes 0..4 of a second record, then move up.
    #[inline(always)]
    fn sse2_pair<const HITS: bool, const REFINES: bool, const DEFERS: bool>(
        packs: &[TrianglePack; 2],
        ray: &PackRay,
        t_min: f32,
        t_max: f32,
        hits: &mut PackHits,
    ) -> (u32, u32) {
        let [low, high] = packs;
        let (low_hit, low_redo) = sse2_one::<HITS, REFINES, DEFERS>(low, ray, t_min, t_max, hits);
        let mut upper = PackHits::default();
        let (high_hit, high_redo) =
            sse2_one::<HITS, REFINES, DEFERS>(high, ray, t_min, t_max, &mut upper);
        for lane in 0..PACK_LANES {
            hits.t[PACK_LANES + lane] = upper.t[lane];
            hits.u[PACK_LANES + lane] = upper.u[lane];
            hits.v[PACK_LANES + lane] = upper.v[lane];
        }
        (
            low_hit | high_hit << PACK_LANES,
            low_redo | high_redo << PACK_LANES,
        )
    }

    impl<const REFINES: bool> PackKernel for Sse2Pack<REFINES> {
        const PAIRS: bool = false;
        const TEST: TriangleTest = mode(REFINES);
        type Fast = Sse2Pack<false>;

        #[inline(always)]
        unsafe fn test<const HITS: bool>(
            pack: &TrianglePack,
            ray: &PackRay,
            t_min: f32,
            t_max: f32,
            hits: &mut PackHits,
        ) -> u32 {
            sse2_one::<HITS, REFINES, false>(pack, ray, t_min, t_max, hits).0
        }

        #[inline(always)]
        unsafe fn test_pair<const HITS: bool>(
            packs: &[TrianglePack; 2],
            ray: &PackRay,
            t_min: f32,
            t_max: f32,
            hits: &mut PackHits,
        ) -> u32 {
            sse2_pair::<HITS, REFINES, false>(packs, ray, t_min, t_max, hits).0
        }

        #[inline(always)]
        unsafe fn test_unrefined<const HITS: bool>(
            pack: &TrianglePack,
            ray: &PackRay,
            t_min: f32,
            t_max: f32,
            hits: &mut PackHits,
        ) -> (u32, u32) {
            sse2_one::<HITS, REFINES, true>(pack, ray, t_min, t_max, hits)
        }

        #[inline(always)]
        unsafe fn test_pair_unrefined<const HITS: bool>(
            packs: &[TrianglePack; 2],
            ray: &PackRay,
            t_min: f32,
            t_max: f32,
            hits: &mut PackHits,
        ) -> (u32, u32) {
            sse2_pair::<HITS, REFINES, true>(packs, ray, t_min, t_max, hits)
        }

        #[inline(always)]
        unsafe fn shapes(pack: &TrianglePack, ray: &Ray, t: &mut [f32; PAIR_LANES]) -> u32 {
            sse2_shapes(pack, ray, t)
        }

        #[inline(always)]
        unsafe fn shape_pair(
            packs: &[TrianglePack; 2],
            ray: &Ray,
            t: &mut [f32; PAIR_LANES],
        ) -> u32 {
            let [low, high] = packs;
            let mut upper = [0.0; PAIR_LANES];
            let hit = sse2_shapes(low, ray, t) | sse2_shapes(high, ray, &mut upper) << PACK_LANES;
            t[PACK_LANES..].copy_from_slice(&upper[..PACK_LANES]);
            hit
        }
    }

    /// One pack's kept shapes in SSE2 lanes.
    #[inline(always)]
    fn sse2_shapes(pack: &TrianglePack, ray: &Ray, t: &mut [f32; PAIR_LANES]) -> u32 {
        // SAFETY: SSE2 is baseline x86-64.
        unsafe { crate::wide::shape_lanes::<__m128>(std::slice::from_ref(pack), ray, t) }
    }

    /// The AVX2 kernel: single packs as SSE2 does, pairs of packs in eight lanes;
    /// `REFINES`: the watertight mode.
    pub(crate) struct Avx2Pack<const REFINES: bool = true>;

    impl<const REFINES: bool> PackKernel for Avx2Pack<REFINES> {
        const PAIRS: bool = true;
        const TEST: TriangleTest = mode(REFINES);
        type Fast = Avx2Pack<false>;

        #[inline(always)]
        unsafe fn test<const HITS: bool>(
            pack: &TrianglePack,
            ray: &PackRay,
            t_min: f32,
            t_max: f32,
            hits: &mut PackHits,
        ) -> u32 {
            sse2_one::<HITS, REFINES, false>(pack, ray, t_min, t_max, hits).0
        }

        #[inline(always)]
        unsafe fn test_pair<const HITS: bool>(
            packs: &[TrianglePack; 2],
            ray: &PackRay,
            t_min: f32,
            t_max: f32,
            hits: &mut PackHits,
        ) -> u32 {
            // SAFETY: the caller guarantees AVX2.
            unsafe { test_lanes::<__m256, HITS, REFINES, false>(packs, ray, t_min, t_max, hits).0 }
        }

        #[inline(always)]
        unsafe fn test_unrefined<const HITS: bool>(
            pack: &TrianglePack,
            ray: &PackRay,
            t_min: f32,
            t_max: f32,
            hits: &mut PackHits,
        ) -> (u32, u32) {
            sse2_one::<HITS, REFINES, true>(pack, ray, t_min, t_max, hits)
        }

        #[inline(always)]
        unsafe fn test_pair_unrefined<const HITS: bool>(
            packs: &[TrianglePack; 2],
            ray: &PackRay,
            t_min: f32,
            t_max: f32,
            hits: &mut PackHits,
        ) -> (u32, u32) {
            // SAFETY: the caller guarantees AVX2.
            unsafe { test_lanes::<__m256, HITS, REFINES, true>(packs, ray, t_min, t_max, hits) }
        }

        #[inline(always)]
        unsafe fn shapes(pack: &TrianglePack, ray: &Ray, t: &mut [f32; PAIR_LANES]) -> u32 {
            sse2_shapes(pack, ray, t)
        }

        #[inline(always)]
        unsafe fn shape_pair(
            packs: &[TrianglePack; 2],
            ray: &Ray,
            t: &mut [f32; PAIR_LANES],
        ) -> u32 {
            // SAFETY: the caller guarantees AVX2.
            unsafe { crate::wide::shape_lanes::<__m256>(packs, ray, t) }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> [Vec3; 3] {
        [Vec3::ZERO, Vec3::X, Vec3::Y]
    }

    /// A xorshift stream of numbers in [-0.5, 0.5] from `seed`.
    fn centred(mut state: u32) -> impl FnMut() -> f32 {
        move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32 - 0.5
        }
    }

    fn hit(o: Vec3, d: Vec3, t_max: f32) -> Option<PrimHit> {
        let ray = Ray::new(o, d, 0.0, t_max);
        intersect_triangle(&tri(), &ray, &ShearedRay::new(&ray))
    }

    #[test]
    fn a_crossing_is_signed_by_the_side_the_ray_leaves_through() {
        let mut next = centred(7);
        let mut seen = [0; 2];
        for _ in 0..2000 {
            let v = [0; 3].map(|_| Vec3::new(next(), next(), next()));
            let normal = (v[1] - v[0]).cross(v[2] - v[0]);
            let inside = (v[0] + v[1] + v[2]) / 3.0;
            let d = Vec3::new(next(), next(), next()).normalize();
            if normal.normalize().dot(d).abs() < 1e-3 {
                continue;
            }
            let ray = Ray::new(inside - d, d, 0.0, f32::INFINITY);
            let sign = signed_crossing(&v, &ray, &ShearedRay::new(&ray));
            let leaves = normal.dot(d) > 0.0;
            assert_eq!(sign, if leaves { 1 } else { -1 }, "{v:?} {d}");
            seen[leaves as usize] += 1;
        }
        assert!(seen[0] > 500 && seen[1] > 500, "{seen:?}");
    }

    #[test]
    fn interior_hit_with_barycentrics() {
        let h = hit(Vec3::new(0.25, 0.5, 1.0), -Vec3::Z, f32::INFINITY).unwrap();
        assert_eq!((h.t, h.u, h.v), (1.0, 0.25, 0.5));
    }

    #[test]
    fn misses_outside_and_beyond_t_max() {
        assert_eq!(
            hit(Vec3::new(0.75, 0.75, 1.0), -Vec3::Z, f32::INFINITY),
            None
        );
        assert_eq!(hit(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, 0.5), None);
    }

    #[test]
    fn edges_and_vertices_count_as_hits() {
        assert!(hit(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z, f32::INFINITY).is_some());
        assert!(hit(Vec3::new(1.0, 0.0, 1.0), -Vec3::Z, f32::INFINITY).is_some());
    }

    /// A pack of the triangle in every lane but one, which is left empty.
    fn pack() -> TrianglePack {
        let mut p = TrianglePack::EMPTY;
        for lane in 0..3 {
            let shift = Vec3::new(0.0, 0.0, lane as f32);
            p.set_triangle(lane, lane as u32, tri().map(|v| v - shift));
        }
        p
    }

    /// Every 4-lane kernel in the mode `REFINES` stands for gives the scalar test's hits.
    fn kernels_agree<const REFINES: bool>(ray: &Ray) {
        let pr = PackRay::new(ray);
        let sheared = ShearedRay::with_test(ray, mode(REFINES));
        let mut scalar = PackHits::default();
        let scalar_mask = unsafe {
            ScalarPack::<REFINES>::test::<true>(&pack(), &pr, ray.t_min, ray.t_max, &mut scalar)
        };
        for lane in 0..PACK_LANES {
            let shift = Vec3::new(0.0, 0.0, lane as f32);
            let expect = (lane < 3)
                .then(|| intersect_triangle(&tri().map(|v| v - shift), ray, &sheared))
                .flatten();
            let got = (scalar_mask & (1 << lane) != 0).then(|| scalar.lane(lane));
            assert_eq!(got, expect, "lane {lane}");
        }
        #[cfg(target_arch = "x86_64")]
        {
            let mut simd = PackHits::default();
            let simd_mask = unsafe {
                Sse2Pack::<REFINES>::test::<true>(&pack(), &pr, ray.t_min, ray.t_max, &mut simd)
            };
            assert_eq!(simd_mask, scalar_mask);
            for lane in 0..PACK_LANES {
                if scalar_mask & (1 << lane) != 0 {
                    assert_eq!(simd.t[lane].to_bits(), scalar.t[lane].to_bits());
                    assert_eq!(simd.u[lane].to_bits(), scalar.u[lane].to_bits());
                    assert_eq!(simd.v[lane].to_bits(), scalar.v[lane].to_bits());
                }
            }
        }
    }

    /// Two packs: `pack()` and, in the second, two more triangles further down z.
    fn pair() -> [TrianglePack; 2] {
        let mut high = TrianglePack::EMPTY;
        for lane in 0..2 {
            let shift = Vec3::new(0.0, 0.0, 3.0 + lane as f32);
            high.set_triangle(lane, 3 + lane as u32, tri().map(|v| v - shift));
        }
        [pack(), high]
    }

    fn expected_pair_lane(lane: usize, ray: &Ray, mode: TriangleTest) -> Option<PrimHit> {
        // Lane 3 and lanes 6 and 7 are empty; the others lie `depth` down z.
        let depth = match lane {
            3 | 6 | 7 => return None,
            0..=2 => lane,
            _ => lane - 1,
        };
        let shift = Vec3::new(0.0, 0.0, depth as f32);
        intersect_triangle(
            &tri().map(|v| v - shift),
            ray,
            &ShearedRay::with_test(ray, mode),
        )
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn avx2_pair<const REFINES: bool>(
        packs: &[TrianglePack; 2],
        ray: &Ray,
        hits: &mut PackHits,
    ) -> u32 {
        let pr = PackRay::new(ray);
        unsafe { Avx2Pack::<REFINES>::test_pair::<true>(packs, &pr, ray.t_min, ray.t_max, hits) }
    }

    /// Every kernel's pair test (two packs, lanes 0..8) gives the scalar test's hits bit
    /// for bit, the 8-lane AVX2 one included where the CPU has it.
    fn pair_kernels_agree<const REFINES: bool>(ray: &Ray) {
        let mode = mode(REFINES);
        let pr = PackRay::new(ray);
        let mut scalar = PackHits::default();
        let scalar_mask = unsafe {
            ScalarPack::<REFINES>::test_pair::<true>(
                &pair(),
                &pr,
                ray.t_min,
                ray.t_max,
                &mut scalar,
            )
        };
        for lane in 0..PAIR_LANES {
            let got = (scalar_mask & (1 << lane) != 0).then(|| scalar.lane(lane));
            assert_eq!(got, expected_pair_lane(lane, ray, mode), "lane {lane}");
        }
        #[cfg(target_arch = "x86_64")]
        {
            let same = |mask: u32, hits: &PackHits, kernel: &str| {
                assert_eq!(mask, scalar_mask, "{kernel}");
                for lane in 0..PAIR_LANES {
                    if mask & (1 << lane) != 0 {
                        let bits = |h: PrimHit| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits());
                        assert_eq!(bits(hits.lane(lane)), bits(scalar.lane(lane)), "{kernel}");
                    }
                }
            };
            let mut sse2 = PackHits::default();
            let mask = unsafe {
                Sse2Pack::<REFINES>::test_pair::<true>(
                    &pair(),
                    &pr,
                    ray.t_min,
                    ray.t_max,
                    &mut sse2,
                )
            };
            same(mask, &sse2, "sse2");
            if std::arch::is_x86_feature_detected!("avx2") {
                let mut avx2 = PackHits::default();
                // SAFETY: AVX2 was just detected.
                let mask = unsafe { avx2_pair::<REFINES>(&pair(), ray, &mut avx2) };
                same(mask, &avx2, "avx2");
            }
        }
    }

    fn kernel_test_rays() -> [Ray; 6] {
        [
            Ray::new(Vec3::new(0.2, 0.3, 5.0), -Vec3::Z, 0.0, f32::INFINITY),
            Ray::new(Vec3::new(0.2, 0.3, 5.0), -Vec3::Z, 0.0, 5.5),
            Ray::new(Vec3::new(0.2, 0.3, 5.0), -Vec3::Z, 6.5, 9.0),
            // Through an edge: exactly-zero edge functions, redone in f64.
            Ray::new(Vec3::new(0.5, 0.0, 5.0), -Vec3::Z, 0.0, f32::INFINITY),
            Ray::new(
                Vec3::new(0.0, 0.0, -5.0),
                Vec3::new(0.01, 0.02, 1.0),
                0.0,
                f32::INFINITY,
            ),
            Ray::new(Vec3::new(-1.0, 0.25, -1.0), Vec3::X, 0.0, f32::INFINITY),
        ]
    }

    #[test]
    fn pair_kernels_match_the_scalar_test_lane_by_lane() {
        for ray in &kernel_test_rays() {
            pair_kernels_agree::<true>(ray);
            pair_kernels_agree::<false>(ray);
        }
    }

    #[test]
    fn pack_kernels_match_the_scalar_test_lane_by_lane() {
        for ray in &kernel_test_rays() {
            kernels_agree::<true>(ray);
            kernels_agree::<false>(ray);
        }
    }

    /// Rays aimed at edge midpoints of random triangles: the fast mode hits wherever the
    /// watertight one does, and also where a rounded-to-zero edge function would have
    /// come out negative in double precision (so the mode does change answers there).
    #[test]
    fn the_fast_test_hits_a_superset_of_the_watertight_one_at_edges() {
        let mut next = centred(11);
        let (mut differ, mut fast_only) = (0, 0);
        for _ in 0..20_000 {
            let v = [0; 3].map(|_| Vec3::new(next(), next(), next()) * 4.0);
            let o = Vec3::new(next(), next(), next()) * 20.0;
            let ray = Ray::new(o, (0.5 * (v[0] + v[1]) - o).normalize(), 0.0, f32::INFINITY);
            let watertight = intersect_triangle(&v, &ray, &ShearedRay::new(&ray));
            let fast = ShearedRay::with_test(&ray, TriangleTest::Fast);
            let fast = intersect_triangle(&v, &ray, &fast);
            assert!(watertight.is_none() || fast.is_some(), "{v:?} {ray:?}");
            differ += (watertight != fast) as u32;
            fast_only += (watertight.is_none() && fast.is_some()) as u32;
        }
        assert!(fast_only > 20 && differ > fast_only, "{differ} {fast_only}");
    }
}
