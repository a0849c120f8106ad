//! Saving what the page shows: the image through canopy's atomic writer (PNG as shown,
//! with its exposure; EXR as linear radiance), into the viewer's folder under a new name,
//! never over a file that is there.

use canopy_render::output::write_image;
use canopy_render::output_policy::{check_output, file_stem_from_name, OutputKind};
use canopy_render::Film;
use std::path::{Path, PathBuf};

/// Most numbered names tried in one folder.
const MAX_NUMBER: u32 = 100_000;

/// An image format the page may ask for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SaveFormat {
    Png,
    Exr,
}

impl SaveFormat {
    pub fn parse(name: &str) -> Result<SaveFormat, String> {
        match name {
            "png" => Ok(SaveFormat::Png),
            "exr" => Ok(SaveFormat::Exr),
            _ => Err(format!("format must be \"png\" or \"exr\", not {name:?}")),
        }
    }

    fn extension(self) -> &'static str {
        match self {
            SaveFormat::Png => "png",
            SaveFormat::Exr => "exr",
        }
    }
}

/// Writes `film` (exposed by `exposure` stops for PNG) as `<scene>-<n>.<ext>` in `folder`,
/// `n` the first number whose file does not exist; never replaces a file, never writes
/// one of `inputs`. Returns the path written.
pub fn save(
    film: &Film,
    exposure: f32,
    format: SaveFormat,
    folder: &Path,
    scene_name: &str,
    inputs: &[PathBuf],
) -> Result<PathBuf, String> {
    let stem = file_stem_from_name(scene_name);
    let mut film = film.clone();
    if format == SaveFormat::Png {
        crate::frame::expose(&mut film, exposure);
    }
    for n in 1..=MAX_NUMBER {
        let path = folder.join(format!("{stem}-{n:03}.{}", format.extension()));
        // Claimed by creating it new: a file that appears meanwhile is never replaced.
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(format!("{}: cannot create it: {e}", path.display())),
        }
        let written = check_output(&path, "image", OutputKind::Image, inputs)
            .and_then(|()| write_image(&film, &path).map_err(|e| e.to_string()));
        return match written {
            Ok(()) => Ok(path),
            Err(e) => {
                // Only the empty file this call made.
                let _ = std::fs::remove_file(&path);
                Err(e)
            }
        };
    }
    Err(format!(
        "{}: {MAX_NUMBER} images of {stem} are there already",
        folder.display()
    ))
}
