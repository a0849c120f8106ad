//! The exact density of the fuzzy-metal lobe.
//!
//! A fuzzy metal reflects along `normalize(r + f·s)`: `r` the unit mirror direction, `f`
//! the fuzz and `s` uniform on the unit sphere. The point `r + f·s` is uniform on the
//! sphere S of radius `f` around `r` (area density `1 / 4πf²`), and a direction `ω` meets
//! S where `t² − 2tc + 1 − f² = 0`, `c = ω·r`. A surface patch at distance `t` whose
//! normal makes angle `α` with `ω` subtends `dA·|cos α| / t²`, and here
//! `|cos α| = √disc / f` with `disc = c² − 1 + f²`, so the density per solid angle is
//! `Σ t² / (4π f √disc)` over the roots `t > 0`:
//! - `f < 1`: both roots, when `c > 0`; `t₊² + t₋² = 2(c² + disc)`.
//! - `f ≥ 1`: the origin is inside S and only `t₊ = c + √disc` counts.
//!
//! It integrates to one over the sphere of directions (tested); directions that end up
//! under the surface are absorbed by the material, not redrawn, so this stays the density.

use glam::Vec3;
use std::f32::consts::PI;

/// Density per solid angle of drawing unit `direction` around unit `mirror` with `fuzz > 0`.
/// Both cases are computed and one is selected, with no early return, so that loops over
/// SIMD lanes vectorise ([`super::lanes`]).
#[inline(always)]
pub fn pdf(mirror: Vec3, fuzz: f32, direction: Vec3) -> f32 {
    let c = direction.dot(mirror);
    let disc = c * c - 1.0 + fuzz * fuzz;
    let root = disc.max(0.0).sqrt();
    let density = if fuzz < 1.0 {
        let both_roots = (c * c + disc) / (2.0 * PI * fuzz * root);
        if c <= 0.0 {
            0.0
        } else {
            both_roots
        }
    } else {
        let t = c + root;
        t * t / (4.0 * PI * fuzz * root)
    };
    if disc <= 0.0 {
        0.0
    } else {
        density
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use crate::sampling::uniform_sphere;
    use glam::Vec2;

    fn draw(mirror: Vec3, fuzz: f32, rng: &mut Rng) -> Vec3 {
        (mirror + fuzz * rng.unit_vector()).normalize_or_zero()
    }

    #[test]
    fn density_integrates_to_one() {
        // Stratified uniform directions: ∫ pdf dω = 4π · mean(pdf). The density has an
        // integrable spike at the cone's edge for f < 1, so allow a little.
        let mirror = Vec3::new(0.3, 0.8, -0.2).normalize();
        for fuzz in [0.3, 0.7, 1.0, 1.5, 4.0] {
            let n = 400;
            let mut sum = 0.0f64;
            for i in 0..n {
                for j in 0..n {
                    let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                    sum += pdf(mirror, fuzz, uniform_sphere(u)) as f64;
                }
            }
            let integral = 4.0 * std::f64::consts::PI * sum / (n * n) as f64;
            assert!((integral - 1.0).abs() < 0.02, "fuzz {fuzz}: {integral}");
        }
    }

    /// Probability that the cosine to the mirror direction falls in `[a, b]`: the density
    /// integrated over that ring. For `f < 1` in the variable `s = √(c² − k²)`,
    /// `k² = 1 − f²`, which removes the density's spike at the cone's edge (`c = k`).
    fn ring_probability(fuzz: f32, a: f64, b: f64) -> f64 {
        let f = fuzz as f64;
        let steps = 2000;
        if fuzz < 1.0 {
            let k2 = 1.0 - f * f;
            let (a, b) = (a.max(k2.sqrt()), b);
            if b <= a {
                return 0.0;
            }
            let (s0, s1) = ((a * a - k2).max(0.0).sqrt(), (b * b - k2).sqrt());
            let ds = (s1 - s0) / steps as f64;
            (0..steps)
                .map(|i| {
                    let s = s0 + (i as f64 + 0.5) * ds;
                    let c = (s * s + k2).sqrt();
                    (c * c + s * s) / (f * c) * ds
                })
                .sum()
        } else {
            let dc = (b - a) / steps as f64;
            (0..steps)
                .map(|i| {
                    let c = (a + (i as f64 + 0.5) * dc) as f32;
                    let d = Vec3::new((1.0 - c * c).max(0.0).sqrt(), 0.0, c);
                    pdf(Vec3::Z, fuzz, d) as f64 * std::f64::consts::TAU * dc
                })
                .sum()
        }
    }

    #[test]
    fn density_matches_the_drawn_directions() {
        // Histogram of the cosine to the mirror direction against the density integrated
        // over the same rings.
        let mirror = Vec3::new(-0.5, 0.5, 0.7).normalize();
        let mut rng = Rng::for_sample(3, 1, 4);
        for fuzz in [0.4f32, 1.0, 1.3] {
            let lowest = if fuzz < 1.0 {
                (1.0 - fuzz * fuzz).sqrt()
            } else {
                -1.0
            };
            let bins = 16;
            let n = 200_000;
            let mut counts = vec![0usize; bins];
            for _ in 0..n {
                let d = draw(mirror, fuzz, &mut rng);
                let cos = d.dot(mirror).clamp(lowest, 1.0);
                let bin = ((cos - lowest) / (1.0 - lowest) * bins as f32) as usize;
                counts[bin.min(bins - 1)] += 1;
            }
            let mut total = 0.0;
            for (bin, &count) in counts.iter().enumerate() {
                let edge =
                    |i: usize| lowest as f64 + (1.0 - lowest as f64) * i as f64 / bins as f64;
                let p = ring_probability(fuzz, edge(bin), edge(bin + 1));
                total += p;
                let expected = p * n as f64;
                let tolerance = 5.0 * expected.sqrt() + 0.005 * expected + 5.0;
                assert!(
                    (count as f64 - expected).abs() < tolerance,
                    "fuzz {fuzz}, bin {bin}: {count} drawn, {expected:.0} expected"
                );
            }
            assert!(
                (total - 1.0).abs() < 1e-3,
                "fuzz {fuzz}: rings sum to {total}"
            );
        }
    }
}
