//! Spatial split BVH (Stich, Friedrich & Dietrich, "Spatial splits in bounding volume
//! hierarchies", HPG 2009).
//!
//! A top-down binned SAH build over *references*: a primitive and a box that holds the
//! part of it a node owns. Where the best object split leaves children that overlap
//! (more than `MIN_OVERLAP` of the root's area), the builder also bins the node's box
//! into equal slabs, cuts every reference at the slab planes (through a [`Clipper`],
//! which knows the geometry) and prices every plane; a spatial split that wins sends
//! each reference it crosses to both sides, clipped, unless putting it whole on one side
//! costs less ("unsplitting"). Duplicates are bounded by a budget
//! ([`BuildParams::max_duplication`] times the primitives), shared out to children in
//! proportion to their references, so the tree does not depend on thread scheduling.

use super::box4::Box4;
use super::clip::Clipper;
use super::top_down::splice;
use crate::{Aabb, BuildParams, Bvh2, Bvh2Node};
use glam::{Vec3, Vec3A};

/// Below this many references on either side, a subtree is built on one thread.
const PARALLEL_THRESHOLD: usize = 4096;

/// Spatial splits are tried where the object split's children overlap by more than this
/// fraction of the root's surface area (Stich's alpha).
const MIN_OVERLAP: f32 = 1e-5;

/// Most bins per axis, for object and spatial splits alike.
const MAX_BINS: usize = super::binned_sah::MAX_BINS;

/// A primitive, or the part of it that one node owns.
#[derive(Clone, Copy)]
struct Ref {
    bounds: Box4,
    prim: u32,
}

impl Ref {
    fn centroid(&self) -> Vec3A {
        let c = (self.bounds.min + self.bounds.max) * 0.5;
        // An empty box (never hit) has a NaN centre; any point will do.
        if c.is_nan() {
            Vec3A::ZERO
        } else {
            c
        }
    }
}

/// A node to build: its references, their bounds, and the duplicates its subtree may
/// still make.
struct Work {
    refs: Vec<Ref>,
    bounds: Aabb,
    budget: usize,
}

enum Decision {
    Leaf(Vec<Ref>),
    Split(Work, Work),
}

/// The cheapest boundary of a row of bins.
#[derive(Clone, Copy)]
struct Boundary {
    /// The first bin of the right side.
    index: usize,
    cost: f32,
    left: Aabb,
    right: Aabb,
    n_left: u32,
    n_right: u32,
}

/// A split by centroid bins: `bin = (centroid[axis] - lo) * scale`.
struct ObjectSplit {
    axis: usize,
    lo: f32,
    scale: f32,
    bins: usize,
    at: Boundary,
}

/// A split by the plane `axis = position`, between slabs `lo + i / scale`.
struct SpatialSplit {
    axis: usize,
    lo: f32,
    scale: f32,
    bins: usize,
    position: f32,
    at: Boundary,
}

pub(crate) fn build(
    boxes: &[Aabb],
    params: &BuildParams,
    clipper: &(impl Clipper + ?Sized),
) -> Bvh2 {
    if boxes.is_empty() {
        return Bvh2::default();
    }
    let refs: Vec<Ref> = boxes
        .iter()
        .enumerate()
        .map(|(i, &b)| Ref {
            bounds: b.into(),
            prim: i as u32,
        })
        .collect();
    let bounds = boxes.iter().fold(Aabb::EMPTY, |a, &b| a.union(b));
    let budget = (boxes.len() as f64 * params.max_duplication.max(0.0) as f64) as usize;
    let builder = Sbvh {
        clipper,
        params,
        min_overlap: MIN_OVERLAP * bounds.surface_area(),
    };
    let (nodes, prims) = builder.subtree(Work {
        refs,
        bounds,
        budget,
    });
    let clipped = prims.len() != boxes.len()
        || nodes.iter().any(|node| {
            node.is_leaf() && {
                let first = node.first as usize;
                let whole = prims[first..first + node.count as usize]
                    .iter()
                    .fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize]));
                whole != node.bounds()
            }
        });
    let mut bvh = Bvh2::from_parts(nodes, prims);
    bvh.spatial_splits = clipped;
    bvh
}

struct Sbvh<'a, C: ?Sized> {
    clipper: &'a C,
    params: &'a BuildParams,
    /// Overlap area above which spatial splits are tried.
    min_overlap: f32,
}

impl<C: Clipper + ?Sized> Sbvh<'_, C> {
    /// Nodes and primitive indices of the subtree of `work`, root first.
    fn subtree(&self, work: Work) -> (Vec<Bvh2Node>, Vec<u32>) {
        let bounds = work.bounds;
        match self.decide(work) {
            Decision::Split(left, right)
                if left.refs.len() >= PARALLEL_THRESHOLD
                    && right.refs.len() >= PARALLEL_THRESHOLD =>
            {
                let ((left_nodes, mut prims), (right_nodes, mut right_prims)) =
                    rayon::join(|| self.subtree(left), || self.subtree(right));
                let nodes = splice(bounds, left_nodes, right_nodes, prims.len() as u32);
                prims.append(&mut right_prims);
                (nodes, prims)
            }
            decision => self.serial(bounds, decision),
        }
    }

    /// Builds a subtree on this thread from an explicit stack (no recursion, so a deep
    /// tree cannot overflow the call stack); its root's decision is made.
    fn serial(&self, bounds: Aabb, root: Decision) -> (Vec<Bvh2Node>, Vec<u32>) {
        let placeholder = Bvh2Node::interior(Aabb::EMPTY, 0);
        let mut nodes = vec![placeholder];
        let mut prims = Vec::new();
        let mut stack = vec![(0usize, bounds, root)];
        while let Some((index, bounds, decision)) = stack.pop() {
            match decision {
                Decision::Leaf(refs) => {
                    nodes[index] = Bvh2Node::leaf(bounds, prims.len() as u32, refs.len() as u32);
                    prims.extend(refs.iter().map(|r| r.prim));
                }
                Decision::Split(left, right) => {
                    let first = nodes.len();
                    nodes[index] = Bvh2Node::interior(bounds, first as u32);
                    nodes.extend([placeholder; 2]);
                    let (left_bounds, right_bounds) = (left.bounds, right.bounds);
                    stack.push((first + 1, right_bounds, self.decide(right)));
                    stack.push((first, left_bounds, self.decide(left)));
                }
            }
        }
        (nodes, prims)
    }

    /// A leaf, or the two children of the cheapest split.
    fn decide(&self, work: Work) -> Decision {
        let Work {
            refs,
            bounds,
            budget,
        } = work;
        let n = refs.len();
        let must_split = n > self.params.max_leaf_size as usize;
        if n <= 1 {
            return Decision::Leaf(refs);
        }
        if !must_split && self.params.leaf_beats_any_split(n) {
            return Decision::Leaf(refs);
        }
        let leaf_cost = self.params.leaf_cost(n);
        let object = self.object_split(&refs, bounds);
        let overlap = object.as_ref().map_or(f32::INFINITY, |o| {
            o.at.left.intersection(o.at.right).surface_area()
        });
        let spatial = (budget > 0 && overlap > self.min_overlap)
            .then(|| self.spatial_split(&refs, bounds, budget))
            .flatten();
        let object_cost = object.as_ref().map_or(f32::INFINITY, |o| o.at.cost);
        let spatial_cost = spatial.as_ref().map_or(f32::INFINITY, |s| s.at.cost);
        if !(object_cost.min(spatial_cost) < leaf_cost || must_split) {
            return Decision::Leaf(refs);
        }
        let (mut left, mut right) = match (spatial, object) {
            (Some(s), _) if spatial_cost < object_cost => self.spatial_partition(refs, &s),
            (_, Some(o)) => object_partition(refs, &o),
            _ => (refs, Vec::new()),
        };
        if left.is_empty() || right.is_empty() {
            left.append(&mut right);
            if !must_split {
                return Decision::Leaf(left);
            }
            right = left.split_off(left.len() / 2);
        }
        // Share what is left of the budget in proportion to the references.
        let (nl, nr) = (left.len(), right.len());
        let left_over = budget.saturating_sub((nl + nr).saturating_sub(n));
        let left_budget = (left_over as u64 * nl as u64 / (nl + nr) as u64) as usize;
        Decision::Split(
            Work {
                bounds: bounds_of(&left),
                refs: left,
                budget: left_budget,
            },
            Work {
                bounds: bounds_of(&right),
                refs: right,
                budget: left_over - left_budget,
            },
        )
    }

    /// The SAH price of `n_left` and `n_right` references in boxes of these areas,
    /// relative to the parent's area (`inv_area` = 1 / its area).
    fn price(&self, inv_area: f32, left: f32, n_left: u32, right: f32, n_right: u32) -> f32 {
        let p = self.params;
        p.sah.traversal
            + p.sah.intersection
                * inv_area
                * (left * p.leaf_tests(n_left as usize) + right * p.leaf_tests(n_right as usize))
    }

    /// The cheapest boundary between `boxes`: the left side counts `entering` of the bins
    /// before it, the right side `leaving` of the bins from it on. `accept` vetoes counts.
    fn sweep(
        &self,
        boxes: &[Box4],
        entering: &[u32],
        leaving: &[u32],
        inv_area: f32,
        accept: impl Fn(u32, u32) -> bool,
    ) -> Option<Boundary> {
        let bins = boxes.len();
        let mut right_boxes = [Box4::EMPTY; MAX_BINS];
        let mut right_counts = [0u32; MAX_BINS];
        let (mut acc, mut count) = (Box4::EMPTY, 0);
        for b in (1..bins).rev() {
            acc = acc.union(boxes[b]);
            count += leaving[b];
            right_boxes[b] = acc;
            right_counts[b] = count;
        }
        let (mut acc, mut count) = (Box4::EMPTY, 0);
        let mut best: Option<Boundary> = None;
        for b in 1..bins {
            acc = acc.union(boxes[b - 1]);
            count += entering[b - 1];
            let n_right = right_counts[b];
            if count == 0 || n_right == 0 || !accept(count, n_right) {
                continue;
            }
            let (left, right) = (acc.aabb(), right_boxes[b].aabb());
            let cost = self.price(
                inv_area,
                left.surface_area(),
                count,
                right.surface_area(),
                n_right,
            );
            if best.is_none_or(|s| cost < s.cost) {
                best = Some(Boundary {
                    index: b,
                    cost,
                    left,
                    right,
                    n_left: count,
                    n_right,
                });
            }
        }
        best
    }

    /// The cheapest split by centroid bins over all three axes, or `None` when every
    /// centroid coincides.
    fn object_split(&self, refs: &[Ref], bounds: Aabb) -> Option<ObjectSplit> {
        let bins = self.params.bins as usize;
        let centroids = refs.iter().fold(Box4::EMPTY, |b, r| b.grow(r.centroid()));
        let extent = Vec3::from(centroids.max - centroids.min);
        let lo = Vec3::from(centroids.min);
        let scale = Vec3::select(extent.cmpgt(Vec3::ZERO), bins as f32 / extent, Vec3::ZERO);
        let mut boxes = [[Box4::EMPTY; MAX_BINS]; 3];
        let mut counts = [[0u32; MAX_BINS]; 3];
        let last = glam::UVec3::splat(bins as u32 - 1);
        for r in refs {
            let index = ((r.centroid() - Vec3A::from(lo)) * Vec3A::from(scale))
                .as_uvec3()
                .min(last);
            for axis in 0..3 {
                let i = index[axis] as usize;
                boxes[axis][i] = boxes[axis][i].union(r.bounds);
                counts[axis][i] += 1;
            }
        }
        let inv_area = 1.0 / bounds.surface_area().max(f32::MIN_POSITIVE);
        let mut best: Option<ObjectSplit> = None;
        for axis in 0..3 {
            if extent[axis] <= 0.0 {
                continue;
            }
            let counts = &counts[axis][..bins];
            let Some(at) = self.sweep(&boxes[axis][..bins], counts, counts, inv_area, |_, _| true)
            else {
                continue;
            };
            if best.as_ref().is_none_or(|s| at.cost < s.at.cost) {
                best = Some(ObjectSplit {
                    axis,
                    lo: lo[axis],
                    scale: scale[axis],
                    bins,
                    at,
                });
            }
        }
        best
    }

    /// The cheapest plane between equal slabs of `bounds` on any axis that duplicates at
    /// most `budget` references.
    fn spatial_split(&self, refs: &[Ref], bounds: Aabb, budget: usize) -> Option<SpatialSplit> {
        let bins = self.params.bins as usize;
        let n = refs.len() as u32;
        let extent = bounds.extent();
        let inv_area = 1.0 / bounds.surface_area().max(f32::MIN_POSITIVE);
        let mut best: Option<SpatialSplit> = None;
        for axis in 0..3 {
            if extent[axis] <= 0.0 {
                continue;
            }
            let (lo, scale) = (bounds.min[axis], bins as f32 / extent[axis]);
            let slabs = Slabs { lo, scale, bins };
            let mut boxes = [Box4::EMPTY; MAX_BINS];
            let mut entering = [0u32; MAX_BINS];
            let mut leaving = [0u32; MAX_BINS];
            for r in refs {
                let (first, last) = slabs.span(r, axis);
                entering[first] += 1;
                leaving[last] += 1;
                // Chop the reference slab by slab, from the left.
                let mut rest = r.bounds.aabb();
                for (b, slab) in boxes.iter_mut().enumerate().take(last).skip(first) {
                    let (piece, above) = self.clipper.split(r.prim, rest, axis, slabs.plane(b + 1));
                    *slab = slab.union(piece.into());
                    rest = above;
                }
                boxes[last] = boxes[last].union(rest.into());
            }
            let accept = |nl: u32, nr: u32| (nl + nr).saturating_sub(n) as usize <= budget;
            let Some(at) = self.sweep(
                &boxes[..bins],
                &entering[..bins],
                &leaving[..bins],
                inv_area,
                accept,
            ) else {
                continue;
            };
            if best.as_ref().is_none_or(|s| at.cost < s.at.cost) {
                best = Some(SpatialSplit {
                    axis,
                    lo,
                    scale,
                    bins,
                    position: slabs.plane(at.index),
                    at,
                });
            }
        }
        best
    }

    /// Sends each reference to the side of the plane it lies on; one that the plane
    /// crosses goes whole to one side when that is cheaper than splitting it (Stich's
    /// unsplitting, priced with the binned sides), else clipped to both.
    fn spatial_partition(&self, refs: Vec<Ref>, split: &SpatialSplit) -> (Vec<Ref>, Vec<Ref>) {
        let slabs = Slabs {
            lo: split.lo,
            scale: split.scale,
            bins: split.bins,
        };
        let at = &split.at;
        let (area_left, area_right) = (at.left.surface_area(), at.right.surface_area());
        let (n_left, n_right) = (at.n_left as f32, at.n_right as f32);
        let split_cost = area_left * n_left + area_right * n_right;
        let (mut left, mut right) = (Vec::with_capacity(refs.len()), Vec::new());
        for r in refs {
            let (first, last) = slabs.span(&r, split.axis);
            if last < at.index {
                left.push(r);
                continue;
            }
            if first >= at.index {
                right.push(r);
                continue;
            }
            let whole = r.bounds.aabb();
            let only_left =
                at.left.union(whole).surface_area() * n_left + area_right * (n_right - 1.0);
            let only_right =
                area_left * (n_left - 1.0) + at.right.union(whole).surface_area() * n_right;
            if only_left < split_cost && only_left <= only_right {
                left.push(r);
            } else if only_right < split_cost {
                right.push(r);
            } else {
                let (below, above) = self
                    .clipper
                    .split(r.prim, whole, split.axis, split.position);
                for (side, piece) in [(&mut left, below), (&mut right, above)] {
                    if !piece.is_empty() {
                        side.push(Ref {
                            bounds: piece.into(),
                            prim: r.prim,
                        });
                    }
                }
                // A clipper that finds nothing of the primitive in its box: keep it.
                if below.is_empty() && above.is_empty() {
                    left.push(r);
                }
            }
        }
        (left, right)
    }
}

/// Equal slabs of a node's box along one axis.
struct Slabs {
    lo: f32,
    scale: f32,
    bins: usize,
}

impl Slabs {
    /// The plane between slabs `i - 1` and `i`.
    fn plane(&self, i: usize) -> f32 {
        self.lo + i as f32 / self.scale
    }

    /// The slab holding coordinate `x`.
    fn of(&self, x: f32) -> usize {
        (((x - self.lo) * self.scale) as usize).min(self.bins - 1)
    }

    /// The first and last slab a reference touches (slab 0 for an empty box).
    fn span(&self, r: &Ref, axis: usize) -> (usize, usize) {
        if r.bounds.min[axis] > r.bounds.max[axis] {
            return (0, 0);
        }
        (self.of(r.bounds.min[axis]), self.of(r.bounds.max[axis]))
    }
}

/// Sends each reference to the side its centroid's bin is on (the same arithmetic as the
/// binning).
fn object_partition(refs: Vec<Ref>, split: &ObjectSplit) -> (Vec<Ref>, Vec<Ref>) {
    refs.into_iter().partition(|r| {
        let c = r.centroid()[split.axis];
        (((c - split.lo) * split.scale) as usize).min(split.bins - 1) < split.at.index
    })
}

fn bounds_of(refs: &[Ref]) -> Aabb {
    refs.iter()
        .fold(Box4::EMPTY, |b, r| b.union(r.bounds))
        .aabb()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::clip::{split_triangle, SplitBoxes};
    use crate::{build, Builder, Ray};

    /// A tilted square tiled by long thin strips that run diagonally, `n` across and 4
    /// along, two triangles each: their boxes overlap so much that object splits
    /// cannot separate them, while planes cut them into short pieces that they can.
    fn slivers(n: usize) -> Vec<[Vec3; 3]> {
        let (along, across) = (Vec3::new(1.0, 1.0, 0.6), Vec3::new(-1.0, 1.0, 0.0));
        let width = 20.0 / n as f32;
        (0..n * 4)
            .flat_map(|k| {
                let (i, j) = (k / 4, k % 4);
                let start = across * (i as f32 * width - 10.0) + along * (j as f32 * 5.0 - 10.0);
                let (a, b) = (start, start + across * width);
                let (c, d) = (a + along * 5.0, b + along * 5.0);
                [[a, b, c], [b, d, c]]
            })
            .collect()
    }

    /// The strips cross so many planes that a split near the root duplicates more than
    /// the default budget of 30% of a node's references allows.
    const PARAMS: BuildParams = BuildParams {
        max_leaf_size: 4,
        sah: crate::SahCosts {
            traversal: 1.0,
            intersection: 1.0,
        },
        bins: 16,
        ploc_radius: 16,
        leaf_block: 1,
        max_duplication: 1.0,
    };

    fn boxes_of(tris: &[[Vec3; 3]]) -> Vec<Aabb> {
        tris.iter().map(|&v| Aabb::from_points(v)).collect()
    }

    fn sbvh_of(tris: &[[Vec3; 3]], params: &BuildParams) -> Bvh2 {
        let clip = |p: u32, within: Aabb, axis: usize, position: f32| {
            split_triangle(tris[p as usize], within, axis, position)
        };
        crate::build_with_clipper(Builder::Sbvh, &boxes_of(tris), params, &clip)
    }

    #[test]
    fn spatial_splits_duplicate_within_budget_and_lower_the_sah() {
        let tris = slivers(60);
        let boxes = boxes_of(&tris);
        let params = PARAMS;
        let sbvh = sbvh_of(&tris, &params);
        sbvh.validate(&boxes).unwrap();
        assert!(sbvh.has_spatial_splits());
        let refs = sbvh.prim_indices().len();
        assert!(refs > boxes.len() && refs <= boxes.len() * 2, "{refs}");
        let binned = build(Builder::BinnedSah, &boxes, &params);
        let (a, b) = (sbvh.stats(&params.sah), binned.stats(&params.sah));
        assert!(a.sah_cost < 0.8 * b.sah_cost, "sbvh {a:?}, binned {b:?}");
    }

    #[test]
    fn a_zero_budget_makes_no_spatial_split() {
        let tris = slivers(60);
        let params = BuildParams {
            max_duplication: 0.0,
            ..PARAMS
        };
        let sbvh = sbvh_of(&tris, &params);
        assert!(!sbvh.has_spatial_splits());
        assert_eq!(sbvh.prim_indices().len(), tris.len());
        sbvh.validate(&boxes_of(&tris)).unwrap();
    }

    #[test]
    fn the_tree_is_the_same_whatever_the_threads() {
        let tris = slivers(2500);
        let params = PARAMS;
        let many = sbvh_of(&tris, &params);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| sbvh_of(&tris, &params));
        assert_eq!(many, one);
        many.validate(&boxes_of(&tris)).unwrap();
    }

    #[test]
    fn clipped_triangles_are_still_found_by_every_ray_that_hits_them() {
        let tris = slivers(400);
        let sbvh = sbvh_of(&tris, &PARAMS);
        assert!(sbvh.has_spatial_splits());
        let hit = |p: u32, r: &Ray| {
            crate::intersect_triangle(&tris[p as usize], r, &crate::ShearedRay::new(r))
        };
        let mut hits = 0;
        for i in 1..4000 {
            let t = i as f32 * 0.618;
            let origin = Vec3::new(-15.0, (t * 7.3) % 20.0 - 10.0, (t * 3.1) % 20.0 - 10.0);
            let target = Vec3::new(10.0, (t * 5.7) % 20.0 - 10.0, (t * 9.9) % 20.0 - 10.0);
            let ray = Ray::new(origin, (target - origin).normalize(), 0.0, f32::INFINITY);
            let expected = (0..tris.len() as u32)
                .filter_map(|p| hit(p, &ray).map(|h| crate::Hit::new(p, h)))
                .reduce(|a, b| if b.is_before(&a) { b } else { a });
            assert_eq!(sbvh.intersect(&ray, hit), expected, "ray {i}");
            assert_eq!(
                sbvh.occluded(&ray, |p, r| hit(p, r).is_some()),
                expected.is_some()
            );
            hits += expected.is_some() as u32;
        }
        assert!(hits > 200, "{hits} hits: the rays should meet the slivers");
    }

    #[test]
    fn box_clipping_serves_callers_without_geometry() {
        // A lattice of thin rods along x and along y: every rod crosses every other.
        let boxes: Vec<Aabb> = (0..80)
            .map(|i| {
                let at = (i / 2) as f32 * 0.5;
                let (lo, hi) = (Vec3::new(0.0, at, 0.0), Vec3::new(20.0, at + 0.05, 0.05));
                match i % 2 {
                    0 => Aabb::new(lo, hi),
                    _ => Aabb::new(Vec3::new(lo.y, lo.x, lo.z), Vec3::new(hi.y, hi.x, hi.z)),
                }
            })
            .collect();
        let bvh = build(Builder::Sbvh, &boxes, &PARAMS);
        bvh.validate(&boxes).unwrap();
        assert!(bvh.has_spatial_splits());
        let again = crate::build_with_clipper(Builder::Sbvh, &boxes, &PARAMS, &SplitBoxes);
        assert_eq!(bvh, again);
    }
}
