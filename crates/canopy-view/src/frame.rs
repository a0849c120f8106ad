//! A frame as the page receives it: the film exposed, sRGB, boxes drawn where asked,
//! JPEG-encoded (a fraction of PNG's bytes and time, and a frame is replaced within
//! moments anyway; saving an image is the render's own writer's job).

use canopy_bvh::Tree;
use canopy_render::camera::{Camera, CameraSpec};
use canopy_render::visualize::{draw_bvh, LevelRange};
use canopy_render::Film;
use image::codecs::jpeg::JpegEncoder;
use image::ExtendedColorType;

/// JPEG quality of frames: no visible blocking on noisy renders.
const JPEG_QUALITY: u8 = 90;

/// What to draw over a film before it is sent.
pub struct Overlay<'a> {
    pub tree: &'a Tree,
    pub camera: &'a CameraSpec,
    pub levels: [u32; 2],
}

/// `film` exposed by `exposure` stops, with `overlay`'s boxes, as JPEG bytes.
pub fn encode(mut film: Film, exposure: f32, overlay: Option<Overlay>) -> Vec<u8> {
    expose(&mut film, exposure);
    if let Some(o) = overlay {
        let camera = Camera::new(o.camera, film.width, film.height);
        let levels = LevelRange {
            first: o.levels[0] as usize,
            last: o.levels[1] as usize,
        };
        draw_bvh(&mut film, &camera, o.tree, levels);
    }
    let rgb = film.to_srgb8();
    let mut bytes = Vec::new();
    JpegEncoder::new_with_quality(&mut bytes, JPEG_QUALITY)
        .encode(&rgb, film.width, film.height, ExtendedColorType::Rgb8)
        .expect("an RGB8 buffer of the film's size encodes into memory");
    bytes
}

/// `film` scaled by `exposure` stops, as the page shows it.
pub fn expose(film: &mut Film, exposure: f32) {
    if exposure != 0.0 {
        let scale = exposure.exp2();
        film.pixels.iter_mut().for_each(|p| *p *= scale);
    }
}

/// The process's resident memory in bytes, where the system tells it (Linux).
pub fn resident_bytes() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096)
}
