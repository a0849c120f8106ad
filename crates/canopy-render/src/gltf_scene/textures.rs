//! A glTF material's textures as canopy's: images decoded once however many textures
//! use them (from a buffer view, a data URI or a file beside the model), samplers' wrap
//! modes, `KHR_texture_transform`. Filters are bilinear whatever the sampler asks.

use super::data::{decode_data_uri, describe, percent_decoded, Buffers};
use crate::scene::Scene;
use crate::scene_file::Assets;
use crate::texture::{Image, NormalMap, TextureRef, UvTransform, Wrap};
use glam::Vec2;
use gltf::texture::WrappingMode;
use std::collections::HashMap;

/// Images read so far, by their index in the file.
#[derive(Default)]
pub(super) struct Images(HashMap<usize, u32>);

impl Images {
    /// canopy's texture for the texture `info` names, or `None` (with a note) for one
    /// canopy cannot use: one that reads a second set of texture coordinates.
    pub fn texture(
        &mut self,
        scene: &mut Scene,
        buffers: &Buffers,
        assets: &dyn Assets,
        info: &gltf::texture::Info<'_>,
        notes: &mut Vec<String>,
    ) -> Result<Option<TextureRef>, String> {
        let transform = info.texture_transform();
        let set = transform
            .as_ref()
            .and_then(|t| t.tex_coord())
            .unwrap_or(info.tex_coord());
        let transform = transform.map(|t| UvTransform {
            offset: Vec2::from(t.offset()),
            rotation: t.rotation(),
            scale: Vec2::from(t.scale()),
        });
        self.source(
            scene,
            buffers,
            assets,
            &info.texture(),
            set,
            transform,
            notes,
        )
    }

    /// A normal map, `scale` included.
    pub fn normal_map(
        &mut self,
        scene: &mut Scene,
        buffers: &Buffers,
        assets: &dyn Assets,
        normal: &gltf::material::NormalTexture<'_>,
        notes: &mut Vec<String>,
    ) -> Result<Option<NormalMap>, String> {
        let texture = self.source(
            scene,
            buffers,
            assets,
            &normal.texture(),
            normal.tex_coord(),
            None,
            notes,
        )?;
        Ok(texture.map(|texture| NormalMap {
            texture,
            scale: normal.scale(),
        }))
    }

    #[allow(clippy::too_many_arguments)]
    fn source(
        &mut self,
        scene: &mut Scene,
        buffers: &Buffers,
        assets: &dyn Assets,
        texture: &gltf::Texture<'_>,
        set: u32,
        transform: Option<UvTransform>,
        notes: &mut Vec<String>,
    ) -> Result<Option<TextureRef>, String> {
        let named = format!("texture {}", describe(texture.index(), texture.name()));
        if set != 0 {
            notes.push(format!(
                "{named} reads TEXCOORD_{set}; only TEXCOORD_0 is read (texture left out)"
            ));
            return Ok(None);
        }
        let source = texture.source();
        let image = match self.0.get(&source.index()) {
            Some(&image) => image,
            None => {
                let image = read_image(scene, buffers, assets, &source)?;
                self.0.insert(source.index(), image);
                image
            }
        };
        let sampler = texture.sampler();
        Ok(Some(TextureRef {
            image,
            wrap: [wrap(sampler.wrap_s()), wrap(sampler.wrap_t())],
            transform,
        }))
    }
}

fn wrap(mode: WrappingMode) -> Wrap {
    match mode {
        WrappingMode::ClampToEdge => Wrap::ClampToEdge,
        WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        WrappingMode::Repeat => Wrap::Repeat,
    }
}

/// Decodes `image` into `scene`; returns its index there.
fn read_image(
    scene: &mut Scene,
    buffers: &Buffers,
    assets: &dyn Assets,
    image: &gltf::Image<'_>,
) -> Result<u32, String> {
    let named = format!("image {}", describe(image.index(), image.name()));
    let decoded = match image.source() {
        gltf::image::Source::View { view, .. } => {
            let buffer = buffers.get(view.buffer()).unwrap_or_default();
            let bytes = view
                .offset()
                .checked_add(view.length())
                .and_then(|end| buffer.get(view.offset()..end))
                .ok_or_else(|| {
                    format!(
                        "{named}: buffer view {} (bytes {}..+{}) overruns buffer {} of {} bytes",
                        view.index(),
                        view.offset(),
                        view.length(),
                        view.buffer().index(),
                        buffer.len()
                    )
                })?;
            Image::decode(bytes)
        }
        gltf::image::Source::Uri { uri, .. } => match uri.strip_prefix("data:") {
            Some(data) => decode_data_uri(data).and_then(|bytes| Image::decode(&bytes)),
            None => {
                let path = percent_decoded(uri);
                scene.inputs.extend(assets.locate(&path));
                let bytes = assets.read(&path).map_err(|e| format!("{named}: {e}"))?;
                Image::decode(&bytes).map_err(|e| format!("`{path}`: {e}"))
            }
        },
    };
    let decoded = decoded.map_err(|e| format!("{named}: {e}"))?;
    Ok(scene.add_image(decoded))
}
