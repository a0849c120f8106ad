//! A render's film denoised by Open Image Denoise, guided by its albedo and normal AOVs
//! where it has them.

use canopy_denoise::{DenoiseError, Images, Oidn, Options};
use canopy_render::{Aov, AovBuffers, Film};
use glam::Vec3;

/// `film` denoised, guided by the albedo and normal of `aovs` (images of the same size,
/// as [`AovBuffers::resolved`] gives them) where present, as `options` say.
pub fn denoise_film(
    oidn: &Oidn,
    film: &Film,
    aovs: &AovBuffers,
    options: &Options,
) -> Result<Film, DenoiseError> {
    let flat = |v: &[Vec3]| -> Vec<f32> { v.iter().flat_map(|p| p.to_array()).collect() };
    let color = flat(&film.pixels);
    let albedo = aovs.set.contains(Aov::Albedo).then(|| flat(&aovs.albedo));
    // OIDN takes a normal only beside an albedo.
    let normal = (albedo.is_some() && aovs.set.contains(Aov::Normal)).then(|| flat(&aovs.normal));
    let images = Images {
        width: film.width as usize,
        height: film.height as usize,
        color: &color,
        albedo: albedo.as_deref(),
        normal: normal.as_deref(),
    };
    let denoised = oidn.denoise(&images, options)?;
    Ok(Film {
        width: film.width,
        height: film.height,
        pixels: denoised
            .chunks_exact(3)
            .map(|c| Vec3::new(c[0], c[1], c[2]))
            .collect(),
    })
}
