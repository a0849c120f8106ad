//! Triangles packed in wide leaves, tested by every SIMD kernel and its scalar twin,
//! against a loop over all primitives: same closest hit (primitive, distance and
//! barycentrics, bit for bit) and same any-hit answer. Scenes mix triangles with other
//! primitives (boxes, tested by the caller's closure), as a renderer's scenes do.

use crate::common;
use common::{uniform, Blocks, Closest, MakeRay, TakeBlocked, TakeHit};

use canopy_bvh::{
    build, build_with_clipper, intersect_triangle, split_box, split_triangle, Aabb, Blas,
    BlasParams, BuildParams, Builder, Bvh2, Bvh4, Bvh8, BvhN, BvhWidth, Coherence, Geometry,
    GpuBvh, Hit, Isa, PrimHit, Ray, RayBatch, RayQuery, SahCosts, ShearedRay, Tree, TreeView,
    TriangleTest, ALL_MASKS, PACKET, PREFETCH_ABOVE_BYTES,
};
use glam::Vec3;
use proptest::prelude::*;

#[derive(Clone, Debug)]
enum Prim {
    Triangle([Vec3; 3]),
    Box(Aabb),
}

impl Prim {
    fn bounds(&self) -> Aabb {
        match self {
            Prim::Triangle(v) => Aabb::from_points(*v),
            Prim::Box(b) => *b,
        }
    }

    fn triangle(&self) -> Option<[Vec3; 3]> {
        match self {
            Prim::Triangle(v) => Some(*v),
            Prim::Box(_) => None,
        }
    }

    fn hit(&self, ray: &Ray) -> Option<PrimHit> {
        self.hit_in(ray, TriangleTest::Watertight)
    }

    /// The hit with triangles tested in mode `test`.
    fn hit_in(&self, ray: &Ray, test: TriangleTest) -> Option<PrimHit> {
        match self {
            Prim::Triangle(v) => intersect_triangle(v, ray, &ShearedRay::with_test(ray, test)),
            Prim::Box(b) => b.ray_entry(ray).map(PrimHit::from),
        }
    }
}

/// A renderer's mixed primitives as geometry a [`Blas`] owns.
struct Prims(Vec<Prim>);

impl Geometry for Prims {
    fn len(&self) -> usize {
        self.0.len()
    }
    fn bounds(&self, prim: u32) -> Aabb {
        self.0[prim as usize].bounds()
    }
    fn triangle(&self, prim: u32) -> Option<[Vec3; 3]> {
        self.0[prim as usize].triangle()
    }
    fn has_triangles(&self) -> bool {
        self.0.iter().any(|p| p.triangle().is_some())
    }
    fn intersect(&self, prim: u32, ray: &Ray, sheared: &ShearedRay) -> Option<PrimHit> {
        self.0[prim as usize].hit_in(ray, sheared.test)
    }
}

fn brute_force(prims: &[Prim], ray: &Ray) -> Option<Hit> {
    brute_force_in(prims, ray, TriangleTest::Watertight)
}

/// The closest hit by a loop over every primitive, triangles tested in mode `test`.
fn brute_force_in(prims: &[Prim], ray: &Ray, test: TriangleTest) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    for (i, p) in prims.iter().enumerate() {
        if let Some(h) = p.hit_in(ray, test) {
            let hit = Hit::new(i as u32, h);
            if best.is_none_or(|b| hit.is_before(&b)) {
                best = Some(hit);
            }
        }
    }
    best
}

/// The tree in every layout (binary, 4- and 8-wide, the GPU's), each without and with
/// triangle packs, named `"<layout> packed <bool>"`.
fn every_layout(bvh: &Bvh2, prims: &[Prim]) -> Vec<(String, Tree)> {
    let layouts = BvhWidth::ALL
        .map(|width| (format!("{width:?}"), Tree::new(bvh.clone(), width)))
        .into_iter()
        .chain([("gpu".to_string(), Tree::Gpu(GpuBvh::from_bvh2(bvh)))]);
    layouts
        .flat_map(|(layout, tree)| {
            [false, true].map(|packed| {
                let mut tree = tree.clone();
                if packed {
                    tree.pack_triangles(|p| prims[p as usize].triangle());
                }
                (format!("{layout} packed {packed}"), tree)
            })
        })
        .collect()
}

/// Bit-exact comparison (`-0.0 != 0.0`, same NaN payloads).
fn bits(hit: Option<Hit>) -> Option<(u32, u32, u32, u32)> {
    hit.map(|h| (h.prim, h.t.to_bits(), h.u.to_bits(), h.v.to_bits()))
}

fn check_tree<const N: usize>(
    name: &str,
    mut wide: BvhN<N>,
    prims: &[Prim],
    rays: &[Ray],
    mode: TriangleTest,
) where
    BvhN<N>: Queries,
{
    wide.pack_triangles(|p| prims[p as usize].triangle());
    wide.set_triangle_test(mode);
    let boxes: Vec<Aabb> = prims.iter().map(Prim::bounds).collect();
    wide.validate(&boxes)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let has_triangles = prims.iter().any(|p| matches!(p, Prim::Triangle(_)));
    assert_eq!(wide.has_triangle_packs(), has_triangles, "{name}");
    for isa in Isa::supported() {
        wide.set_isa(isa).unwrap();
        let packets = wide.closest_coherent(prims, rays);
        let blocked = wide.any_coherent(prims, rays);
        for ((ray, packet), blocked) in rays.iter().zip(packets).zip(blocked) {
            let expected = brute_force_in(prims, ray, mode);
            assert_eq!(
                blocked,
                expected.is_some(),
                "{name} {isa}: any hit in a packet for {ray:?}"
            );
            assert_eq!(
                bits(packet),
                bits(expected),
                "{name} {isa}: closest hit in a packet for {ray:?}"
            );
            assert_eq!(
                bits(wide.closest(prims, ray)),
                bits(expected),
                "{name} {isa}: closest hit for {ray:?}"
            );
            assert_eq!(
                wide.any(prims, ray),
                expected.is_some(),
                "{name} {isa}: any hit for {ray:?}"
            );
        }
    }
}

/// Closest and any hit with the boxes tested by the closure, and closest hits of a
/// batch traced in packets.
trait Queries {
    fn closest(&self, prims: &[Prim], ray: &Ray) -> Option<Hit>;
    fn any(&self, prims: &[Prim], ray: &Ray) -> bool;
    fn closest_coherent(&self, prims: &[Prim], rays: &[Ray]) -> Vec<Option<Hit>>;
    fn any_coherent(&self, prims: &[Prim], rays: &[Ray]) -> Vec<bool>;
}

macro_rules! queries {
    ($($t:ty),*) => {$(
        impl Queries for $t {
            fn closest(&self, prims: &[Prim], ray: &Ray) -> Option<Hit> {
                let test: Closest = &boxes_only(prims);
                self.intersect(ray, test)
            }
            fn any(&self, prims: &[Prim], ray: &Ray) -> bool {
                let blocks: Blocks = &|p, r| prims[p as usize].hit(r).is_some();
                self.occluded(ray, blocks)
            }
            fn closest_coherent(&self, prims: &[Prim], rays: &[Ray]) -> Vec<Option<Hit>> {
                let mut hits = vec![None; rays.len()];
                let (ray, answer): (MakeRay, TakeHit) = (&|i| rays[i], &mut |i, h| hits[i] = h);
                let test: Closest = &boxes_only(prims);
                self.intersect_coherent(rays.len(), ray, answer, test);
                hits
            }
            fn any_coherent(&self, prims: &[Prim], rays: &[Ray]) -> Vec<bool> {
                let mut blocked = vec![false; rays.len()];
                let (ray, answer): (MakeRay, TakeBlocked) =
                    (&|i| rays[i], &mut |i, b| blocked[i] = b);
                let boxes = boxes_only(prims);
                let blocks: Blocks = &|p, r| boxes(p, r).is_some();
                self.occluded_coherent(rays.len(), ray, answer, blocks);
                blocked
            }
        }
    )*};
}

/// The closest-hit test of the boxes among `prims`: the trees test their triangles.
/// (One type for every caller, see `common::Closest`.)
fn boxes_only(prims: &[Prim]) -> impl Fn(u32, &Ray) -> Option<PrimHit> + '_ {
    |p, r| {
        assert!(
            matches!(prims[p as usize], Prim::Box(_)),
            "triangle {p} sent to the closure"
        );
        prims[p as usize].hit(r)
    }
}

queries!(Bvh4, Bvh8);

/// Every builder's tree, 4 and 8 wide, against brute force, in both triangle modes.
fn check(prims: &[Prim], rays: &[Ray], params: &BuildParams) {
    let boxes: Vec<Aabb> = prims.iter().map(Prim::bounds).collect();
    // Spatial splits clip triangles (and cut boxes as boxes).
    let clip = |prim: u32, within: Aabb, axis: usize, position: f32| match &prims[prim as usize] {
        Prim::Triangle(v) => split_triangle(*v, within, axis, position),
        Prim::Box(_) => split_box(within, axis, position),
    };
    for &builder in Builder::ALL {
        let bvh = build_with_clipper(builder, &boxes, params, &clip);
        bvh.validate(&boxes)
            .unwrap_or_else(|e| panic!("{builder}: {e}"));
        for mode in [TriangleTest::Watertight, TriangleTest::Fast] {
            let (four, eight) = (Bvh4::from_bvh2(&bvh), Bvh8::from_bvh2(&bvh));
            check_tree(&format!("{builder} x4 {mode:?}"), four, prims, rays, mode);
            check_tree(&format!("{builder} x8 {mode:?}"), eight, prims, rays, mode);
        }
    }
}

fn vec3(range: std::ops::Range<f32>) -> impl Strategy<Value = Vec3> {
    (range.clone(), range.clone(), range).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn prim() -> impl Strategy<Value = Prim> {
    prop_oneof![
        4 => (vec3(-10.0..10.0), vec3(-2.0..2.0), vec3(-2.0..2.0))
            .prop_map(|(a, e1, e2)| Prim::Triangle([a, a + e1, a + e2])),
        1 => (vec3(-10.0..10.0), vec3(0.0..1.0)).prop_map(|(a, s)| Prim::Box(Aabb::new(a, a + s))),
    ]
}

/// Rays from anywhere, some axis-aligned (zero direction components), some with a
/// limited `[t_min, t_max]`.
fn ray() -> impl Strategy<Value = Ray> {
    let dir = prop_oneof![
        3 => vec3(-1.0..1.0),
        1 => (0usize..3, prop::bool::ANY).prop_map(|(axis, neg)| {
            let mut d = Vec3::ZERO;
            d[axis] = if neg { -1.0 } else { 1.0 };
            d
        }),
    ];
    (
        vec3(-12.0..12.0),
        dir,
        prop_oneof![Just(0.0f32), 0.0f32..5.0],
        prop_oneof![Just(f32::INFINITY), 1.0f32..20.0],
    )
        .prop_filter("non-zero direction", |(_, d, _, _)| d.length() > 1e-3)
        .prop_map(|(o, d, t_min, t_max)| Ray::new(o, d.normalize(), t_min, t_max.max(t_min)))
}

/// Rays aimed at triangle vertices, edge midpoints and centroids: shared features and
/// exact ties are where kernels would differ if they could.
fn rays_at_features(prims: &[Prim], origins: &[Vec3]) -> Vec<Ray> {
    let targets: Vec<Vec3> = prims
        .iter()
        .flat_map(|p| match p {
            Prim::Triangle([a, b, c]) => vec![*a, 0.5 * (*a + *b), (*a + *b + *c) / 3.0],
            Prim::Box(b) => vec![b.center()],
        })
        .collect();
    origins
        .iter()
        .zip(targets.iter().cycle())
        .filter_map(|(&o, &t)| {
            let d = t - o;
            (d.length() > 1e-3).then(|| Ray::new(o, d.normalize(), 0.0, f32::INFINITY))
        })
        .collect()
}

/// Packets' worth of coherent rays: from each origin, [`PACKET`] rays spread a little
/// about a vertex, edge midpoint or centroid (the first aimed at it exactly), as camera
/// rays of neighbouring pixels are; some with a short range.
fn bundles_at_features(prims: &[Prim], origins: &[Vec3]) -> Vec<Ray> {
    let exact = rays_at_features(prims, origins);
    let mut bundles = Vec::new();
    for (k, ray) in exact.iter().enumerate() {
        for lane in 0..PACKET {
            let spread = 0.002 * lane as f32;
            let dir = ray.dir + Vec3::new(spread, -0.5 * spread, 0.3 * spread);
            let t_max = if k % 3 == 0 { 5.0 } else { f32::INFINITY };
            bundles.push(Ray::new(ray.origin, dir, 0.0, t_max));
        }
    }
    bundles
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn packed_triangles_match_brute_force_in_every_kernel(
        prims in prop::collection::vec(prim(), 1..160),
        rays in prop::collection::vec(ray(), 24),
        origins in prop::collection::vec(vec3(-12.0..12.0), 24),
        max_leaf_size in 1u32..9,
        max_duplication in prop_oneof![Just(0.3f32), 0.0f32..3.0],
    ) {
        let params = BuildParams { max_leaf_size, max_duplication, ..BuildParams::default() };
        let mut all = rays;
        all.extend(rays_at_features(&prims, &origins));
        all.extend(bundles_at_features(&prims, &origins));
        check(&prims, &all, &params);
    }
}

/// The unit square at y = 0 as an `n` x `n` grid of cells, two triangles each; with
/// `repeat_every` > 0, every cell whose `i + j` it divides has its first triangle once
/// more after its second (ties go to the lower index).
fn unit_grid(n: usize, repeat_every: usize) -> Vec<Prim> {
    let at = |i: usize, j: usize| Vec3::new(i as f32 / n as f32, 0.0, j as f32 / n as f32);
    let mut prims = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let first = Prim::Triangle([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            prims.push(first.clone());
            prims.push(Prim::Triangle([at(i, j), at(i + 1, j + 1), at(i, j + 1)]));
            if repeat_every > 0 && (i + j) % repeat_every == 0 {
                prims.push(first);
            }
        }
    }
    prims
}

/// A closed, finely tessellated grid with rays straight down through its vertices and edge
/// midpoints, from inside the bounding boxes: every ray must hit, with identical answers
/// from every kernel.
#[test]
fn grid_rays_through_shared_vertices_hit_in_every_kernel() {
    let n = 12;
    let prims = unit_grid(n, 0);
    let mut rays = Vec::new();
    for i in 0..=2 * n {
        for j in 0..=2 * n {
            let p = Vec3::new(i as f32 / (2 * n) as f32, 0.0, j as f32 / (2 * n) as f32);
            rays.push(Ray::new(p + Vec3::Y, -Vec3::Y, 0.0, f32::INFINITY));
        }
    }
    for ray in &rays {
        assert!(
            brute_force(&prims, ray).is_some(),
            "{ray:?} escapes the grid"
        );
    }
    check(&prims, &rays, &BuildParams::default());
}

/// [`unit_grid`] of `n` (a repeat every 5), with 12 boxes above it and 12 sloping
/// triangles through them.
fn grid_with_boxes_and_slopes(n: usize) -> Vec<Prim> {
    let mut prims = unit_grid(n, 5);
    for k in 0..12 {
        let a = Vec3::new(0.1 * k as f32, 0.3, 0.5);
        prims.push(Prim::Box(Aabb::new(a, a + 0.05)));
        prims.push(Prim::Triangle([
            a,
            a + Vec3::X,
            a + Vec3::new(0.0, 0.4, 0.9),
        ]));
    }
    prims
}

/// Packets whose rays tie on duplicated triangles, pass exactly through shared vertices
/// and edges, run most steeply along different axes within one packet (so the packet
/// tests its leaves ray by ray), part ways (so the packet goes on ray by ray) or cannot
/// be traced: every layout and instruction set
/// answers each ray as brute force does, bit for bit.
#[test]
fn packets_of_awkward_rays_match_brute_force_in_every_layout() {
    let n = 8;
    let prims = grid_with_boxes_and_slopes(n);
    let mut rays = Vec::new();
    let eye = Vec3::new(0.5, 2.0, 0.5);
    for i in 0..=2 * n {
        for j in 0..=2 * n {
            let p = Vec3::new(i as f32 / (2 * n) as f32, 0.0, j as f32 / (2 * n) as f32);
            // Straight down through vertices and edge midpoints, and from one eye.
            rays.push(Ray::new(p + Vec3::Y, -Vec3::Y, 0.0, f32::INFINITY));
            rays.push(Ray::new(eye, p - eye, 0.0, f32::INFINITY));
            // Alternately steepest along x and y: packets that mix shears.
            let sideways = Vec3::new(if (i + j) % 2 == 0 { 3.0 } else { 0.2 }, -1.0, 0.1);
            rays.push(Ray::new(p - sideways, sideways, 0.0, 2.0));
            // A fan from one point over the whole sphere, as diffuse bounces are: packets
            // whose rays part ways below the root, and go on ray by ray.
            let (theta, phi) = (
                std::f32::consts::PI * i as f32 / (2 * n) as f32,
                std::f32::consts::TAU * j as f32 / (2 * n) as f32,
            );
            let dir = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            rays.push(Ray::new(
                Vec3::new(0.5, 0.35, 0.45),
                dir,
                0.0,
                f32::INFINITY,
            ));
        }
    }
    rays.insert(37, Ray::new(Vec3::NAN, -Vec3::Y, 0.0, f32::INFINITY));
    rays.insert(70, Ray::new(eye, Vec3::ZERO, 0.0, f32::INFINITY));
    rays.insert(90, Ray::new(eye, -Vec3::Y, 0.0, f32::NAN));
    assert_packets_answer_as_brute_force(&prims, &rays);
}

/// Packets of nearly parallel rays, as a pixel's samples and the shadow rays from its
/// points to a light are, which walk the tree as one (a frustum about the packet, not
/// each ray): every ray's closest hit and occlusion are brute force's, in every layout and
/// instruction set. The packets run the same way along every axis, and some pass by
/// the edges of boxes and triangles with part of their rays.
#[test]
fn packets_of_nearly_parallel_rays_match_brute_force_in_every_layout() {
    let n = 8;
    let prims = grid_with_boxes_and_slopes(n);
    let mut next = uniform(31);
    let mut rays = Vec::new();
    let eye = Vec3::new(-0.4, 2.0, -0.3);
    let light = Vec3::new(1.3, 1.5, 1.2);
    let pixels = 12;
    for y in 0..pixels {
        for x in 0..pixels {
            // A pixel's 16 samples (a pixel a hundredth of the grid wide) from one eye,
            // then from points on a small lens, then the shadow rays from where the first
            // ones land towards a small square light: all within a degree of each other.
            let corner = Vec3::new(x as f32, 0.0, y as f32) / pixels as f32;
            let samples: Vec<Vec3> = (0..PACKET)
                .map(|_| corner + Vec3::new(next(), 0.0, next()) * 0.0104)
                .collect();
            for &p in &samples {
                rays.push(Ray::new(eye, p - eye, 0.0, f32::INFINITY));
            }
            for &p in &samples {
                let o = eye + Vec3::new(next(), 0.0, next()) * 0.003;
                rays.push(Ray::new(o, p - o, 0.0, f32::INFINITY));
            }
            for &p in &samples {
                let to = light + Vec3::new(next(), 0.0, next()) * 0.005 - p;
                rays.push(Ray::new(p, to, 1e-4, 1.0));
            }
        }
    }
    assert_packets_answer_as_brute_force(&prims, &rays);
}

/// Traces `rays` as coherent batches (packets) in every layout and instruction set, with
/// builds of several leaf sizes, and checks each ray's closest hit and occlusion against
/// brute force.
fn assert_packets_answer_as_brute_force(prims: &[Prim], rays: &[Ray]) {
    // Rays that cannot be traced miss everything (see `Ray`).
    let expected: Vec<Option<Hit>> = rays
        .iter()
        .map(|r| brute_force(prims, r).filter(|_| r.is_traceable()))
        .collect();
    assert!(expected.iter().filter(|h| h.is_some()).count() > rays.len() / 2);
    assert!(
        expected
            .iter()
            .flatten()
            .any(|h| matches!(prims[h.prim as usize], Prim::Box(_))),
        "some rays stop on boxes"
    );
    let boxes: Vec<Aabb> = prims.iter().map(Prim::bounds).collect();
    let test: Closest = &|p, r| prims[p as usize].hit(r);
    let blocks: Blocks = &|p, r| test(p, r).is_some();
    for leaf in [1, 4, 8] {
        let params = BuildParams {
            max_leaf_size: leaf,
            ..BuildParams::default()
        };
        let bvh = build(Builder::BinnedSah, &boxes, &params);
        for (layout, mut tree) in every_layout(&bvh, prims) {
            for isa in Isa::supported() {
                if tree.set_isa(isa).is_err() {
                    continue;
                }
                let mut hits = vec![None; rays.len()];
                let coherent = RayBatch::new(rays.len()).with(Coherence::Coherent);
                let (ray, answer): (MakeRay, TakeHit) = (&|i| rays[i], &mut |i, h| hits[i] = h);
                tree.closest_hits(coherent, ray, answer, test, &mut ());
                let mut blocked = vec![false; rays.len()];
                let answer: TakeBlocked = &mut |i, b| blocked[i] = b;
                tree.any_hits(coherent, ray, answer, blocks);
                for (i, ray) in rays.iter().enumerate() {
                    assert_eq!(
                        blocked[i],
                        expected[i].is_some(),
                        "{layout}, leaves of {leaf}, {isa}: ray {i} {ray:?} blocked"
                    );
                    assert_eq!(
                        bits(hits[i]),
                        bits(expected[i]),
                        "{layout}, leaves of {leaf}, {isa}: ray {i} {ray:?}"
                    );
                }
            }
        }
    }
}

/// Long slivers in every direction, where spatial splits pay: `sbvh` cuts many of them
/// (the test demands it), and every clipped reference still answers as brute force does,
/// for rays at vertices, edge midpoints and centroids and for axis-aligned rays.
#[test]
fn clipped_slivers_match_brute_force_in_every_kernel() {
    let mut next = uniform(777);
    let mut point = || Vec3::new(next(), next(), next()) * 20.0 - Vec3::splat(10.0);
    let prims: Vec<Prim> = (0..400)
        .map(|_| {
            let (a, b) = (point(), point());
            let c = a + (b - a) * 0.01 + Vec3::new(0.2, -0.1, 0.15);
            Prim::Triangle([a, b, c])
        })
        .collect();
    let params = BuildParams {
        max_duplication: 1.0,
        ..BuildParams::default()
    };
    let boxes: Vec<Aabb> = prims.iter().map(Prim::bounds).collect();
    let clip = |prim: u32, within: Aabb, axis: usize, position: f32| match &prims[prim as usize] {
        Prim::Triangle(v) => split_triangle(*v, within, axis, position),
        Prim::Box(_) => unreachable!(),
    };
    let sbvh = build_with_clipper(Builder::Sbvh, &boxes, &params, &clip);
    assert!(sbvh.has_spatial_splits());
    assert!(sbvh.prim_indices().len() > boxes.len() * 11 / 10);
    let origins: Vec<Vec3> = (0..600).map(|_| point() * 1.2).collect();
    let mut rays = rays_at_features(&prims, &origins);
    for (i, o) in origins.iter().enumerate().take(300) {
        let mut d = Vec3::ZERO;
        d[i % 3] = if i % 2 == 0 { 1.0 } else { -1.0 };
        rays.push(Ray::new(*o, d, 0.0, f32::INFINITY));
    }
    check(&prims, &rays, &params);
}

/// A tree deeper than the walk's stack holds inline (128 entries): triangles along a
/// line, spaced ever wider, so that the splits peel them off one or two at a time, with
/// a box among them now and then (a leaf the walk tests apart). Rays along the line
/// meet them all, stacking the far side of every level they pass.
#[test]
fn deep_trees_match_brute_force() {
    let prims: Vec<Prim> = (0..300)
        .map(|i| {
            let x = 1.25f32.powi(i);
            match i % 11 {
                5 => Prim::Box(Aabb::new(Vec3::new(x, -0.5, -0.5), Vec3::new(x, 0.5, 0.5))),
                _ => Prim::Triangle([
                    Vec3::new(x, -1.0, -1.0),
                    Vec3::new(x, 2.0, -1.0),
                    Vec3::new(x, -1.0, 2.0),
                ]),
            }
        })
        .collect();
    let along = |o: Vec3, d: Vec3, t_max: f32| Ray::new(o, d.normalize(), 0.0, t_max);
    let rays = [
        along(Vec3::new(-1.0, 0.1, 0.2), Vec3::X, f32::INFINITY),
        along(
            Vec3::new(-1.0, 0.7, -0.3),
            Vec3::new(1.0, 1e-9, 0.0),
            f32::INFINITY,
        ),
        along(Vec3::new(1e30, 0.2, 0.1), -Vec3::X, f32::INFINITY),
        along(Vec3::new(1e6, 0.0, 0.0), -Vec3::X, 1e3),
        along(Vec3::new(30.0, 0.3, 0.3), Vec3::X, 1e9),
    ];
    let boxes: Vec<Aabb> = prims.iter().map(Prim::bounds).collect();
    let bvh = build(Builder::BinnedSah, &boxes, &BuildParams::default());
    let depth = Bvh8::from_bvh2(&bvh).stats(&SahCosts::default()).max_depth;
    // `N - 1` entries for each interior level (`max_depth` counts the leaves' too).
    assert!(
        7 * (depth - 1) > 128,
        "an 8-wide tree of depth {depth} fits the inline stack"
    );
    check(&prims, &rays, &BuildParams::default());
}

/// Parallel subtree building happens above a few thousand primitives, parallel binning
/// above 32,768: a validated build of 40,000 triangles from every parallel builder,
/// packed, against brute force on a sample (a tree large enough to be traversed with
/// prefetches).
#[test]
fn large_builds_validate_and_match_brute_force() {
    let mut next = uniform(12345);
    let mut point = || Vec3::new(next(), next(), next()) * 100.0;
    let prims: Vec<Prim> = (0..40_000)
        .map(|_| {
            let a = point();
            let e = Vec3::new(1.0, 0.5, 0.25);
            Prim::Triangle([a, a + e, a + Vec3::new(e.z, e.x, e.y)])
        })
        .collect();
    let boxes: Vec<Aabb> = prims.iter().map(Prim::bounds).collect();
    let rays: Vec<Ray> = (0..200)
        .map(|i| {
            let o = Vec3::new(-10.0, 50.0, 50.0);
            let target = prims[i * 97].bounds().center();
            Ray::new(o, (target - o).normalize(), 0.0, f32::INFINITY)
        })
        .collect();
    for builder in [
        Builder::BinnedSah,
        Builder::Lbvh,
        Builder::Ploc,
        Builder::SweepSah,
    ] {
        let bvh = build(builder, &boxes, &BuildParams::default());
        bvh.validate(&boxes)
            .unwrap_or_else(|e| panic!("{builder}: {e}"));
        // Large enough that traversal prefetches stacked children.
        let mut packed = Bvh8::from_bvh2(&bvh);
        packed.pack_triangles(|p| prims[p as usize].triangle());
        assert!(TreeView::memory_bytes(&packed) > 2 * PREFETCH_ABOVE_BYTES);
        let modes = match builder {
            Builder::BinnedSah => &[TriangleTest::Watertight, TriangleTest::Fast][..],
            _ => &[TriangleTest::Watertight],
        };
        for &mode in modes {
            let name = format!("{builder} x8 {mode:?}");
            check_tree(&name, Bvh8::from_bvh2(&bvh), &prims, &rays, mode);
        }
    }
}

/// The batch calls answer each ray exactly as the single-ray calls do, whatever the
/// chunking and thread count.
#[test]
fn batch_calls_equal_single_ray_calls() {
    let prims: Vec<Prim> = (0..3000)
        .map(|i| {
            let a = Vec3::new((i % 17) as f32, (i / 17 % 13) as f32, (i / 221) as f32);
            if i % 5 == 0 {
                Prim::Box(Aabb::new(a, a + 0.3))
            } else {
                Prim::Triangle([a, a + Vec3::X * 0.9, a + Vec3::new(0.2, 0.8, 0.4)])
            }
        })
        .collect();
    let blas = Blas::build(Prims(prims), &BlasParams::default());
    let wide = match blas.tree() {
        Some(Tree::Eight(wide)) => wide,
        _ => unreachable!("the default layout is 8-wide"),
    };
    let prims = &blas.geometry().0;
    let rays: Vec<Ray> = (0..5000)
        .map(|i| {
            let o = Vec3::new(-5.0, (i % 70) as f32 * 0.2, (i / 70) as f32 * 0.2);
            let d = Vec3::new(1.0, ((i * 7) % 11) as f32 * 0.05 - 0.25, 0.1);
            Ray::new(o, d.normalize(), 0.0, f32::INFINITY)
        })
        .collect();
    let mut hits = vec![None; rays.len()];
    let mut blocked = vec![false; rays.len()];
    blas.intersect_batch(&rays, &mut hits, ALL_MASKS);
    blas.occluded_batch(&rays, &mut blocked, ALL_MASKS);
    assert!(
        hits.iter().filter(|h| h.is_some()).count() > 1000,
        "the rays should mostly hit"
    );
    for (i, ray) in rays.iter().enumerate() {
        assert_eq!(bits(hits[i]), bits(wide.closest(prims, ray)), "ray {i}");
        assert_eq!(bits(hits[i]), bits(blas.intersect(ray)), "ray {i}");
        assert_eq!(blocked[i], hits[i].is_some(), "ray {i}");
    }
}

/// `Tree::intersect_each` and `occluded_each` (one layout and kernel choice for many rays)
/// answer each ray, in order, exactly as the single-ray calls and brute force do, in every
/// layout, packed or not.
#[test]
fn each_calls_equal_single_ray_calls_in_every_layout() {
    let prims: Vec<Prim> = (0..2000)
        .map(|i| {
            let a = Vec3::new((i % 13) as f32, (i / 13 % 11) as f32, (i / 143) as f32);
            if i % 4 == 0 {
                Prim::Box(Aabb::new(a, a + 0.4))
            } else {
                Prim::Triangle([a, a + Vec3::Y * 0.9, a + Vec3::new(0.7, 0.3, 0.5)])
            }
        })
        .collect();
    let boxes: Vec<Aabb> = prims.iter().map(Prim::bounds).collect();
    let bvh = build(Builder::BinnedSah, &boxes, &BuildParams::default());
    let rays: Vec<Ray> = (0..3000)
        .map(|i| {
            let o = Vec3::new((i % 50) as f32 * 0.3, -4.0, (i / 50) as f32 * 0.25);
            let d = Vec3::new(((i * 5) % 9) as f32 * 0.04 - 0.16, 1.0, 0.05);
            Ray::new(
                o,
                d.normalize(),
                0.0,
                if i % 7 == 0 { 6.0 } else { f32::INFINITY },
            )
        })
        .collect();
    let expected: Vec<Option<Hit>> = rays.iter().map(|r| brute_force(&prims, r)).collect();
    assert!(expected.iter().filter(|h| h.is_some()).count() > 500);
    let test: Closest = &|p, r| prims[p as usize].hit(r);
    let blocks: Blocks = &|p, r| test(p, r).is_some();
    let ray: MakeRay = &|i| rays[i];
    for (layout, tree) in every_layout(&bvh, &prims) {
        let mut hits = vec![None; rays.len()];
        let mut order = Vec::new();
        let answer: TakeHit = &mut |i, h| {
            order.push(i);
            hits[i] = h;
        };
        tree.closest_hits(RayBatch::new(rays.len()), ray, answer, test, &mut ());
        assert!(order.iter().copied().eq(0..rays.len()), "answers in order");
        let mut blocked = vec![false; rays.len()];
        let answer: TakeBlocked = &mut |i, b| blocked[i] = b;
        tree.any_hits(RayBatch::new(rays.len()), ray, answer, blocks);
        for (i, ray) in rays.iter().enumerate() {
            let name = format!("{layout}, ray {i}");
            assert_eq!(bits(hits[i]), bits(expected[i]), "{name}");
            assert_eq!(
                bits(hits[i]),
                bits(tree.intersect_counted(ray, test, &mut ())),
                "{name}"
            );
            assert_eq!(blocked[i], expected[i].is_some(), "{name}");
        }
    }
}

/// Over a tree larger than the cache, batches of scattered rays are traced in the order of
/// their origins: every answer still lands on its own ray, equal to the single-ray call's,
/// and shuffling the batch shuffles the answers the same way.
#[test]
fn reordered_batches_answer_each_ray_in_place() {
    let mut next = uniform(777);
    let prims: Vec<Prim> = (0..40_000)
        .map(|i| {
            let a = Vec3::new(next(), next(), next()) * 100.0;
            if i % 10 == 0 {
                Prim::Box(Aabb::new(a, a + 0.5))
            } else {
                Prim::Triangle([
                    a,
                    a + Vec3::new(2.0, 0.5, 0.2),
                    a + Vec3::new(0.3, 2.0, 0.9),
                ])
            }
        })
        .collect();
    let blas = Blas::build(Prims(prims), &BlasParams::default());
    let prims = &blas.geometry().0;
    assert!(blas.orders_batches(), "a tree larger than the cache");
    // Rays from scattered origins in all directions, some with a short range.
    let rays: Vec<Ray> = (0..3 * canopy_bvh::RAY_ORDER_MIN)
        .map(|i| {
            let o = Vec3::new(next(), next(), next()) * 100.0;
            let d = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
            let t_max = if i % 5 == 0 { 3.0 } else { f32::INFINITY };
            Ray::new(o, d.normalize(), 0.0, t_max)
        })
        .collect();
    assert!(canopy_bvh::RayOrder::by_origin(rays.len(), |i| rays[i].origin).is_some());
    let test: Closest = &|p, r| prims[p as usize].hit(r);
    let blocks: Blocks = &|p, r| test(p, r).is_some();
    let mut hits = vec![None; rays.len()];
    let mut blocked = vec![false; rays.len()];
    blas.intersect_batch(&rays, &mut hits, ALL_MASKS);
    blas.occluded_batch(&rays, &mut blocked, ALL_MASKS);
    assert!(hits.iter().filter(|h| h.is_some()).count() > rays.len() / 10);
    let tree = blas.tree().unwrap();
    for (i, ray) in rays.iter().enumerate() {
        assert_eq!(bits(hits[i]), bits(blas.intersect(ray)), "ray {i}");
        assert_eq!(
            bits(hits[i]),
            bits(tree.intersect_counted(ray, test, &mut ())),
            "ray {i}"
        );
        assert_eq!(blocked[i], tree.occluded(ray, blocks), "ray {i}");
    }
    let reversed: Vec<Ray> = rays.iter().rev().copied().collect();
    let mut hits_reversed = vec![None; rays.len()];
    blas.intersect_batch(&reversed, &mut hits_reversed, ALL_MASKS);
    assert!(hits_reversed
        .iter()
        .rev()
        .map(|&h| bits(h))
        .eq(hits.iter().map(|&h| bits(h))));
}

/// Rays that cannot hit anything (NaN or infinite origin or direction, a zero direction,
/// a direction denormal in every component, a NaN end) miss in every layout, kernel and
/// structure and in brute force, and any-hit agrees; rays with tiny but normal directions
/// get brute force's answer, and no hit anywhere has an infinite `t`.
#[test]
fn degenerate_rays_miss_everywhere_and_no_hit_is_at_infinity() {
    let tri = [
        Vec3::new(-1.0, -1.0, -2.0),
        Vec3::new(1.0, -1.0, -2.0),
        Vec3::new(0.0, 1.0, -2.0),
    ];
    let mut prims = vec![Prim::Triangle(tri)];
    // A few more so that the trees have interior nodes and packs of several lanes.
    for i in 0..40 {
        let a = Vec3::new(
            (i % 7) as f32 - 3.0,
            (i / 7) as f32 - 3.0,
            -3.0 - i as f32 * 0.1,
        );
        prims.push(if i % 5 == 0 {
            Prim::Box(Aabb::new(a, a + 0.3))
        } else {
            Prim::Triangle([a, a + Vec3::X * 0.5, a + Vec3::Y * 0.5])
        });
    }
    let o = Vec3::ZERO;
    let degenerate = [
        Ray::new(o, Vec3::new(0.0, 0.0, -1e-45), 0.0, f32::INFINITY),
        Ray::new(o, Vec3::new(1e-40, -1e-39, -1e-45), 0.0, f32::INFINITY),
        Ray::new(o, Vec3::ZERO, 0.0, f32::INFINITY),
        Ray::new(o, Vec3::new(0.0, 0.0, -0.0), 0.0, f32::INFINITY),
        Ray::new(o, Vec3::new(f32::NAN, 0.0, -1.0), 0.0, f32::INFINITY),
        Ray::new(Vec3::new(0.0, f32::NAN, 0.0), -Vec3::Z, 0.0, f32::INFINITY),
        Ray::new(
            Vec3::new(0.0, 0.0, f32::INFINITY),
            -Vec3::Z,
            0.0,
            f32::INFINITY,
        ),
        Ray::new(
            o,
            Vec3::new(0.0, 0.0, f32::NEG_INFINITY),
            0.0,
            f32::INFINITY,
        ),
        Ray::new(o, -Vec3::Z, f32::NAN, f32::INFINITY),
        Ray::new(o, -Vec3::Z, 0.0, f32::NAN),
    ];
    let tiny = [1e-20f32, 1e-30, 1e-36, f32::MIN_POSITIVE]
        .map(|s| Ray::new(o, Vec3::new(0.0, 0.0, -s), 0.0, f32::INFINITY));
    for ray in &degenerate {
        assert!(!ray.is_traceable(), "{ray:?}");
    }
    for ray in &tiny {
        assert!(ray.is_traceable(), "{ray:?}");
    }
    // Small directions are rays like any other: t grows as the direction shrinks.
    assert!(brute_force(&prims, &tiny[0]).is_some_and(|h| (h.t * 1e-20 - 2.0).abs() < 1e-5));

    let boxes: Vec<Aabb> = prims.iter().map(Prim::bounds).collect();
    let test: Closest = &|p, r| prims[p as usize].hit(r).filter(|_| r.is_traceable());
    let blocks: Blocks = &|p, r| test(p, r).is_some();
    for &builder in Builder::ALL {
        let bvh = build(builder, &boxes, &BuildParams::default());
        for (layout, mut tree) in every_layout(&bvh, &prims) {
            for isa in Isa::supported() {
                if tree.set_isa(isa).is_err() {
                    continue;
                }
                let name = format!("{builder} {layout} {isa}");
                for ray in &degenerate {
                    assert_eq!(
                        tree.intersect_counted(ray, test, &mut ()),
                        None,
                        "{name} {ray:?}"
                    );
                    assert!(!tree.occluded(ray, blocks), "{name} {ray:?}");
                }
                for ray in &tiny {
                    let hit = tree.intersect_counted(ray, test, &mut ());
                    assert_eq!(bits(hit), bits(brute_force(&prims, ray)), "{name} {ray:?}");
                    assert!(
                        hit.is_none_or(|h| h.t.is_finite()),
                        "{name} {ray:?}: {hit:?}"
                    );
                }
            }
        }
    }
    // Structures that own their geometry, brute force (`None`) included.
    for builder in [None, Some(Builder::BinnedSah), Some(Builder::Lbvh)] {
        for width in BvhWidth::ALL {
            let blas = Blas::build(
                Prims(prims.clone()),
                &BlasParams {
                    builder,
                    width,
                    ..BlasParams::default()
                },
            );
            for ray in &degenerate {
                assert_eq!(blas.intersect(ray), None, "{builder:?} {width:?} {ray:?}");
                assert!(!blas.occluded(ray), "{builder:?} {width:?} {ray:?}");
            }
            for ray in &tiny {
                let hit = blas.intersect(ray);
                assert_eq!(
                    bits(hit),
                    bits(brute_force(&prims, ray)),
                    "{builder:?} {width:?}"
                );
                assert!(
                    hit.is_none_or(|h| h.t.is_finite()),
                    "{builder:?} {width:?} {hit:?}"
                );
            }
            // Through instances, the top tree built by the same builder.
            let params = BlasParams {
                builder,
                width,
                ..BlasParams::default()
            };
            let instances = vec![
                canopy_bvh::Instance::new(0, glam::Affine3A::IDENTITY),
                canopy_bvh::Instance::new(0, glam::Affine3A::from_translation(Vec3::X * 9.0)),
            ];
            let tlas = canopy_bvh::Tlas::build(vec![blas], instances, &params).unwrap();
            for ray in &degenerate {
                assert_eq!(
                    tlas.intersect(ray),
                    None,
                    "tlas {builder:?} {width:?} {ray:?}"
                );
                assert!(!tlas.occluded(ray), "tlas {builder:?} {width:?} {ray:?}");
            }
        }
    }
}

/// A mesh under a floor and beside a few boxes (a renderer's scene: mostly triangles) is
/// built for its packs, leaves of up to two, as a mesh alone is; a scene where other
/// primitives are more than a tenth keeps the caller's leaf size. Both answer as brute
/// force does.
#[test]
fn mostly_triangles_are_built_for_packs() {
    let grid = unit_grid(16, 0);
    let boxes_beside = |n: usize| -> Vec<Prim> {
        let floor = Prim::Box(Aabb::new(
            Vec3::new(-2.0, -0.2, -2.0),
            Vec3::new(3.0, -0.1, 3.0),
        ));
        let beside = (1..n).map(|k| {
            let a = Vec3::new(0.05 * k as f32, 0.3, 0.5);
            Prim::Box(Aabb::new(a, a + 0.03))
        });
        std::iter::once(floor).chain(beside).collect()
    };
    let mut u = uniform(41);
    let rays: Vec<Ray> = (0..2000)
        .map(|_| {
            let o = Vec3::new(u() * 1.4 - 0.2, 0.5 + u(), u() * 1.4 - 0.2);
            let d = Vec3::new(u() - 0.5, -1.0, u() - 0.5);
            Ray::new(o, d.normalize(), 0.0, f32::INFINITY)
        })
        .collect();
    // 512 triangles with 3 boxes (99% triangles), then with 80 (86%).
    for (others, packed) in [(3, true), (80, false)] {
        let prims: Vec<Prim> = grid.iter().cloned().chain(boxes_beside(others)).collect();
        let params = BlasParams::new(Some(Builder::BinnedSah), BvhWidth::Eight);
        let blas = Blas::build(Prims(prims.clone()), &params);
        let tree = blas.tree().expect("a tree");
        let stats = tree.stats(&BuildParams::default().sah);
        let context = format!("{others} boxes beside 512 triangles");
        assert_eq!(stats.max_leaf_size > 4, packed, "{context}: {stats:?}");
        assert!(stats.max_leaf_size <= 8, "{context}: {stats:?}");
        let expected: Vec<Option<Hit>> = rays.iter().map(|r| brute_force(&prims, r)).collect();
        let hits = expected.iter().flatten();
        let boxes_hit = hits.clone().filter(|h| h.prim >= 512).count();
        assert!(
            boxes_hit > 100 && hits.count() - boxes_hit > 100,
            "{context}"
        );
        for (i, ray) in rays.iter().enumerate() {
            assert_eq!(
                bits(blas.intersect(ray)),
                bits(expected[i]),
                "{context}: ray {i}"
            );
            assert_eq!(
                blas.occluded(ray),
                expected[i].is_some(),
                "{context}: ray {i}"
            );
        }
    }
}

/// Every structure a [`Blas`] can be (brute force, every builder at every width) answers
/// in the fast triangle mode as a loop over the primitives in that mode does: the packs'
/// kernels and the caller's closures (binary trees, brute force) test alike. The rays
/// aim at edge midpoints, where the modes differ, and some of them must.
#[test]
fn every_structure_answers_in_the_fast_mode_as_brute_force_does() {
    let mut next = uniform(23);
    let mut coordinate = move || 8.0 * next() - 4.0;
    let mut point = move || Vec3::new(coordinate(), coordinate(), coordinate());
    let mut prims: Vec<Prim> = (0..300)
        .map(|_| {
            let a = point();
            Prim::Triangle([a, a + 0.3 * point(), a + 0.3 * point()])
        })
        .collect();
    prims.push(Prim::Box(Aabb::new(Vec3::ZERO, Vec3::ONE)));
    let origins: Vec<Vec3> = (0..900).map(|_| 3.0 * point()).collect();
    let rays = rays_at_features(&prims, &origins);
    let fast = |ray: &Ray| brute_force_in(&prims, ray, TriangleTest::Fast);
    let differ = rays
        .iter()
        .filter(|r| bits(fast(r)) != bits(brute_force(&prims, r)))
        .count();
    assert!(differ > 0, "no ray tells the modes apart");
    let mut structures = vec![BlasParams::new(None, BvhWidth::Two)];
    for &builder in Builder::ALL {
        structures.extend(BvhWidth::ALL.map(|width| BlasParams::new(Some(builder), width)));
    }
    for params in structures {
        let params = BlasParams {
            triangle_test: TriangleTest::Fast,
            ..params
        };
        let name = format!("{:?} {:?}", params.builder, params.width);
        let blas = Blas::build(Prims(prims.clone()), &params);
        let mut hits = vec![None; rays.len()];
        blas.intersect_each(rays.len(), ALL_MASKS, |i| rays[i], |i, h| hits[i] = h);
        for (ray, hit) in rays.iter().zip(hits) {
            let expected = fast(ray);
            assert_eq!(bits(hit), bits(expected), "{name} {ray:?}");
            assert_eq!(blas.occluded(ray), expected.is_some(), "{name} {ray:?}");
        }
    }
}
