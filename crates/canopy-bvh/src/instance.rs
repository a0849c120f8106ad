//! [`Instance`]: one placement of a bottom-level structure in the world — its affine
//! transform and inverse, a mask that rays select by, and the caller's id.

use crate::{Aabb, Ray};
use glam::{Affine3A, Vec3};
use thiserror::Error;

/// Every mask bit: an instance that every ray sees.
pub const EVERY_RAY: u32 = u32::MAX;

/// How far (in units in the last place of the largest term of a transformed
/// coordinate) an instance's world box is widened beyond its transformed corners.
pub const BOX_SLACK_ULPS: f32 = 64.0;

/// A structure placed in the world by an affine transform.
///
/// Rays are taken into the structure's space by the inverse transform, origin and
/// direction alike and the direction not normalised, so a hit's `t` is the same in both
/// spaces. Mirrors (negative determinant) and non-uniform scale are allowed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// Index of the structure in the [`crate::Tlas`]'s list.
    pub blas: u32,
    /// Rays whose mask shares no bit with this one pass through the instance.
    pub mask: u32,
    /// The caller's name for the instance (canopy does not read it).
    pub id: u32,
    to_world: Affine3A,
    to_local: Affine3A,
    /// The transform is the identity: rays need no transforming.
    identity: bool,
}

/// Why instances cannot be placed.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum InstanceError {
    #[error("instance {instance}: its transform is not finite")]
    NonFinite { instance: usize },
    #[error("instance {instance}: its transform cannot be inverted (determinant {determinant:e})")]
    Singular { instance: usize, determinant: f32 },
    #[error("instance {instance} places structure {blas}, but there are only {count}")]
    NoSuchBlas {
        instance: usize,
        blas: u32,
        count: usize,
    },
    #[error("{given} transforms for {instances} instances")]
    TransformCount { given: usize, instances: usize },
}

impl Instance {
    /// Structure `blas` placed by `to_world`, seen by every ray, with id 0.
    pub fn new(blas: u32, to_world: Affine3A) -> Self {
        Self {
            blas,
            mask: EVERY_RAY,
            id: 0,
            to_world,
            to_local: to_world.inverse(),
            identity: to_world == Affine3A::IDENTITY,
        }
    }

    pub fn with_mask(self, mask: u32) -> Self {
        Self { mask, ..self }
    }

    pub fn with_id(self, id: u32) -> Self {
        Self { id, ..self }
    }

    /// The same instance placed by `to_world`.
    pub fn with_transform(self, to_world: Affine3A) -> Self {
        Self {
            to_world,
            to_local: to_world.inverse(),
            identity: to_world == Affine3A::IDENTITY,
            ..self
        }
    }

    pub fn to_world(&self) -> &Affine3A {
        &self.to_world
    }

    pub fn to_local(&self) -> &Affine3A {
        &self.to_local
    }

    pub fn is_identity(&self) -> bool {
        self.identity
    }

    /// Why this instance (number `index`) cannot be traced, if it cannot: a transform
    /// that is not finite, or cannot be inverted.
    pub fn check(&self, index: usize) -> Result<(), InstanceError> {
        let finite = |a: &Affine3A| a.matrix3.is_finite() && a.translation.is_finite();
        if !finite(&self.to_world) {
            return Err(InstanceError::NonFinite { instance: index });
        }
        let determinant = self.to_world.matrix3.determinant();
        if determinant == 0.0 || !finite(&self.to_local) {
            return Err(InstanceError::Singular {
                instance: index,
                determinant,
            });
        }
        Ok(())
    }

    /// `ray` in the structure's space (the same `t` range).
    #[inline(always)]
    pub fn ray_to_local(&self, ray: &Ray) -> Ray {
        Ray::new(
            self.to_local.transform_point3(ray.origin),
            self.to_local.transform_vector3(ray.dir),
            ray.t_min,
            ray.t_max,
        )
    }

    /// A point of the structure's space in the world.
    #[inline]
    pub fn point_to_world(&self, p: Vec3) -> Vec3 {
        self.to_world.transform_point3(p)
    }

    /// A direction of the structure's space in the world (not normalised).
    #[inline]
    pub fn vector_to_world(&self, v: Vec3) -> Vec3 {
        self.to_world.transform_vector3(v)
    }

    /// A normal of the structure's space in the world (by the inverse transpose; not
    /// normalised). Mirrors keep the normal on the same side of the surface.
    #[inline]
    pub fn normal_to_world(&self, n: Vec3) -> Vec3 {
        self.to_local.matrix3.transpose().mul_vec3(n)
    }

    /// The world box of `local`, the structure's box: its corners transformed, widened
    /// by [`BOX_SLACK_ULPS`] units in the last place of the largest terms of the
    /// transform, so that rounding in the transforms of corners and rays does not lose a
    /// hit near the box's faces.
    pub fn world_bounds(&self, local: Aabb) -> Aabb {
        if local.is_empty() {
            return Aabb::EMPTY;
        }
        if self.identity {
            return local;
        }
        let corner = |i: u32| {
            Vec3::new(
                if i & 1 == 0 { local.min.x } else { local.max.x },
                if i & 2 == 0 { local.min.y } else { local.max.y },
                if i & 4 == 0 { local.min.z } else { local.max.z },
            )
        };
        let world = Aabb::from_points((0..8).map(|i| self.point_to_world(corner(i))));
        // Per axis, the largest term a transformed coordinate sums: |M| |p| + |t|.
        let m = &self.to_world.matrix3;
        let abs = glam::Mat3A::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs());
        let reach = abs * glam::Vec3A::from(local.min.abs().max(local.max.abs()))
            + self.to_world.translation.abs();
        let slack = Vec3::from(reach) * (BOX_SLACK_ULPS * f32::EPSILON);
        Aabb::new(world.min - slack, world.max + slack)
    }
}
