//! Scenes built in code (Rust callers, the Python `canopy_rt.Scene`), checked as the scene
//! file parser checks its entries: every call refuses what a scene file would, with a
//! message that names the argument at fault, and leaves the scene unchanged when it does.

use crate::background::{decode_environment, Background};
use crate::camera::CameraSpec;
use crate::geometry::{Cuboid, Shape, Sphere, Triangle};
use crate::material::Material;
use crate::mesh::MeshData;
use crate::scene::{MeshInstance, Primitive, Scene, SceneMesh};
use crate::scene_file::{instances::MAX_INSTANCES, MAX_COORDINATE, MAX_RADIANCE};
use crate::texture::MaterialMaps;
use canopy_bvh::{Aabb, Instance, TriangleMesh};
use glam::{Affine3A, EulerRot, Mat3, Quat, Vec3};
use std::path::Path;
use std::sync::Arc;

/// Finite and within [`MAX_COORDINATE`] in magnitude.
pub(crate) fn in_range(values: &[f32]) -> bool {
    values.iter().all(|v| v.abs() <= MAX_COORDINATE)
}

/// A radiance: every component in [0, MAX_RADIANCE].
pub(crate) fn radiance_ok(c: Vec3) -> bool {
    c.to_array()
        .iter()
        .all(|v| (0.0..=MAX_RADIANCE).contains(v))
}

/// Rotation by Euler angles in degrees: about x first, then y, then z.
pub fn rotation_from_degrees(degrees: [f32; 3]) -> Quat {
    let [x, y, z] = degrees.map(f32::to_radians);
    Quat::from_euler(EulerRot::ZYX, z, y, x)
}

impl CameraSpec {
    /// Why this camera cannot see, if it cannot.
    pub fn check(&self) -> Result<(), String> {
        let c = self;
        let numbers = [
            &c.look_from.to_array()[..],
            &c.look_at.to_array(),
            &c.up.to_array(),
            &[c.vfov, c.aperture],
        ]
        .concat();
        if !in_range(&numbers) || c.focus_distance.is_some_and(|f| !in_range(&[f])) {
            return Err(format!(
                "every number must be finite and within ±{MAX_COORDINATE:e}"
            ));
        }
        if c.look_from == c.look_at {
            return Err("`look_from` and `look_at` are the same point".into());
        }
        if c.up.cross(c.look_at - c.look_from).length_squared() == 0.0 {
            return Err("`up` is parallel to the viewing direction".into());
        }
        if !(c.vfov > 0.0 && c.vfov < 180.0) {
            return Err(format!(
                "`vfov` must be in (0, 180) degrees, not {}",
                c.vfov
            ));
        }
        if c.aperture < 0.0 || c.focus_distance.is_some_and(|f| f <= 0.0) {
            return Err("`aperture` must be >= 0 and `focus_distance` > 0".into());
        }
        match c.ortho_height {
            Some(h) if !(h > 0.0 && in_range(&[h])) => Err(format!(
                "`ortho_height` must be > 0 and within ±{MAX_COORDINATE:e}, not {h}"
            )),
            Some(_) if c.aperture > 0.0 => {
                Err("an orthographic camera has no lens: `aperture` must be 0".into())
            }
            _ => Ok(()),
        }?;
        Ok(())
    }
}

impl Material {
    /// Why this material is not physical, if it is not: a surface cannot reflect more
    /// light than it receives.
    pub fn check(&self) -> Result<(), String> {
        let colour =
            |name: &str, c: Vec3| match c.to_array().iter().all(|v| (0.0..=1.0).contains(v)) {
                true => Ok(()),
                false => Err(format!("`{name}` components must be in [0, 1], not {c}")),
            };
        let fraction = |name: &str, v: f32| match (0.0..=1.0).contains(&v) {
            true => Ok(()),
            false => Err(format!("`{name}` must be in [0, 1], not {v}")),
        };
        match *self {
            Material::Lambertian { albedo } => colour("albedo", albedo),
            Material::Metal { albedo, fuzz } => {
                colour("albedo", albedo).and_then(|()| fraction("fuzz", fuzz))
            }
            Material::Dielectric { ior } if !(ior.is_finite() && ior > 0.0) => {
                Err(format!("`ior` must be finite and > 0, not {ior}"))
            }
            Material::Dielectric { .. } => Ok(()),
            Material::Emissive { radiance } if !radiance_ok(radiance) => Err(format!(
                "`radiance` components must be in [0, {MAX_RADIANCE:e}], not {radiance}"
            )),
            Material::Emissive { .. } => Ok(()),
            Material::Pbr(p) if !radiance_ok(p.emission) => Err(format!(
                "`emission` components must be in [0, {MAX_RADIANCE:e}], not {}",
                p.emission
            )),
            Material::Pbr(p) => colour("base_color", p.base_color)
                .and_then(|()| fraction("metallic", p.metallic))
                .and_then(|()| fraction("roughness", p.roughness)),
        }
    }
}

impl Scene {
    /// Sets the camera, if it can see.
    pub fn set_camera(&mut self, camera: CameraSpec) -> Result<(), String> {
        camera.check()?;
        self.camera = camera;
        Ok(())
    }

    /// Lights the scene by an environment map (`.hdr` or `.exr`), rotated by Euler
    /// angles in degrees and scaled by `strength`; the file becomes an input of the scene.
    pub fn set_environment(
        &mut self,
        path: &Path,
        rotate_degrees: [f32; 3],
        strength: f32,
    ) -> Result<(), String> {
        if !rotate_degrees.iter().all(|d| d.is_finite()) {
            return Err("`rotate` must be finite".into());
        }
        if !(strength.is_finite() && (0.0..=MAX_RADIANCE).contains(&strength)) {
            return Err(format!("`strength` must be in [0, {MAX_RADIANCE:e}]"));
        }
        let name = path.display().to_string();
        let bytes =
            crate::files::read_regular_file(path, crate::background::MAX_ENVIRONMENT_PIXELS * 16)
                .map_err(|e| format!("`{name}`: {e}"))?;
        let to_world = Mat3::from_quat(rotation_from_degrees(rotate_degrees));
        let map = decode_environment(&name, &bytes, to_world, strength)?;
        self.background = Background::Environment(Arc::new(map));
        self.inputs.push(path.to_owned());
        Ok(())
    }

    /// Adds the glTF model at `path` (`.glb`, or `.gltf` with its buffers beside it, or in
    /// the folders `allowed`),
    /// placed by `to_world`: its meshes, materials and instances, and notes of what it
    /// uses that canopy does not read yet (see [`crate::gltf_scene`]). Returns its
    /// camera, placed, if it has one (the scene's camera is not changed). Changes
    /// nothing when it refuses the file.
    pub fn add_gltf(
        &mut self,
        path: &Path,
        to_world: Affine3A,
        allowed: &[std::path::PathBuf],
    ) -> Result<Option<crate::gltf_scene::ModelCamera>, String> {
        let name = path.display().to_string();
        let fail = |e: String| format!("`{name}`: {e}");
        let (assets, _) = crate::scene_file::DirAssets::beside(path);
        let assets = assets.allowing(allowed)?;
        let bytes = crate::scene_file::read_input_file(path).map_err(fail)?;
        let before = Appended::lengths(self);
        let added = crate::gltf_scene::add_gltf(self, &bytes, &assets, to_world);
        match added {
            Ok(camera) => {
                self.inputs.push(path.to_owned());
                Ok(camera)
            }
            Err(e) => {
                before.remove_from(self);
                Err(fail(e))
            }
        }
    }

    /// A uniform background of `radiance`.
    pub fn set_background_color(&mut self, radiance: Vec3) -> Result<(), String> {
        if !radiance_ok(radiance) {
            return Err(format!(
                "a background colour's components must be in [0, {MAX_RADIANCE:e}], not {radiance}"
            ));
        }
        self.background = Background::Constant(radiance);
        Ok(())
    }

    /// Adds a material; returns its index.
    pub fn add_material(&mut self, material: Material) -> Result<u32, String> {
        material.check()?;
        self.materials.push(material);
        Ok(self.materials.len() as u32 - 1)
    }

    fn check_material_index(&self, material: u32) -> Result<(), String> {
        if (material as usize) < self.materials.len() {
            Ok(())
        } else {
            Err(format!(
                "material {material} does not exist (the scene has {})",
                self.materials.len()
            ))
        }
    }

    fn push_primitive(&mut self, shape: Shape, material: u32) {
        Arc::make_mut(&mut self.primitives).push(Primitive { shape, material });
    }

    /// Adds a sphere of material `material` (an index from [`add_material`](Self::add_material)).
    pub fn add_sphere(&mut self, center: Vec3, radius: f32, material: u32) -> Result<(), String> {
        if !(in_range(&center.to_array()) && radius > 0.0 && radius <= MAX_COORDINATE) {
            return Err(format!(
                "`center` must be within ±{MAX_COORDINATE:e} and `radius` in (0, {MAX_COORDINATE:e}] (got {center}, {radius})"
            ));
        }
        self.check_material_index(material)?;
        self.push_primitive(Shape::Sphere(Sphere::new(center, radius)), material);
        Ok(())
    }

    /// Adds the box `min..max`, rotated by Euler angles in degrees (about x, then y, then
    /// z) and then translated.
    pub fn add_cuboid(
        &mut self,
        min: Vec3,
        max: Vec3,
        rotate_degrees: [f32; 3],
        translate: Vec3,
        material: u32,
    ) -> Result<(), String> {
        if !rotate_degrees.iter().all(|d| d.is_finite())
            || !in_range(&[min.to_array(), max.to_array(), translate.to_array()].concat())
        {
            return Err(format!(
                "every number must be finite, and positions within ±{MAX_COORDINATE:e}"
            ));
        }
        if min.cmpgt(max).any() {
            return Err("`min` must not exceed `max` on any axis".into());
        }
        self.check_material_index(material)?;
        let cuboid = Cuboid::new(
            Aabb::new(min, max),
            Mat3::from_quat(rotation_from_degrees(rotate_degrees)),
            translate,
        );
        self.push_primitive(Shape::Cuboid(cuboid), material);
        Ok(())
    }

    /// Adds a mesh to be placed by instances ([`add_instance`](Self::add_instance));
    /// returns its index. `normals` are per vertex (smooth shading) or empty (flat);
    /// `smooth` with no normals computes them. Triangles without area are left out (and
    /// counted, see [`Scene::warnings`]).
    pub fn add_mesh(
        &mut self,
        name: &str,
        vertices: Vec<Vec3>,
        triangles: Vec<[u32; 3]>,
        normals: Vec<Vec3>,
        smooth: bool,
    ) -> Result<u32, String> {
        if let Some(i) = vertices.iter().position(|p| !in_range(&p.to_array())) {
            return Err(format!(
                "vertex {i} lies at {}, beyond ±{MAX_COORDINATE:e}",
                vertices[i]
            ));
        }
        if !normals.is_empty() && normals.len() != vertices.len() {
            return Err(format!(
                "{} normals for {} vertices: give one per vertex, or none",
                normals.len(),
                vertices.len()
            ));
        }
        if let Some(i) = normals.iter().position(|n| !n.is_finite()) {
            return Err(format!("normal {i} is not finite ({})", normals[i]));
        }
        let mut data = MeshData {
            positions: vertices,
            normals,
            triangles,
        };
        if let Some(i) = data
            .triangles
            .iter()
            .position(|t| t.iter().any(|&v| v as usize >= data.positions.len()))
        {
            return Err(format!(
                "triangle {i} uses vertex {:?}, past the last of {} vertices",
                data.triangles[i],
                data.positions.len()
            ));
        }
        if smooth && data.normals.is_empty() {
            data.compute_vertex_normals();
        }
        let before = data.triangles.len();
        let positions = &data.positions;
        data.triangles.retain(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            Triangle::new(a, b, c).area() != 0.0
        });
        let skipped = before - data.triangles.len();
        let mesh = TriangleMesh::new(data.positions, data.triangles).map_err(|e| e.to_string())?;
        self.skipped_degenerate += skipped;
        self.meshes.push(SceneMesh {
            name: name.to_owned(),
            mesh: Arc::new(mesh),
            normals: data.normals,
            uvs: Vec::new(),
            tangents: Vec::new(),
        });
        Ok(self.meshes.len() as u32 - 1)
    }

    /// Gives mesh `mesh` texture coordinates, one per vertex.
    pub fn set_mesh_uvs(&mut self, mesh: u32, uvs: Vec<glam::Vec2>) -> Result<(), String> {
        let Some(target) = self.meshes.get_mut(mesh as usize) else {
            return Err(format!("mesh {mesh} does not exist"));
        };
        if uvs.len() != target.mesh.vertices().len() {
            return Err(format!(
                "{} texture coordinates for {} vertices",
                uvs.len(),
                target.mesh.vertices().len()
            ));
        }
        if let Some(i) = uvs.iter().position(|uv| !uv.is_finite()) {
            return Err(format!("texture coordinate {i} is not finite ({})", uvs[i]));
        }
        target.uvs = uvs;
        Ok(())
    }

    /// Adds a point, spot or directional light.
    pub fn add_light(&mut self, light: crate::lights::PunctualLight) -> Result<(), String> {
        light.check()?;
        self.lights.push(light);
        Ok(())
    }

    /// Adds a decoded image for textures to use; returns its index.
    pub fn add_image(&mut self, image: crate::texture::Image) -> u32 {
        self.images.push(Arc::new(image));
        self.images.len() as u32 - 1
    }

    /// Scales material `material`'s parameters by textures (see [`MaterialMaps`]).
    pub fn set_material_maps(&mut self, material: u32, maps: MaterialMaps) -> Result<(), String> {
        self.check_material_index(material)?;
        let normal = maps.normal.map(|n| n.texture);
        let textures = [
            maps.base_color,
            maps.metallic_roughness,
            normal,
            maps.emissive,
        ];
        for t in textures.iter().flatten() {
            if t.image as usize >= self.images.len() {
                return Err(format!("image {} does not exist", t.image));
            }
        }
        let i = material as usize;
        if self.material_maps.len() <= i {
            self.material_maps.resize(i + 1, MaterialMaps::default());
        }
        self.material_maps[i] = maps;
        Ok(())
    }

    /// Places mesh `mesh` by the affine transform `to_world` (any invertible one:
    /// rotations, mirrors, non-uniform scale); returns the instance's index.
    pub fn add_instance(
        &mut self,
        mesh: u32,
        to_world: Affine3A,
        material: u32,
    ) -> Result<u32, String> {
        let Some(local) = self
            .meshes
            .get(mesh as usize)
            .map(|m| m.mesh.bounding_box())
        else {
            return Err(format!(
                "mesh {mesh} does not exist (the scene has {})",
                self.meshes.len()
            ));
        };
        self.check_material_index(material)?;
        if self.instances.len() as u64 >= MAX_INSTANCES {
            return Err(format!("a scene holds at most {MAX_INSTANCES} instances"));
        }
        check_placement(local, to_world)?;
        self.instances.push(MeshInstance {
            mesh,
            to_world,
            material,
        });
        Ok(self.instances.len() as u32 - 1)
    }

    /// Moves mesh instance `instance` to `to_world` (a frame of an animation), checked
    /// as [`Scene::add_instance`] checks its transform.
    pub fn set_instance_transform(
        &mut self,
        instance: u32,
        to_world: Affine3A,
    ) -> Result<(), String> {
        let Some(placed) = self.instances.get(instance as usize) else {
            return Err(format!(
                "instance {instance} does not exist (the scene has {})",
                self.instances.len()
            ));
        };
        let local = self.meshes[placed.mesh as usize].mesh.bounding_box();
        check_placement(local, to_world)?;
        self.instances[instance as usize].to_world = to_world;
        Ok(())
    }
}

impl Scene {
    /// Why this scene cannot be rendered, if it cannot: the one check of a whole scene that
    /// every front end makes (scene files, glTF, meshes, built-in scenes, scenes built in
    /// code), so that what `canopy check` accepts, the renderer can build and render. The
    /// calls that build a scene check as they go; this sees the scene as it is now, after
    /// any field was changed directly.
    pub fn validate(&self) -> Result<(), String> {
        self.settings.check()?;
        self.camera.check().map_err(|e| format!("camera: {e}"))?;
        for (i, m) in self.materials.iter().enumerate() {
            m.check().map_err(|e| format!("material {i}: {e}"))?;
        }
        for (i, p) in self.primitives.iter().enumerate() {
            self.check_material_index(p.material)
                .map_err(|e| format!("primitive {i}: {e}"))?;
            let b = p.shape.bounds();
            if !in_range(&[b.min.to_array(), b.max.to_array()].concat()) {
                return Err(format!(
                    "primitive {i} reaches {} .. {}, beyond ±{MAX_COORDINATE:e}",
                    b.min, b.max
                ));
            }
        }
        if self.instances.len() as u64 > MAX_INSTANCES {
            return Err(format!("a scene holds at most {MAX_INSTANCES} instances"));
        }
        for (i, placed) in self.instances.iter().enumerate() {
            let Some(mesh) = self.meshes.get(placed.mesh as usize) else {
                return Err(format!(
                    "instance {i}: mesh {} does not exist (the scene has {})",
                    placed.mesh,
                    self.meshes.len()
                ));
            };
            self.check_material_index(placed.material)
                .map_err(|e| format!("instance {i}: {e}"))?;
            check_placement(mesh.mesh.bounding_box(), placed.to_world)
                .map_err(|e| format!("instance {i} of mesh `{}`: {e}", mesh.name))?;
        }
        Ok(())
    }
}

/// Why a mesh with box `local` cannot be placed by `to_world`: the one placement check of
/// scene files, glTF, Python and [`Scene::validate`].
pub(crate) fn check_placement(local: Aabb, to_world: Affine3A) -> Result<(), String> {
    let placed = Instance::new(0, to_world);
    placed.check(0).map_err(|e| match e {
        canopy_bvh::InstanceError::Singular { determinant, .. } => format!(
            "the transform is not invertible (its determinant is {determinant:e}; is a scale zero or tiny?)"
        ),
        _ => "the transform is not finite".to_string(),
    })?;
    let world = placed.world_bounds(local);
    if !local.is_empty() && !in_range(&[world.min.to_array(), world.max.to_array()].concat()) {
        return Err(format!(
            "the instance reaches {} .. {}, beyond ±{MAX_COORDINATE:e}",
            world.min, world.max
        ));
    }
    Ok(())
}

/// How long each list a loader appends to was, so that a failed load can be undone.
struct Appended {
    meshes: usize,
    materials: usize,
    instances: usize,
    inputs: usize,
    notes: usize,
    images: usize,
    material_maps: usize,
    lights: usize,
    skipped_degenerate: usize,
}

impl Appended {
    fn lengths(scene: &Scene) -> Self {
        Self {
            meshes: scene.meshes.len(),
            materials: scene.materials.len(),
            instances: scene.instances.len(),
            inputs: scene.inputs.len(),
            notes: scene.notes.len(),
            images: scene.images.len(),
            material_maps: scene.material_maps.len(),
            lights: scene.lights.len(),
            skipped_degenerate: scene.skipped_degenerate,
        }
    }

    /// Removes what was appended to `scene` since.
    fn remove_from(self, scene: &mut Scene) {
        scene.meshes.truncate(self.meshes);
        scene.materials.truncate(self.materials);
        scene.instances.truncate(self.instances);
        scene.inputs.truncate(self.inputs);
        scene.notes.truncate(self.notes);
        scene.images.truncate(self.images);
        scene.material_maps.truncate(self.material_maps);
        scene.lights.truncate(self.lights);
        scene.skipped_degenerate = self.skipped_degenerate;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey(scene: &mut Scene) -> u32 {
        scene
            .add_material(Material::Lambertian {
                albedo: Vec3::splat(0.5),
            })
            .unwrap()
    }

    #[test]
    fn a_scene_built_in_code_is_checked_call_by_call() {
        let mut scene = Scene::default();
        let m = grey(&mut scene);
        assert!(scene
            .add_material(Material::Lambertian {
                albedo: Vec3::splat(1.5)
            })
            .unwrap_err()
            .contains("[0, 1]"));
        scene.add_sphere(Vec3::ZERO, 1.0, m).unwrap();
        assert!(scene
            .add_sphere(Vec3::ZERO, -1.0, m)
            .unwrap_err()
            .contains("radius"));
        assert!(scene
            .add_sphere(Vec3::ZERO, 1.0, 7)
            .unwrap_err()
            .contains("material 7"));
        scene
            .add_cuboid(Vec3::ZERO, Vec3::ONE, [0.0, 45.0, 0.0], Vec3::X, m)
            .unwrap();
        assert!(scene
            .add_cuboid(Vec3::ONE, Vec3::ZERO, [0.0; 3], Vec3::ZERO, m)
            .unwrap_err()
            .contains("`min`"));
        assert_eq!(scene.primitives.len(), 2, "refused calls add nothing");

        let square = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE, Vec3::ZERO];
        let mesh = scene
            .add_mesh(
                "quad",
                square.clone(),
                vec![[0, 1, 2], [1, 3, 2], [0, 4, 1]],
                vec![],
                true,
            )
            .unwrap();
        assert_eq!(
            scene.meshes[0].mesh.indices().len(),
            2,
            "the degenerate one is left out"
        );
        assert_eq!(scene.skipped_degenerate, 1);
        assert_eq!(scene.meshes[0].normals.len(), 5, "smooth: normals computed");
        assert!(scene
            .add_mesh("bad", square.clone(), vec![[0, 1, 9]], vec![], false)
            .unwrap_err()
            .contains("triangle 0"));
        assert!(scene
            .add_mesh("bad", square, vec![[0, 1, 2]], vec![Vec3::Z], false)
            .unwrap_err()
            .contains("1 normals for 5 vertices"));

        let mirror = Affine3A::from_scale(Vec3::new(-1.0, 2.0, 1.0));
        assert_eq!(scene.add_instance(mesh, mirror, m), Ok(0));
        let flat = Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0));
        assert!(scene
            .add_instance(mesh, flat, m)
            .unwrap_err()
            .contains("invertible"));
        assert!(scene
            .add_instance(3, Affine3A::IDENTITY, m)
            .unwrap_err()
            .contains("mesh 3"));
        let far = Affine3A::from_translation(Vec3::splat(2e12));
        assert!(scene
            .add_instance(mesh, far, m)
            .unwrap_err()
            .contains("beyond"));
        assert_eq!(scene.instances.len(), 1);

        let blind = CameraSpec {
            look_at: scene.camera.look_from,
            ..scene.camera
        };
        assert!(scene.set_camera(blind).unwrap_err().contains("same point"));
        assert!(scene
            .set_background_color(Vec3::new(1.0, -1.0, 0.0))
            .is_err());
        let missing = scene.set_environment(Path::new("/no/such/sky.hdr"), [0.0; 3], 1.0);
        assert!(missing.unwrap_err().contains("sky.hdr"));
    }
}
