//! Image textures: 8-bit RGBA images decoded by the `image` crate (their memory checked
//! before decoding), looked up with bilinear filtering, glTF's wrap modes and
//! `KHR_texture_transform`, and the material parameters they scale.
//!
//! Colours are stored as the file holds them and converted from sRGB to linear per texel
//! before filtering (filtering encoded values would darken edges); data textures
//! (metallic-roughness) are read as they are.

use crate::files;
use crate::material::Material;
use glam::{Vec2, Vec3, Vec4};
use std::sync::{Arc, LazyLock};

/// Largest side of an image canopy decodes, in texels.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// An image's texels, row by row from the top (glTF's UV origin is its top-left corner).
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<[u8; 4]>,
}

impl Image {
    /// Decodes a PNG or JPEG image, refusing one whose decoded size is out of bounds or
    /// exceeds the memory available, before its pixels are decoded.
    pub fn decode(bytes: &[u8]) -> Result<Self, String> {
        let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| format!("cannot read the image: {e}"))?;
        let format = reader
            .format()
            .ok_or("not an image format canopy reads (PNG or JPEG)")?;
        if !matches!(format, image::ImageFormat::Png | image::ImageFormat::Jpeg) {
            return Err(format!("a {format:?} image; textures must be PNG or JPEG"));
        }
        let (width, height) = reader
            .into_dimensions()
            .map_err(|e| format!("cannot read the image's size: {e}"))?;
        if width == 0 || height == 0 || width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
            return Err(format!(
                "the image is {width}x{height}; each side must be 1 to {MAX_IMAGE_SIDE}"
            ));
        }
        // The decoder's buffer (up to 16 bytes a texel) and ours (4).
        let needed = width as u64 * height as u64 * 20;
        files::check_memory(needed, files::available_memory(), "the image")?;
        let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes));
        reader.set_format(format);
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_IMAGE_SIDE);
        limits.max_image_height = Some(MAX_IMAGE_SIDE);
        limits.max_alloc = Some(needed);
        reader.limits(limits);
        let decoded = reader
            .decode()
            .map_err(|e| format!("cannot decode the image: {e}"))?
            .into_rgba8();
        Ok(Self {
            width,
            height,
            texels: decoded.pixels().map(|p| p.0).collect(),
        })
    }

    #[inline]
    fn texel(&self, x: u32, y: u32) -> [u8; 4] {
        self.texels[(y * self.width + x) as usize]
    }
}

/// How texture coordinates outside [0, 1] are folded back (glTF's sampler modes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    #[default]
    Repeat,
    ClampToEdge,
    MirroredRepeat,
}

impl Wrap {
    /// Texel index `i` (any integer) folded into `0..n`.
    #[inline]
    fn fold(self, i: i64, n: u32) -> u32 {
        let n = n as i64;
        let folded = match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::ClampToEdge => i.clamp(0, n - 1),
            Wrap::MirroredRepeat => {
                let period = i.rem_euclid(2 * n);
                if period < n {
                    period
                } else {
                    2 * n - 1 - period
                }
            }
        };
        folded as u32
    }
}

/// `KHR_texture_transform`: texture coordinates scaled, then rotated (radians,
/// counter-clockwise in UV space), then offset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    pub offset: Vec2,
    pub rotation: f32,
    pub scale: Vec2,
}

impl UvTransform {
    #[inline]
    fn apply(&self, uv: Vec2) -> Vec2 {
        let s = uv * self.scale;
        let (sin, cos) = self.rotation.sin_cos();
        // The extension's matrix: [cos, sin; -sin, cos] applied to (u, v).
        Vec2::new(cos * s.x + sin * s.y, -sin * s.x + cos * s.y) + self.offset
    }
}

/// One use of an image by a material: which image, how it wraps, how its coordinates
/// are transformed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureRef {
    /// Index into [`crate::Scene::images`].
    pub image: u32,
    pub wrap: [Wrap; 2],
    pub transform: Option<UvTransform>,
}

static SRGB_TO_LINEAR: LazyLock<[f32; 256]> =
    LazyLock::new(|| std::array::from_fn(|i| crate::film::srgb_to_linear(i as f32 / 255.0)));

impl TextureRef {
    /// The texture at `uv`, bilinearly filtered between texel centres; with `srgb` the
    /// colour channels are decoded to linear first (alpha never is).
    pub fn lookup(&self, images: &[Arc<Image>], uv: Vec2, srgb: bool) -> Vec4 {
        let image = &images[self.image as usize];
        let uv = match &self.transform {
            Some(t) => t.apply(uv),
            None => uv,
        };
        if !uv.is_finite() {
            return Vec4::ONE;
        }
        // Texel centres sit at half-integers.
        let x = uv.x as f64 * image.width as f64 - 0.5;
        let y = uv.y as f64 * image.height as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        // Far beyond i64 a coordinate means nothing; saturating keeps it harmless.
        let (x0, y0) = (x0 as i64, y0 as i64);
        let xs = [
            self.wrap[0].fold(x0, image.width),
            self.wrap[0].fold(x0.saturating_add(1), image.width),
        ];
        let ys = [
            self.wrap[1].fold(y0, image.height),
            self.wrap[1].fold(y0.saturating_add(1), image.height),
        ];
        let decode = |t: [u8; 4]| {
            let c = |v: u8| match srgb {
                true => SRGB_TO_LINEAR[v as usize],
                false => v as f32 / 255.0,
            };
            Vec4::new(c(t[0]), c(t[1]), c(t[2]), t[3] as f32 / 255.0)
        };
        let row = |y| {
            let (a, b) = (decode(image.texel(xs[0], y)), decode(image.texel(xs[1], y)));
            a + (b - a) * fx
        };
        let (top, bottom) = (row(ys[0]), row(ys[1]));
        top + (bottom - top) * fy
    }
}

/// How much of a surface is there: glTF's alpha modes. Its alpha is the base colour
/// factor's times the base colour texture's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Coverage {
    /// Present where alpha ≥ `cutoff`, absent elsewhere (leaves, fences).
    Mask { alpha: f32, cutoff: f32 },
    /// Present with probability alpha (stochastic transparency): on average a ray is
    /// stopped by a fraction alpha of the surface, as blending would show.
    Blend { alpha: f32 },
}

/// A tangent-space normal map: +X along the tangent, +Y along the bitangent, +Z along
/// the surface normal, each stored as (c + 1) / 2; `scale` scales X and Y.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalMap {
    pub texture: TextureRef,
    pub scale: f32,
}

impl NormalMap {
    /// The shading normal `normal` (unit) bent by the map at `uv`, in the frame of the
    /// surface's `tangent` and `bitangent` (any length, not yet orthogonal to it); `None`
    /// where the frame is degenerate.
    pub fn perturb(
        &self,
        images: &[Arc<Image>],
        uv: Vec2,
        normal: Vec3,
        tangent: Vec3,
        bitangent: Vec3,
    ) -> Option<Vec3> {
        let t = (tangent - normal * normal.dot(tangent)).try_normalize()?;
        let b =
            (bitangent - normal * normal.dot(bitangent) - t * t.dot(bitangent)).try_normalize()?;
        let c = self.texture.lookup(images, uv, false);
        let local = Vec3::new(
            (2.0 * c.x - 1.0) * self.scale,
            (2.0 * c.y - 1.0) * self.scale,
            2.0 * c.z - 1.0,
        );
        (t * local.x + b * local.y + normal * local.z).try_normalize()
    }
}

/// The textures a material's parameters are scaled by (glTF's metallic-roughness slots),
/// its normal map, and its coverage where it is not opaque.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MaterialMaps {
    /// sRGB colour times the base colour factor.
    pub base_color: Option<TextureRef>,
    /// Roughness in green and metallic in blue, times their factors (linear).
    pub metallic_roughness: Option<TextureRef>,
    /// Bends the shading normal (meshes with tangents only).
    pub normal: Option<NormalMap>,
    /// sRGB colour times the emission (glTF's emissive factor).
    pub emissive: Option<TextureRef>,
    /// `None`: opaque.
    pub coverage: Option<Coverage>,
}

impl MaterialMaps {
    pub fn is_empty(&self) -> bool {
        self.base_color.is_none()
            && self.metallic_roughness.is_none()
            && self.normal.is_none()
            && self.emissive.is_none()
            && self.coverage.is_none()
    }

    /// Whether a ray meeting the surface at `uv` (if it has texture coordinates) stops
    /// there; `u` draws the uniform number stochastic transparency needs.
    pub fn stops(&self, images: &[Arc<Image>], uv: Option<Vec2>, u: impl FnOnce() -> f32) -> bool {
        let Some(coverage) = self.coverage else {
            return true;
        };
        let texture_alpha = |alpha: f32| match (&self.base_color, uv) {
            (Some(t), Some(uv)) => alpha * t.lookup(images, uv, true).w,
            _ => alpha,
        };
        match coverage {
            Coverage::Mask { alpha, cutoff } => texture_alpha(alpha) >= cutoff,
            Coverage::Blend { alpha } => {
                let alpha = texture_alpha(alpha);
                alpha >= 1.0 || (alpha > 0.0 && u() < alpha)
            }
        }
    }

    /// `material` with its parameters scaled by these textures at `uv`. Only the
    /// metallic-roughness material has texture slots; any other is returned as it is.
    pub fn apply(&self, material: Material, images: &[Arc<Image>], uv: Vec2) -> Material {
        let Material::Pbr(mut pbr) = material else {
            return material;
        };
        if let Some(t) = &self.base_color {
            let c = t.lookup(images, uv, true);
            pbr.base_color *= Vec3::new(c.x, c.y, c.z);
        }
        if let Some(t) = &self.metallic_roughness {
            let c = t.lookup(images, uv, false);
            pbr.roughness *= c.y;
            pbr.metallic *= c.z;
        }
        if let Some(t) = &self.emissive {
            pbr.emission = self.emission(t, pbr.emission, images, uv);
        }
        Material::Pbr(pbr)
    }

    /// The emission `factor` scaled by the emissive texture `t` at `uv`.
    #[inline]
    fn emission(&self, t: &TextureRef, factor: Vec3, images: &[Arc<Image>], uv: Vec2) -> Vec3 {
        factor * t.lookup(images, uv, true).truncate()
    }

    /// The radiance a material emitting `factor` sends from `uv` (its emissive texture
    /// applied, where it has one).
    pub fn emitted(&self, factor: Vec3, images: &[Arc<Image>], uv: Vec2) -> Vec3 {
        match &self.emissive {
            Some(t) if factor != Vec3::ZERO => self.emission(t, factor, images, uv),
            _ => factor,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker() -> Arc<Image> {
        // 2x2: black, white / red, 50% grey (sRGB 188 is linear ~0.5).
        Arc::new(Image {
            width: 2,
            height: 2,
            texels: vec![
                [0, 0, 0, 255],
                [255, 255, 255, 255],
                [255, 0, 0, 0],
                [188, 188, 188, 255],
            ],
        })
    }

    fn plain(wrap: Wrap) -> TextureRef {
        TextureRef {
            image: 0,
            wrap: [wrap; 2],
            transform: None,
        }
    }

    #[test]
    fn texel_centres_return_their_texel_and_midpoints_blend() {
        let images = [checker()];
        let t = plain(Wrap::ClampToEdge);
        assert_eq!(
            t.lookup(&images, Vec2::new(0.25, 0.25), true),
            Vec4::new(0.0, 0.0, 0.0, 1.0)
        );
        assert_eq!(t.lookup(&images, Vec2::new(0.75, 0.25), true), Vec4::ONE);
        let red = t.lookup(&images, Vec2::new(0.25, 0.75), false);
        assert_eq!(red, Vec4::new(1.0, 0.0, 0.0, 0.0));
        // Halfway between black and white (linear), not the average of encoded values.
        let mid = t.lookup(&images, Vec2::new(0.5, 0.25), true);
        assert!(
            (mid - Vec4::new(0.5, 0.5, 0.5, 1.0)).abs().max_element() < 1e-6,
            "{mid}"
        );
        let grey = t.lookup(&images, Vec2::new(0.75, 0.75), true);
        assert!((grey.x - 0.5029).abs() < 1e-3, "{grey}");
        // Clamped: beyond the corner is the corner texel.
        assert_eq!(
            t.lookup(&images, Vec2::new(-3.0, -0.2), true),
            Vec4::new(0.0, 0.0, 0.0, 1.0)
        );
    }

    #[test]
    fn wrap_modes_fold_coordinates_as_gltf_says() {
        assert_eq!(
            (-4..5).map(|i| Wrap::Repeat.fold(i, 3)).collect::<Vec<_>>(),
            [2, 0, 1, 2, 0, 1, 2, 0, 1]
        );
        assert_eq!(
            (-4..5)
                .map(|i| Wrap::ClampToEdge.fold(i, 3))
                .collect::<Vec<_>>(),
            [0, 0, 0, 0, 0, 1, 2, 2, 2]
        );
        assert_eq!(
            (-4..7)
                .map(|i| Wrap::MirroredRepeat.fold(i, 3))
                .collect::<Vec<_>>(),
            [2, 2, 1, 0, 0, 1, 2, 2, 1, 0, 0]
        );
        let images = [checker()];
        let repeat = plain(Wrap::Repeat);
        for uv in [Vec2::new(0.25, 0.75), Vec2::new(0.6, 0.1)] {
            // Equal up to the rounding of uv + (3, −2).
            let (a, b) = (
                repeat.lookup(&images, uv, true),
                repeat.lookup(&images, uv + Vec2::new(3.0, -2.0), true),
            );
            assert!((a - b).abs().max_element() < 1e-5, "{a} {b}");
        }
        let mirror = plain(Wrap::MirroredRepeat);
        let a = mirror.lookup(&images, Vec2::new(0.25, 0.25), true);
        assert_eq!(a, mirror.lookup(&images, Vec2::new(-0.25, 0.25), true));
        assert_eq!(a, mirror.lookup(&images, Vec2::new(1.75, 0.25), true));
    }

    #[test]
    fn texture_transforms_scale_rotate_then_offset() {
        let t = UvTransform {
            offset: Vec2::new(0.5, 0.0),
            rotation: std::f32::consts::FRAC_PI_2,
            scale: Vec2::new(2.0, 1.0),
        };
        // (1, 0) → scaled (2, 0) → rotated (0, −2) → offset (0.5, −2).
        let uv = t.apply(Vec2::new(1.0, 0.0));
        assert!((uv - Vec2::new(0.5, -2.0)).length() < 1e-6, "{uv}");
    }

    #[test]
    fn maps_scale_the_metallic_roughness_parameters_and_emission() {
        let images = [checker()];
        let maps = MaterialMaps {
            base_color: Some(plain(Wrap::Repeat)),
            metallic_roughness: Some(plain(Wrap::Repeat)),
            normal: None,
            emissive: Some(plain(Wrap::Repeat)),
            coverage: None,
        };
        let m = Material::Pbr(crate::material::Pbr {
            base_color: Vec3::new(0.5, 1.0, 1.0),
            metallic: 1.0,
            roughness: 0.8,
            emission: Vec3::splat(2.0),
        });
        let white = Vec2::new(0.75, 0.25);
        let Material::Pbr(p) = maps.apply(m, &images, white) else {
            unreachable!()
        };
        assert_eq!(
            (p.base_color, p.metallic, p.roughness, p.emission),
            (Vec3::new(0.5, 1.0, 1.0), 1.0, 0.8, Vec3::splat(2.0))
        );
        let red = Vec2::new(0.25, 0.75);
        let Material::Pbr(p) = maps.apply(m, &images, red) else {
            unreachable!()
        };
        assert_eq!(
            (p.base_color, p.metallic, p.roughness, p.emission),
            (Vec3::new(0.5, 0.0, 0.0), 0.0, 0.0, Vec3::new(2.0, 0.0, 0.0))
        );
        assert_eq!(maps.emitted(Vec3::splat(2.0), &images, red), p.emission);
        let glass = Material::Dielectric { ior: 1.5 };
        assert_eq!(maps.apply(glass, &images, Vec2::ZERO), glass);
    }

    #[test]
    fn coverage_masks_by_the_cutoff_and_blends_by_chance() {
        let images = [checker()];
        let (opaque_texel, clear_texel) = (Vec2::new(0.25, 0.25), Vec2::new(0.25, 0.75));
        let masked = MaterialMaps {
            base_color: Some(plain(Wrap::ClampToEdge)),
            coverage: Some(Coverage::Mask {
                alpha: 0.8,
                cutoff: 0.5,
            }),
            ..MaterialMaps::default()
        };
        let never = || -> f32 { unreachable!("a mask draws no number") };
        assert!(masked.stops(&images, Some(opaque_texel), never));
        assert!(!masked.stops(&images, Some(clear_texel), never));
        // Without texture coordinates only the factor counts.
        assert!(masked.stops(&images, None, never));
        let blended = MaterialMaps {
            coverage: Some(Coverage::Blend { alpha: 0.3 }),
            ..MaterialMaps::default()
        };
        assert!(blended.stops(&images, None, || 0.29));
        assert!(!blended.stops(&images, None, || 0.31));
        assert!(MaterialMaps::default().stops(&images, None, never));
    }

    #[test]
    fn images_are_decoded_and_bad_ones_refused() {
        let mut png = Vec::new();
        image::RgbaImage::from_fn(3, 2, |x, y| {
            image::Rgba([x as u8 * 100, y as u8 * 200, 7, 255])
        })
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
        let image = Image::decode(&png).unwrap();
        assert_eq!((image.width, image.height), (3, 2));
        assert_eq!(image.texel(2, 1), [200, 200, 7, 255]);
        assert!(Image::decode(&png[..png.len() / 2])
            .unwrap_err()
            .contains("decode"));
        assert!(Image::decode(b"not an image")
            .unwrap_err()
            .contains("PNG or JPEG"));
    }
}
