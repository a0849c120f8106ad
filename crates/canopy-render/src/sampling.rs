//! Sampling building blocks: orthonormal frames, directions in cones and on triangles,
//! discrete and piecewise-constant distributions, and the MIS weight.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_PI_2, PI, TAU};

/// An orthonormal basis around a unit vector `z`.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub x: Vec3,
    pub y: Vec3,
    pub z: Vec3,
}

impl Frame {
    /// The basis of Duff et al. 2017 ("Building an Orthonormal Basis, Revisited"): no
    /// branch on the dominant axis, continuous except at z = -Z.
    pub fn from_z(z: Vec3) -> Self {
        let sign = 1.0f32.copysign(z.z);
        let a = -1.0 / (sign + z.z);
        let b = z.x * z.y * a;
        Self {
            x: Vec3::new(1.0 + sign * z.x * z.x * a, sign * b, -sign * z.x),
            y: Vec3::new(b, sign + z.y * z.y * a, -z.y),
            z,
        }
    }

    #[inline]
    pub fn to_world(&self, local: Vec3) -> Vec3 {
        local.x * self.x + local.y * self.y + local.z * self.z
    }

    #[inline]
    pub fn to_local(&self, world: Vec3) -> Vec3 {
        Vec3::new(world.dot(self.x), world.dot(self.y), world.dot(self.z))
    }
}

/// The direction at polar angle `acos(cos_theta)` and azimuth `phi` around +z.
#[inline]
pub fn spherical_direction(sin_theta: f32, cos_theta: f32, phi: f32) -> Vec3 {
    let (s, c) = phi.sin_cos();
    Vec3::new(sin_theta * c, sin_theta * s, cos_theta)
}

/// `(sin 2πu, cos 2πu)` for `u` in `[0, 1]`, in plain arithmetic with no branch, so
/// that loops over SIMD lanes compile to vector code and give the bits a single call
/// gives (the C library's `sincosf` is neither). Within 2e-7 of the true values.
#[inline(always)]
pub fn sin_cos_turns(u: f32) -> (f32, f32) {
    // The nearest quarter turn k and the rest x in [-1/2, 1/2] quarter turns: both exact.
    let t = u * 4.0;
    let k = (t + 0.5) as i32;
    let x = (t - k as f32) * FRAC_PI_2;
    // Cephes' minimax polynomials of sinf and cosf on [-π/4, π/4].
    let z = x * x;
    let sin = ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * x + x;
    let cos = ((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - 0.5 * z + 1.0;
    // Turned by k quarter turns: each one maps (sin, cos) to (cos, -sin).
    let (sin, cos) = if k & 1 == 1 { (cos, -sin) } else { (sin, cos) };
    if k & 2 == 2 {
        (-sin, -cos)
    } else {
        (sin, cos)
    }
}

/// Uniform on the unit sphere from two uniform numbers; pdf `1 / 4π`. The same bits in
/// scalar code and in loops over SIMD lanes ([`sin_cos_turns`]).
#[inline(always)]
pub fn unit_vector(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = sin_cos_turns(u.y);
    Vec3::new(r * c, r * s, z)
}

/// Uniform on the unit sphere; pdf `1 / 4π`.
#[inline]
pub fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    spherical_direction(r, z, TAU * u.y)
}

pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Barycentric weights `(b0, b1, b2)` uniform over a triangle's area (the square-root
/// warp: Osada et al. 2002).
#[inline]
pub fn uniform_triangle(u: Vec2) -> [f32; 3] {
    let s = u.x.sqrt();
    let b0 = 1.0 - s;
    let b1 = u.y * s;
    [b0, b1, (1.0 - b0 - b1).max(0.0)]
}

/// Veach's power heuristic (β = 2) for one sample from each of two strategies: the weight
/// of the strategy with density `this` against the one with density `other`.
#[inline]
pub fn power_heuristic(this: f32, other: f32) -> f32 {
    if this.is_infinite() {
        return 1.0;
    }
    let (a, b) = (this * this, other * other);
    if a + b == 0.0 || !(a + b).is_finite() {
        // Both zero (cannot happen for a sample that was drawn) or `other` infinite.
        return if b.is_infinite() { 0.0 } else { 1.0 };
    }
    a / (a + b)
}

/// Luminance of linear sRGB (Rec. 709 weights).
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// A discrete distribution proportional to non-negative weights, sampled by binary search
/// over its cumulative sums (kept in f64, so a million tiny weights still sum exactly
/// enough).
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution1D {
    /// `cdf[i]` = sum of weights before `i`; `cdf[n]` = total.
    cdf: Vec<f64>,
}

impl Distribution1D {
    /// `None` when no weight is positive (nothing to sample). Negative, NaN and infinite
    /// weights count as zero.
    pub fn new(weights: impl IntoIterator<Item = f32>) -> Option<Self> {
        let mut cdf = vec![0.0f64];
        let mut total = 0.0f64;
        for w in weights {
            if w.is_finite() && w > 0.0 {
                total += w as f64;
            }
            cdf.push(total);
        }
        (total > 0.0).then_some(Self { cdf })
    }

    pub fn len(&self) -> usize {
        self.cdf.len() - 1
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn total(&self) -> f64 {
        self.cdf[self.len()]
    }

    /// The cumulative sums: `cdf()[i]` is the weight before index `i`, the last the total.
    pub fn cdf(&self) -> &[f64] {
        &self.cdf
    }

    /// Probability of drawing `index`.
    #[inline]
    pub fn pmf(&self, index: usize) -> f32 {
        ((self.cdf[index + 1] - self.cdf[index]) / self.total()) as f32
    }

    /// The index drawn by `u` in `[0, 1)`, with `u`'s position inside that index's slice
    /// rescaled to `[0, 1)` (so one random number can serve twice).
    #[inline]
    pub fn sample(&self, u: f32) -> (usize, f32) {
        let target = u as f64 * self.total();
        // The first index whose slice ends beyond the target; never a zero-weight one.
        let index = self.cdf[1..]
            .partition_point(|&end| end <= target)
            .min(self.len() - 1);
        let (start, end) = (self.cdf[index], self.cdf[index + 1]);
        let rest = ((target - start) / (end - start)).clamp(0.0, 1.0) as f32;
        (index, rest.min(1.0 - f32::EPSILON / 2.0))
    }
}

/// A piecewise-constant density over `[0, 1)²` from a grid of weights (rows of `width`),
/// sampled as a marginal over rows, then a conditional over the row's columns.
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution2D {
    width: usize,
    height: usize,
    rows: Vec<Option<Distribution1D>>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// `None` when no weight is positive.
    pub fn new(weights: &[f32], width: usize, height: usize) -> Option<Self> {
        assert_eq!(
            weights.len(),
            width * height,
            "weights do not fill the grid"
        );
        let rows: Vec<_> = weights
            .chunks(width)
            .map(|row| Distribution1D::new(row.iter().copied()))
            .collect();
        let marginal = Distribution1D::new(
            rows.iter()
                .map(|r| r.as_ref().map_or(0.0, |r| r.total() as f32)),
        )?;
        Some(Self {
            width,
            height,
            rows,
            marginal,
        })
    }

    /// A point in `[0, 1)²` and its density there.
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (row, v_rest) = self.marginal.sample(u.y);
        let cells = self.rows[row]
            .as_ref()
            .expect("the marginal never picks an empty row");
        let (column, u_rest) = cells.sample(u.x);
        let point = Vec2::new(
            (column as f32 + u_rest) / self.width as f32,
            (row as f32 + v_rest) / self.height as f32,
        );
        (point, self.pdf_cell(column, row))
    }

    /// The density at `point` in `[0, 1]²`.
    pub fn pdf(&self, point: Vec2) -> f32 {
        let column = ((point.x * self.width as f32) as usize).min(self.width - 1);
        let row = ((point.y * self.height as f32) as usize).min(self.height - 1);
        self.pdf_cell(column, row)
    }

    /// Cells per row and rows.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The distribution over the columns of `row` (`None` for a row of zero weight).
    pub fn row(&self, row: usize) -> Option<&Distribution1D> {
        self.rows[row].as_ref()
    }

    /// The distribution over rows.
    pub fn marginal(&self) -> &Distribution1D {
        &self.marginal
    }

    /// The density in cell (`column`, `row`), constant over the cell.
    pub fn pdf_cell(&self, column: usize, row: usize) -> f32 {
        match &self.rows[row] {
            Some(cells) => {
                self.marginal.pmf(row) * cells.pmf(column) * (self.width * self.height) as f32
            }
            None => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn frames_are_orthonormal_for_any_axis() {
        let mut rng = Rng::for_sample(1, 2, 3);
        let mut axes: Vec<Vec3> = (0..1000).map(|_| rng.unit_vector()).collect();
        axes.extend([Vec3::Z, -Vec3::Z, Vec3::X, -Vec3::Y]);
        for z in axes {
            let f = Frame::from_z(z);
            for (a, b) in [(f.x, f.y), (f.y, f.z), (f.x, f.z)] {
                assert!(a.dot(b).abs() < 1e-5, "{z}");
            }
            for v in [f.x, f.y] {
                assert!((v.length() - 1.0).abs() < 1e-5, "{z}");
            }
            assert!((f.to_world(Vec3::Z) - z).length() < 1e-6);
        }
    }

    #[test]
    fn sines_and_cosines_of_turns_are_within_2e7() {
        let n = 1 << 20;
        let mut worst = 0.0f64;
        for i in 0..=n {
            let u = i as f32 / n as f32;
            let (s, c) = sin_cos_turns(u);
            let angle = std::f64::consts::TAU * u as f64;
            worst = worst.max((s as f64 - angle.sin()).abs());
            worst = worst.max((c as f64 - angle.cos()).abs());
        }
        assert!(worst < 2e-7, "{worst}");
        // Exact at the quarter turns.
        assert_eq!(sin_cos_turns(0.0), (0.0, 1.0));
        assert_eq!(sin_cos_turns(0.25), (1.0, -0.0));
        assert_eq!(sin_cos_turns(0.5), (-0.0, -1.0));
    }

    #[test]
    fn uniform_triangle_weights_sum_to_one_and_have_equal_means() {
        let mut rng = Rng::for_sample(4, 5, 6);
        let n = 100_000;
        let mut sum = [0.0f64; 3];
        for _ in 0..n {
            let b = uniform_triangle(Vec2::new(rng.next_f32(), rng.next_f32()));
            assert!((b.iter().sum::<f32>() - 1.0).abs() < 1e-6);
            for i in 0..3 {
                assert!(b[i] >= 0.0);
                sum[i] += b[i] as f64;
            }
        }
        for s in sum {
            assert!((s / n as f64 - 1.0 / 3.0).abs() < 0.005, "{sum:?}");
        }
    }

    #[test]
    fn power_heuristic_weights_of_two_strategies_sum_to_one() {
        for (a, b) in [(1.0, 1.0), (0.3, 7.0), (5.0, 0.0), (f32::INFINITY, 2.0)] {
            let sum = power_heuristic(a, b) + power_heuristic(b, a);
            assert!((sum - 1.0).abs() < 1e-6, "{a} {b}: {sum}");
        }
        assert_eq!(power_heuristic(1.0, 1.0), 0.5);
    }

    #[test]
    fn discrete_samples_follow_the_weights_and_skip_zero_weights() {
        let d = Distribution1D::new([1.0, 0.0, 3.0, f32::NAN, 4.0]).unwrap();
        assert_eq!(d.len(), 5);
        assert_eq!(d.pmf(1), 0.0);
        assert_eq!(d.pmf(3), 0.0);
        assert!((d.pmf(2) - 0.375).abs() < 1e-7);
        let mut counts = [0usize; 5];
        let n = 80_000;
        for i in 0..n {
            let u = (i as f32 + 0.5) / n as f32;
            let (index, rest) = d.sample(u);
            assert!((0.0..1.0).contains(&rest));
            counts[index] += 1;
        }
        assert_eq!(counts, [10_000, 0, 30_000, 0, 40_000]);
        // The very ends of [0, 1) land on positive weights.
        assert_eq!(d.sample(0.0).0, 0);
        assert_eq!(d.sample(1.0 - f32::EPSILON).0, 4);
    }

    #[test]
    fn nothing_to_sample_is_none() {
        assert!(Distribution1D::new([0.0, -1.0]).is_none());
        assert!(Distribution1D::new([]).is_none());
        assert!(Distribution2D::new(&[0.0; 6], 3, 2).is_none());
    }

    #[test]
    fn grid_density_is_proportional_to_the_weights_and_integrates_to_one() {
        let weights = [1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 4.0];
        let d = Distribution2D::new(&weights, 3, 3).unwrap();
        let total: f32 = weights.iter().sum();
        for (i, w) in weights.iter().enumerate() {
            let centre = Vec2::new((i % 3) as f32 + 0.5, (i / 3) as f32 + 0.5) / 3.0;
            // Density = probability of the cell / its area (1/9).
            assert!((d.pdf(centre) - w / total * 9.0).abs() < 1e-5, "cell {i}");
        }
        let mut rng = Rng::for_sample(9, 9, 9);
        let mut counts = [0usize; 9];
        for _ in 0..60_000 {
            let (p, pdf) = d.sample(Vec2::new(rng.next_f32(), rng.next_f32()));
            assert_eq!(pdf, d.pdf(p));
            assert!(pdf > 0.0);
            let cell = (p.y * 3.0) as usize * 3 + (p.x * 3.0) as usize;
            counts[cell] += 1;
        }
        for (i, w) in weights.iter().enumerate() {
            let expected = w / total * 60_000.0;
            assert!(
                (counts[i] as f32 - expected).abs() < 4.0 * expected.sqrt() + 1.0,
                "cell {i}: {counts:?}"
            );
        }
    }
}
