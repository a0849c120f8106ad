//! Checkpoints of a render in progress, so that a long render survives an interruption.
//!
//! A checkpoint holds what is needed to continue: the scene (as the command line named
//! it), the render settings, a fingerprint of the loaded scene (to refuse resuming into a
//! different one), and the accumulated samples. Layout, all little-endian:
//!
//! ```text
//! b"CANOPYCK" | version u32 | fingerprint u64 | scene: u32 length + UTF-8 |
//! width u32 | height u32 | spp u32 | max_depth u32 | seed u64 |
//! samples u32 | rays u64 | invalid u64 | sums: width*height*3 f32 | checksum u64
//! ```
//!
//! The checksum (FNV-1a over everything before it) catches truncated or damaged files;
//! writes go through a temporary file and a rename, so a checkpoint on disk is always
//! whole.

use crate::integrator::Accumulator;
use crate::output::write_atomically;
use crate::scene::{RenderSettings, Scene};
use glam::Vec3;
use std::io::Write;
use std::path::Path;
use thiserror::Error;

const MAGIC: &[u8; 8] = b"CANOPYCK";
const VERSION: u32 = 1;

#[derive(Debug, Error)]
pub enum CheckpointError {
    #[error("{file}: cannot read the checkpoint: {cause}")]
    Read { file: String, cause: std::io::Error },
    #[error("{file}: cannot write the checkpoint: {cause}")]
    Write { file: String, cause: std::io::Error },
    #[error("{file}: not a canopy checkpoint, or a damaged one ({what})")]
    Corrupt { file: String, what: String },
    #[error("{file}: the checkpoint was made for a different scene or settings")]
    Mismatch { file: String },
}

/// A render's state, as saved.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    /// The scene as the command line named it (built-in name or path).
    pub scene: String,
    pub settings: RenderSettings,
    pub fingerprint: u64,
    pub accumulator: Accumulator,
}

/// FNV-1a, 64 bits.
fn fnv1a(bytes: &[u8], mut hash: u64) -> u64 {
    for &b in bytes {
        hash ^= b as u64;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    hash
}

const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// A hash of what determines the image: settings, camera, background, materials and
/// every primitive's bounds.
pub fn fingerprint(scene: &Scene) -> u64 {
    let text = format!(
        "{:?}{:?}{:?}{:?}{}",
        scene.settings,
        scene.camera,
        scene.background,
        scene.materials,
        scene.primitives.len()
    );
    let mut hash = fnv1a(text.as_bytes(), FNV_OFFSET);
    for b in scene.primitive_bounds() {
        hash = fnv1a(bytemuck::bytes_of(&b), hash);
    }
    hash
}

impl Checkpoint {
    pub fn new(scene_arg: &str, scene: &Scene, accumulator: Accumulator) -> Self {
        Self {
            scene: scene_arg.to_owned(),
            settings: scene.settings,
            fingerprint: fingerprint(scene),
            accumulator,
        }
    }

    fn to_bytes(&self) -> Vec<u8> {
        let a = &self.accumulator;
        let s = &self.settings;
        let mut out = Vec::with_capacity(96 + self.scene.len() + a.sums.len() * 12);
        out.extend(MAGIC);
        out.extend(VERSION.to_le_bytes());
        out.extend(self.fingerprint.to_le_bytes());
        out.extend((self.scene.len() as u32).to_le_bytes());
        out.extend(self.scene.as_bytes());
        for v in [s.width, s.height, s.spp, s.max_depth] {
            out.extend(v.to_le_bytes());
        }
        out.extend(s.seed.to_le_bytes());
        out.extend(a.samples.to_le_bytes());
        out.extend(a.rays.to_le_bytes());
        out.extend(a.invalid_samples.to_le_bytes());
        for p in &a.sums {
            for c in p.to_array() {
                out.extend(c.to_le_bytes());
            }
        }
        let checksum = fnv1a(&out, FNV_OFFSET);
        out.extend(checksum.to_le_bytes());
        out
    }

    /// Writes the checkpoint atomically.
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        let bytes = self.to_bytes();
        write_atomically(path, |w| w.write_all(&bytes)).map_err(|cause| CheckpointError::Write {
            file: path.display().to_string(),
            cause,
        })
    }

    pub fn load(path: &Path) -> Result<Self, CheckpointError> {
        let file = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|cause| CheckpointError::Read {
            file: file.clone(),
            cause,
        })?;
        Self::from_bytes(&bytes).map_err(|what| CheckpointError::Corrupt { file, what })
    }

    fn from_bytes(bytes: &[u8]) -> Result<Self, String> {
        let body_len = bytes.len().checked_sub(8).ok_or("file too short")?;
        let (body, checksum) = bytes.split_at(body_len);
        if fnv1a(body, FNV_OFFSET).to_le_bytes() != checksum {
            return Err("checksum mismatch".into());
        }
        let mut r = Reader {
            bytes: body,
            pos: 0,
        };
        if r.take(8)? != MAGIC {
            return Err("wrong magic number".into());
        }
        let version = r.u32()?;
        if version != VERSION {
            return Err(format!(
                "version {version}, this canopy reads version {VERSION}"
            ));
        }
        let fingerprint = r.u64()?;
        let scene_len = r.u32()? as usize;
        let scene = String::from_utf8(r.take(scene_len)?.to_vec())
            .map_err(|_| "scene name is not UTF-8")?;
        let settings = RenderSettings {
            width: r.u32()?,
            height: r.u32()?,
            spp: r.u32()?,
            max_depth: r.u32()?,
            seed: r.u64()?,
        };
        settings.check()?;
        let (samples, rays, invalid_samples) = (r.u32()?, r.u64()?, r.u64()?);
        let pixels = settings.width as usize * settings.height as usize;
        if r.bytes.len() - r.pos != pixels * 12 {
            return Err("pixel data does not match the image size".into());
        }
        let sums = (0..pixels)
            .map(|_| Ok(Vec3::new(r.f32()?, r.f32()?, r.f32()?)))
            .collect::<Result<Vec<_>, String>>()?;
        Ok(Self {
            scene,
            settings,
            fingerprint,
            accumulator: Accumulator {
                width: settings.width,
                height: settings.height,
                sums,
                samples,
                rays,
                invalid_samples,
            },
        })
    }

    /// Checks that this checkpoint belongs to `scene` (loaded with this checkpoint's
    /// settings).
    pub fn matches(&self, scene: &Scene, path: &Path) -> Result<(), CheckpointError> {
        if fingerprint(scene) == self.fingerprint {
            Ok(())
        } else {
            Err(CheckpointError::Mismatch {
                file: path.display().to_string(),
            })
        }
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or("file ends early")?;
        let slice = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(slice)
    }

    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }

    fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }

    fn f32(&mut self) -> Result<f32, String> {
        Ok(f32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BuiltinScene;

    fn sample() -> (Scene, Checkpoint) {
        let mut scene = BuiltinScene::find("cornell").unwrap().load().unwrap();
        scene.settings.width = 4;
        scene.settings.height = 3;
        let mut acc = Accumulator::new(4, 3);
        acc.sums[5] = Vec3::new(1.5, -0.0, 7.25);
        acc.samples = 9;
        acc.rays = 1234;
        let checkpoint = Checkpoint::new("cornell", &scene, acc);
        (scene, checkpoint)
    }

    #[test]
    fn round_trips_exactly() {
        let (scene, checkpoint) = sample();
        let back = Checkpoint::from_bytes(&checkpoint.to_bytes()).unwrap();
        assert_eq!(back, checkpoint);
        assert!(back.matches(&scene, Path::new("x")).is_ok());
    }

    #[test]
    fn every_truncation_and_every_flipped_byte_is_detected() {
        let bytes = sample().1.to_bytes();
        for cut in 0..bytes.len() {
            assert!(
                Checkpoint::from_bytes(&bytes[..cut]).is_err(),
                "cut at {cut}"
            );
        }
        for i in 0..bytes.len() {
            let mut damaged = bytes.clone();
            damaged[i] ^= 0x10;
            assert!(Checkpoint::from_bytes(&damaged).is_err(), "byte {i}");
        }
    }

    #[test]
    fn another_scene_does_not_match() {
        let (_, checkpoint) = sample();
        let mut other = BuiltinScene::find("paper-3").unwrap().load().unwrap();
        other.settings = checkpoint.settings;
        assert!(matches!(
            checkpoint.matches(&other, Path::new("x")),
            Err(CheckpointError::Mismatch { .. })
        ));
    }
}
