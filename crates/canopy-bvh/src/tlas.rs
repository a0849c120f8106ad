//! [`Tlas`]: a top-level structure over [`Instance`]s of bottom-level structures (Wald et
//! al., "Ray tracing animated scenes using coherent grid traversal", and every production
//! ray tracer since: Embree's and OptiX's instances, tinybvh's `BLASInstance`).
//!
//! The top tree is built by any builder over the instances' world boxes and walked like
//! any tree; at a leaf, the ray is taken into the instance's space and handed to its
//! structure, whose hit comes back with the instance's index. A structure placed many
//! times is stored once.

use crate::instance::InstanceError;
use crate::proximity::Placement;
use crate::query::{Coherence, RayBatch, RayQuery};
use crate::{
    build, Aabb, BlasParams, Hit, Instance, IntoHit, Ray, TraversalCounter, TraversalStats, Tree,
};
use glam::Affine3A;
use rayon::prelude::*;
use std::time::{Duration, Instant};

/// Instances of structures `B` (one type for all; an enum serves mixed kinds) and the
/// top tree over them.
#[derive(Clone, Debug)]
pub struct Tlas<B> {
    blases: Vec<B>,
    instances: Vec<Instance>,
    /// Over the instances' world boxes; `None`: every instance is tested.
    tree: Option<Tree>,
    params: BlasParams,
    bounds: Aabb,
    /// The only instance whose world box holds anything, where it is untransformed.
    alone: Option<u32>,
    /// Each instance's placement, for point queries.
    pub(crate) placements: Vec<Placement>,
    build_time: Duration,
}

impl<B: RayQuery> Tlas<B> {
    /// Places `instances` of `blases` and builds the top tree with `params` (its builder
    /// and width; `builder: None` tests every instance). Refuses an instance whose
    /// transform is not finite or cannot be inverted, or that names no structure.
    pub fn build(
        blases: Vec<B>,
        instances: Vec<Instance>,
        params: &BlasParams,
    ) -> Result<Self, InstanceError> {
        for (index, instance) in instances.iter().enumerate() {
            if instance.blas as usize >= blases.len() {
                return Err(InstanceError::NoSuchBlas {
                    instance: index,
                    blas: instance.blas,
                    count: blases.len(),
                });
            }
            instance.check(index)?;
        }
        let mut tlas = Self {
            blases,
            instances,
            tree: None,
            params: *params,
            bounds: Aabb::EMPTY,
            alone: None,
            placements: Vec::new(),
            build_time: Duration::ZERO,
        };
        tlas.rebuild();
        Ok(tlas)
    }

    /// Moves every instance (`transforms[i]` places instance `i`) and rebuilds the top
    /// tree; the structures are untouched. Refuses, changing nothing, a transform that
    /// [`Tlas::build`] would refuse.
    pub fn set_transforms(&mut self, transforms: &[Affine3A]) -> Result<(), InstanceError> {
        if transforms.len() != self.instances.len() {
            return Err(InstanceError::TransformCount {
                given: transforms.len(),
                instances: self.instances.len(),
            });
        }
        let moved: Vec<Instance> = self
            .instances
            .par_iter()
            .zip(transforms)
            .map(|(instance, &t)| instance.with_transform(t))
            .collect();
        for (index, instance) in moved.iter().enumerate() {
            instance.check(index)?;
        }
        self.instances = moved;
        self.rebuild();
        Ok(())
    }

    /// Edits every structure in place (`edit` may change what they hold or how they
    /// test it) and rebuilds the top tree over their bounds as they are then.
    pub fn edit_blases(&mut self, edit: impl FnMut(&mut B)) {
        self.blases.iter_mut().for_each(edit);
        self.rebuild();
    }

    /// Builds the top tree over the instances as they are placed now.
    fn rebuild(&mut self) {
        let start = Instant::now();
        let boxes: Vec<Aabb> = self
            .instances
            .par_iter()
            .map(|i| i.world_bounds(self.blases[i.blas as usize].bounds()))
            .collect();
        self.bounds = boxes.iter().copied().fold(Aabb::EMPTY, Aabb::union);
        self.placements = self.instances.par_iter().map(Placement::of).collect();
        let mut holding = (0..boxes.len()).filter(|&i| !boxes[i].is_empty());
        self.alone = match (holding.next(), holding.next()) {
            (Some(i), None) if self.instances[i].is_identity() => Some(i as u32),
            _ => None,
        };
        self.tree = self.params.builder.map(|builder| {
            Tree::new(
                build(builder, &boxes, &self.params.build),
                self.params.width,
            )
        });
        self.build_time = start.elapsed();
    }

    /// Uses the kernels of `isa` for the top tree (see [`Tree::set_isa`]).
    pub fn set_isa(&mut self, isa: crate::Isa) -> Result<(), crate::IsaError> {
        self.tree.as_mut().map_or(Ok(()), |t| t.set_isa(isa))
    }

    pub fn blases(&self) -> &[B] {
        &self.blases
    }

    pub fn instances(&self) -> &[Instance] {
        &self.instances
    }

    /// The top tree, unless every instance is tested.
    pub fn tree(&self) -> Option<&Tree> {
        self.tree.as_ref()
    }

    /// Wall-clock time of the last build of the top tree (world boxes included).
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// The one structure when the only instance that holds anything is untransformed:
    /// queries go straight to it, at no extra cost. With its index and mask.
    #[inline(always)]
    pub(crate) fn alone(&self) -> Option<(&B, u32, u32)> {
        let index = self.alone?;
        let only = &self.instances[index as usize];
        Some((&self.blases[only.blas as usize], index, only.mask))
    }

    /// The hit of `ray` (world space, its `t_max` the best so far) on instance `index`.
    #[inline(always)]
    fn closest_in<C: FnMut(&B, &Ray) -> Option<Hit>>(
        &self,
        index: u32,
        ray: &Ray,
        mask: u32,
        mut closest: C,
    ) -> Option<Hit> {
        let instance = &self.instances[index as usize];
        if instance.mask & mask == 0 {
            return None;
        }
        let blas = &self.blases[instance.blas as usize];
        match instance.is_identity() {
            true => closest(blas, ray),
            false => closest(blas, &instance.ray_to_local(ray)),
        }
    }

    #[inline(always)]
    fn occluded_in(&self, index: u32, ray: &Ray, mask: u32) -> bool {
        let instance = &self.instances[index as usize];
        if instance.mask & mask == 0 {
            return false;
        }
        let blas = &self.blases[instance.blas as usize];
        match instance.is_identity() {
            true => blas.occluded_masked(ray, mask),
            false => blas.occluded_masked(&instance.ray_to_local(ray), mask),
        }
    }

    /// Closest hit, each instance's structure queried by `closest`, the top tree's work
    /// reported to `counter`.
    #[inline(always)]
    fn closest<C, Q>(&self, ray: &Ray, mask: u32, counter: &mut C, mut closest: Q) -> Option<Hit>
    where
        C: TraversalCounter,
        Q: FnMut(&B, &Ray) -> Option<Hit>,
    {
        if let Some((blas, index, only)) = self.alone() {
            return (only & mask != 0)
                .then(|| closest(blas, ray))
                .flatten()
                .map(|h| h.into_hit(index));
        }
        let test = |i: u32, r: &Ray| self.closest_in(i, r, mask, &mut closest);
        match &self.tree {
            Some(tree) => tree.intersect_counted(ray, test, counter),
            None => brute_force(self.instances.len(), ray, counter, test),
        }
    }
}

/// The closest hit by testing every instance (ties to the lower instance).
fn brute_force<C, F>(count: usize, ray: &Ray, counter: &mut C, mut test: F) -> Option<Hit>
where
    C: TraversalCounter,
    F: FnMut(u32, &Ray) -> Option<Hit>,
{
    if !ray.is_traceable() {
        return None;
    }
    let mut best: Option<Hit> = None;
    let mut ray = *ray;
    for index in 0..count as u32 {
        counter.test_primitive();
        if let Some(hit) = test(index, &ray).map(|h| h.into_hit(index)) {
            if best.is_none_or(|b| hit.is_before(&b)) {
                ray.t_max = hit.t;
                best = Some(hit);
            }
        }
    }
    best
}

impl<B: RayQuery> Tlas<B> {
    /// Closest hit of one ray, every level's work reported to `counter`.
    #[inline(always)]
    fn closest_counted<C: TraversalCounter>(
        &self,
        ray: &Ray,
        mask: u32,
        counter: &mut C,
    ) -> Option<Hit> {
        if !C::COUNTS {
            return self.closest(ray, mask, &mut (), |blas, r| blas.intersect_masked(r, mask));
        }
        // The structures' work goes to `counter` as it happens, the top tree's to `top`
        // (both cannot borrow it at once), replayed after.
        let mut top = TraversalStats::default();
        let hit = self.closest(ray, mask, &mut top, |blas, r| {
            blas.intersect_counted(r, mask, counter)
        });
        top.replay(counter);
        hit
    }

    /// Whether anything `mask` accepts blocks one ray.
    #[inline(always)]
    fn any_one(&self, ray: &Ray, mask: u32) -> bool {
        if let Some((blas, _, only)) = self.alone() {
            return only & mask != 0 && blas.occluded_masked(ray, mask);
        }
        let test = |i: u32, r: &Ray| self.occluded_in(i, r, mask);
        match &self.tree {
            Some(tree) => tree.occluded(ray, test),
            None => ray.is_traceable() && (0..self.instances.len() as u32).any(|i| test(i, ray)),
        }
    }
}

impl<B: RayQuery> RayQuery for Tlas<B> {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    // Out of line: the batch's entry, where the kernels of the top tree and of every
    // structure it holds are compiled, once for each kind of structure and counter.
    #[inline(never)]
    fn closest_hits_into<C: TraversalCounter>(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        mask: u32,
        coherence: Coherence,
        counter: &mut C,
    ) {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        match (self.alone(), &self.tree) {
            // One structure placed as itself: the whole batch goes to it (packets too).
            (Some((blas, index, only)), _) if only & mask != 0 => {
                blas.closest_hits_into(rays, hits, mask, coherence, counter);
                if index != 0 {
                    for hit in hits.iter_mut().flatten() {
                        *hit = hit.into_hit(index);
                    }
                }
            }
            // Instances: each ray goes its own way through the top tree, which chooses
            // its kernels once for the batch.
            (None, Some(tree)) if !C::COUNTS => {
                let test = |i: u32, r: &Ray| {
                    self.closest_in(i, r, mask, |blas, r| blas.intersect_masked(r, mask))
                };
                let one_by_one = RayBatch::new(rays.len());
                let (ray, answer) = (|i: usize| rays[i], |i: usize, h| hits[i] = h);
                tree.closest_hits(one_by_one, ray, answer, test, &mut ())
            }
            _ => {
                for (ray, hit) in rays.iter().zip(hits) {
                    *hit = self.closest_counted(ray, mask, counter);
                }
            }
        }
    }

    #[inline(never)]
    fn any_hits_into(&self, rays: &[Ray], blocked: &mut [bool], mask: u32, coherence: Coherence) {
        assert_eq!(rays.len(), blocked.len(), "one answer per ray");
        match (self.alone(), &self.tree) {
            (Some((blas, _, only)), _) if only & mask != 0 => {
                blas.any_hits_into(rays, blocked, mask, coherence)
            }
            (None, Some(tree)) => {
                let test = |i: u32, r: &Ray| self.occluded_in(i, r, mask);
                let (ray, answer) = (|i: usize| rays[i], |i: usize, b| blocked[i] = b);
                tree.any_hits(RayBatch::new(rays.len()), ray, answer, test)
            }
            _ => {
                for (ray, b) in rays.iter().zip(blocked) {
                    *b = self.any_one(ray, mask);
                }
            }
        }
    }

    fn orders_batches(&self) -> bool {
        self.tree.as_ref().is_some_and(Tree::orders_batches)
            || self.blases.iter().any(RayQuery::orders_batches)
    }
}
