//! Every hit along a ray, for the queries that are not the closest hit: each crossing of
//! the surface (or every triangle hit) through the tree's any-hit walk told that nothing
//! blocks ([`crate::Tree::for_each_hit`]), and a closed surface's exact winding number as
//! the signed count of one ray's crossings.

use super::{HitsAlong, SurfaceQuery, TriangleSurface};
use crate::triangle::signed_crossing;
use crate::{
    crosses_triangle, intersect_triangle, Aabb, Blas, Hit, Ray, RayQuery, ShearedRay, Tlas,
};
use glam::Vec3;
use std::collections::HashMap;

/// The ray whose signed crossings give a closed surface's winding number at `query`:
/// any direction gives the same count (ties are broken exactly), so the ray leaves the
/// surface's box by its nearest face, the shortest walk through the tree. The
/// directions lean off the axes a little, to meet the edges and vertices of meshes made
/// on a grid less often.
fn winding_ray(query: Vec3, bounds: &Aabb) -> Ray {
    const LEAN: [f32; 2] = [0.012_345_7, 0.007_654_3];
    let to_min = query - bounds.min;
    let to_max = bounds.max - query;
    let (mut axis, mut up, mut nearest) = (0, false, f32::INFINITY);
    for a in 0..3 {
        for (distance, towards_max) in [(to_min[a], false), (to_max[a], true)] {
            if distance < nearest {
                (axis, up, nearest) = (a, towards_max, distance);
            }
        }
    }
    let mut dir = Vec3::ZERO;
    dir[axis] = if up { 1.0 } else { -1.0 };
    dir[(axis + 1) % 3] = LEAN[0];
    dir[(axis + 2) % 3] = LEAN[1];
    Ray::new(query, dir, 0.0, f32::INFINITY)
}

/// Whether the watertight test may have met `hit` on an edge or a vertex (an edge
/// function exactly zero), where the tie rule decides whether it is a crossing. A zero
/// edge function makes its barycentric weight exactly zero, or, for the weight of
/// vertex 0, the other two sum to 1 within a few roundings; elsewhere the hit is a
/// crossing as it is.
#[inline(always)]
fn may_lie_on_an_edge(hit: &Hit) -> bool {
    hit.u == 0.0 || hit.v == 0.0 || hit.u + hit.v >= 1.0 - 1e-6
}

impl<G: TriangleSurface> Blas<G> {
    /// Calls `each(hit, vertices)` for every hit along `ray` that `along` counts (a
    /// triangle in several leaves, after spatial splits, once per leaf).
    pub(super) fn each_hit(
        &self,
        ray: &Ray,
        along: HitsAlong,
        mut each: impl FnMut(Hit, &[Vec3; 3]),
    ) {
        let rays = std::slice::from_ref(ray);
        self.each_hit_of(rays, along, |_, hit, vertices| each(hit, vertices));
    }

    /// [`Blas::each_hit`] of each of `rays`, one ray after another, as
    /// `each(i, hit, vertices)`: one walk of the tree for the batch.
    pub(super) fn each_hit_of(
        &self,
        rays: &[Ray],
        along: HitsAlong,
        mut each: impl FnMut(usize, Hit, &[Vec3; 3]),
    ) {
        let g = self.geometry();
        // The closure tests what the tree does not pack (every triangle of a binary
        // tree; none of a wide one), a ray at a time: the shear, made from the direction
        // alone, is made at a ray's first test and kept for the rest (by the direction's
        // bits: a zero's sign changes it).
        let mut prepared: Option<([u32; 3], ShearedRay)> = None;
        let test = move |prim: u32, ray: &Ray| {
            let dir = ray.dir.to_array().map(f32::to_bits);
            let sheared = match prepared {
                Some((made_for, sheared)) if made_for == dir => sheared,
                _ => prepared.insert((dir, ShearedRay::new(ray))).1,
            };
            intersect_triangle(&g.vertices_of_triangle(prim), ray, &sheared)
        };
        // Hits are few: the tie rule is applied to them alone, after the tree's own
        // (packed) tests, whose hits are the scalar test's bit for bit.
        let found = |i: usize, hit: Hit, vertices: Option<[Vec3; 3]>| {
            let v = vertices.unwrap_or_else(|| g.vertices_of_triangle(hit.prim));
            let tie = along == HitsAlong::Crossings && may_lie_on_an_edge(&hit);
            let ray = &rays[i];
            if !tie || crosses_triangle(&v, ray, &ShearedRay::new(ray)).is_some() {
                each(i, hit, &v);
            }
        };
        match self.tree() {
            Some(tree) => tree.for_each_hit_of(rays, test, found),
            None => {
                let mut found = found;
                for (i, ray) in rays.iter().enumerate() {
                    if !ray.is_traceable() {
                        continue;
                    }
                    let sheared = ShearedRay::new(ray);
                    for prim in 0..g.len() as u32 {
                        let v = g.vertices_of_triangle(prim);
                        if let Some(h) = intersect_triangle(&v, ray, &sheared) {
                            found(i, Hit::new(prim, h), Some(v));
                        }
                    }
                }
            }
        }
    }

    /// Whether a triangle may be met in several leaves (a tree with spatial splits).
    pub(super) fn repeats_triangles(&self) -> bool {
        self.tree().is_some_and(|t| t.view().has_spatial_splits())
    }

    /// Whether every edge of the surface is met by as many triangles running along it
    /// one way as the other (vertices told apart by their coordinates): a closed surface,
    /// whose winding number off it is the signed count of a ray's crossings. Worked out
    /// at the first inside test.
    pub(super) fn is_closed(&self) -> bool {
        *self.closed.get_or_init(|| {
            let g = self.geometry();
            // +0.0 for -0.0: the same point.
            let key = |p: Vec3| (p + Vec3::ZERO).to_array().map(f32::to_bits);
            let mut balance: HashMap<([u32; 3], [u32; 3]), i64> = HashMap::new();
            for prim in 0..g.len() as u32 {
                let v = g.vertices_of_triangle(prim).map(key);
                for (a, b) in [(v[0], v[1]), (v[1], v[2]), (v[2], v[0])] {
                    match a < b {
                        true => *balance.entry((a, b)).or_default() += 1,
                        false => *balance.entry((b, a)).or_default() -= 1,
                    }
                }
            }
            balance.values().all(|&n| n == 0)
        })
    }

    /// The winding number of a closed surface at `query`: the sum of
    /// [`signed_crossing`] along a ray from it, each triangle once.
    pub(super) fn winding_by_crossings(&self, query: Vec3) -> i64 {
        let ray = winding_ray(query, &self.bounds());
        let sheared = ShearedRay::new(&ray);
        let sign = |v: &[Vec3; 3]| signed_crossing(v, &ray, &sheared) as i64;
        if self.repeats_triangles() {
            let mut crossed = Vec::new();
            self.each_hit(&ray, HitsAlong::Triangles, |hit, v| {
                crossed.push((hit.prim, sign(v)))
            });
            crossed.sort_unstable();
            crossed.dedup();
            return crossed.iter().map(|&(_, s)| s).sum();
        }
        let mut total = 0;
        self.each_hit(&ray, HitsAlong::Triangles, |_, v| total += sign(v));
        total
    }
}

impl<B: RayQuery + SurfaceQuery> Tlas<B> {
    /// Calls `each(index, structure, ray)` for every instance that `mask` accepts and
    /// whose box `ray` passes through, with the ray in the instance's space.
    pub(super) fn each_instance_along(
        &self,
        ray: &Ray,
        mask: u32,
        mut each: impl FnMut(u32, &B, &Ray),
    ) {
        if let Some((blas, index, only_mask)) = self.alone() {
            if only_mask & mask != 0 {
                each(index, blas, ray);
            }
            return;
        }
        let mut visit = |index: u32| {
            let instance = &self.instances()[index as usize];
            if instance.mask & mask == 0 {
                return;
            }
            let blas = &self.blases()[instance.blas as usize];
            match instance.is_identity() {
                true => each(index, blas, ray),
                false => each(index, blas, &instance.ray_to_local(ray)),
            }
        };
        match self.tree() {
            // The any-hit walk, told that no instance blocks, visits every one the ray
            // passes.
            Some(tree) => {
                _ = tree.occluded(ray, |index, _| {
                    visit(index);
                    false
                })
            }
            None if ray.is_traceable() => (0..self.instances().len() as u32).for_each(visit),
            None => {}
        }
    }
}
