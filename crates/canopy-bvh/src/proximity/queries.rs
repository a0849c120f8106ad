//! [`SurfaceQuery`] for the structures that own their geometry: a [`Blas`] over
//! triangles (its tree in any layout, or brute force), and a [`Tlas`] of them.

use super::walk::{self, beats, Best};
use super::{closest_point_on_triangle, solid_angle, HitsAlong, Nearest, Placement, SurfaceQuery};
use super::{count_hits_one_by_one, hits_one_by_one, sort_and_dedup_each};
use super::{PointTree, TriangleSurface, INSIDE_FAR_FIELD};
use crate::{Blas, Hit, Ray, RayQuery, Tlas};
use glam::Vec3;

/// Measures triangle `prim` (vertices `v` in the query's space) against `query`, and
/// returns it where it beats `best`.
#[inline(always)]
fn measure(query: Vec3, prim: u32, v: &[Vec3; 3], best: &Best, limit_sq: f32) -> Best {
    let (point, [u, v]) = closest_point_on_triangle(query, v);
    let d2 = point.distance_squared(query);
    let candidate = Nearest {
        point,
        distance: d2.sqrt(),
        inst: 0,
        prim,
        u,
        v,
    };
    beats(d2, &candidate, best, limit_sq).then_some((d2, candidate))
}

impl<G: TriangleSurface> Blas<G> {
    /// The tree laid out for point queries, made at the first one; `None` for brute
    /// force.
    fn point_tree(&self) -> Option<&PointTree> {
        let tree = self.tree()?;
        let g = self.geometry();
        let vertices = |p: u32| g.vertices_of_triangle(p);
        Some(
            self.point_tree
                .get_or_init(|| PointTree::new(tree.view(), g.len(), &vertices)),
        )
    }
}

impl<G: TriangleSurface> SurfaceQuery for Blas<G> {
    fn nearest_placed(&self, query: Vec3, placement: Option<&Placement>, limit_sq: f32) -> Best {
        // Triangles are measured where the query is (the world, for a placed one); boxes
        // are pruned in the structure's space.
        let placed = |prim: u32, v: &[Vec3; 3], best: &Best| {
            let v = match placement {
                None => *v,
                Some(p) => v.map(|x| p.to_world.transform_point3(x)),
            };
            measure(query, prim, &v, best, limit_sq)
        };
        match self.point_tree() {
            Some(flat) => {
                let (local, stretch) = match placement {
                    None => (query, 1.0),
                    Some(p) => (p.to_local.transform_point3(query), p.stretch),
                };
                flat.nearest(local, stretch, limit_sq, placed)
            }
            None => {
                let g = self.geometry();
                (0..g.len() as u32).fold(None, |best, prim| {
                    placed(prim, &g.vertices_of_triangle(prim), &best).or(best)
                })
            }
        }
    }

    fn winding_number_within(&self, query: Vec3, far_field: f32) -> f64 {
        let g = self.geometry();
        let vertices = |p: u32| g.vertices_of_triangle(p);
        match self.point_tree() {
            Some(flat) => flat.winding_number(query, far_field),
            None => {
                let total: f64 = (0..g.len() as u32)
                    .map(|p| solid_angle(query, &vertices(p)))
                    .sum();
                total / (4.0 * std::f64::consts::PI)
            }
        }
    }

    fn inside_winding_number(&self, query: Vec3) -> f64 {
        match self.is_closed() {
            true => self.winding_by_crossings(query) as f64,
            false => self.winding_number_within(query, INSIDE_FAR_FIELD),
        }
    }

    fn all_hits(&self, ray: &Ray, _mask: u32, along: HitsAlong, out: &mut Vec<Hit>) {
        self.each_hit(ray, along, |hit, _| out.push(hit));
    }

    fn count_hits(&self, ray: &Ray, mask: u32, along: HitsAlong) -> usize {
        let mut count = [0];
        self.count_hits_each(std::slice::from_ref(ray), mask, along, &mut count);
        count[0]
    }

    fn count_hits_each(&self, rays: &[Ray], mask: u32, along: HitsAlong, counts: &mut [usize]) {
        assert_eq!(rays.len(), counts.len(), "one count per ray");
        if self.repeats_triangles() {
            // A triangle met in several leaves counts once: listed and deduplicated.
            let mut hits = Vec::new();
            return self.hits_each(rays, mask, along, &mut hits, counts);
        }
        counts.fill(0);
        self.each_hit_of(rays, along, |i, _, _| counts[i] += 1);
    }

    fn hits_each(
        &self,
        rays: &[Ray],
        _mask: u32,
        along: HitsAlong,
        hits: &mut Vec<Hit>,
        counts: &mut [usize],
    ) {
        assert_eq!(rays.len(), counts.len(), "one count per ray");
        hits.clear();
        counts.fill(0);
        // The walk takes the rays one after another, so each ray's hits come together.
        self.each_hit_of(rays, along, |i, hit, _| {
            hits.push(hit);
            counts[i] += 1;
        });
        sort_and_dedup_each(hits, counts);
    }
}

impl<B: RayQuery + SurfaceQuery> SurfaceQuery for Tlas<B> {
    fn nearest_placed(&self, query: Vec3, placement: Option<&Placement>, limit_sq: f32) -> Best {
        if let (Some((blas, index, _)), None) = (self.alone(), placement) {
            return blas
                .nearest_placed(query, None, limit_sq)
                .map(|(d2, n)| (d2, Nearest { inst: index, ..n }));
        }
        let test = |index: u32, best: &Best| {
            let instance = &self.instances()[index as usize];
            let blas = &self.blases()[instance.blas as usize];
            let inner = match placement {
                None if instance.is_identity() => None,
                None => Some(self.placements[index as usize]),
                Some(outer) => Some(outer.then(instance)),
            };
            let within = best.map_or(limit_sq, |(d2, _)| d2);
            let (d2, found) = blas.nearest_placed(query, inner.as_ref(), within)?;
            let found = Nearest {
                inst: index,
                ..found
            };
            beats(d2, &found, best, limit_sq).then_some((d2, found))
        };
        match self.tree() {
            Some(tree) => {
                let (local, stretch) = match placement {
                    None => (query, 1.0),
                    Some(p) => (p.to_local.transform_point3(query), p.stretch),
                };
                walk::nearest(tree.view(), local, stretch, limit_sq, test)
            }
            None => {
                (0..self.instances().len() as u32).fold(None, |best, i| test(i, &best).or(best))
            }
        }
    }

    fn winding_number_within(&self, query: Vec3, far_field: f32) -> f64 {
        if let Some((blas, _, _)) = self.alone() {
            return blas.winding_number_within(query, far_field);
        }
        self.sum_over_instances(query, |blas, local| {
            blas.winding_number_within(local, far_field)
        })
    }

    fn inside_winding_number(&self, query: Vec3) -> f64 {
        if let Some((blas, _, _)) = self.alone() {
            return blas.inside_winding_number(query);
        }
        self.sum_over_instances(query, |blas, local| blas.inside_winding_number(local))
    }

    fn all_hits(&self, ray: &Ray, mask: u32, along: HitsAlong, out: &mut Vec<Hit>) {
        self.each_instance_along(ray, mask, |index, blas, ray| {
            let first = out.len();
            blas.all_hits(ray, mask, along, out);
            out[first..].iter_mut().for_each(|h| h.inst = index);
        });
    }

    fn count_hits(&self, ray: &Ray, mask: u32, along: HitsAlong) -> usize {
        let mut count = 0;
        self.each_instance_along(ray, mask, |_, blas, ray| {
            count += blas.count_hits(ray, mask, along)
        });
        count
    }

    fn count_hits_each(&self, rays: &[Ray], mask: u32, along: HitsAlong, counts: &mut [usize]) {
        assert_eq!(rays.len(), counts.len(), "one count per ray");
        match self.alone() {
            Some((blas, _, only_mask)) if only_mask & mask != 0 => {
                blas.count_hits_each(rays, mask, along, counts)
            }
            Some(_) => counts.fill(0),
            None => count_hits_one_by_one(self, rays, mask, along, counts),
        }
    }

    fn hits_each(
        &self,
        rays: &[Ray],
        mask: u32,
        along: HitsAlong,
        hits: &mut Vec<Hit>,
        counts: &mut [usize],
    ) {
        assert_eq!(rays.len(), counts.len(), "one count per ray");
        match self.alone() {
            Some((blas, index, only_mask)) if only_mask & mask != 0 => {
                blas.hits_each(rays, mask, along, hits, counts);
                hits.iter_mut().for_each(|h| h.inst = index);
            }
            _ => hits_one_by_one(self, rays, mask, along, hits, counts),
        }
    }
}

impl<B: RayQuery + SurfaceQuery> Tlas<B> {
    /// The sum of `winding(structure, query in its space)` over every instance. The
    /// winding number is unchanged by a transform that keeps orientation. A mirror keeps
    /// the instance's inside too: its normals are mirrored with it, as the renderer's are
    /// ([`crate::Instance::normal_to_world`]).
    fn sum_over_instances(&self, query: Vec3, winding: impl Fn(&B, Vec3) -> f64) -> f64 {
        self.instances()
            .iter()
            .map(|instance| {
                let blas = &self.blases()[instance.blas as usize];
                winding(blas, instance.to_local().transform_point3(query))
            })
            .sum()
    }
}
