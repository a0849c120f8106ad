//! [`Box4`]: a box in SIMD lanes, the working box of the binning builders.

use crate::Aabb;
use glam::Vec3A;

/// A box in SIMD lanes (the fourth unused): a union is two instructions. Min and max are
/// exact, so bins give the same bounds, areas and splits as `Aabb`s would.
#[derive(Clone, Copy)]
pub(crate) struct Box4 {
    pub min: Vec3A,
    pub max: Vec3A,
}

impl Box4 {
    pub const EMPTY: Box4 = Box4 {
        min: Vec3A::splat(f32::INFINITY),
        max: Vec3A::splat(f32::NEG_INFINITY),
    };

    #[inline(always)]
    pub fn union(self, other: Box4) -> Box4 {
        Box4 {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    #[inline(always)]
    pub fn grow(self, p: Vec3A) -> Box4 {
        Box4 {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    pub fn aabb(self) -> Aabb {
        Aabb::new(self.min.into(), self.max.into())
    }
}

impl From<Aabb> for Box4 {
    #[inline]
    fn from(b: Aabb) -> Self {
        Box4 {
            min: b.min.into(),
            max: b.max.into(),
        }
    }
}
