//! The TOML scene format (documented in `docs/scene-format.md`) and its translation into a
//! validated [`Scene`]. Every error names the file and the line of the offending entry.

use crate::background::decode_environment;
use crate::camera::CameraSpec;
use crate::error::SceneError;
use crate::files::{available_memory, read_regular_file, regular_file_size};
use crate::geometry::{Shape, Triangle};
use crate::material::{Material, Pbr};
use crate::mesh::{parse_mesh, MeshData, MeshFormat};
use crate::scene::{Background, Primitive, RenderSettings, Scene};
use glam::{Mat3, Mat4, Quat, Vec3};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use toml::Spanned;

pub(crate) mod instances;
mod lights;
mod models;
pub use instances::MAX_INSTANCES;

/// Where a scene's mesh files come from.
pub trait Assets {
    /// The bytes of the file at `path` (as written in the scene), or why not.
    fn read(&self, path: &str) -> Result<Vec<u8>, String>;

    /// Where `path` is on disk, when it is a file: the scene records its inputs so that
    /// nothing is ever written over them.
    fn locate(&self, _path: &str) -> Option<PathBuf> {
        None
    }
}

/// The files a scene names, read from its own folder (the scene file's, or a model's):
/// a path that leads out of it — `../`, an absolute path, a link to elsewhere, a
/// percent-encoded `..` once decoded — is refused unless it lies in a folder the user
/// allowed ([`DirAssets::allowing`]). On a render farm that renders files its users
/// upload, a scene can then never read (or quote in an error) another file of the
/// machine.
pub struct DirAssets {
    dir: PathBuf,
    /// Further folders the user allowed, resolved.
    allowed: Vec<PathBuf>,
}

impl DirAssets {
    /// Files in `dir` (and its subfolders) only.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            allowed: Vec::new(),
        }
    }

    /// The directory holding `path`, and the file's name in it: how a file given on
    /// its own (a mesh, a model) is read, with what lies beside it.
    pub fn beside(path: &std::path::Path) -> (Self, String) {
        let dir = crate::files::directory_of(path).to_owned();
        let file = path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default();
        (Self::new(dir), file)
    }

    /// Also the files in `dirs` (and their subfolders). Fails naming a folder that does
    /// not exist.
    pub fn allowing(mut self, dirs: &[PathBuf]) -> Result<Self, String> {
        for dir in dirs {
            let resolved = std::fs::canonicalize(dir)
                .ok()
                .filter(|d| d.is_dir())
                .ok_or_else(|| {
                    format!(
                        "{}: an allowed path must be an existing folder",
                        dir.display()
                    )
                })?;
            self.allowed.push(resolved);
        }
        Ok(self)
    }

    /// Where the file `path` (as the scene writes it) is, links followed, if it lies in
    /// the scene's folder or an allowed one.
    pub fn resolve(&self, path: &str) -> Result<PathBuf, String> {
        let full = self.dir.join(path);
        let resolved = std::fs::canonicalize(&full)
            .map_err(|e| format!("cannot read {}: {e}", full.display()))?;
        let root = std::fs::canonicalize(&self.dir)
            .map_err(|e| format!("cannot read {}: {e}", self.dir.display()))?;
        if resolved.starts_with(&root) || self.allowed.iter().any(|a| resolved.starts_with(a)) {
            return Ok(resolved);
        }
        Err(format!(
            "`{path}` leads out of the scene's folder {} (to {}); a scene reads only files in its own folder, unless the user allows more (`--allow-path DIR`, Python `allow_paths=`)",
            root.display(),
            resolved.display()
        ))
    }
}

impl Assets for DirAssets {
    fn read(&self, path: &str) -> Result<Vec<u8>, String> {
        read_input_file(&self.resolve(path)?)
    }

    fn locate(&self, path: &str) -> Option<PathBuf> {
        self.resolve(path).ok()
    }
}

/// The bytes of an input file (a regular file, no larger than memory holds); errors
/// name it.
pub fn read_input_file(path: &std::path::Path) -> Result<Vec<u8>, String> {
    let fail = |e: &dyn std::fmt::Display| format!("cannot read {}: {e}", path.display());
    let size = regular_file_size(path).map_err(|e| fail(&e))?;
    check_fits_in_memory(size, available_memory())?;
    read_regular_file(path, size).map_err(|e| fail(&e))
}

/// Refuses a file larger than the memory available (when known). What it decodes to is
/// checked by its reader: meshes by [`crate::mesh::parse_mesh`], models, images and
/// environment maps by the sizes they declare.
fn check_fits_in_memory(file_bytes: u64, available: Option<u64>) -> Result<(), String> {
    crate::files::check_memory(
        file_bytes,
        available,
        &format!("reading a file of {} MiB", file_bytes >> 20),
    )
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneDoc {
    name: Option<String>,
    description: Option<String>,
    camera: Spanned<CameraDoc>,
    render: Option<Spanned<RenderDoc>>,
    background: Option<Spanned<toml::Value>>,
    #[serde(default)]
    materials: BTreeMap<String, Spanned<toml::Value>>,
    #[serde(default)]
    spheres: Vec<Spanned<SphereDoc>>,
    #[serde(default)]
    cuboids: Vec<Spanned<CuboidDoc>>,
    #[serde(default)]
    meshes: Vec<Spanned<MeshDoc>>,
    /// Named meshes, placed only by `instances`.
    #[serde(default)]
    geometry: BTreeMap<String, Spanned<instances::GeometryDoc>>,
    #[serde(default)]
    instances: Vec<Spanned<instances::InstanceDoc>>,
    /// Whole glTF models, each placed by a transform.
    #[serde(default)]
    gltf: Vec<Spanned<models::GltfDoc>>,
    /// Point, spot and directional lights.
    #[serde(default)]
    lights: Vec<Spanned<lights::LightDoc>>,
}

/// `background = { environment = "file.hdr", rotate = 90, strength = 1 }`
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EnvironmentDoc {
    environment: String,
    rotate: Option<RotateDoc>,
    #[serde(default = "one")]
    strength: f32,
}

fn one() -> f32 {
    1.0
}

/// Degrees about the vertical axis, or about x, then y, then z.
#[derive(Deserialize)]
#[serde(untagged)]
enum RotateDoc {
    AboutUp(f32),
    Euler([f32; 3]),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraDoc {
    look_from: [f32; 3],
    look_at: [f32; 3],
    #[serde(default = "default_up")]
    up: [f32; 3],
    #[serde(default = "default_vfov")]
    vfov: f32,
    #[serde(default)]
    aperture: f32,
    focus_distance: Option<f32>,
    ortho_height: Option<f32>,
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}

fn default_vfov() -> f32 {
    40.0
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RenderDoc {
    width: Option<u32>,
    height: Option<u32>,
    spp: Option<u32>,
    max_depth: Option<u32>,
    seed: Option<u64>,
    integrator: Option<Spanned<String>>,
    russian_roulette: Option<bool>,
    sampler: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
enum MaterialDoc {
    Lambertian {
        albedo: [f32; 3],
    },
    Metal {
        albedo: [f32; 3],
        #[serde(default)]
        fuzz: f32,
    },
    Dielectric {
        ior: f32,
    },
    Emissive {
        radiance: [f32; 3],
    },
    Pbr {
        base_color: [f32; 3],
        #[serde(default)]
        metallic: f32,
        #[serde(default = "default_roughness")]
        roughness: f32,
        #[serde(default)]
        emission: [f32; 3],
    },
}

/// glTF's default roughness.
fn default_roughness() -> f32 {
    1.0
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SphereDoc {
    center: [f32; 3],
    radius: f32,
    material: Spanned<toml::Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CuboidDoc {
    min: [f32; 3],
    max: [f32; 3],
    /// Degrees about x, then y, then z.
    #[serde(default)]
    rotate: [f32; 3],
    #[serde(default)]
    translate: [f32; 3],
    material: Spanned<toml::Value>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum ScaleDoc {
    Uniform(f32),
    PerAxis([f32; 3]),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MeshDoc {
    file: String,
    material: Spanned<toml::Value>,
    scale: Option<ScaleDoc>,
    #[serde(default)]
    rotate: [f32; 3],
    #[serde(default)]
    translate: [f32; 3],
    /// Interpolate vertex normals: from the file, or computed when it has none.
    /// Absent: smooth exactly when the file has normals.
    smooth: Option<bool>,
}

/// Turns TOML spans into `file:line` errors.
struct Context<'a> {
    file: &'a str,
    source: &'a str,
}

impl Context<'_> {
    fn line_of(&self, offset: usize) -> usize {
        let offset = offset.min(self.source.len());
        self.source.as_bytes()[..offset]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1
    }

    fn invalid<T>(
        &self,
        span: std::ops::Range<usize>,
        message: impl Into<String>,
    ) -> Result<T, SceneError> {
        Err(SceneError::Invalid {
            file: self.file.to_owned(),
            line: self.line_of(span.start),
            message: message.into(),
        })
    }

    fn syntax(&self, e: &toml::de::Error) -> SceneError {
        let start = e.span().map_or(0, |s| s.start).min(self.source.len());
        let line_start = self.source[..start].rfind('\n').map_or(0, |i| i + 1);
        let text = self.source[line_start..]
            .lines()
            .next()
            .unwrap_or("")
            .to_owned();
        SceneError::Syntax {
            file: self.file.to_owned(),
            line: self.line_of(start),
            column: self.source[line_start..start].chars().count() + 1,
            message: e.message().to_owned(),
            text,
        }
    }
}

/// Parses and validates a scene. `file` names the source in error messages; mesh paths
/// are resolved by `assets`.
pub fn parse_scene(source: &str, file: &str, assets: &dyn Assets) -> Result<Scene, SceneError> {
    let cx = Context { file, source };
    let doc: SceneDoc = toml::from_str(source).map_err(|e| cx.syntax(&e))?;
    let mut builder = SceneBuilder {
        cx: &cx,
        scene: Scene {
            name: doc.name.clone().unwrap_or_default(),
            description: doc.description.clone().unwrap_or_default(),
            ..Scene::default()
        },
        named: BTreeMap::new(),
        geometry_index: BTreeMap::new(),
    };
    builder.camera(&doc.camera)?;
    builder.settings(doc.render.as_ref())?;
    if let Some(bg) = &doc.background {
        builder.background(bg, assets)?;
    }
    for (name, value) in &doc.materials {
        let material = builder.material_from_table(value)?;
        builder.scene.materials.push(material);
        builder
            .named
            .insert(name.clone(), builder.scene.materials.len() as u32 - 1);
    }
    for sphere in &doc.spheres {
        builder.sphere(sphere)?;
    }
    for cuboid in &doc.cuboids {
        builder.cuboid(cuboid)?;
    }
    for mesh in &doc.meshes {
        builder.mesh(mesh, assets)?;
    }
    for (name, geometry) in &doc.geometry {
        builder.geometry(name, geometry, assets)?;
    }
    for instance in &doc.instances {
        builder.instances(instance)?;
    }
    for model in &doc.gltf {
        builder.gltf(model, assets)?;
    }
    for light in &doc.lights {
        builder.light(light)?;
    }
    Ok(builder.scene)
}

struct SceneBuilder<'a> {
    cx: &'a Context<'a>,
    scene: Scene,
    /// Material index by name.
    named: BTreeMap<String, u32>,
    /// Index into `scene.meshes` by geometry name.
    geometry_index: BTreeMap<String, u32>,
}

fn finite(values: &[f32]) -> bool {
    values.iter().all(|v| v.is_finite())
}

/// Largest coordinate, radius or distance a scene may use. Squares and products of
/// such numbers (ray-sphere tests, areas) stay finite in f32, so geometry never
/// overflows into an invisible or black render.
pub const MAX_COORDINATE: f32 = 1e12;

/// Brightest radiance (emitters, background): sums of many samples of it stay finite.
pub const MAX_RADIANCE: f32 = 1e12;

/// A radiance: every component in [0, MAX_RADIANCE].
pub(crate) use crate::scene_build::in_range;

fn radiance_ok(c: &[f32; 3]) -> bool {
    crate::scene_build::radiance_ok(Vec3::from(*c))
}

impl SceneBuilder<'_> {
    fn camera(&mut self, doc: &Spanned<CameraDoc>) -> Result<(), SceneError> {
        let c = doc.get_ref();
        let camera = CameraSpec {
            look_from: c.look_from.into(),
            look_at: c.look_at.into(),
            up: c.up.into(),
            vfov: c.vfov,
            aperture: c.aperture,
            focus_distance: c.focus_distance,
            ortho_height: c.ortho_height,
        };
        self.scene
            .set_camera(camera)
            .or_else(|problem| self.cx.invalid(doc.span(), format!("camera: {problem}")))
    }

    /// The choice `name` gives (an integrator, a sampler), or `default` without one; an
    /// unknown name is an error at its line.
    fn named<T: std::str::FromStr<Err = String>>(
        &self,
        name: &Option<Spanned<String>>,
        default: T,
    ) -> Result<T, SceneError> {
        match name {
            None => Ok(default),
            Some(name) => name
                .get_ref()
                .parse()
                .or_else(|problem| self.cx.invalid(name.span(), format!("render: {problem}"))),
        }
    }

    fn settings(&mut self, doc: Option<&Spanned<RenderDoc>>) -> Result<(), SceneError> {
        let d = RenderSettings::default();
        let Some(doc) = doc else {
            self.scene.settings = d;
            return Ok(());
        };
        let r = doc.get_ref();
        let settings = RenderSettings {
            width: r.width.unwrap_or(d.width),
            height: r.height.unwrap_or(d.height),
            spp: r.spp.unwrap_or(d.spp),
            max_depth: r.max_depth.unwrap_or(d.max_depth),
            seed: r.seed.unwrap_or(d.seed),
            integrator: self.named(&r.integrator, d.integrator)?,
            russian_roulette: r.russian_roulette.unwrap_or(d.russian_roulette),
            sampler: self.named(&r.sampler, d.sampler)?,
        };
        if let Err(problem) = settings.check() {
            return self.cx.invalid(doc.span(), format!("render: {problem}"));
        }
        self.scene.settings = settings;
        Ok(())
    }

    fn background(
        &mut self,
        value: &Spanned<toml::Value>,
        assets: &dyn Assets,
    ) -> Result<(), SceneError> {
        let span = value.span();
        self.scene.background = match value.get_ref() {
            toml::Value::String(s) if s == "sky" => Background::Sky,
            toml::Value::Table(table) => {
                let doc: EnvironmentDoc = match toml::Value::Table(table.clone()).try_into() {
                    Ok(doc) => doc,
                    Err(e) => return self.cx.invalid(span, format!("background: {}", e.message())),
                };
                self.environment(&doc, assets)
                    .or_else(|problem| self.cx.invalid(span, format!("background: {problem}")))?
            }
            other => match other.clone().try_into::<[f32; 3]>() {
                Ok(c) if radiance_ok(&c) => Background::Constant(Vec3::from(c)),
                _ => return self.cx.invalid(
                    span,
                    format!("background: expected \"sky\", an [r, g, b] colour with each number in [0, {MAX_RADIANCE:e}], or {{ environment = \"file.hdr\" }}"),
                ),
            },
        };
        Ok(())
    }

    fn environment(
        &mut self,
        doc: &EnvironmentDoc,
        assets: &dyn Assets,
    ) -> Result<Background, String> {
        let degrees = match doc.rotate {
            None => [0.0; 3],
            Some(RotateDoc::AboutUp(y)) => [0.0, y, 0.0],
            Some(RotateDoc::Euler(xyz)) => xyz,
        };
        if !finite(&degrees) {
            return Err("`rotate` must be finite".into());
        }
        if !(doc.strength.is_finite() && (0.0..=MAX_RADIANCE).contains(&doc.strength)) {
            return Err(format!("`strength` must be in [0, {MAX_RADIANCE:e}]"));
        }
        let bytes = assets.read(&doc.environment)?;
        self.scene.inputs.extend(assets.locate(&doc.environment));
        let to_world = Mat3::from_quat(rotation(degrees));
        let map = decode_environment(&doc.environment, &bytes, to_world, doc.strength)?;
        Ok(Background::Environment(Arc::new(map)))
    }

    fn material_from_table(&self, value: &Spanned<toml::Value>) -> Result<Material, SceneError> {
        let span = value.span();
        let doc: MaterialDoc = match value.get_ref().clone().try_into() {
            Ok(doc) => doc,
            Err(e) => return self.cx.invalid(span, format!("material: {}", e.message())),
        };
        let material = match doc {
            MaterialDoc::Lambertian { albedo } => Material::Lambertian {
                albedo: albedo.into(),
            },
            MaterialDoc::Metal { albedo, fuzz } => Material::Metal {
                albedo: albedo.into(),
                fuzz,
            },
            MaterialDoc::Dielectric { ior } => Material::Dielectric { ior },
            MaterialDoc::Emissive { radiance } => Material::Emissive {
                radiance: radiance.into(),
            },
            MaterialDoc::Pbr {
                base_color,
                metallic,
                roughness,
                emission,
            } => Material::Pbr(Pbr {
                base_color: base_color.into(),
                metallic,
                roughness,
                emission: emission.into(),
            }),
        };
        match material.check() {
            Ok(()) => Ok(material),
            Err(problem) => self.cx.invalid(span, format!("material: {problem}")),
        }
    }

    /// A material given by name or inline as a table.
    fn material_ref(&mut self, value: &Spanned<toml::Value>) -> Result<u32, SceneError> {
        match value.get_ref() {
            toml::Value::String(name) => match self.named.get(name) {
                Some(&index) => Ok(index),
                None => {
                    let known: Vec<&str> = self.named.keys().map(String::as_str).collect();
                    self.cx.invalid(
                        value.span(),
                        format!(
                            "unknown material `{name}` (defined: {})",
                            if known.is_empty() {
                                "none".into()
                            } else {
                                known.join(", ")
                            }
                        ),
                    )
                }
            },
            toml::Value::Table(_) => {
                let material = self.material_from_table(value)?;
                self.scene.materials.push(material);
                Ok(self.scene.materials.len() as u32 - 1)
            }
            _ => self.cx.invalid(
                value.span(),
                "`material` must be a material name or a table",
            ),
        }
    }

    fn push(&mut self, shape: Shape, material: u32) {
        Arc::make_mut(&mut self.scene.primitives).push(Primitive { shape, material });
    }

    fn sphere(&mut self, doc: &Spanned<SphereDoc>) -> Result<(), SceneError> {
        let s = doc.get_ref();
        let material = self.material_ref(&s.material)?;
        self.scene
            .add_sphere(s.center.into(), s.radius, material)
            .or_else(|problem| self.cx.invalid(doc.span(), format!("sphere: {problem}")))
    }

    fn cuboid(&mut self, doc: &Spanned<CuboidDoc>) -> Result<(), SceneError> {
        let c = doc.get_ref();
        let material = self.material_ref(&c.material)?;
        self.scene
            .add_cuboid(
                c.min.into(),
                c.max.into(),
                c.rotate,
                c.translate.into(),
                material,
            )
            .or_else(|problem| self.cx.invalid(doc.span(), format!("cuboid: {problem}")))
    }

    /// Reads and parses mesh file `file` (named by the entry at `span`), recording it
    /// as an input.
    fn read_mesh(
        &mut self,
        file: &str,
        span: std::ops::Range<usize>,
        assets: &dyn Assets,
    ) -> Result<MeshData, SceneError> {
        let line = self.cx.line_of(span.start);
        let mesh_error = |cause| SceneError::Mesh {
            file: self.cx.file.to_owned(),
            line,
            mesh: file.to_owned(),
            cause,
        };
        let format = MeshFormat::from_path(file).map_err(mesh_error)?;
        let bytes = assets
            .read(file)
            .map_err(|e| mesh_error(crate::mesh::MeshError::Invalid(e)))?;
        self.scene.inputs.extend(assets.locate(file));
        parse_mesh(&bytes, format).map_err(mesh_error)
    }

    fn mesh(&mut self, doc: &Spanned<MeshDoc>, assets: &dyn Assets) -> Result<(), SceneError> {
        let m = doc.get_ref();
        let Some(scale) = checked_scale(&m.scale, m.rotate, m.translate) else {
            return self.cx.invalid(
                doc.span(),
                "mesh: transform numbers must be finite and `scale` non-zero",
            );
        };
        let mut data = self.read_mesh(&m.file, doc.span(), assets)?;
        data.transform(&Mat4::from_scale_rotation_translation(
            scale,
            rotation(m.rotate),
            m.translate.into(),
        ));
        if let Some(i) = data.positions.iter().position(|p| !in_range(&p.to_array())) {
            return self.cx.invalid(
                doc.span(),
                format!(
                    "mesh `{}`: vertex {i} lies at {} once scaled, rotated and translated, beyond ±{MAX_COORDINATE:e}",
                    m.file, data.positions[i]
                ),
            );
        }
        apply_smooth(&mut data, m.smooth);
        let material = self.material_ref(&m.material)?;
        for &[a, b, c] in &data.triangles {
            let [pa, pb, pc] = [a, b, c].map(|i| data.positions[i as usize]);
            let mut triangle = Triangle::new(pa, pb, pc);
            // A triangle without area can never be hit: leave it out, and say so.
            if triangle.area() == 0.0 {
                self.scene.skipped_degenerate += 1;
                continue;
            }
            if !data.normals.is_empty() {
                triangle.normals = self.scene.vertex_normals.len() as u32;
                self.scene
                    .vertex_normals
                    .push([a, b, c].map(|i| data.normals[i as usize]));
            }
            self.push(Shape::Triangle(triangle), material);
        }
        Ok(())
    }
}

/// The scale of a transform given as `scale`, `rotate` and `translate`, if every number is
/// finite and the scale non-zero on every axis.
fn checked_scale(scale: &Option<ScaleDoc>, rotate: [f32; 3], translate: [f32; 3]) -> Option<Vec3> {
    let scale = match *scale {
        None => Vec3::ONE,
        Some(ScaleDoc::Uniform(s)) => Vec3::splat(s),
        Some(ScaleDoc::PerAxis(s)) => s.into(),
    };
    (finite(&[&scale.to_array()[..], &rotate, &translate].concat())
        && !scale.cmpeq(Vec3::ZERO).any())
    .then_some(scale)
}

/// A mesh's `smooth` setting: `false` drops its normals, `true` computes them where the
/// file has none, absent keeps what the file has.
fn apply_smooth(data: &mut MeshData, smooth: Option<bool>) {
    match smooth {
        Some(false) => data.normals.clear(),
        Some(true) if data.normals.is_empty() => data.compute_vertex_normals(),
        _ => {}
    }
}

/// Rotation by Euler angles in degrees: about x first, then y, then z.
fn rotation(degrees: [f32; 3]) -> Quat {
    crate::scene_build::rotation_from_degrees(degrees)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct NoAssets;
    impl Assets for NoAssets {
        fn read(&self, path: &str) -> Result<Vec<u8>, String> {
            if path == "quad.obj" {
                Ok(b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n".to_vec())
            } else if path == "sky.hdr" {
                let mut pixels = vec![image::Rgb([0.5f32, 0.5, 0.5]); 8];
                pixels[5] = image::Rgb([2.0; 3]);
                let mut bytes = Vec::new();
                image::codecs::hdr::HdrEncoder::new(&mut bytes)
                    .encode(&pixels, 4, 2)
                    .map_err(|e| e.to_string())?;
                Ok(bytes)
            } else if path == "nan.exr" {
                let mut image = image::Rgb32FImage::from_pixel(4, 2, image::Rgb([0.5; 3]));
                image.put_pixel(1, 1, image::Rgb([f32::NAN; 3]));
                let mut bytes = std::io::Cursor::new(Vec::new());
                image
                    .write_to(&mut bytes, image::ImageFormat::OpenExr)
                    .map_err(|e| e.to_string())?;
                Ok(bytes.into_inner())
            } else if path == "sky.png" {
                Ok(vec![0x89, b'P', b'N', b'G'])
            } else {
                Err(format!("no such file {path}"))
            }
        }
    }

    const CAMERA: &str = "[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n";

    fn parse(body: &str) -> Result<Scene, SceneError> {
        parse_scene(&format!("{CAMERA}{body}"), "test.toml", &NoAssets)
    }

    /// A scene whose top-level keys (before the tables) are `top`.
    fn parse_top(top: &str) -> Result<Scene, SceneError> {
        parse_scene(&format!("{top}{CAMERA}"), "test.toml", &NoAssets)
    }

    fn error(body: &str) -> String {
        parse(body).unwrap_err().to_string()
    }

    #[test]
    fn lights_of_every_kind_are_read_and_bad_ones_named_by_line() {
        let scene = parse(
            "[[lights]]\ntype = \"point\"\nposition = [0, 4, 0]\nintensity = [20, 20, 20]\n\
             [[lights]]\ntype = \"spot\"\nposition = [2, 3, 0]\ndirection = [0, -2, 0]\n\
             intensity = [1, 1, 1]\ninner_angle = 15\nouter_angle = 30\n\
             [[lights]]\ntype = \"directional\"\ndirection = [0, 0, -3]\nirradiance = [2, 2, 2]\n",
        )
        .unwrap();
        use crate::lights::PunctualLight;
        assert!(
            matches!(scene.lights[0], PunctualLight::Point { position, .. } if position == Vec3::new(0.0, 4.0, 0.0))
        );
        let PunctualLight::Spot {
            direction,
            cos_inner,
            cos_outer,
            ..
        } = scene.lights[1]
        else {
            panic!("{:?}", scene.lights[1]);
        };
        assert_eq!(direction, Vec3::NEG_Y);
        assert!((cos_inner - 15f32.to_radians().cos()).abs() < 1e-6);
        assert!((cos_outer - 30f32.to_radians().cos()).abs() < 1e-6);
        assert!(
            matches!(scene.lights[2], PunctualLight::Directional { direction, .. } if direction == Vec3::NEG_Z)
        );
        let e = error("\n[[lights]]\ntype = \"spot\"\nposition = [0, 0, 0]\ndirection = [0, -1, 0]\nintensity = [1, 1, 1]\ninner_angle = 50\n");
        assert!(
            e.contains("test.toml:5") && e.contains("outer cone must be wider"),
            "{e}"
        );
        let e = error(
            "[[lights]]\ntype = \"directional\"\ndirection = [0, 0, 0]\nirradiance = [1, 1, 1]\n",
        );
        assert!(e.contains("`direction` must be finite and not zero"), "{e}");
        let e = error("[[lights]]\ntype = \"area\"\n");
        assert!(e.contains("area"), "{e}");
    }

    #[test]
    fn minimal_scene_with_every_shape() {
        let scene = parse(
            "[materials.red]\ntype = \"lambertian\"\nalbedo = [0.8, 0.1, 0.1]\n\
             [[spheres]]\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"red\"\n\
             [[cuboids]]\nmin = [0, 0, 0]\nmax = [1, 2, 3]\nrotate = [0, 15, 0]\nmaterial = { type = \"metal\", albedo = [1, 1, 1], fuzz = 0.1 }\n\
             [[meshes]]\nfile = \"quad.obj\"\nmaterial = \"red\"\nscale = 2\nsmooth = true\n",
        )
        .unwrap();
        let counts = scene.shape_counts();
        assert_eq!(
            (counts.spheres, counts.cuboids, counts.triangles),
            (1, 1, 2)
        );
        assert_eq!(scene.materials.len(), 2);
        assert_eq!(scene.vertex_normals.len(), 2);
        assert_eq!(scene.camera.look_from, Vec3::new(0.0, 0.0, 5.0));
    }

    #[test]
    fn unknown_key_names_line_and_key() {
        let e = error("[[spheres]]\ncenter = [0, 0, 0]\nradus = 1\nmaterial = \"x\"\n");
        assert!(e.starts_with("test.toml:6:"), "{e}");
        assert!(e.contains("radus"), "{e}");
    }

    #[test]
    fn unknown_material_names_line_and_name() {
        let e = error("[[spheres]]\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"glass\"\n");
        assert!(e.starts_with("test.toml:7:"), "{e}");
        assert!(e.contains("unknown material `glass`"), "{e}");
    }

    #[test]
    fn negative_radius_is_rejected_with_its_line() {
        let e = error("\n[[spheres]]\ncenter = [0, 0, 0]\nradius = -1\nmaterial = {type = \"dielectric\", ior = 1.5}\n");
        assert!(e.starts_with("test.toml:5:") && e.contains("radius"), "{e}");
    }

    #[test]
    fn bad_material_type_is_reported() {
        let e = error("[materials.x]\ntype = \"plastic\"\nalbedo = [1, 1, 1]\n");
        assert!(e.contains("test.toml:4") && e.contains("plastic"), "{e}");
    }

    #[test]
    fn toml_syntax_error_has_line_and_column() {
        let e = parse_scene("[camera\nlook_from = 1", "bad.toml", &NoAssets).unwrap_err();
        assert!(matches!(e, SceneError::Syntax { line: 1, .. }), "{e}");
    }

    #[test]
    fn missing_mesh_file_names_the_mesh() {
        let e = error("[[meshes]]\nfile = \"gone.ply\"\nmaterial = {type = \"lambertian\", albedo = [1, 1, 1]}\n");
        assert!(e.contains("test.toml:4") && e.contains("gone.ply"), "{e}");
    }

    #[test]
    fn zero_area_triangles_are_skipped_and_counted() {
        struct Mesh;
        impl Assets for Mesh {
            fn read(&self, _: &str) -> Result<Vec<u8>, String> {
                // One good triangle, one with a repeated vertex, one with collinear ones.
                Ok(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 2\nf 1 2 4\n".to_vec())
            }
        }
        let source = format!("{CAMERA}[[meshes]]\nfile = \"m.obj\"\nmaterial = {{ type = \"lambertian\", albedo = [1, 1, 1] }}\n");
        let scene = parse_scene(&source, "t.toml", &Mesh).unwrap();
        assert_eq!(scene.primitives.len(), 1);
        assert_eq!(scene.skipped_degenerate, 2);
    }

    const QUAD_GEOMETRY: &str = "[geometry.quad]\nfile = \"quad.obj\"\n";

    #[test]
    fn named_geometry_is_stored_once_and_placed_by_instances() {
        let scene = parse(&format!(
            "{QUAD_GEOMETRY}\
             [[instances]]\ngeometry = \"quad\"\nmaterial = {{ type = \"lambertian\", albedo = [1, 1, 1] }}\n\
             scale = [1, -2, 1]\nrotate = [0, 90, 0]\ntranslate = [1, 2, 3]\n\
             [[instances]]\ngeometry = \"quad\"\nmaterial = {{ type = \"emissive\", radiance = [1, 1, 1] }}\n\
             grid = {{ count = [3, 1, 2], step = [2, 0, 5] }}\n"
        ))
        .unwrap();
        assert!(
            scene.primitives.is_empty(),
            "named geometry is not placed by itself"
        );
        assert_eq!(scene.meshes.len(), 1);
        assert_eq!(scene.meshes[0].mesh.indices().len(), 2);
        assert_eq!(scene.instances.len(), 7);
        let first = scene.instances[0].to_world;
        assert!(first.matrix3.determinant() < 0.0, "a mirrored instance");
        assert!((first.transform_point3(Vec3::ZERO) - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-6);
        // Grid copy (i, j, k) = (2, 0, 1) is moved by (4, 0, 5); x runs fastest.
        let last = scene.instances[6].to_world;
        assert_eq!(last.transform_point3(Vec3::ZERO), Vec3::new(4.0, 0.0, 5.0));
        assert_eq!(scene.instanced_triangles(), 14);
        let listed = parse(&format!(
            "{QUAD_GEOMETRY}[[instances]]\ngeometry = \"quad\"\nmaterial = {{ type = \"lambertian\", albedo = [1, 1, 1] }}\n\
             scale = 2\nplaces = [{{ translate = [1, 0, 0] }}, {{ rotate = [0, 0, 90], translate = [0, 5, 0] }}]\n"
        ))
        .unwrap();
        assert_eq!(listed.instances.len(), 2);
        // Each place moves the instance after its own transform (scale 2 first).
        let corner = |k: usize| listed.instances[k].to_world.transform_point3(Vec3::X);
        assert!(
            (corner(0) - Vec3::new(3.0, 0.0, 0.0)).length() < 1e-6,
            "{}",
            corner(0)
        );
        assert!(
            (corner(1) - Vec3::new(0.0, 7.0, 0.0)).length() < 1e-5,
            "{}",
            corner(1)
        );
        assert_ne!(scene.instances[0].material, scene.instances[1].material);
    }

    #[test]
    fn instance_errors_name_the_line_and_what_is_wrong() {
        let lambert = "material = { type = \"lambertian\", albedo = [1, 1, 1] }";
        let e = error(&format!(
            "{QUAD_GEOMETRY}[[instances]]\ngeometry = \"quads\"\n{lambert}\n"
        ));
        assert!(
            e.contains("test.toml:6")
                && e.contains("unknown geometry `quads`")
                && e.contains("quad"),
            "{e}"
        );
        let e = error(&format!(
            "{QUAD_GEOMETRY}[[instances]]\ngeometry = \"quad\"\n{lambert}\nscale = [1, 0, 1]\n"
        ));
        assert!(e.contains("test.toml:6") && e.contains("non-zero"), "{e}");
        let e = error(&format!(
            "{QUAD_GEOMETRY}[[instances]]\ngeometry = \"quad\"\n{lambert}\ngrid = {{ count = [4096, 4096, 1], step = [1, 1, 1] }}\n"
        ));
        assert!(e.contains("16777216 copies"), "{e}");
        let e = error(&format!(
            "{QUAD_GEOMETRY}[[instances]]\ngeometry = \"quad\"\n{lambert}\nplaces = [{{ translate = [1, 0, 0] }}, {{ scale = 0 }}]\n"
        ));
        assert!(e.contains("test.toml:6") && e.contains("(place 1)"), "{e}");
        let e = error(&format!(
            "{QUAD_GEOMETRY}[[instances]]\ngeometry = \"quad\"\n{lambert}\nplaces = [{{}}]\ngrid = {{ count = [2, 1, 1], step = [1, 0, 0] }}\n"
        ));
        assert!(e.contains("not both"), "{e}");
        let e = error(&format!(
            "{QUAD_GEOMETRY}[[instances]]\ngeometry = \"quad\"\n{lambert}\ntranslate = [2e12, 0, 0]\n"
        ));
        assert!(e.contains("beyond"), "{e}");
        let e = error("[geometry.gone]\nfile = \"gone.ply\"\n");
        assert!(e.contains("test.toml:4") && e.contains("gone.ply"), "{e}");
    }

    #[test]
    fn a_file_too_big_for_memory_is_refused_before_reading() {
        let err = check_fits_in_memory(9 << 30, Some(8 << 30)).unwrap_err();
        assert!(
            err.contains("9216 MiB") && err.contains("8192 MiB available"),
            "{err}"
        );
        assert!(check_fits_in_memory(1 << 20, Some(8 << 30)).is_ok());
        assert!(
            check_fits_in_memory(u64::MAX, None).is_ok(),
            "unknown memory: no limit"
        );
        assert!(available_memory().is_none_or(|m| m > 0));
    }

    #[test]
    fn missing_camera_is_reported() {
        let e = parse_scene("name = \"no camera\"\n", "c.toml", &NoAssets)
            .unwrap_err()
            .to_string();
        assert!(e.contains("camera"), "{e}");
    }

    #[test]
    fn constant_background_and_settings_are_read() {
        let source =
            format!("background = [0.1, 0.2, 0.3]\n{CAMERA}[render]\nwidth = 32\nspp = 3\n");
        let scene = parse_scene(&source, "test.toml", &NoAssets).unwrap();
        assert_eq!(
            scene.background,
            Background::Constant(Vec3::new(0.1, 0.2, 0.3))
        );
        assert_eq!((scene.settings.width, scene.settings.spp), (32, 3));
        assert_eq!(scene.settings.height, RenderSettings::default().height);
    }

    #[test]
    fn integrator_and_roulette_are_read_and_checked() {
        let scene = parse("[render]\nintegrator = \"bsdf\"\nrussian_roulette = false\n").unwrap();
        assert_eq!(scene.settings.integrator, crate::scene::Integrator::Bsdf);
        assert!(!scene.settings.russian_roulette);
        let defaults = parse("").unwrap().settings;
        assert_eq!(defaults.integrator, crate::scene::Integrator::Path);
        assert!(defaults.russian_roulette);
        let e = error("[render]\nintegrator = \"photon\"\n");
        assert!(
            e.contains("test.toml:5") && e.contains("unknown integrator `photon`"),
            "{e}"
        );
    }

    #[test]
    fn the_sampler_is_read_and_checked() {
        use crate::rng::Sampler;
        let scene = parse("[render]\nsampler = \"independent\"\n").unwrap();
        assert_eq!(scene.settings.sampler, Sampler::Independent);
        assert_eq!(parse("").unwrap().settings.sampler, Sampler::Sobol);
        let e = error("[render]\nspp = 4\nsampler = \"halton\"\n");
        assert!(
            e.contains("test.toml:6") && e.contains("unknown sampler `halton`"),
            "{e}"
        );
    }

    #[test]
    fn environment_background_is_loaded_rotated_and_scaled() {
        let scene =
            parse_top("background = { environment = \"sky.hdr\", rotate = 90, strength = 3 }\n")
                .unwrap();
        let Background::Environment(map) = &scene.background else {
            panic!("{:?}", scene.background);
        };
        assert_eq!(map.size(), (4, 2));
        assert_eq!(map.source, "sky.hdr");
        // Pixel 5 (column 1, lower row) holds 2 x strength 3; the others 0.5 x 3.
        let values: Vec<f32> = (0..64)
            .map(|i| {
                let phi = i as f32 / 64.0 * std::f32::consts::TAU;
                map.radiance(Vec3::new(phi.cos(), -0.5, phi.sin())).x
            })
            .collect();
        assert!(values
            .iter()
            .all(|&v| (v - 1.5).abs() < 1e-3 || (v - 6.0).abs() < 1e-2));
        assert!(values.iter().any(|&v| (v - 6.0).abs() < 1e-2));
        // Turning the map moves its bright pixel.
        let turned =
            parse_top("background = { environment = \"sky.hdr\", rotate = 180 }\n").unwrap();
        let plain = parse_top("background = { environment = \"sky.hdr\" }\n").unwrap();
        let bright_from = |s: &Scene| {
            (0..64)
                .find(|i| {
                    let phi = *i as f32 / 64.0 * std::f32::consts::TAU;
                    s.background
                        .radiance(Vec3::new(phi.cos(), -0.5, phi.sin()))
                        .x
                        > 1.0
                })
                .unwrap()
        };
        assert_eq!(
            (bright_from(&turned) + 32) % 64 / 4,
            bright_from(&plain) / 4
        );
    }

    #[test]
    fn bad_environment_maps_are_errors_naming_the_file() {
        for (body, expected) in [
            (
                "{ environment = \"sky.png\" }",
                "must be a .hdr or .exr file",
            ),
            (
                "{ environment = \"missing.hdr\" }",
                "no such file missing.hdr",
            ),
            (
                "{ environment = \"nan.exr\" }",
                "`nan.exr`: pixel (1, 1) is not a finite colour",
            ),
            (
                "{ environment = \"sky.hdr\", strength = -1 }",
                "`strength` must be in",
            ),
            (
                "{ environment = \"sky.hdr\", rotate = [1, 2] }",
                "background",
            ),
            (
                "{ environment = \"sky.hdr\", spin = 3 }",
                "unknown field `spin`",
            ),
        ] {
            let e = parse_top(&format!("background = {body}\n"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("test.toml:1") && e.contains(expected),
                "{body}: {e}"
            );
        }
    }

    #[test]
    fn rotation_applies_x_then_y_then_z() {
        let q = rotation([90.0, 90.0, 0.0]);
        // x first takes +y to +z; then y takes +z to +x.
        assert!((q * Vec3::Y - Vec3::X).length() < 1e-6);
    }
}
