//! canopy-denoise: a render's noise removed by Intel Open Image Denoise (OIDN) 2, the
//! denoiser Cycles, Mitsuba and most production renderers use on the CPU.
//!
//! OIDN is loaded when a denoise is asked for, not linked: canopy builds and runs on a
//! machine without it, and only `--denoise` needs it ([`Oidn::load`] says where it
//! looked and how to install it). The binding is the handful of OIDN's C functions a
//! denoise takes, behind a safe interface: [`Oidn::denoise`] checks the images' sizes,
//! and every call's error is read back from the device.
//!
//! ```no_run
//! let oidn = canopy_denoise::Oidn::load(&[]).expect("OIDN installed");
//! let (width, height) = (2, 1);
//! let color = vec![0.5f32; width * height * 3];
//! let images = canopy_denoise::Images { width, height, color: &color, albedo: None, normal: None };
//! let clean = oidn.denoise(&images, &canopy_denoise::Options::default()).unwrap();
//! ```

mod ffi;
mod search;

pub use search::{library_candidates, CANOPY_OIDN_VARIABLE, LIBRARY_NAME};

use std::path::{Path, PathBuf};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum DenoiseError {
    #[error("Open Image Denoise 2 ({LIBRARY_NAME}) is not installed: looked in {searched}. Install it with `scripts/oidn.sh` (it takes the library from PyPI's pyoidn wheel), or set {CANOPY_OIDN_VARIABLE} to the library or its folder")]
    NotFound { searched: String },
    #[error("{}: not a usable Open Image Denoise 2 library: {cause}", path.display())]
    Unusable { path: PathBuf, cause: String },
    #[error("Open Image Denoise failed: {0}")]
    Failed(String),
    #[error("cannot denoise: {0}")]
    Input(String),
}

/// The images of one denoise: linear RGB floats, row by row from the top, three per
/// pixel. The albedo and normal (the render's AOVs) make the result much sharper; a
/// normal needs an albedo.
#[derive(Clone, Copy, Debug)]
pub struct Images<'a> {
    pub width: usize,
    pub height: usize,
    /// The noisy render (high dynamic range).
    pub color: &'a [f32],
    pub albedo: Option<&'a [f32]>,
    pub normal: Option<&'a [f32]>,
}

/// How a denoise runs; by default on all cores, the guides as they are.
#[derive(Clone, Copy, Debug, Default)]
pub struct Options {
    /// Worker threads; `None`: all cores.
    pub threads: Option<usize>,
    /// Denoise the albedo and normal first, then the colour with them as noise-free
    /// guides (OIDN's `cleanAux` mode, its advice where the guides are noisy: depth of
    /// field, glass). Off by default: it took 6.7x the time (10.4 s against 1.56 s a
    /// megapixel on 2 cores of an Intel Xeon) for about the same error where the guides
    /// are clean (`bench/denoise.sh`, docs/denoising.md).
    pub prefilter: bool,
}

/// A loaded Open Image Denoise library.
pub struct Oidn {
    api: ffi::Api,
    path: PathBuf,
}

impl Oidn {
    /// Loads OIDN from the first place that has it: the file or folder named by
    /// `CANOPY_OIDN`, the folders `extra` (a Python package's, say), canopy's own
    /// folder (`~/.local/share/canopy/oidn/lib`, where `scripts/oidn.sh` puts it), then
    /// the system's library path.
    pub fn load(extra: &[PathBuf]) -> Result<Oidn, DenoiseError> {
        Self::load_first(&library_candidates(extra))
    }

    /// Loads the first of `candidates` (library files, or the bare [`LIBRARY_NAME`] for
    /// the system's loader) that exists.
    fn load_first(candidates: &[PathBuf]) -> Result<Oidn, DenoiseError> {
        let mut searched = Vec::new();
        for candidate in candidates {
            let is_soname = candidate.as_os_str() == LIBRARY_NAME;
            if !is_soname && !candidate.is_file() {
                searched.push(candidate.display().to_string());
                continue;
            }
            match ffi::Api::open(candidate) {
                Ok(api) => {
                    return Ok(Oidn {
                        api,
                        path: candidate.clone(),
                    })
                }
                // The system loader found nothing under the name: keep looking.
                Err(_) if is_soname => searched.push("the system's library path".into()),
                Err(cause) => {
                    return Err(DenoiseError::Unusable {
                        path: candidate.clone(),
                        cause,
                    })
                }
            }
        }
        Err(DenoiseError::NotFound {
            searched: searched.join(", "),
        })
    }

    /// Where the library was loaded from (its name alone: found by the system).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The denoised colour of `images`, three floats a pixel like the input.
    pub fn denoise(&self, images: &Images, options: &Options) -> Result<Vec<f32>, DenoiseError> {
        check(images)?;
        let device = ffi::Device::new(&self.api, options.threads)?;
        let mut albedo = images.albedo.map(<[f32]>::to_vec);
        let mut normal = images.normal.map(<[f32]>::to_vec);
        let prefilter = options.prefilter && albedo.is_some();
        if prefilter {
            for (name, aux) in [("albedo", &mut albedo), ("normal", &mut normal)] {
                if let Some(aux) = aux {
                    *aux = device.filter(images.width, images.height, &[(name, aux)], false)?;
                }
            }
        }
        let mut inputs = vec![("color", images.color)];
        inputs.extend(albedo.as_deref().map(|a| ("albedo", a)));
        inputs.extend(normal.as_deref().map(|n| ("normal", n)));
        device.filter(images.width, images.height, &inputs, prefilter)
    }
}

/// Sizes and combinations OIDN would refuse (or read past the end of).
fn check(images: &Images) -> Result<(), DenoiseError> {
    let (w, h) = (images.width, images.height);
    if w == 0 || h == 0 {
        return Err(DenoiseError::Input(format!("an empty {w}x{h} image")));
    }
    let floats = w
        .checked_mul(h)
        .and_then(|p| p.checked_mul(3))
        .ok_or_else(|| DenoiseError::Input(format!("a {w}x{h} image is too large")))?;
    let layers = [
        ("color", Some(images.color)),
        ("albedo", images.albedo),
        ("normal", images.normal),
    ];
    for (name, layer) in layers {
        if let Some(layer) = layer.filter(|l| l.len() != floats) {
            return Err(DenoiseError::Input(format!(
                "the {name} image has {} floats, not the {floats} of {w}x{h} RGB pixels",
                layer.len()
            )));
        }
    }
    if images.normal.is_some() && images.albedo.is_none() {
        return Err(DenoiseError::Input(
            "a normal image needs an albedo image beside it".into(),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrong_sizes_and_a_normal_alone_are_refused() {
        let three = [0.0f32; 3];
        let six = [0.0f32; 6];
        let images = |color, albedo, normal| Images {
            width: 2,
            height: 1,
            color,
            albedo,
            normal,
        };
        assert!(check(&images(&six, None, None)).is_ok());
        let err = check(&images(&three, None, None)).unwrap_err().to_string();
        assert!(err.contains("color image has 3 floats, not the 6"), "{err}");
        let err = check(&images(&six, Some(&three), None))
            .unwrap_err()
            .to_string();
        assert!(err.contains("albedo"), "{err}");
        let err = check(&images(&six, None, Some(&six)))
            .unwrap_err()
            .to_string();
        assert!(err.contains("needs an albedo"), "{err}");
        let empty = Images {
            width: 0,
            ..images(&six, None, None)
        };
        assert!(check(&empty).is_err());
    }

    #[test]
    fn a_missing_or_broken_library_is_named_with_where_to_get_it() {
        let dir = std::env::temp_dir().join(format!("canopy-no-oidn-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let candidates = library_candidates(std::slice::from_ref(&dir));
        let in_dir = dir.join(LIBRARY_NAME);
        assert!(candidates.contains(&in_dir), "{candidates:?}");
        let err = Oidn::load_first(std::slice::from_ref(&in_dir))
            .err()
            .unwrap();
        let message = err.to_string();
        assert!(matches!(err, DenoiseError::NotFound { .. }), "{message}");
        assert!(message.contains(&dir.display().to_string()), "{message}");
        assert!(
            message.contains("scripts/oidn.sh") && message.contains("CANOPY_OIDN"),
            "{message}"
        );
        // A file that is not a library: named, not loaded, no crash.
        std::fs::write(&in_dir, b"not a library").unwrap();
        match Oidn::load_first(std::slice::from_ref(&in_dir)) {
            Err(DenoiseError::Unusable { path, .. }) => assert_eq!(path, in_dir),
            other => panic!("{:?}", other.err()),
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
