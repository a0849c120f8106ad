//! Textures for the GPU, read by `textures.wgsl` as the CPU's `canopy_render::texture`
//! reads them: every image's 8-bit texels in one buffer (filtered in the kernel, sRGB
//! decoded per texel before filtering, glTF's wrap modes and texture transforms), each
//! material's maps and coverage, and each textured mesh triangle's texture coordinates
//! and tangents.

use bytemuck::{Pod, Zeroable};
use canopy_render::texture::{Coverage, MaterialMaps, TextureRef, Wrap};
use canopy_render::{Scene, SceneMesh};

/// No image: a texture slot the material leaves empty.
const NO_IMAGE: u32 = u32::MAX;

/// One use of an image: 32 bytes; WGSL `TextureRef` in `textures.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuTexture {
    /// `KHR_texture_transform`'s offset (xy) and scale (zw); the identity without one.
    transform: [f32; 4],
    /// The image ([`NO_IMAGE`]: none), the wraps (s in bits 0..8, t in 8..16), and the
    /// bits of the rotation's sine and cosine (computed here, so that both devices use
    /// the same).
    info: [u32; 4],
}

impl GpuTexture {
    const NONE: Self = Self {
        transform: [0.0, 0.0, 1.0, 1.0],
        info: [NO_IMAGE, 0, 0, 0],
    };

    fn new(texture: Option<&TextureRef>) -> Self {
        let Some(t) = texture else {
            return Self::NONE;
        };
        let wrap = |w: Wrap| match w {
            Wrap::Repeat => 0,
            Wrap::ClampToEdge => 1,
            Wrap::MirroredRepeat => 2,
        };
        let (offset, scale, (sin, cos)) = match t.transform {
            Some(m) => (m.offset, m.scale, m.rotation.sin_cos()),
            None => (glam::Vec2::ZERO, glam::Vec2::ONE, (0.0, 1.0)),
        };
        Self {
            transform: [offset.x, offset.y, scale.x, scale.y],
            info: [
                t.image,
                wrap(t.wrap[0]) | wrap(t.wrap[1]) << 8,
                f32::to_bits(sin),
                f32::to_bits(cos),
            ],
        }
    }
}

/// A material's textures and coverage: 144 bytes; WGSL `MaterialMaps`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuMaterialMaps {
    base_color: GpuTexture,
    metallic_roughness: GpuTexture,
    normal: GpuTexture,
    emissive: GpuTexture,
    /// Coverage (0 opaque, 1 mask, 2 blend), the bits of its alpha factor and cutoff,
    /// and the bits of the normal map's scale.
    coverage: [u32; 4],
}

impl GpuMaterialMaps {
    fn new(maps: &MaterialMaps) -> Self {
        let (mode, alpha, cutoff) = match maps.coverage {
            None => (0, 1.0, 0.0),
            Some(Coverage::Mask { alpha, cutoff }) => (1, alpha, cutoff),
            Some(Coverage::Blend { alpha }) => (2, alpha, 0.0),
        };
        let normal_scale = maps.normal.map_or(1.0, |n| n.scale);
        Self {
            base_color: GpuTexture::new(maps.base_color.as_ref()),
            metallic_roughness: GpuTexture::new(maps.metallic_roughness.as_ref()),
            normal: GpuTexture::new(maps.normal.as_ref().map(|n| &n.texture)),
            emissive: GpuTexture::new(maps.emissive.as_ref()),
            coverage: [
                mode,
                alpha.to_bits(),
                cutoff.to_bits(),
                normal_scale.to_bits(),
            ],
        }
    }
}

/// Everything the kernels' texture bindings hold.
pub(crate) struct GpuTextures {
    /// One per material (opaque and untextured past the scene's maps).
    pub maps: Vec<GpuMaterialMaps>,
    /// Per image: its first texel, width and height.
    pub images: Vec<[u32; 4]>,
    /// Every image's texels (RGBA, 8 bits each: WGSL's `unpack4x8unorm` order).
    pub texels: Vec<[u8; 4]>,
}

impl GpuTextures {
    pub fn new(scene: &Scene) -> Self {
        let opaque = MaterialMaps::default();
        let maps = (0..scene.materials.len().max(1))
            .map(|i| GpuMaterialMaps::new(scene.material_maps.get(i).unwrap_or(&opaque)))
            .collect();
        let (mut images, mut texels) = (Vec::new(), Vec::new());
        for image in &scene.images {
            images.push([texels.len() as u32, image.width, image.height, 0]);
            texels.extend_from_slice(&image.texels);
        }
        Self {
            maps,
            images,
            texels,
        }
    }
}

/// Appends what a textured mesh's triangle `t` needs for its textures to `data` and
/// returns where it starts ([`crate::FLAT`] for a mesh without texture coordinates):
/// its corners' texture coordinates (uv0, uv1 | uv2, the bitangent's sign, whether
/// tangents follow), then, where the mesh has tangents, its corners' tangents.
pub(crate) fn push_surface(data: &mut Vec<[f32; 4]>, mesh: &SceneMesh, t: usize) -> u32 {
    if mesh.uvs.is_empty() {
        return crate::FLAT;
    }
    let start = data.len() as u32;
    let [a, b, c] = mesh.mesh.indices()[t].map(|i| mesh.uvs[i as usize]);
    let tangents = mesh.tangents.get(t);
    let sign = tangents.map_or(1.0, |corners| corners[0].w);
    data.push([a.x, a.y, b.x, b.y]);
    data.push([c.x, c.y, sign, tangents.is_some() as u32 as f32]);
    for corner in tangents.into_iter().flatten() {
        data.push([corner.x, corner.y, corner.z, 0.0]);
    }
    start
}
