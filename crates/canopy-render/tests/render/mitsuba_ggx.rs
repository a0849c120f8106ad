//! The glTF metallic-roughness BRDF against values Mitsuba 3 computed (`scalar_rgb`,
//! `roughconductor` and `principled` with metallic 1), kept in `data/mitsuba_ggx.csv` by
//! `bench/brdf_compare.sh --write-reference`, which compares 10,000 pairs per case.
//!
//! Mitsuba masks with Smith's separable G1·G1, canopy with the height-correlated G2 of the
//! glTF specification: Mitsuba's values are scaled by G2 / (G1·G1) before comparing.
//! Densities are the same model in both and are compared as they are.

use canopy_render::geometry::Surface;
use canopy_render::material::ggx::Ggx;
use canopy_render::material::{Material, Pbr};
use glam::Vec3;

#[test]
fn values_and_densities_equal_mitsubas() {
    let table = include_str!("../data/mitsuba_ggx.csv");
    let surface = Surface {
        p: Vec3::ZERO,
        geometric_normal: Vec3::Z,
        shading_normal: Vec3::Z,
        error: 0.0,
    };
    let mut rows = 0;
    for line in table.lines().filter(|l| !l.starts_with('#')) {
        let v: Vec<f32> = line.split(',').map(|x| x.parse().unwrap()).collect();
        let [roughness, r, g, b, ox, oy, oz, ix, iy, iz, mr, mg, mb, mpdf] = v[..] else {
            panic!("bad row {line}");
        };
        let (wo, wi) = (Vec3::new(ox, oy, oz), Vec3::new(ix, iy, iz));
        let material = Material::Pbr(Pbr {
            base_color: Vec3::new(r, g, b),
            metallic: 1.0,
            roughness,
            emission: Vec3::ZERO,
        });
        let ggx = Ggx::from_roughness(roughness);
        let masking = ggx.g2(wo, wi) / (ggx.g1(wo) * ggx.g1(wi));
        let expected = Vec3::new(mr, mg, mb) * masking;
        let value = material.eval(-wo, &surface, wi);
        let pdf = material.pdf(-wo, &surface, wi);
        let close = |a: f32, b: f32| (a - b).abs() <= 2e-3 * b.abs() + 1e-6;
        for c in 0..3 {
            assert!(
                close(value[c], expected[c]),
                "{line}: value {value} vs Mitsuba's {expected}"
            );
        }
        assert!(
            close(pdf, mpdf),
            "{line}: density {pdf} vs Mitsuba's {mpdf}"
        );
        rows += 1;
    }
    assert_eq!(rows, 240);
}
