//! Rays and hit records.

use glam::Vec3;

/// A ray with its valid parameter interval `[t_min, t_max]`.
///
/// The reciprocal direction is precomputed for the slab test; a zero direction component
/// gives an infinite reciprocal, which the slab test handles.
///
/// A ray that is not [traceable](Ray::is_traceable) — an origin or direction that is not
/// finite, a direction with no component of normal size (zero, or denormal in every
/// component), a NaN end — misses everything, in every structure and layout and in
/// brute force alike. [`Ray::new`] caps `t_max` at `f32::MAX`, so a hit's `t` is always
/// finite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub inv_dir: Vec3,
    pub t_min: f32,
    pub t_max: f32,
}

impl Ray {
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Self {
        Self {
            origin,
            dir,
            inv_dir: dir.recip(),
            t_min,
            // Not `min`, which would turn a NaN into a number.
            t_max: if t_max > f32::MAX { f32::MAX } else { t_max },
        }
    }

    /// Whether the ray can hit anything: finite origin and direction, a direction with
    /// at least one component of normal size (at least `f32::MIN_POSITIVE`), and no NaN
    /// end. Every query answers a miss for a ray that is not.
    #[inline(always)]
    pub fn is_traceable(&self) -> bool {
        // Every ray of every query asks this, so it is computed without branches: `x - x`
        // is 0 for a finite `x` and NaN otherwise, and NaN spreads through the sum, so
        // one comparison covers all six coordinates (the `&&`s of `is_finite` took about
        // 20 more instructions a ray).
        #[allow(clippy::eq_op)] // `x - x` is meant: it is not 0 for an infinite or NaN `x`
        let zeros = (self.origin - self.origin) + (self.dir - self.dir);
        let finite = zeros.x + zeros.y + zeros.z == 0.0;
        let normal = self.dir.abs().max_element() >= f32::MIN_POSITIVE;
        finite & normal & !self.t_min.is_nan() & !self.t_max.is_nan()
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + t * self.dir
    }
}

/// What a primitive test reports: the hit distance and, for triangles, the barycentric
/// weights `u` of the second vertex and `v` of the third (zero for other primitives).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PrimHit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
}

impl From<f32> for PrimHit {
    /// A hit at distance `t` on a primitive without barycentrics.
    #[inline]
    fn from(t: f32) -> Self {
        Self { t, u: 0.0, v: 0.0 }
    }
}

/// The closest hit found by a query: ray parameter, the instance and the primitive hit,
/// and the primitive's barycentrics there (see [`PrimHit`]).
///
/// `inst` is the index of the instance in a [`crate::Tlas`]; a query of one structure on
/// its own (a [`crate::Blas`], a tree with the caller's primitive test) reports 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub inst: u32,
    pub prim: u32,
    pub u: f32,
    pub v: f32,
}

impl Hit {
    /// A hit of primitive `prim` (of instance 0) as its test reported it.
    #[inline]
    pub fn new(prim: u32, hit: PrimHit) -> Self {
        Self {
            t: hit.t,
            inst: 0,
            prim,
            u: hit.u,
            v: hit.v,
        }
    }

    /// Whether `self` is closer than `other`; equal distances go to the lower instance,
    /// then the lower primitive index, so every acceleration structure (and brute force)
    /// agrees on the answer.
    #[inline]
    pub fn is_before(&self, other: &Hit) -> bool {
        self.t < other.t || (self.t == other.t && (self.inst, self.prim) < (other.inst, other.prim))
    }
}

/// What a leaf entry's test reports, made into the [`Hit`] of that entry: a distance
/// (`f32`) or a [`PrimHit`] is a hit of primitive `entry`; a [`Hit`] (what an instance's
/// structure answers) is a hit of instance `entry`, keeping its primitive.
pub trait IntoHit {
    fn into_hit(self, entry: u32) -> Hit;
}

impl IntoHit for f32 {
    #[inline(always)]
    fn into_hit(self, entry: u32) -> Hit {
        Hit::new(entry, PrimHit::from(self))
    }
}

impl IntoHit for PrimHit {
    #[inline(always)]
    fn into_hit(self, entry: u32) -> Hit {
        Hit::new(entry, self)
    }
}

impl IntoHit for Hit {
    #[inline(always)]
    fn into_hit(self, entry: u32) -> Hit {
        Hit {
            inst: entry,
            ..self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definition `is_traceable` computes without branches.
    fn traceable_by_definition(r: &Ray) -> bool {
        r.origin.is_finite()
            && r.dir.is_finite()
            && r.dir.abs().max_element() >= f32::MIN_POSITIVE
            && !r.t_min.is_nan()
            && !r.t_max.is_nan()
    }

    #[test]
    fn traceable_rays_are_those_of_the_definition() {
        let special = [
            0.0,
            -0.0,
            1.0,
            -3.5,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            f32::MIN_POSITIVE / 4.0,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let mut seen = [0; 2];
        let mut check = |origin: [f32; 3], dir: [f32; 3], t_min: f32, t_max: f32| {
            let ray = Ray {
                origin: Vec3::from_array(origin),
                dir: Vec3::from_array(dir),
                inv_dir: Vec3::from_array(dir).recip(),
                t_min,
                t_max,
            };
            let expected = traceable_by_definition(&ray);
            assert_eq!(ray.is_traceable(), expected, "{ray:?}");
            seen[expected as usize] += 1;
        };
        // Each coordinate and end on its own, the others ordinary.
        for &x in &special {
            for axis in 0..3 {
                let mut origin = [0.5, -2.0, 7.0];
                origin[axis] = x;
                check(origin, [0.3, -0.4, 0.5], 0.0, 10.0);
                let mut dir = [0.3, -0.4, 0.5];
                dir[axis] = x;
                check([0.5, -2.0, 7.0], dir, 0.0, 10.0);
            }
            check([1.0; 3], [0.0, 1.0, 0.0], x, 10.0);
            check([1.0; 3], [0.0, 1.0, 0.0], 0.0, x);
        }
        // Every direction of small, zero and infinite components: only some of normal
        // size counts, and any infinite or NaN one spoils it.
        for &x in &special {
            for &y in &special {
                for &z in &special {
                    check([0.0; 3], [x, y, z], 0.0, f32::MAX);
                }
            }
        }
        assert!(seen[0] > 100 && seen[1] > 100, "{seen:?}");
    }
}
