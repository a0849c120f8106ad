//! Checkpoints of a render in progress, so that a long render survives an interruption.
//!
//! A checkpoint holds what is needed to continue: the scene (a built-in name, or the
//! absolute path of the scene file, so a render resumes from any directory), the render settings, a fingerprint of the loaded scene (to refuse resuming into a
//! different one), and the accumulated samples. Layout, all little-endian:
//!
//! ```text
//! b"CANOPYCK" | version u32 | fingerprint u64 | owner u64 | scene: u32 length + UTF-8 |
//! width u32 | height u32 | spp u32 | max_depth u32 | seed u64 |
//! integrator u32 (0 path, 1 bsdf) | russian_roulette u32 (0 or 1) |
//! sampler u32 (0 sobol, 1 independent; from version 7 on, before it independent) |
//! triangle test u32 (0 watertight, 1 fast; from version 9 on, before it watertight) |
//! region: x u32 | y u32 | width u32 | height u32 |
//! samples u32 | rays u64 | invalid u64 | sums: region pixels * 3 f32 |
//! AOVs (from version 8 on): set u32 | its layers, each region pixels long, in the order
//! albedo 3 f32, normal 3 f32, depth f32, position 3 f32, instance u32, primitive u32 |
//! checksum u64
//! ```
//!
//! The checksum (FNV-1a over everything before it) catches truncated or damaged files;
//! writes go through a temporary file and a rename, so a checkpoint on disk is always
//! whole.
//!
//! `owner` is the random identity of the render that wrote the file. A render replaces
//! or removes a checkpoint only if it is its own, or the one it continues
//! ([`Checkpoint::save_owned`], [`Checkpoint::remove_owned`]): two renders given one
//! path never destroy each other's work.

use crate::aov::{Aov, AovBuffers, AovSet};
use crate::files::{read_prefix, read_regular_file};
use crate::geometry::Shape;
use crate::integrator::Accumulator;
use crate::output::write_atomically;
use crate::region::Region;
use crate::rng::Sampler;
use crate::scene::{Integrator, RenderSettings, Scene};
use canopy_bvh::TriangleTest;
use glam::Vec3;
use std::io::Write;
use std::path::Path;
use thiserror::Error;

const MAGIC: &[u8; 8] = b"CANOPYCK";
/// Version 2: the scene path is absolute and the fingerprint covers all geometry.
/// Version 3: the integrator and Russian roulette settings.
/// Version 4: samples drawn from the counter-based random streams the GPU shares (a
/// version 3 checkpoint's samples came from other streams).
/// Version 5: the region of the image rendered (version 4 files, still read, hold the
/// whole image).
/// Version 6: the owner, the identity of the render that wrote the file (files of
/// versions 4 and 5, still read, have owner 0: no render's).
/// Version 7: the sampler.
/// Version 8: the AOV layers.
/// Version 9: the triangle test (`TriangleTest`), which decides the rare pixels whose rays
/// pass within rounding of an edge.
const VERSION: u32 = 9;
/// The oldest version whose samples this canopy can continue.
const OLDEST_READ: u32 = 4;

/// Largest checkpoint read: the header, the largest film allowed and every AOV layer.
const MAX_CHECKPOINT_BYTES: u64 = 1024 * 1024 + RenderSettings::MAX_PIXELS * (12 + 48);

#[derive(Debug, Error)]
pub enum CheckpointError {
    #[error("{file}: cannot read the checkpoint: {cause}")]
    Read { file: String, cause: std::io::Error },
    #[error("{file}: cannot write the checkpoint: {cause}")]
    Write { file: String, cause: std::io::Error },
    #[error("{file}: not a canopy checkpoint, or a damaged one ({what})")]
    Corrupt { file: String, what: String },
    #[error("{file}: the checkpoint was made for a different scene or settings (has the scene or a mesh changed since?)")]
    Mismatch { file: String },
    #[error("{file}: exists and is not a canopy checkpoint; refusing to overwrite it")]
    NotACheckpoint { file: String },
    #[error("{file}: holds the checkpoint of another render ({samples} samples per pixel of `{scene}`); not replacing it (continue it with `canopy render --resume {file}`, or choose another checkpoint path)")]
    Taken {
        file: String,
        scene: String,
        samples: u32,
    },
}

/// What a checkpoint path holds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Slot {
    /// Nothing: a checkpoint may be saved there.
    Free,
    /// A canopy checkpoint written by render `owner` (0: an older canopy's, which only
    /// a render continuing it may replace).
    Checkpoint { owner: u64 },
    /// Something that is not a canopy checkpoint: the user's, never touched.
    Other,
}

/// A render's state, as saved.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    /// The scene as the command line named it (built-in name or path).
    pub scene: String,
    pub settings: RenderSettings,
    pub fingerprint: u64,
    /// The identity of the render that saves it (0: none given).
    pub owner: u64,
    /// How the render tests triangles: not part of the scene, but of the image (a
    /// resumed render must go on in the same mode).
    pub triangle_test: TriangleTest,
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

/// A hash of everything that determines the image: settings, camera, background,
/// materials, every primitive's exact geometry, material and vertex normals (so a
/// mesh whose `smooth` setting changed no longer matches), every instanced mesh and
/// every instance's mesh, transform and material.
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
    let mut words: Vec<f32> = Vec::with_capacity(16);
    for p in scene.primitives.iter() {
        words.clear();
        words.push(f32::from_bits(p.material));
        match &p.shape {
            Shape::Sphere(s) => {
                words.extend(s.center.to_array());
                words.push(s.radius);
            }
            Shape::Triangle(t) => {
                words.extend(t.v.iter().flat_map(|v| v.to_array()));
                words.push(f32::from_bits(t.normals));
            }
            Shape::Cuboid(c) => {
                words.extend(c.local.min.to_array());
                words.extend(c.local.max.to_array());
                words.extend(c.rotation().to_cols_array());
                words.extend(c.translation.to_array());
            }
        }
        hash = fnv1a(bytemuck::cast_slice(&words), hash);
    }
    for normals in &scene.vertex_normals {
        hash = fnv1a(bytemuck::cast_slice(normals), hash);
    }
    for mesh in &scene.meshes {
        hash = fnv1a(mesh.name.as_bytes(), hash);
        hash = fnv1a(bytemuck::cast_slice(mesh.mesh.vertices()), hash);
        hash = fnv1a(bytemuck::cast_slice(mesh.mesh.indices()), hash);
        hash = fnv1a(bytemuck::cast_slice(&mesh.normals), hash);
    }
    for instance in &scene.instances {
        words.clear();
        words.push(f32::from_bits(instance.mesh));
        words.push(f32::from_bits(instance.material));
        words.extend(instance.to_world.to_cols_array());
        hash = fnv1a(bytemuck::cast_slice(&words), hash);
    }
    hash
}

impl Checkpoint {
    pub fn new(scene_arg: &str, scene: &Scene, accumulator: Accumulator) -> Self {
        Self {
            scene: scene_arg.to_owned(),
            settings: scene.settings,
            fingerprint: fingerprint(scene),
            owner: 0,
            triangle_test: TriangleTest::Watertight,
            accumulator,
        }
    }

    /// The checkpoint of a render that tests triangles in mode `test`.
    pub fn with_triangle_test(self, test: TriangleTest) -> Self {
        Self {
            triangle_test: test,
            ..self
        }
    }

    /// The checkpoint as render `owner` saves it.
    pub fn owned_by(self, owner: u64) -> Self {
        Self { owner, ..self }
    }

    /// The checkpoint as the bytes of its file.
    pub fn to_bytes(&self) -> Vec<u8> {
        let a = &self.accumulator;
        let s = &self.settings;
        let mut out = Vec::with_capacity(96 + self.scene.len() + a.sums.len() * 12);
        out.extend(MAGIC);
        out.extend(VERSION.to_le_bytes());
        out.extend(self.fingerprint.to_le_bytes());
        out.extend(self.owner.to_le_bytes());
        out.extend((self.scene.len() as u32).to_le_bytes());
        out.extend(self.scene.as_bytes());
        for v in [s.width, s.height, s.spp, s.max_depth] {
            out.extend(v.to_le_bytes());
        }
        out.extend(s.seed.to_le_bytes());
        let integrator = Integrator::ALL
            .iter()
            .position(|&i| i == s.integrator)
            .expect("every integrator is listed") as u32;
        out.extend(integrator.to_le_bytes());
        out.extend((s.russian_roulette as u32).to_le_bytes());
        let sampler = Sampler::ALL
            .iter()
            .position(|&i| i == s.sampler)
            .expect("every sampler is listed") as u32;
        out.extend(sampler.to_le_bytes());
        out.extend(triangle_test_code(self.triangle_test).to_le_bytes());
        let r = a.region;
        for v in [r.x, r.y, r.width, r.height] {
            out.extend(v.to_le_bytes());
        }
        out.extend(a.samples.to_le_bytes());
        out.extend(a.rays.to_le_bytes());
        out.extend(a.invalid_samples.to_le_bytes());
        for p in &a.sums {
            for c in p.to_array() {
                out.extend(c.to_le_bytes());
            }
        }
        write_aovs(&a.aovs, &mut out);
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
        let bytes = read_regular_file(path, MAX_CHECKPOINT_BYTES).map_err(|cause| {
            CheckpointError::Read {
                file: file.clone(),
                cause: cause.into(),
            }
        })?;
        Self::from_bytes(&bytes).map_err(|what| CheckpointError::Corrupt { file, what })
    }

    /// A checkpoint from the bytes of its file, or what is wrong with them.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, String> {
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
        if !(OLDEST_READ..=VERSION).contains(&version) {
            return Err(format!(
                "version {version}, this canopy reads versions {OLDEST_READ} to {VERSION}"
            ));
        }
        let fingerprint = r.u64()?;
        let owner = if version >= 6 { r.u64()? } else { 0 };
        let scene_len = r.u32()? as usize;
        let scene = String::from_utf8(r.take(scene_len)?.to_vec())
            .map_err(|_| "scene name is not UTF-8")?;
        let settings = RenderSettings {
            width: r.u32()?,
            height: r.u32()?,
            spp: r.u32()?,
            max_depth: r.u32()?,
            seed: r.u64()?,
            integrator: *Integrator::ALL
                .get(r.u32()? as usize)
                .ok_or("unknown integrator")?,
            russian_roulette: match r.u32()? {
                0 => false,
                1 => true,
                _ => return Err("bad Russian roulette flag".into()),
            },
            // Renders before version 7 drew independent numbers only.
            sampler: match version {
                ..7 => Sampler::Independent,
                _ => *Sampler::ALL
                    .get(r.u32()? as usize)
                    .ok_or("unknown sampler")?,
            },
        };
        settings.check()?;
        let triangle_test = match version {
            ..9 => TriangleTest::Watertight,
            _ => triangle_test_of(r.u32()?)?,
        };
        let region = match version {
            4 => Region::full(settings.width, settings.height),
            _ => Region {
                x: r.u32()?,
                y: r.u32()?,
                width: r.u32()?,
                height: r.u32()?,
            },
        };
        region.check_within(settings.width, settings.height)?;
        let (samples, rays, invalid_samples) = (r.u32()?, r.u64()?, r.u64()?);
        let pixels = region.pixels();
        // Checked before reading: a damaged size must not allocate.
        if r.bytes.len() - r.pos < pixels * 12 {
            return Err("pixel data does not match the region's size".into());
        }
        let sums = r.vec3s(pixels)?;
        let aovs = match version {
            ..8 => AovBuffers::default(),
            _ => read_aovs(&mut r, pixels)?,
        };
        if r.pos != r.bytes.len() {
            return Err("pixel data does not match the region's size".into());
        }
        Ok(Self {
            scene,
            settings,
            fingerprint,
            owner,
            triangle_test,
            accumulator: Accumulator {
                region,
                sums,
                samples,
                rays,
                invalid_samples,
                aovs,
            },
        })
    }

    /// What `path` holds: nothing, a checkpoint (of any version: a regular file that
    /// starts with the magic number) and whose, or something else. Only checkpoints are
    /// ever overwritten or removed as such.
    pub fn slot(path: &Path) -> Slot {
        if std::fs::symlink_metadata(path).is_err() {
            return Slot::Free;
        }
        // Magic, version, fingerprint, owner.
        let Some(head) = read_prefix(path, 28) else {
            return Slot::Other;
        };
        if head.len() < 12 || &head[..8] != MAGIC {
            return Slot::Other;
        }
        let version = u32::from_le_bytes(head[8..12].try_into().expect("4 bytes"));
        let owner = match (version, head.get(20..28)) {
            (6.., Some(owner)) => u64::from_le_bytes(owner.try_into().expect("8 bytes")),
            _ => 0,
        };
        Slot::Checkpoint { owner }
    }

    /// Why no checkpoint may be saved at `path`, if something other than a canopy
    /// checkpoint is there: such a file is the user's, and the first save would replace it.
    pub fn check_slot(path: &Path) -> Result<(), String> {
        match Self::slot(path) {
            Slot::Other => Err(Self::not_a_checkpoint(path).to_string()),
            _ => Ok(()),
        }
    }

    fn not_a_checkpoint(path: &Path) -> CheckpointError {
        CheckpointError::NotACheckpoint {
            file: path.display().to_string(),
        }
    }

    /// Why a render whose checkpoints are `owners` (its own identity, and that of the
    /// checkpoint it continues) may not save at `path`: something of the user's is
    /// there, or another render's checkpoint.
    pub fn check_owned_slot(path: &Path, owners: &[u64]) -> Result<(), CheckpointError> {
        match Self::slot(path) {
            Slot::Free => Ok(()),
            Slot::Checkpoint { owner } if owners.contains(&owner) => Ok(()),
            Slot::Checkpoint { .. } => {
                let (scene, samples) = describe_header(path).unwrap_or(("?".into(), 0));
                Err(CheckpointError::Taken {
                    file: path.display().to_string(),
                    scene,
                    samples,
                })
            }
            Slot::Other => Err(Self::not_a_checkpoint(path)),
        }
    }

    /// Saves the checkpoint, as render `self.owner`, at `path` only if the path is free or
    /// holds a checkpoint of one of `owners` (checked right before the write): another
    /// render's checkpoint, or a user's file, is never replaced.
    pub fn save_owned(&self, path: &Path, owners: &[u64]) -> Result<(), CheckpointError> {
        Self::check_owned_slot(path, owners)?;
        self.save(path)
    }

    /// Removes the checkpoint at `path` if it is one of `owners`'; anything else (another
    /// render's checkpoint, a user's file) is left alone.
    pub fn remove_owned(path: &Path, owners: &[u64]) -> std::io::Result<bool> {
        match Self::slot(path) {
            Slot::Checkpoint { owner } if owners.contains(&owner) => {
                std::fs::remove_file(path)?;
                Ok(true)
            }
            _ => Ok(false),
        }
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

/// How a checkpoint writes a triangle test.
fn triangle_test_code(test: TriangleTest) -> u32 {
    match test {
        TriangleTest::Watertight => 0,
        TriangleTest::Fast => 1,
    }
}

/// The triangle test a checkpoint's code names.
fn triangle_test_of(code: u32) -> Result<TriangleTest, String> {
    match code {
        0 => Ok(TriangleTest::Watertight),
        1 => Ok(TriangleTest::Fast),
        _ => Err(format!("unknown triangle test {code}")),
    }
}

/// The scene and samples per pixel of the checkpoint at `path`, read from its header
/// alone (the samples themselves may be gigabytes): for messages about it.
fn describe_header(path: &Path) -> Option<(String, u32)> {
    let head = read_prefix(path, 64 << 10)?;
    let mut r = Reader {
        bytes: &head,
        pos: 0,
    };
    if r.take(8).ok()? != MAGIC {
        return None;
    }
    let version = r.u32().ok()?;
    r.u64().ok()?; // fingerprint
    if version >= 6 {
        r.u64().ok()?; // owner
    }
    let scene_len = r.u32().ok()? as usize;
    let scene = String::from_utf8_lossy(r.take(scene_len).ok()?).into_owned();
    // Settings (4 u32, seed u64, 2 u32, and the sampler's u32 from version 7 on), the
    // triangle test's u32 from version 9 on, then the region (4 u32) from version 5 on.
    let sampler = if version >= 7 { 4 } else { 0 };
    let triangle_test = if version >= 9 { 4 } else { 0 };
    let region = if version >= 5 { 16 } else { 0 };
    r.take(4 * 4 + 8 + 2 * 4 + sampler + triangle_test + region)
        .ok()?;
    Some((scene, r.u32().ok()?))
}

/// Appends the layers of `aovs` in the checkpoint's layout.
fn write_aovs(aovs: &AovBuffers, out: &mut Vec<u8>) {
    out.extend(aovs.set.bits().to_le_bytes());
    let vec3s = aovs.albedo.iter().chain(&aovs.normal);
    out.extend(vec3s.flat_map(|v| v.to_array()).flat_map(f32::to_le_bytes));
    out.extend(aovs.depth.iter().flat_map(|d| d.to_le_bytes()));
    out.extend(
        aovs.position
            .iter()
            .flat_map(|v| v.to_array())
            .flat_map(f32::to_le_bytes),
    );
    for id in aovs.instance.iter().chain(&aovs.primitive) {
        out.extend(id.to_le_bytes());
    }
}

/// The AOV layers as [`write_aovs`] wrote them for `pixels` pixels.
fn read_aovs(r: &mut Reader, pixels: usize) -> Result<AovBuffers, String> {
    let set = AovSet::from_bits(r.u32()?)?;
    let layer_words = [
        (Aov::Albedo, 3),
        (Aov::Normal, 3),
        (Aov::Depth, 1),
        (Aov::Position, 3),
        (Aov::Id, 2),
    ];
    let words: usize = layer_words
        .iter()
        .filter(|(a, _)| set.contains(*a))
        .map(|(_, w)| w)
        .sum();
    if r.bytes.len() - r.pos != pixels * words * 4 {
        return Err("the AOV layers do not match the region's size".into());
    }
    let mut aovs = AovBuffers::new(set, pixels);
    let has = |aov| set.contains(aov);
    if has(Aov::Albedo) {
        aovs.albedo = r.vec3s(pixels)?;
    }
    if has(Aov::Normal) {
        aovs.normal = r.vec3s(pixels)?;
    }
    if has(Aov::Depth) {
        aovs.depth = (0..pixels).map(|_| r.f32()).collect::<Result<_, _>>()?;
    }
    if has(Aov::Position) {
        aovs.position = r.vec3s(pixels)?;
    }
    if has(Aov::Id) {
        aovs.instance = (0..pixels).map(|_| r.u32()).collect::<Result<_, _>>()?;
        aovs.primitive = (0..pixels).map(|_| r.u32()).collect::<Result<_, _>>()?;
    }
    Ok(aovs)
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

    fn vec3s(&mut self, n: usize) -> Result<Vec<Vec3>, String> {
        (0..n)
            .map(|_| Ok(Vec3::new(self.f32()?, self.f32()?, self.f32()?)))
            .collect()
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
        // The integrator settings travel too.
        let mut bsdf = scene.clone();
        bsdf.settings.integrator = Integrator::Bsdf;
        bsdf.settings.russian_roulette = false;
        let other = Checkpoint::new("cornell", &bsdf, checkpoint.accumulator.clone());
        let back = Checkpoint::from_bytes(&other.to_bytes()).unwrap();
        assert_eq!(back.settings, bsdf.settings);
        assert!(back.matches(&scene, Path::new("x")).is_err());
    }

    #[test]
    fn the_triangle_test_round_trips_and_older_files_were_watertight() {
        let (_, checkpoint) = sample();
        let fast = checkpoint.clone().with_triangle_test(TriangleTest::Fast);
        let back = Checkpoint::from_bytes(&fast.to_bytes()).unwrap();
        assert_eq!(back.triangle_test, TriangleTest::Fast);
        assert_eq!(back, fast);
        // Version 8 wrote no triangle test: its renders were watertight.
        let mut v8 = fast.to_bytes();
        v8.truncate(v8.len() - 8);
        v8[8..12].copy_from_slice(&8u32.to_le_bytes());
        let test_at = 8 + 4 + 8 + 8 + 4 + checkpoint.scene.len() + 4 * 4 + 8 + 4 + 4 + 4;
        assert_eq!(v8[test_at..test_at + 4], 1u32.to_le_bytes());
        v8.drain(test_at..test_at + 4);
        let checksum = fnv1a(&v8, FNV_OFFSET);
        v8.extend(checksum.to_le_bytes());
        assert_eq!(Checkpoint::from_bytes(&v8).unwrap(), checkpoint);
        // A code no canopy wrote is damage.
        let mut bad = fast.to_bytes();
        bad.truncate(bad.len() - 8);
        bad[test_at] = 7;
        let checksum = fnv1a(&bad, FNV_OFFSET);
        bad.extend(checksum.to_le_bytes());
        let what = Checkpoint::from_bytes(&bad).unwrap_err();
        assert!(what.contains("unknown triangle test 7"), "{what}");
    }

    #[test]
    fn aov_layers_round_trip_exactly() {
        let (_, mut checkpoint) = sample();
        let set = AovSet::of(&Aov::ALL);
        let acc = &mut checkpoint.accumulator;
        acc.aovs = AovBuffers::new(set, acc.region.pixels());
        acc.aovs.albedo[1] = Vec3::new(0.25, 0.5, 1.0);
        acc.aovs.normal[2] = Vec3::new(-0.0, 1.0, 0.0);
        acc.aovs.depth[3] = f32::INFINITY;
        acc.aovs.position[4] = Vec3::new(1e-30, 3.0, -2.0);
        (acc.aovs.instance[5], acc.aovs.primitive[6]) = (7, 123_456_789);
        let bytes = checkpoint.to_bytes();
        assert_eq!(Checkpoint::from_bytes(&bytes).unwrap(), checkpoint);
        // Only the albedo: the layers' sizes follow the set.
        let acc = &mut checkpoint.accumulator;
        acc.aovs = AovBuffers::new(AovSet::of(&[Aov::Albedo]), acc.region.pixels());
        let smaller = checkpoint.to_bytes();
        assert_eq!(bytes.len() - smaller.len(), 12 * (3 + 1 + 3 + 2) * 4);
        assert_eq!(Checkpoint::from_bytes(&smaller).unwrap(), checkpoint);
    }

    /// The bytes of `checkpoint` (without AOVs) as version 4 wrote them: no region (the
    /// whole image), no sampler (independent numbers), no triangle test (watertight), no
    /// AOV set.
    fn version_4_bytes(checkpoint: &Checkpoint) -> Vec<u8> {
        let mut bytes = checkpoint.to_bytes();
        bytes.truncate(bytes.len() - 8 - 4);
        bytes[8..12].copy_from_slice(&4u32.to_le_bytes());
        let sampler_at = 8 + 4 + 8 + 8 + 4 + checkpoint.scene.len() + 4 * 4 + 8 + 4 + 4;
        bytes.drain(sampler_at..sampler_at + 4 + 4 + 16);
        bytes.drain(20..28); // no owner before version 6
        let checksum = fnv1a(&bytes, FNV_OFFSET);
        bytes.extend(checksum.to_le_bytes());
        bytes
    }

    #[test]
    fn a_region_round_trips_and_version_4_files_hold_the_whole_image() {
        let (scene, mut whole) = sample();
        let v4 = version_4_bytes(&whole);
        // Renders before version 7 drew independent numbers.
        assert_eq!(whole.settings.sampler, Sampler::Sobol);
        whole.settings.sampler = Sampler::Independent;
        assert_eq!(Checkpoint::from_bytes(&v4).unwrap(), whole);
        let back = Checkpoint::from_bytes(&whole.to_bytes()).unwrap();
        assert_eq!(back.settings.sampler, Sampler::Independent);

        let region = Region {
            x: 1,
            y: 2,
            width: 3,
            height: 1,
        };
        let mut acc = Accumulator::for_region(region);
        acc.sums[2] = Vec3::new(0.5, 2.0, -1.0);
        acc.samples = 4;
        let part = Checkpoint::new("cornell", &scene, acc);
        let back = Checkpoint::from_bytes(&part.to_bytes()).unwrap();
        assert_eq!(back, part);
        assert_eq!(back.accumulator.region, region);

        // A region that leaves the image is damage, not a render to continue.
        let mut outside = part.clone();
        outside.accumulator.region.x = 2;
        let what = Checkpoint::from_bytes(&outside.to_bytes()).unwrap_err();
        assert!(what.contains("beyond"), "{what}");
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

    #[test]
    fn any_change_to_geometry_or_shading_does_not_match() {
        let (scene, checkpoint) = sample();
        let mut moved = scene.clone();
        match &mut std::sync::Arc::make_mut(&mut moved.primitives)[3].shape {
            Shape::Triangle(t) => t.v[1].x += 1e-3,
            Shape::Sphere(s) => s.radius += 1e-3,
            Shape::Cuboid(c) => c.translation.x += 1e-3,
        }
        assert!(checkpoint.matches(&moved, Path::new("x")).is_err());
        let mut smoothed = scene.clone();
        smoothed.vertex_normals.push([Vec3::Y; 3]);
        assert!(checkpoint.matches(&smoothed, Path::new("x")).is_err());
        let mut recoloured = scene;
        std::sync::Arc::make_mut(&mut recoloured.primitives)[0].material ^= 1;
        assert!(checkpoint.matches(&recoloured, Path::new("x")).is_err());
    }

    /// Two renders given one path never destroy each other's work: a checkpoint is
    /// replaced or removed only by the render that wrote it, or one that continues it.
    #[test]
    fn a_checkpoint_is_replaced_and_removed_only_by_its_owners() {
        let dir = std::env::temp_dir().join(format!("canopy-owner-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let ck = dir.join("ck");
        let (_, checkpoint) = sample();
        assert_eq!(Checkpoint::slot(&ck), Slot::Free);
        checkpoint
            .clone()
            .owned_by(7)
            .save_owned(&ck, &[7])
            .unwrap();
        assert_eq!(Checkpoint::slot(&ck), Slot::Checkpoint { owner: 7 });
        // Render 9 neither replaces nor removes render 7's checkpoint.
        let taken = checkpoint
            .clone()
            .owned_by(9)
            .save_owned(&ck, &[9])
            .unwrap_err();
        assert!(matches!(taken, CheckpointError::Taken { .. }), "{taken}");
        assert!(
            taken
                .to_string()
                .contains("9 samples per pixel of `cornell`"),
            "{taken}"
        );
        assert!(!Checkpoint::remove_owned(&ck, &[9]).unwrap());
        assert_eq!(Checkpoint::load(&ck).unwrap().owner, 7);
        // A render continuing it may do both.
        checkpoint
            .clone()
            .owned_by(9)
            .save_owned(&ck, &[9, 7])
            .unwrap();
        assert_eq!(Checkpoint::load(&ck).unwrap().owner, 9);
        assert!(Checkpoint::remove_owned(&ck, &[9, 7]).unwrap());
        // A user's file is no one's to replace.
        std::fs::write(&ck, "notes").unwrap();
        assert_eq!(Checkpoint::slot(&ck), Slot::Other);
        assert!(checkpoint.owned_by(9).save_owned(&ck, &[9]).is_err());
        assert!(!Checkpoint::remove_owned(&ck, &[9]).unwrap());
        assert_eq!(std::fs::read_to_string(&ck).unwrap(), "notes");
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn only_checkpoints_are_recognised_and_removed() {
        let dir = std::env::temp_dir().join(format!("canopy-ck-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (ck, notes) = (dir.join("ck"), dir.join("notes.txt"));
        sample().1.owned_by(3).save(&ck).unwrap();
        std::fs::write(&notes, "my notes").unwrap();
        assert!(matches!(Checkpoint::slot(&ck), Slot::Checkpoint { .. }));
        assert_eq!(Checkpoint::slot(&notes), Slot::Other);
        assert_eq!(Checkpoint::slot(&dir.join("absent")), Slot::Free);
        assert!(!Checkpoint::remove_owned(&notes, &[3]).unwrap());
        assert!(notes.exists());
        assert!(Checkpoint::remove_owned(&ck, &[3]).unwrap());
        assert!(!ck.exists());
        std::fs::remove_dir_all(dir).unwrap();
    }
}
