//! Writing images: PNG (8-bit sRGB) and OpenEXR (linear float), chosen by extension,
//! written to a temporary file and renamed into place so that a failed or interrupted
//! write never leaves a broken image behind.

use crate::error::OutputError;
use crate::film::Film;
use image::{ImageBuffer, ImageFormat, Rgb};
use std::fs::File;
use std::io::{BufWriter, Cursor, Write};
use std::path::Path;

/// The image format for a path, from its extension.
pub fn image_format(path: &Path) -> Result<ImageFormat, OutputError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    match ext.to_ascii_lowercase().as_str() {
        "png" => Ok(ImageFormat::Png),
        "exr" => Ok(ImageFormat::OpenExr),
        _ => Err(OutputError::UnsupportedFormat {
            path: path.to_owned(),
        }),
    }
}

/// Writes the film to `path` atomically.
pub fn write_image(film: &Film, path: &Path) -> Result<(), OutputError> {
    let format = image_format(path)?;
    let bytes = encode(film, format).map_err(|cause| OutputError::Encode {
        path: path.to_owned(),
        cause,
    })?;
    write_atomically(path, |w| w.write_all(&bytes)).map_err(|cause| OutputError::Write {
        path: path.to_owned(),
        cause,
    })
}

/// The film as the bytes of an image file.
fn encode(film: &Film, format: ImageFormat) -> Result<Vec<u8>, image::ImageError> {
    let mut bytes = Cursor::new(Vec::new());
    match format {
        ImageFormat::OpenExr => {
            let data: Vec<f32> = film.pixels.iter().flat_map(|p| p.to_array()).collect();
            let img: ImageBuffer<Rgb<f32>, _> =
                ImageBuffer::from_raw(film.width, film.height, data)
                    .expect("film holds width * height pixels");
            img.write_to(&mut bytes, format)?;
        }
        _ => {
            let img: ImageBuffer<Rgb<u8>, _> =
                ImageBuffer::from_raw(film.width, film.height, film.to_srgb8())
                    .expect("film holds width * height pixels");
            img.write_to(&mut bytes, format)?;
        }
    }
    Ok(bytes.into_inner())
}

/// Writes a file through a hidden temporary sibling, synced and then renamed over
/// `path`: readers see the old file or the whole new one, never a part. On failure the
/// temporary file is removed.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy())
        .unwrap_or_default();
    let temp = path.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| {
        let mut out = BufWriter::new(File::create(&temp)?);
        write(&mut out)?;
        let file = out.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(&temp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&temp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use std::path::PathBuf;

    fn film() -> Film {
        let mut f = Film::new(3, 2);
        f.pixels[1] = Vec3::new(1.0, 0.5, 0.25);
        f
    }

    fn temp_dir(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("canopy-output-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn png_round_trips_through_srgb() {
        let dir = temp_dir("png");
        let path = dir.join("a.png");
        write_image(&film(), &path).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (3, 2));
        assert_eq!(img.get_pixel(1, 0).0, [255, 188, 137]);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn exr_keeps_linear_values() {
        let dir = temp_dir("exr");
        let path = dir.join("a.exr");
        write_image(&film(), &path).unwrap();
        let img = image::open(&path).unwrap().to_rgb32f();
        assert_eq!(img.get_pixel(1, 0).0, [1.0, 0.5, 0.25]);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn unknown_extension_is_refused_before_writing() {
        let dir = temp_dir("ext");
        let path = dir.join("a.bmp");
        assert!(matches!(
            write_image(&film(), &path),
            Err(OutputError::UnsupportedFormat { .. })
        ));
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn failed_write_leaves_nothing_behind() {
        let dir = temp_dir("missing");
        let path = dir.join("no-such-dir").join("a.png");
        assert!(write_image(&film(), &path).is_err());
        assert!(!path.exists());
        std::fs::remove_dir_all(dir).unwrap();
    }
}
