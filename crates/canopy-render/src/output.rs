//! Writing images: PNG (8-bit sRGB) and OpenEXR (linear float), chosen by extension,
//! written to a temporary file and renamed into place so that a failed or interrupted
//! write never leaves a broken image behind.

use crate::aov::AovBuffers;
use crate::error::OutputError;
use crate::film::Film;
use image::{ImageBuffer, ImageFormat, Rgb};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

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

/// Writes the film to `path` atomically, encoding straight into the temporary file.
pub fn write_image(film: &Film, path: &Path) -> Result<(), OutputError> {
    let format = image_format(path)?;
    write_encoded(path, |out| encode(film, format, out))
}

/// Writes the film and the AOV layers of `aovs` (as images: see
/// [`AovBuffers::resolved`]) to `path` atomically: an OpenEXR image whose channels are
/// the film's `R`, `G`, `B` and each AOV's named ones ([`exr_layers`]). Without AOVs,
/// [`write_image`].
pub fn write_image_with_aovs(
    film: &Film,
    aovs: &AovBuffers,
    path: &Path,
) -> Result<(), OutputError> {
    if aovs.set.is_empty() {
        return write_image(film, path);
    }
    if image_format(path)? != ImageFormat::OpenExr {
        return Err(OutputError::LayersNeedExr {
            path: path.to_owned(),
        });
    }
    write_encoded(path, |out| crate::exr_layers::encode(film, aovs, out))
}

/// Writes `path` atomically by `encode`, telling a failed write from a failed encoding.
fn write_encoded(
    path: &Path,
    encode: impl FnOnce(&mut Recording<'_>) -> Result<(), image::ImageError>,
) -> Result<(), OutputError> {
    let mut encode_error = None;
    let written = write_atomically(path, |w| {
        let mut recorded = Recording {
            inner: w,
            failed: None,
        };
        encode(&mut recorded).map_err(|e| match (e, recorded.failed.take()) {
            (image::ImageError::IoError(e), _) => e,
            // An encoder may wrap a failed write in an error of its own (the EXR one
            // calls a full disk a "Format error decoding OpenExr"): the write's own
            // error is what went wrong.
            (_, Some(io)) => io,
            (other, None) => {
                encode_error = Some(other);
                std::io::Error::other("encoding failed")
            }
        })
    });
    match (written, encode_error) {
        (Ok(()), _) => Ok(()),
        (Err(_), Some(cause)) => Err(OutputError::Encode {
            path: path.to_owned(),
            cause,
        }),
        (Err(cause), None) => Err(OutputError::Write {
            path: path.to_owned(),
            cause,
        }),
    }
}

/// A writer that keeps the first error its file gave, whatever the encoder makes of it.
pub(crate) struct Recording<'w> {
    inner: &'w mut BufWriter<File>,
    failed: Option<std::io::Error>,
}

impl Recording<'_> {
    fn keep<T>(&mut self, result: std::io::Result<T>) -> std::io::Result<T> {
        result.inspect_err(|e| {
            if self.failed.is_none() {
                self.failed = Some(std::io::Error::new(e.kind(), e.to_string()));
            }
        })
    }
}

impl std::io::Write for Recording<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let result = self.inner.write(buf);
        self.keep(result)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        let result = self.inner.flush();
        self.keep(result)
    }
}

impl std::io::Seek for Recording<'_> {
    fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
        let result = self.inner.seek(to);
        self.keep(result)
    }
}

/// Encodes the film as an image file into `out`.
fn encode(
    film: &Film,
    format: ImageFormat,
    out: &mut Recording<'_>,
) -> Result<(), image::ImageError> {
    match format {
        ImageFormat::OpenExr => {
            let data: Vec<f32> = film.pixels.iter().flat_map(|p| p.to_array()).collect();
            let img: ImageBuffer<Rgb<f32>, _> =
                ImageBuffer::from_raw(film.width, film.height, data)
                    .expect("film holds width * height pixels");
            img.write_to(out, format)
        }
        _ => {
            let img: ImageBuffer<Rgb<u8>, _> =
                ImageBuffer::from_raw(film.width, film.height, film.to_srgb8())
                    .expect("film holds width * height pixels");
            img.write_to(out, format)
        }
    }
}

/// Peak bytes per pixel of reading an image: the decoded pixels (8-bit or float) and
/// their float copy.
pub const READ_BYTES_PER_PIXEL: u64 = 12 + 12;

/// Largest image file read: the largest film as uncompressed float RGB, and some.
const MAX_IMAGE_FILE_BYTES: u64 = crate::RenderSettings::MAX_PIXELS * 12 + (64 << 20);

/// Reads a PNG (8-bit values / 255, as stored) or EXR (linear float) image as its width,
/// height and RGB floats, rows from the top. Only a regular file is opened (a FIFO or
/// device is refused, never waited on), and the size its header declares is checked
/// against the largest image canopy renders and the memory available before anything
/// is decoded. Errors name the file.
pub fn read_image(path: &Path) -> Result<(u32, u32, Vec<f32>), String> {
    let fail = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let bytes =
        crate::files::read_regular_file(path, MAX_IMAGE_FILE_BYTES).map_err(|e| fail(&e))?;
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(&bytes[..]))
            .with_guessed_format()
            .expect("reading from memory cannot fail")
    };
    let (width, height) = reader().into_dimensions().map_err(|e| fail(&e))?;
    let pixels = width as u64 * height as u64;
    if pixels > crate::RenderSettings::MAX_PIXELS {
        return Err(fail(&format!(
            "a {width}x{height} image is larger than the {} pixels canopy reads",
            crate::RenderSettings::MAX_PIXELS
        )));
    }
    crate::files::check_memory(
        pixels * READ_BYTES_PER_PIXEL,
        crate::files::available_memory(),
        &format!("reading a {width}x{height} image"),
    )
    .map_err(|e| fail(&e))?;
    let mut reader = reader();
    reader.no_limits(); // bounded above, by what the header declares
    let image = reader.decode().map_err(|e| fail(&e))?.into_rgb32f();
    Ok((image.width(), image.height(), image.into_raw()))
}

/// The temporary files of writes in flight, so that a program ending on a signal can
/// remove them ([`abandon_temporary_files`]). Held while a temporary file is created and
/// while it is renamed into place, so the list is never stale.
static IN_FLIGHT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn in_flight() -> MutexGuard<'static, Vec<PathBuf>> {
    IN_FLIGHT
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// For a program about to exit mid-write (a second Ctrl-C): removes the temporary file
/// of every write in flight and blocks every later write from starting or finishing, so
/// nothing half-written is left behind. Never returns control to a write in flight: call
/// it only right before exiting.
pub fn abandon_temporary_files() {
    let list = in_flight();
    for temp in list.iter() {
        let _ = std::fs::remove_file(temp);
    }
    // Keep the lock: no write may create or rename a file after this.
    std::mem::forget(list);
}

/// Writes a file through a hidden temporary sibling, synced and then renamed over
/// `path`: readers see the old file or the whole new one, never a part. On failure the
/// temporary file is removed.
///
/// The temporary file is created new (`O_CREAT | O_EXCL`, which follows no link) under a
/// name nobody can predict, retried on a collision: a link planted where it would be
/// (to the scene, say) is never written through, and only a file this call made is
/// ever removed.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let (temp, file) = {
        let mut list = in_flight();
        let (temp, file) = create_temporary_sibling(path)?;
        list.push(temp.clone());
        (temp, file)
    };
    let result = (|| {
        let mut out = BufWriter::new(file);
        write(&mut out)?;
        let file = out.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        drop(file);
        let mut list = in_flight();
        list.retain(|t| t != &temp);
        std::fs::rename(&temp, path)
    })();
    if result.is_err() {
        let mut list = in_flight();
        list.retain(|t| t != &temp);
        let _ = std::fs::remove_file(&temp);
    }
    result
}

/// Tries at creating the temporary file before giving up: a collision of two random
/// 64-bit names is already next to impossible.
const TEMPORARY_TRIES: u32 = 16;

/// A new, empty file beside `path` named `.<name>.<random>.tmp`, and its path.
pub(crate) fn create_temporary_sibling(path: &Path) -> std::io::Result<(PathBuf, File)> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy())
        .unwrap_or_default();
    let mut last = None;
    for _ in 0..TEMPORARY_TRIES {
        let temp = path.with_file_name(format!(".{name}.{:016x}.tmp", crate::files::random_u64()));
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temp)
        {
            Ok(file) => return Ok((temp, file)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(last.expect("at least one try"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

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

    /// The temporary names this canopy's writer could pick are unpredictable; an older
    /// one used `.<name>.<pid>.tmp`, and a link planted there was written through.
    #[cfg(unix)]
    #[test]
    fn a_link_where_the_temporary_file_would_be_is_never_written_through() {
        let dir = temp_dir("links");
        let scene = dir.join("scene.toml");
        std::fs::write(&scene, "my scene").unwrap();
        let path = dir.join("o.png");
        let planted = dir.join(format!(".o.png.{}.tmp", std::process::id()));
        std::os::unix::fs::symlink(&scene, &planted).unwrap();
        let hard = dir.join(format!(".o.png.{}.tmp.hard", std::process::id()));
        std::fs::hard_link(&scene, &hard).unwrap();
        write_image(&film(), &path).unwrap();
        assert_eq!(std::fs::read_to_string(&scene).unwrap(), "my scene");
        assert!(image::open(&path).is_ok());
        // Only the image is new; the planted names are left as they were.
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        let pid = std::process::id();
        let mut expected = vec![
            format!(".o.png.{pid}.tmp"),
            format!(".o.png.{pid}.tmp.hard"),
            "o.png".to_string(),
            "scene.toml".to_string(),
        ];
        expected.sort();
        assert_eq!(names, expected);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn temporary_names_differ_from_call_to_call() {
        let dir = temp_dir("names");
        let path = dir.join("x.bin");
        let (a, _) = create_temporary_sibling(&path).unwrap();
        let (b, _) = create_temporary_sibling(&path).unwrap();
        assert_ne!(a, b);
        for p in [&a, &b] {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            assert!(
                name.starts_with(".x.bin.") && name.ends_with(".tmp"),
                "{name}"
            );
        }
        std::fs::remove_dir_all(dir).unwrap();
    }

    /// A full disk during an EXR write was reported as "Format error decoding OpenExr":
    /// the file's own error is kept, whatever the encoder wraps it in. (Checked by hand
    /// on a full tmpfs: "cannot write the image: No space left on device".)
    #[test]
    fn the_files_own_error_is_kept_through_the_encoder() {
        let dir = temp_dir("recording");
        let path = dir.join("read-only.exr");
        std::fs::write(&path, b"").unwrap();
        for format in [ImageFormat::OpenExr, ImageFormat::Png] {
            // Opened for reading only: every write fails.
            let mut file = BufWriter::with_capacity(0, File::open(&path).unwrap());
            let mut recorded = Recording {
                inner: &mut file,
                failed: None,
            };
            assert!(encode(&film(), format, &mut recorded).is_err());
            assert!(recorded.failed.is_some(), "{format:?}");
        }
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
