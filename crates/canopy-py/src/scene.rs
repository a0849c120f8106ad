//! `canopy_rt._canopy.Scene`: a scene built from Python calls (the Python class
//! `canopy_rt.Scene` wraps it), each checked as the scene file parser checks its entries.

use crate::arrays;
use crate::render::SceneInfo;
use canopy_render::camera::CameraSpec;
use canopy_render::material::{Material, Pbr};
use canopy_render::{Background, Scene};
use glam::Vec3;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyDictMethods};

/// A scene under construction: geometry, instances, materials, camera, background and
/// render settings.
#[pyclass(module = "canopy_rt._canopy", name = "Scene")]
pub struct PyScene {
    pub scene: Scene,
}

/// `what: problem` as a ValueError.
fn refused(what: &str) -> impl Fn(String) -> PyErr + '_ {
    move |problem| PyValueError::new_err(format!("{what}: {problem}"))
}

/// A material from its table form, as a scene file writes it: `{"type": "metal",
/// "albedo": [r, g, b], "fuzz": 0.1}`.
fn material_from_dict(table: &Bound<'_, PyDict>) -> PyResult<Material> {
    let bad = |message: String| PyValueError::new_err(format!("material: {message}"));
    let kind: String = table
        .get_item("type")?
        .ok_or_else(|| {
            bad("needs a `type` (lambertian, metal, dielectric, emissive or pbr)".into())
        })?
        .extract()
        .map_err(|_| bad("`type` must be a string".into()))?;
    let allowed: &[&str] = match kind.as_str() {
        "lambertian" => &["type", "albedo"],
        "metal" => &["type", "albedo", "fuzz"],
        "dielectric" => &["type", "ior"],
        "emissive" => &["type", "radiance"],
        "pbr" => &["type", "base_color", "metallic", "roughness", "emission"],
        other => {
            return Err(bad(format!(
                "unknown type `{other}` (lambertian, metal, dielectric, emissive or pbr)"
            )))
        }
    };
    for key in table.keys() {
        let key: String = key.extract()?;
        if !allowed.contains(&key.as_str()) {
            return Err(bad(format!(
                "a {kind} material has no `{key}` (it takes {})",
                allowed[1..].join(", ")
            )));
        }
    }
    let colour = |key: &str| -> PyResult<Vec3> {
        let value = table
            .get_item(key)?
            .ok_or_else(|| bad(format!("a {kind} material needs `{key}`")))?;
        let c: [f32; 3] = value
            .extract()
            .map_err(|_| bad(format!("`{key}` must be three numbers")))?;
        Ok(c.into())
    };
    let number = |key: &str, default: Option<f32>| -> PyResult<f32> {
        match (table.get_item(key)?, default) {
            (Some(v), _) => v
                .extract()
                .map_err(|_| bad(format!("`{key}` must be a number"))),
            (None, Some(d)) => Ok(d),
            (None, None) => Err(bad(format!("a {kind} material needs `{key}`"))),
        }
    };
    Ok(match kind.as_str() {
        "lambertian" => Material::Lambertian {
            albedo: colour("albedo")?,
        },
        "metal" => Material::Metal {
            albedo: colour("albedo")?,
            fuzz: number("fuzz", Some(0.0))?,
        },
        "dielectric" => Material::Dielectric {
            ior: number("ior", None)?,
        },
        "pbr" => Material::Pbr(Pbr {
            base_color: colour("base_color")?,
            metallic: number("metallic", Some(0.0))?,
            roughness: number("roughness", Some(1.0))?,
            emission: match table.get_item("emission")? {
                Some(_) => colour("emission")?,
                None => Vec3::ZERO,
            },
        }),
        _ => Material::Emissive {
            radiance: colour("radiance")?,
        },
    })
}

/// A material argument: an index from `add_material`, or a table added with the call
/// that names it (and only if that call succeeds).
#[derive(FromPyObject)]
pub enum MaterialArg<'py> {
    Index(u32),
    Table(Bound<'py, PyDict>),
}

impl PyScene {
    /// Runs `add` with the index of `material`, added first when it is a table; when
    /// `add` refuses, the scene is left as it was (the table's material and any
    /// primitives `add` pushed removed again).
    fn with_material<T>(
        &mut self,
        material: MaterialArg<'_>,
        what: &str,
        add: impl FnOnce(&mut Scene, u32) -> Result<T, String>,
    ) -> PyResult<T> {
        let (materials, primitives) = (self.scene.materials.len(), self.scene.primitives.len());
        let index = match material {
            MaterialArg::Index(i) => i,
            MaterialArg::Table(table) => {
                let material = material_from_dict(&table)?;
                self.scene
                    .add_material(material)
                    .map_err(refused("material"))?
            }
        };
        add(&mut self.scene, index).map_err(|problem| {
            self.scene.materials.truncate(materials);
            if self.scene.primitives.len() > primitives {
                std::sync::Arc::make_mut(&mut self.scene.primitives).truncate(primitives);
            }
            PyValueError::new_err(format!("{what}: {problem}"))
        })
    }
}

#[pymethods]
impl PyScene {
    #[new]
    #[pyo3(signature = (name=""))]
    fn new(name: &str) -> Self {
        Self {
            scene: Scene {
                name: name.to_owned(),
                ..Scene::default()
            },
        }
    }

    #[pyo3(signature = (width, height, spp, max_depth, seed, integrator, russian_roulette, sampler="sobol"))]
    #[allow(clippy::too_many_arguments)]
    fn set_settings(
        &mut self,
        width: u32,
        height: u32,
        spp: u32,
        max_depth: u32,
        seed: u64,
        integrator: &str,
        russian_roulette: bool,
        sampler: &str,
    ) -> PyResult<()> {
        let settings = canopy_render::RenderSettings {
            width,
            height,
            spp,
            max_depth,
            seed,
            integrator: integrator.parse().map_err(PyValueError::new_err)?,
            russian_roulette,
            sampler: sampler.parse().map_err(PyValueError::new_err)?,
        };
        settings.check().map_err(refused("settings"))?;
        self.scene.settings = settings;
        Ok(())
    }

    #[pyo3(signature = (look_from, look_at, up, vfov, aperture, focus_distance=None, ortho_height=None))]
    #[allow(clippy::too_many_arguments)]
    fn set_camera(
        &mut self,
        look_from: [f32; 3],
        look_at: [f32; 3],
        up: [f32; 3],
        vfov: f32,
        aperture: f32,
        focus_distance: Option<f32>,
        ortho_height: Option<f32>,
    ) -> PyResult<()> {
        let camera = CameraSpec {
            look_from: look_from.into(),
            look_at: look_at.into(),
            up: up.into(),
            vfov,
            aperture,
            focus_distance,
            ortho_height,
        };
        self.scene.set_camera(camera).map_err(refused("camera"))
    }

    fn set_sky(&mut self) {
        self.scene.background = Background::Sky;
    }

    fn set_background_color(&mut self, radiance: [f32; 3]) -> PyResult<()> {
        self.scene
            .set_background_color(radiance.into())
            .map_err(refused("background"))
    }

    fn set_environment(
        &mut self,
        py: Python<'_>,
        path: std::path::PathBuf,
        rotate: [f32; 3],
        strength: f32,
    ) -> PyResult<()> {
        let scene = &mut self.scene;
        py.detach(|| scene.set_environment(&path, rotate, strength))
            .map_err(refused("background"))
    }

    /// Adds a material given as a dict (see `canopy.lambertian` and friends); returns
    /// its index.
    fn add_material(&mut self, material: &Bound<'_, PyDict>) -> PyResult<u32> {
        let material = material_from_dict(material)?;
        self.scene
            .add_material(material)
            .map_err(refused("material"))
    }

    /// Adds a point light, or a spot light where `spot` gives (direction, inner and
    /// outer cone angles in degrees).
    #[pyo3(signature = (position, intensity, spot=None))]
    fn add_point_light(
        &mut self,
        position: [f32; 3],
        intensity: [f32; 3],
        spot: Option<([f32; 3], f32, f32)>,
    ) -> PyResult<()> {
        use canopy_render::lights::PunctualLight;
        let light = match spot {
            None => PunctualLight::Point {
                position: position.into(),
                intensity: intensity.into(),
            },
            Some((direction, inner, outer)) => PunctualLight::Spot {
                position: position.into(),
                direction: Vec3::from(direction).try_normalize().ok_or_else(|| {
                    PyValueError::new_err("add_spot_light: `direction` must be finite and not zero")
                })?,
                intensity: intensity.into(),
                cos_inner: inner.to_radians().cos(),
                cos_outer: outer.to_radians().cos(),
            },
        };
        let what = if spot.is_some() {
            "add_spot_light"
        } else {
            "add_point_light"
        };
        self.scene.add_light(light).map_err(refused(what))
    }

    /// Adds light from infinitely far away travelling along `direction`.
    fn add_directional_light(&mut self, direction: [f32; 3], irradiance: [f32; 3]) -> PyResult<()> {
        let direction = Vec3::from(direction).try_normalize().ok_or_else(|| {
            PyValueError::new_err("add_directional_light: `direction` must be finite and not zero")
        })?;
        self.scene
            .add_light(canopy_render::lights::PunctualLight::Directional {
                direction,
                irradiance: irradiance.into(),
            })
            .map_err(refused("add_directional_light"))
    }

    fn add_sphere(
        &mut self,
        center: [f32; 3],
        radius: f32,
        material: MaterialArg<'_>,
    ) -> PyResult<()> {
        self.with_material(material, "add_sphere", |scene, m| {
            scene.add_sphere(center.into(), radius, m)
        })
    }

    /// Adds many spheres of one material; all or none (the first bad one is named).
    fn add_spheres(
        &mut self,
        centers: PyReadonlyArray2<'_, f32>,
        radii: PyReadonlyArray1<'_, f32>,
        material: MaterialArg<'_>,
    ) -> PyResult<()> {
        let centers = arrays::points("centers", &centers)?;
        let radii = radii
            .as_slice()
            .map_err(|_| PyValueError::new_err("radii must be C-contiguous"))?;
        if radii.len() != centers.len() {
            return Err(PyValueError::new_err(format!(
                "{} radii for {} centers: give one radius per sphere",
                radii.len(),
                centers.len()
            )));
        }
        self.with_material(material, "add_spheres", |scene, m| {
            for (i, (&c, &r)) in centers.iter().zip(radii).enumerate() {
                scene
                    .add_sphere(c.into(), r, m)
                    .map_err(|e| format!("sphere {i}: {e}"))?;
            }
            Ok(())
        })
    }

    fn add_box(
        &mut self,
        min: [f32; 3],
        max: [f32; 3],
        rotate: [f32; 3],
        translate: [f32; 3],
        material: MaterialArg<'_>,
    ) -> PyResult<()> {
        self.with_material(material, "add_box", |scene, m| {
            scene.add_cuboid(min.into(), max.into(), rotate, translate.into(), m)
        })
    }

    /// Adds a mesh and places one instance of it by `transform` (a (3, 4) float32
    /// matrix) with `material`; returns the mesh's index and the material's. Both or
    /// neither: a refused instance takes its mesh away again.
    #[pyo3(signature = (name, vertices, faces, normals, smooth, transform, material))]
    #[allow(clippy::too_many_arguments)]
    fn add_mesh(
        &mut self,
        py: Python<'_>,
        name: &str,
        vertices: PyReadonlyArray2<'_, f32>,
        faces: PyReadonlyArray2<'_, i64>,
        normals: Option<PyReadonlyArray2<'_, f32>>,
        smooth: bool,
        transform: PyReadonlyArray2<'_, f32>,
        material: MaterialArg<'_>,
    ) -> PyResult<(u32, u32)> {
        let to_world = arrays::affine(&transform)?;
        let positions: Vec<Vec3> = arrays::points("vertices", &vertices)?
            .iter()
            .map(|&p| p.into())
            .collect();
        let triangles: Vec<[u32; 3]> = arrays::faces(&faces, positions.len())?
            .iter()
            .map(|f| f.map(|i| i as u32))
            .collect();
        let normals: Vec<Vec3> = match &normals {
            Some(n) => arrays::points("normals", n)?
                .iter()
                .map(|&p| p.into())
                .collect(),
            None => Vec::new(),
        };
        let skipped = self.scene.skipped_degenerate;
        let scene = &mut self.scene;
        let mesh = py
            .detach(|| scene.add_mesh(name, positions, triangles, normals, smooth))
            .map_err(|e| PyValueError::new_err(format!("add_mesh `{name}`: {e}")))?;
        let placed = self.with_material(material, "add_mesh", |scene, m| {
            scene.add_instance(mesh, to_world, m).map(|_| m)
        });
        if placed.is_err() {
            self.scene.meshes.pop();
            self.scene.skipped_degenerate = skipped;
        }
        Ok((mesh, placed?))
    }

    /// Places mesh `mesh` by `transform` (a (3, 4) float32 matrix); returns the
    /// instance's index.
    fn add_instance(
        &mut self,
        mesh: u32,
        transform: PyReadonlyArray2<'_, f32>,
        material: MaterialArg<'_>,
    ) -> PyResult<u32> {
        let to_world = arrays::affine(&transform)?;
        self.with_material(material, "add_instance", |scene, m| {
            scene.add_instance(mesh, to_world, m)
        })
    }

    /// Adds the glTF model at `path`, placed by `transform` (a (3, 4) float32 matrix),
    /// its buffers and images read from its folder or those of `allow_paths`; returns
    /// how many instances it placed. Changes nothing when the file is refused.
    fn add_gltf(
        &mut self,
        py: Python<'_>,
        path: std::path::PathBuf,
        transform: PyReadonlyArray2<'_, f32>,
        allow_paths: Vec<std::path::PathBuf>,
    ) -> PyResult<usize> {
        let to_world = arrays::affine(&transform)?;
        let scene = &mut self.scene;
        let before = scene.instances.len();
        py.detach(|| scene.add_gltf(&path, to_world, &allow_paths))
            .map_err(refused("add_gltf"))?;
        Ok(self.scene.instances.len() - before)
    }

    /// The scene described, as `canopy.load_scene` describes a file.
    fn info(&self) -> SceneInfo {
        SceneInfo::new(self.scene.clone())
    }

    fn __repr__(&self) -> String {
        let s = &self.scene;
        format!(
            "Scene(name={:?}, {} primitives, {} meshes, {} instances, {} materials, {}x{}, {} spp)",
            s.name,
            s.primitives.len(),
            s.meshes.len(),
            s.instances.len(),
            s.materials.len(),
            s.settings.width,
            s.settings.height,
            s.settings.spp
        )
    }
}

type Values<'py> = Bound<'py, numpy::PyArray2<f32>>;
type Densities<'py> = Bound<'py, numpy::PyArray1<f32>>;

/// A material's BSDF times the cosine, and its sampling density, for the direction pairs
/// `wo[i]` (to the viewer) and `wi[i]` (to the light), unit vectors in the surface's frame
/// (normal +z).
#[pyfunction]
pub fn eval_material<'py>(
    py: Python<'py>,
    material: &Bound<'py, PyDict>,
    wo: PyReadonlyArray2<'py, f32>,
    wi: PyReadonlyArray2<'py, f32>,
) -> PyResult<(Values<'py>, Densities<'py>)> {
    let material = material_from_dict(material)?;
    material
        .check()
        .map_err(|e| PyValueError::new_err(format!("material: {e}")))?;
    let (wo, wi) = (arrays::points("wo", &wo)?, arrays::points("wi", &wi)?);
    if wo.len() != wi.len() {
        return Err(PyValueError::new_err(format!(
            "wo has {} rows and wi {}; they pair up row by row",
            wo.len(),
            wi.len()
        )));
    }
    let surface = canopy_render::geometry::Surface {
        p: Vec3::ZERO,
        geometric_normal: Vec3::Z,
        shading_normal: Vec3::Z,
        error: 0.0,
    };
    let (values, pdfs): (Vec<[f32; 3]>, Vec<f32>) = wo
        .iter()
        .zip(wi)
        .map(|(&o, &i)| {
            let (dir, wi) = (-Vec3::from(o).normalize(), Vec3::from(i).normalize());
            let value = material.eval(dir, &surface, wi);
            (value.to_array(), material.pdf(dir, &surface, wi))
        })
        .unzip();
    let values =
        numpy::PyArray2::from_vec2(py, &values.iter().map(|v| v.to_vec()).collect::<Vec<_>>())?;
    Ok((values, numpy::PyArray1::from_vec(py, pdfs)))
}
