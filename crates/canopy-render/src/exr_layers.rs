//! The film and its AOVs as one OpenEXR image: the film in `R`, `G`, `B` (what every
//! viewer shows) and each AOV in channels named `layer.channel`, as Blender, Nuke and
//! Open Image Denoise's tools read them:
//!
//! | AOV | channels | type |
//! |---|---|---|
//! | albedo | `albedo.R`, `albedo.G`, `albedo.B` | f32 |
//! | normal | `normal.X`, `normal.Y`, `normal.Z` | f32 |
//! | depth | `depth.Z` | f32 |
//! | position | `position.X`, `position.Y`, `position.Z` | f32 |
//! | id | `id.instance`, `id.primitive` | u32 ([`crate::aov::NO_ID`]: nothing hit) |

use crate::aov::{Aov, AovBuffers};
use crate::film::Film;
use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, SmallVec,
    WritableImage,
};
use glam::Vec3;
use std::io::{Seek, Write};

/// The channels of `aovs` (images, as [`AovBuffers::resolved`] gives them): name and
/// samples.
pub fn aov_channels(aovs: &AovBuffers) -> Vec<(String, FlatSamples)> {
    let mut channels = Vec::new();
    let mut vec3 = |layer: &str, names: [&str; 3], values: &[Vec3]| {
        for (axis, name) in names.iter().enumerate() {
            let samples = values.iter().map(|v| v[axis]).collect();
            channels.push((format!("{layer}.{name}"), FlatSamples::F32(samples)));
        }
    };
    let (rgb, xyz) = (["R", "G", "B"], ["X", "Y", "Z"]);
    for aov in aovs.set.iter() {
        match aov {
            Aov::Albedo => vec3("albedo", rgb, &aovs.albedo),
            Aov::Normal => vec3("normal", xyz, &aovs.normal),
            Aov::Position => vec3("position", xyz, &aovs.position),
            Aov::Depth | Aov::Id => {}
        }
    }
    if aovs.set.contains(Aov::Depth) {
        channels.push(("depth.Z".into(), FlatSamples::F32(aovs.depth.clone())));
    }
    if aovs.set.contains(Aov::Id) {
        channels.push((
            "id.instance".into(),
            FlatSamples::U32(aovs.instance.clone()),
        ));
        channels.push((
            "id.primitive".into(),
            FlatSamples::U32(aovs.primitive.clone()),
        ));
    }
    channels
}

/// Encodes `film` and the AOV images `aovs` as one EXR image into `out`.
pub(crate) fn encode(
    film: &Film,
    aovs: &AovBuffers,
    out: impl Write + Seek,
) -> Result<(), image::ImageError> {
    let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (axis, name) in ["R", "G", "B"].into_iter().enumerate() {
        let samples = film.pixels.iter().map(|p| p[axis]).collect();
        channels.push(AnyChannel::new(name, FlatSamples::F32(samples)));
    }
    for (name, samples) in aov_channels(aovs) {
        channels.push(AnyChannel::new(name.as_str(), samples));
    }
    let size = (film.width as usize, film.height as usize);
    let layer = Layer::new(
        size,
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(channels),
    );
    Image::from_layer(layer)
        .write()
        .to_buffered(out)
        .map_err(|e| match e {
            exr::error::Error::Io(io) => image::ImageError::IoError(io),
            other => image::ImageError::Encoding(image::error::EncodingError::new(
                image::ImageFormat::OpenExr.into(),
                other,
            )),
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::aov::{AovSample, AovSet};
    use exr::prelude::{read, ReadChannels, ReadLayers};

    #[test]
    fn every_layer_reads_back_under_its_name() {
        let film = Film {
            width: 2,
            height: 1,
            pixels: vec![Vec3::new(1.0, 2.0, 3.0), Vec3::splat(0.5)],
        };
        let mut aovs = AovBuffers::new(AovSet::of(&Aov::ALL), 2);
        let hit = AovSample {
            albedo: Vec3::new(0.1, 0.2, 0.3),
            normal: Vec3::Y,
            depth: 4.0,
            position: Vec3::new(5.0, 6.0, 7.0),
            instance: 8,
            primitive: 9,
        };
        aovs.add(0, &hit, true);
        aovs.add(1, &AovSample::escaped(Vec3::ONE), true);
        let mut bytes = std::io::Cursor::new(Vec::new());
        encode(&film, &aovs.resolved(1), &mut bytes).unwrap();
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes.into_inner()))
            .unwrap();
        let channel = |name: &str| {
            let list = &image.layer_data.channel_data.list;
            let found = list.iter().find(|c| c.name.to_string() == name);
            found
                .unwrap_or_else(|| panic!("no channel {name}"))
                .sample_data
                .clone()
        };
        let f32s = |name: &str| channel(name).values_as_f32().collect::<Vec<_>>();
        assert_eq!(f32s("G"), [2.0, 0.5]);
        assert_eq!(f32s("albedo.B"), [0.3, 1.0]);
        assert_eq!(f32s("normal.Y"), [1.0, 0.0]);
        assert_eq!(f32s("depth.Z"), [4.0, f32::INFINITY]);
        assert_eq!(f32s("position.Z"), [7.0, f32::INFINITY]);
        let FlatSamples::U32(ids) = channel("id.primitive") else {
            panic!("ids are not u32");
        };
        assert_eq!(ids, [9, crate::aov::NO_ID]);
    }
}
