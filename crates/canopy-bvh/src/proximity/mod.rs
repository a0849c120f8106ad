//! Queries of a surface that are not the closest hit of a ray (Open3D's
//! `RaycastingScene`, Embree's point queries): the nearest point of the surface to a
//! point, distance, signed distance and inside tests by winding number, and every hit
//! along a ray. [`SurfaceQuery`] is their interface; [`crate::Blas`] over triangles and
//! [`crate::Tlas`] over such structures answer it, walking any tree layout.

mod along;
mod queries;
mod triangle;
mod walk;
mod winding;

pub use triangle::{closest_point_on_triangle, solid_angle};
pub(crate) use winding::PointTree;
pub use winding::{FAR_FIELD, INSIDE_FAR_FIELD};

use crate::{Geometry, Hit, Instance, Ray, TriangleMesh};
use glam::{Affine3A, DMat3, Vec3};

/// Geometry whose every primitive is a triangle: what distances and winding numbers
/// are measured on.
pub trait TriangleSurface: Geometry {
    /// The vertices of triangle `prim`, in winding order (the normal is
    /// `(v1 - v0) x (v2 - v0)`, pointing out of a closed surface).
    fn vertices_of_triangle(&self, prim: u32) -> [Vec3; 3];
}

impl TriangleSurface for TriangleMesh {
    #[inline(always)]
    fn vertices_of_triangle(&self, prim: u32) -> [Vec3; 3] {
        self.vertices_of(prim)
    }
}

impl<G: TriangleSurface + Send> TriangleSurface for std::sync::Arc<G> {
    #[inline(always)]
    fn vertices_of_triangle(&self, prim: u32) -> [Vec3; 3] {
        (**self).vertices_of_triangle(prim)
    }
}

/// The nearest point of a surface to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Nearest {
    /// The point, in the query's space.
    pub point: Vec3,
    /// Its distance from the query point.
    pub distance: f32,
    /// The instance it lies on ([`crate::Tlas`]; 0 for a structure on its own).
    pub inst: u32,
    /// The triangle it lies on.
    pub prim: u32,
    /// Barycentric weights of the triangle's vertices 1 and 2 there (as [`Hit`]'s).
    pub u: f32,
    pub v: f32,
}

/// Where a structure is placed when it answers for a placed instance: the transforms,
/// and the least factor by which the placement lengthens any vector (so that a box's
/// distance in the structure's space bounds distances in the world).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub to_world: Affine3A,
    pub to_local: Affine3A,
    /// A lower bound of the smallest singular value of `to_world`'s linear part.
    pub stretch: f32,
}

impl Placement {
    /// The placement of `instance`.
    pub fn of(instance: &Instance) -> Self {
        Self::new(*instance.to_world())
    }

    /// `inner` placed inside a structure that this places (a nested top-level tree).
    pub fn then(&self, inner: &Instance) -> Self {
        Self::new(self.to_world * *inner.to_world())
    }

    fn new(to_world: Affine3A) -> Self {
        Self {
            to_world,
            to_local: to_world.inverse(),
            stretch: least_stretch(&to_world),
        }
    }
}

/// A lower bound of the smallest singular value of `a`'s linear part: the exact value
/// (from the eigenvalues of `MᵀM` in double precision) less a margin for rounding, or
/// `1 / ‖M⁻¹‖_F` where that is larger.
fn least_stretch(a: &Affine3A) -> f32 {
    let m = glam::Mat3::from(a.matrix3).as_dmat3();
    let frobenius_bound = {
        let inverse = m.inverse();
        let norm_sq = [inverse.x_axis, inverse.y_axis, inverse.z_axis]
            .iter()
            .map(|c| c.length_squared())
            .sum::<f64>();
        1.0 / norm_sq.sqrt()
    };
    let gram = m.transpose() * m;
    let (smallest, largest) = symmetric_eigenvalue_range(&gram);
    let exact_bound = (smallest - 1e-9 * largest).max(0.0).sqrt();
    // Rounded down into single precision by a relative margin.
    (exact_bound.max(frobenius_bound) * (1.0 - 1e-6)) as f32
}

/// The smallest and largest eigenvalues of the symmetric matrix `a` (Smith's closed
/// form, 1961).
fn symmetric_eigenvalue_range(a: &DMat3) -> (f64, f64) {
    let (a00, a11, a22) = (a.x_axis.x, a.y_axis.y, a.z_axis.z);
    let (a01, a02, a12) = (a.y_axis.x, a.z_axis.x, a.z_axis.y);
    let off = a01 * a01 + a02 * a02 + a12 * a12;
    if off == 0.0 {
        let d = [a00, a11, a22];
        return (
            d.iter().copied().fold(f64::INFINITY, f64::min),
            d.iter().copied().fold(0.0, f64::max),
        );
    }
    let q = (a00 + a11 + a22) / 3.0;
    let p = (((a00 - q).powi(2) + (a11 - q).powi(2) + (a22 - q).powi(2) + 2.0 * off) / 6.0).sqrt();
    let b = (*a - DMat3::from_diagonal(glam::DVec3::splat(q))) * (1.0 / p);
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    (smallest, largest)
}

/// Point and inside queries of a surface, and every hit along a ray.
///
/// Inside tests use the generalised winding number (see [`FAR_FIELD`]): robust where
/// ray parity is not (holes, overlapping or duplicated triangles, grazing rays), and
/// independent of any choice of rays. Signed distances are negative inside, as
/// Open3D's and most signed distance fields' are.
pub trait SurfaceQuery: Sync {
    /// The nearest point of the surface to `query` (placed by `placement` where given)
    /// whose squared distance is at most `limit_sq`, with that squared distance.
    fn nearest_placed(
        &self,
        query: Vec3,
        placement: Option<&Placement>,
        limit_sq: f32,
    ) -> Option<(f32, Nearest)>;

    /// The winding number of the surface at `query`, nodes farther than `far_field`
    /// of their radii counted by their far-field expansions ([`FAR_FIELD`]).
    fn winding_number_within(&self, query: Vec3, far_field: f32) -> f64;

    /// Appends the hits of `ray` within its range that `along` counts, in no particular
    /// order, on the instances `mask` accepts (a triangle referenced by several leaves
    /// may appear more than once: [`SurfaceQuery::hits`] sorts and removes repeats).
    fn all_hits(&self, ray: &Ray, mask: u32, along: HitsAlong, out: &mut Vec<Hit>);

    /// The nearest point of the surface to `query` no farther than `max_distance`.
    /// Equal distances go to the lower instance, then the lower triangle.
    fn closest_point(&self, query: Vec3, max_distance: f32) -> Option<Nearest> {
        let limit_sq = max_distance * max_distance;
        self.nearest_placed(query, None, limit_sq).map(|(_, n)| n)
    }

    /// The winding number of the surface at `query`: 1 inside a closed surface whose
    /// normals face out, 0 outside, fractional near holes (to about 1e-2).
    fn winding_number(&self, query: Vec3) -> f64 {
        self.winding_number_within(query, FAR_FIELD)
    }

    /// Distance from `query` to the surface (infinite where there is none).
    fn distance(&self, query: Vec3) -> f32 {
        self.closest_point(query, f32::INFINITY)
            .map_or(f32::INFINITY, |n| n.distance)
    }

    /// The winding number at `query` as accurately as telling inside from outside
    /// needs: exact (an integer) where the surface is closed (a ray's signed
    /// crossings), and otherwise to about 0.1 ([`INSIDE_FAR_FIELD`]).
    fn inside_winding_number(&self, query: Vec3) -> f64;

    /// Whether `query` lies inside: a winding number above one half
    /// ([`SurfaceQuery::inside_winding_number`]).
    fn contains(&self, query: Vec3) -> bool {
        self.inside_winding_number(query) > 0.5
    }

    /// [`SurfaceQuery::distance`], negative inside.
    fn signed_distance(&self, query: Vec3) -> f32 {
        let distance = self.distance(query);
        match self.contains(query) {
            true => -distance,
            false => distance,
        }
    }

    /// The hits of `ray` within its range that `along` counts, once each, nearest first
    /// (equal distances by instance, then triangle).
    fn hits(&self, ray: &Ray, mask: u32, along: HitsAlong) -> Vec<Hit> {
        let mut hits = Vec::new();
        self.hits_into(ray, mask, along, &mut hits);
        hits
    }

    /// How many hits [`SurfaceQuery::hits`] reports, without listing them.
    fn count_hits(&self, ray: &Ray, mask: u32, along: HitsAlong) -> usize {
        self.hits(ray, mask, along).len()
    }

    /// [`SurfaceQuery::hits`] into `out` (cleared first), whose memory a batch of rays
    /// reuses.
    fn hits_into(&self, ray: &Ray, mask: u32, along: HitsAlong, out: &mut Vec<Hit>) {
        out.clear();
        self.all_hits(ray, mask, along, out);
        sort_and_dedup_from(out, 0);
    }

    /// [`SurfaceQuery::count_hits`] of each of `rays`, into `counts`.
    ///
    /// # Panics
    /// If `counts` does not hold one count per ray.
    fn count_hits_each(&self, rays: &[Ray], mask: u32, along: HitsAlong, counts: &mut [usize]) {
        count_hits_one_by_one(self, rays, mask, along, counts)
    }

    /// [`SurfaceQuery::hits`] of each of `rays`, one ray's after another's into `hits`
    /// (cleared first): `counts[i]` of them for ray `i`.
    ///
    /// # Panics
    /// If `counts` does not hold one count per ray.
    fn hits_each(
        &self,
        rays: &[Ray],
        mask: u32,
        along: HitsAlong,
        hits: &mut Vec<Hit>,
        counts: &mut [usize],
    ) {
        hits_one_by_one(self, rays, mask, along, hits, counts)
    }
}

/// [`SurfaceQuery::count_hits_each`], a ray at a time.
fn count_hits_one_by_one<Q: SurfaceQuery + ?Sized>(
    query: &Q,
    rays: &[Ray],
    mask: u32,
    along: HitsAlong,
    counts: &mut [usize],
) {
    assert_eq!(rays.len(), counts.len(), "one count per ray");
    for (ray, count) in rays.iter().zip(counts) {
        *count = query.count_hits(ray, mask, along);
    }
}

/// [`SurfaceQuery::hits_each`], a ray at a time.
fn hits_one_by_one<Q: SurfaceQuery + ?Sized>(
    query: &Q,
    rays: &[Ray],
    mask: u32,
    along: HitsAlong,
    hits: &mut Vec<Hit>,
    counts: &mut [usize],
) {
    assert_eq!(rays.len(), counts.len(), "one count per ray");
    hits.clear();
    for (ray, count) in rays.iter().zip(counts) {
        let first = hits.len();
        query.all_hits(ray, mask, along, hits);
        sort_and_dedup_from(hits, first);
        *count = hits.len() - first;
    }
}

/// Sorts `hits[first..]` (one ray's) and drops its repeats, as [`sort_and_dedup`].
fn sort_and_dedup_from(hits: &mut Vec<Hit>, first: usize) {
    let kept = sort_and_dedup(&mut hits[first..]);
    hits.truncate(first + kept);
}

/// Sorts and dedups each ray's hits, `counts[i]` of them for ray `i` one after another
/// in `hits` (as [`sort_and_dedup`]), moving them together and lowering the counts.
fn sort_and_dedup_each(hits: &mut Vec<Hit>, counts: &mut [usize]) {
    let (mut read, mut write) = (0, 0);
    for count in counts {
        hits.copy_within(read..read + *count, write);
        read += *count;
        *count = sort_and_dedup(&mut hits[write..write + *count]);
        write += *count;
    }
    hits.truncate(write);
}

/// Sorts one ray's hits nearest first (equal distances by instance, then triangle) and
/// moves them to the front without repeats (a triangle met in several leaves); returns
/// how many are kept.
fn sort_and_dedup(hits: &mut [Hit]) -> usize {
    hits.sort_unstable_by(|a, b| {
        a.t.total_cmp(&b.t)
            .then((a.inst, a.prim).cmp(&(b.inst, b.prim)))
    });
    let mut kept = 0;
    for k in 0..hits.len() {
        let repeat = kept > 0 && {
            let (last, hit) = (&hits[kept - 1], &hits[k]);
            (last.inst, last.prim) == (hit.inst, hit.prim) && last.t == hit.t
        };
        if !repeat {
            hits[kept] = hits[k];
            kept += 1;
        }
    }
    kept
}

/// Which hits along a ray [`SurfaceQuery::hits`] reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HitsAlong {
    /// Each crossing of the surface once: a ray through an edge or a vertex that
    /// triangles share crosses there once, not once per triangle, and a ray through a
    /// closed surface crosses it an even number of times wherever it passes (the tie
    /// rule of [`crate::crosses_triangle`]). Coincident triangles (two faces back to
    /// back) are two crossings.
    #[default]
    Crossings,
    /// Every triangle the watertight test hits ([`crate::intersect_triangle`]): a ray
    /// through a shared edge or vertex hits each triangle around it.
    Triangles,
}

impl<S: SurfaceQuery + Send> SurfaceQuery for std::sync::Arc<S> {
    fn nearest_placed(
        &self,
        query: Vec3,
        placement: Option<&Placement>,
        limit_sq: f32,
    ) -> Option<(f32, Nearest)> {
        (**self).nearest_placed(query, placement, limit_sq)
    }

    fn winding_number_within(&self, query: Vec3, far_field: f32) -> f64 {
        (**self).winding_number_within(query, far_field)
    }

    fn inside_winding_number(&self, query: Vec3) -> f64 {
        (**self).inside_winding_number(query)
    }

    fn count_hits(&self, ray: &Ray, mask: u32, along: HitsAlong) -> usize {
        (**self).count_hits(ray, mask, along)
    }

    fn all_hits(&self, ray: &Ray, mask: u32, along: HitsAlong, out: &mut Vec<Hit>) {
        (**self).all_hits(ray, mask, along, out)
    }

    fn count_hits_each(&self, rays: &[Ray], mask: u32, along: HitsAlong, counts: &mut [usize]) {
        (**self).count_hits_each(rays, mask, along, counts)
    }

    fn hits_each(
        &self,
        rays: &[Ray],
        mask: u32,
        along: HitsAlong,
        hits: &mut Vec<Hit>,
        counts: &mut [usize],
    ) {
        (**self).hits_each(rays, mask, along, hits, counts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Quat};

    fn singular_values(m: Mat3) -> Vec<f64> {
        // By brute force: the extremes of |M x| over many unit vectors.
        let mut lengths: Vec<f64> = (0..20000)
            .map(|i| {
                let (a, b) = (
                    i as f64 * 0.618_034 * std::f64::consts::TAU,
                    (i as f64 / 20000.0) * 2.0 - 1.0,
                );
                let s = (1.0 - b * b).sqrt();
                let x = glam::DVec3::new(s * a.cos(), s * a.sin(), b);
                (m.as_dmat3() * x).length()
            })
            .collect();
        lengths.sort_by(f64::total_cmp);
        lengths
    }

    #[test]
    fn the_least_stretch_bounds_every_vector_from_below_and_is_tight() {
        let cases = [
            Mat3::IDENTITY,
            Mat3::from_diagonal(Vec3::new(2.0, 0.5, 3.0)),
            Mat3::from_quat(Quat::from_euler(glam::EulerRot::XYZ, 0.3, 1.1, -0.7)) * 4.0,
            Mat3::from_cols(
                Vec3::new(1.0, 0.2, 0.0),
                Vec3::new(0.9, 1.0, 0.3),
                Vec3::new(0.0, 0.1, 0.01),
            ),
            Mat3::from_diagonal(Vec3::new(-1.0, 1.0, 1.0)),
        ];
        for m in cases {
            let placement = Placement::new(Affine3A::from_mat3(m));
            let lengths = singular_values(m);
            let least = lengths[0];
            assert!(
                placement.stretch as f64 <= least * (1.0 + 1e-9),
                "{m}: {} > {least}",
                placement.stretch
            );
            assert!(
                placement.stretch as f64 >= least * 0.99,
                "{m}: {} far below {least}",
                placement.stretch
            );
        }
    }
}
