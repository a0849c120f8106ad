//! Morton codes (Z-order) of points: the bits of the three quantised coordinates
//! interleaved, so that sorting by code walks space along a Z-shaped curve
//! (Morton 1966; for BVHs, Lauterbach et al. 2009).

use crate::Aabb;
use glam::Vec3;
use rayon::prelude::*;

/// Spreads the low 21 bits of `v` so that two zero bits follow each one.
#[inline]
fn spread_bits_21(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// 63-bit Morton code of `p` on a 2^21 grid over `bounds`.
#[inline]
pub(crate) fn morton_code(p: Vec3, bounds: &Aabb) -> u64 {
    const CELLS: f32 = (1u32 << 21) as f32;
    let extent = bounds.extent();
    let scale = Vec3::select(extent.cmpgt(Vec3::ZERO), CELLS / extent, Vec3::ZERO);
    let q = ((p - bounds.min) * scale).clamp(Vec3::ZERO, Vec3::splat(CELLS - 1.0));
    spread_bits_21(q.x as u64) << 2 | spread_bits_21(q.y as u64) << 1 | spread_bits_21(q.z as u64)
}

/// Morton codes of the boxes' centres, on a grid over the centres' bounds.
pub(crate) fn morton_codes(boxes: &[Aabb]) -> Vec<u64> {
    let centroid_bounds = Aabb::from_points(boxes.iter().map(Aabb::center));
    boxes
        .iter()
        .map(|b| morton_code(b.center(), &centroid_bounds))
        .collect()
}

/// Primitive indices sorted by Morton code (ties by index, so the order is total).
pub(crate) fn morton_order(codes: &[u64]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..codes.len() as u32).collect();
    // Keys are unique (index breaks ties), so the parallel sort is deterministic.
    order.par_sort_unstable_by_key(|&i| (codes[i as usize], i));
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_are_interleaved_x_highest() {
        let b = Aabb::new(Vec3::ZERO, Vec3::splat((1u32 << 21) as f32));
        assert_eq!(morton_code(Vec3::new(1.0, 0.0, 0.0), &b), 0b100);
        assert_eq!(morton_code(Vec3::new(0.0, 1.0, 0.0), &b), 0b010);
        assert_eq!(morton_code(Vec3::new(0.0, 0.0, 1.0), &b), 0b001);
        assert_eq!(morton_code(Vec3::new(3.0, 0.0, 0.0), &b), 0b100100);
    }

    #[test]
    fn codes_fit_in_63_bits_and_corners_are_extreme() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        assert_eq!(morton_code(Vec3::ZERO, &b), 0);
        assert_eq!(morton_code(Vec3::ONE, &b), (1u64 << 63) - 1);
    }

    #[test]
    fn flat_bounds_do_not_divide_by_zero() {
        let b = Aabb::new(Vec3::ZERO, Vec3::new(1.0, 0.0, 1.0));
        let code = morton_code(Vec3::new(0.5, 0.0, 0.5), &b);
        assert_eq!(code & 0b010, 0);
    }
}
