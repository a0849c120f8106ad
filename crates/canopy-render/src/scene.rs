//! The validated, in-memory scene that the integrator renders.

pub use crate::background::Background;
use crate::camera::CameraSpec;
use crate::geometry::{Shape, Surface, Triangle};
use crate::lights::PunctualLight;
use crate::material::Material;
use crate::rng::Sampler;
use crate::texture::{Image, MaterialMaps, NormalMap};
use canopy_bvh::{Aabb, Hit, Ray, TriangleMesh};
use glam::{Affine3A, Vec2, Vec3, Vec4};
use std::path::PathBuf;
use std::sync::Arc;

/// How the radiance of a pixel sample is estimated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Integrator {
    /// Path tracing with light sampling (next-event estimation) and multiple importance
    /// sampling against the BSDF, with Russian roulette when the settings allow.
    #[default]
    Path,
    /// The report's estimator: follow the BSDF and count light only where a path happens
    /// to hit it. No light sampling, no Russian roulette.
    Bsdf,
}

impl Integrator {
    pub const ALL: [Integrator; 2] = [Integrator::Path, Integrator::Bsdf];

    pub fn name(self) -> &'static str {
        match self {
            Integrator::Path => "path",
            Integrator::Bsdf => "bsdf",
        }
    }
}

impl std::fmt::Display for Integrator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Integrator {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Integrator::ALL
            .into_iter()
            .find(|i| i.name() == s)
            .ok_or_else(|| format!("unknown integrator `{s}`, expected one of: path, bsdf"))
    }
}

/// How an image is rendered; a scene file gives defaults, the command line overrides.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Most ray segments per path, the camera ray included (the report's "bounces").
    pub max_depth: u32,
    pub seed: u64,
    pub integrator: Integrator,
    /// Let the path integrator end paths at random after a few bounces, weighting the
    /// survivors up (unbiased; saves time on long, dim paths).
    pub russian_roulette: bool,
    /// How each sample's random numbers are made (see [`Sampler`]).
    pub sampler: Sampler,
}

impl RenderSettings {
    /// Most pixels an image may have (the film takes 12 bytes per pixel).
    pub const MAX_PIXELS: u64 = 1 << 28;
    /// Most ray segments per path.
    pub const MAX_DEPTH: u32 = 1024;
    /// Most samples per pixel (16M: days of rendering at any size).
    pub const MAX_SPP: u32 = 1 << 24;

    /// Why these settings cannot be rendered, if they cannot.
    pub fn check(&self) -> Result<(), String> {
        let pixels = self.width as u64 * self.height as u64;
        if pixels == 0 {
            return Err(format!(
                "image size {}x{} is empty",
                self.width, self.height
            ));
        }
        if pixels > Self::MAX_PIXELS {
            return Err(format!(
                "image size {}x{} is too large: at most {} pixels (this one would need {} MiB of film)",
                self.width,
                self.height,
                Self::MAX_PIXELS,
                (pixels * 12) >> 20
            ));
        }
        if !(1..=Self::MAX_SPP).contains(&self.spp) {
            return Err(format!("spp {} is outside 1..={}", self.spp, Self::MAX_SPP));
        }
        if !(1..=Self::MAX_DEPTH).contains(&self.max_depth) {
            return Err(format!(
                "max_depth {} is outside 1..={} (a path needs at least its camera ray)",
                self.max_depth,
                Self::MAX_DEPTH
            ));
        }
        Ok(())
    }

    /// Bytes of film the render needs.
    pub fn film_bytes(&self) -> u64 {
        self.width as u64 * self.height as u64 * 12
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 480,
            height: 480,
            spp: 64,
            max_depth: 8,
            seed: 0,
            integrator: Integrator::Path,
            russian_roulette: true,
            sampler: Sampler::Sobol,
        }
    }
}

/// A triangle mesh stored once, placed in the world by [`MeshInstance`]s.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneMesh {
    /// The name instances refer to it by.
    pub name: String,
    /// Shared with the acceleration structure, which tests it without a copy.
    pub mesh: Arc<TriangleMesh>,
    /// Per-vertex normals for smooth shading: empty (flat), or one per vertex.
    pub normals: Vec<Vec3>,
    /// Per-vertex texture coordinates: empty, or one per vertex.
    pub uvs: Vec<Vec2>,
    /// Tangent (xyz) and bitangent sign (w) at each corner of each triangle, for normal
    /// maps: empty, or one triple per triangle.
    pub tangents: Vec<[Vec4; 3]>,
}

/// A mesh placed in the world: by an affine transform (mirrors and non-uniform scale
/// allowed), with one material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshInstance {
    /// Index into [`Scene::meshes`].
    pub mesh: u32,
    pub to_world: Affine3A,
    pub material: u32,
}

/// Which part of a scene an instance index of a hit ([`Hit::inst`]) names: 0 is the
/// scene's own primitives, `k + 1` its mesh instance `k`.
pub const PRIMITIVES_INSTANCE: u32 = 0;

/// One shape with its material.
#[derive(Clone, Debug, PartialEq)]
pub struct Primitive {
    pub shape: Shape,
    pub material: u32,
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    pub name: String,
    pub description: String,
    pub camera: CameraSpec,
    pub settings: RenderSettings,
    pub background: Background,
    pub materials: Vec<Material>,
    /// Shapes placed in the world as they are (spheres, cuboids, mesh triangles baked
    /// into world space); shared with the acceleration structure, which tests them
    /// without a copy.
    pub primitives: Arc<Vec<Primitive>>,
    /// Vertex normals of smooth triangles, indexed by `Triangle::normals`.
    pub vertex_normals: Vec<[Vec3; 3]>,
    /// Meshes stored once, placed by `instances`.
    pub meshes: Vec<SceneMesh>,
    pub instances: Vec<MeshInstance>,
    /// Mesh triangles left out because they have no area (they can never be hit).
    pub skipped_degenerate: usize,
    /// The files the scene was read from (scene file, meshes): never to be written over.
    pub inputs: Vec<PathBuf>,
    /// What a loader left out or read only in part (a model's textures, say), one
    /// sentence each; reported with the warnings.
    pub notes: Vec<String>,
    /// Images textures read, shared by every material that uses them.
    pub images: Vec<Arc<Image>>,
    /// The textures of material `i`, where `i` is in range and it has any.
    pub material_maps: Vec<MaterialMaps>,
    /// Lights without area (point, spot, directional), beside the emissive surfaces.
    pub lights: Vec<PunctualLight>,
}

impl Scene {
    /// Bounding box of every primitive, in primitive order (the BVH builders' input).
    pub fn primitive_bounds(&self) -> Vec<Aabb> {
        self.primitives.iter().map(|p| p.shape.bounds()).collect()
    }

    /// Box of everything in the world: primitives and mesh instances.
    pub fn bounds(&self) -> Aabb {
        let primitives = self.primitives.iter().map(|p| p.shape.bounds());
        // Each mesh's box once, however many instances place it.
        let local: Vec<Aabb> = self.meshes.iter().map(|m| m.mesh.bounding_box()).collect();
        let instances = self
            .instances
            .iter()
            .map(|i| canopy_bvh::Instance::new(0, i.to_world).world_bounds(local[i.mesh as usize]));
        primitives.chain(instances).fold(Aabb::EMPTY, Aabb::union)
    }

    /// The mesh instance a hit's instance index names, if it names one (not the
    /// scene's own primitives).
    #[inline]
    pub fn instance_of(&self, inst: u32) -> Option<&MeshInstance> {
        inst.checked_sub(1).map(|k| &self.instances[k as usize])
    }

    /// Triangle `prim` of mesh instance `instance` in world space.
    pub fn instance_triangle(&self, instance: &MeshInstance, prim: u32) -> Triangle {
        let local = self.meshes[instance.mesh as usize].mesh.vertices_of(prim);
        // The identity (a bare mesh file) is common: no transforms.
        let [a, b, c] = match instance.to_world == Affine3A::IDENTITY {
            true => local,
            false => local.map(|v| instance.to_world.transform_point3(v)),
        };
        Triangle::new(a, b, c)
    }

    /// The vertex normals of triangle `prim` of mesh instance `instance` in world space;
    /// `None` for a flat mesh.
    pub fn instance_normals(&self, instance: &MeshInstance, prim: u32) -> Option<[Vec3; 3]> {
        let mesh = &self.meshes[instance.mesh as usize];
        if mesh.normals.is_empty() {
            return None;
        }
        let indices = mesh.mesh.indices()[prim as usize];
        let normals = indices.map(|i| mesh.normals[i as usize]);
        let world = match instance.to_world == Affine3A::IDENTITY {
            true => normals,
            false => {
                let to_normal = instance.to_world.matrix3.inverse().transpose();
                normals.map(|n| to_normal * n)
            }
        };
        Some(world.map(Vec3::normalize_or_zero))
    }

    /// The surface where `ray` hits and the material there (`hit` from a query of `ray`
    /// on the scene's structure, [`crate::Accel`]).
    #[inline]
    pub fn hit_surface(&self, ray: &Ray, hit: &Hit) -> (Surface, u32) {
        match self.instance_of(hit.inst) {
            None => {
                let primitive = &self.primitives[hit.prim as usize];
                let surface = primitive.shape.surface(ray, hit, &self.vertex_normals);
                (surface, primitive.material)
            }
            Some(instance) => {
                let triangle = self.instance_triangle(instance, hit.prim);
                let normals = self.instance_normals(instance, hit.prim);
                let surface = triangle.surface_with_normals(hit.u, hit.v, normals.as_ref());
                (surface, instance.material)
            }
        }
    }

    /// Starts loading the record of the primitive `hit` names (not in an instance), which
    /// [`Scene::shade`] reads first: a stage that shades many hits in turn asks for the
    /// records of hits a few ahead, so that each is in the cache when its turn comes. A
    /// hint: it changes no result.
    #[inline(always)]
    pub fn prefetch_primitive(&self, hit: &Hit) {
        if hit.inst != 0 {
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(primitive) = self.primitives.get(hit.prim as usize) {
            let first = std::ptr::from_ref(primitive).cast::<i8>();
            let last = first.wrapping_add(std::mem::size_of::<Primitive>() - 1);
            // SAFETY: SSE is baseline x86-64, and a prefetch reads nothing the program
            // sees. A record may span two cache lines: both are asked for.
            unsafe {
                use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
                _mm_prefetch::<_MM_HINT_T0>(first);
                _mm_prefetch::<_MM_HINT_T0>(last);
            }
        }
    }

    /// The surface where `ray` hits and its material there, textures applied (where
    /// the surface has texture coordinates; without them a material is its factors).
    #[inline]
    pub fn shade(&self, ray: &Ray, hit: &Hit) -> (Surface, Material) {
        let (mut surface, index) = self.hit_surface(ray, hit);
        let material = self.materials[index as usize];
        let Some(maps) = self
            .material_maps
            .get(index as usize)
            .filter(|m| !m.is_empty())
        else {
            return (surface, material);
        };
        let Some(uv) = self.hit_uv(hit) else {
            return (surface, material);
        };
        if let Some(map) = &maps.normal {
            if let Some(bent) = self.normal_mapped(map, hit, uv, &surface) {
                surface.shading_normal = bent;
            }
        }
        (surface, maps.apply(material, &self.images, uv))
    }

    /// The shading normal at `hit` bent by `map`, where the mesh has tangents and the
    /// bent normal stays on the side of the surface the shading normal is on.
    fn normal_mapped(
        &self,
        map: &NormalMap,
        hit: &Hit,
        uv: Vec2,
        surface: &Surface,
    ) -> Option<Vec3> {
        let instance = self.instance_of(hit.inst)?;
        let mesh = &self.meshes[instance.mesh as usize];
        let corners = mesh.tangents.get(hit.prim as usize)?;
        let weights = [1.0 - hit.u - hit.v, hit.u, hit.v];
        let tangent: Vec3 = (0..3).map(|i| weights[i] * corners[i].truncate()).sum();
        // The bitangent in the mesh's own space, from its own normal there, so that the
        // instance's transform (mirrors included) carries both as it carries the mesh.
        let indices = mesh.mesh.indices()[hit.prim as usize];
        let local_normal = match mesh.normals.is_empty() {
            true => {
                let [a, b, c] = indices.map(|i| mesh.mesh.vertices()[i as usize]);
                (b - a).cross(c - a)
            }
            false => (0..3)
                .map(|i| weights[i] * mesh.normals[indices[i] as usize])
                .sum(),
        };
        let bitangent = corners[0].w * local_normal.normalize_or_zero().cross(tangent);
        let to_world = instance.to_world.matrix3;
        let bent = map.perturb(
            &self.images,
            uv,
            surface.shading_normal,
            to_world * tangent,
            to_world * bitangent,
        )?;
        (bent.dot(surface.geometric_normal) * surface.shading_normal.dot(surface.geometric_normal)
            > 0.0)
            .then_some(bent)
    }

    /// The texture coordinates where `hit` lies, for a mesh instance with them.
    pub fn hit_uv(&self, hit: &Hit) -> Option<Vec2> {
        self.uv_at(hit.inst, hit.prim, hit.u, hit.v)
    }

    /// The texture coordinates at barycentrics `(u, v)` (weights of vertices 1 and 2)
    /// of triangle `prim` of what instance index `inst` names, for a mesh instance with
    /// them.
    fn uv_at(&self, inst: u32, prim: u32, u: f32, v: f32) -> Option<Vec2> {
        let instance = self.instance_of(inst)?;
        let mesh = &self.meshes[instance.mesh as usize];
        if mesh.uvs.is_empty() {
            return None;
        }
        let [a, b, c] = mesh.mesh.indices()[prim as usize].map(|i| mesh.uvs[i as usize]);
        Some(a * (1.0 - u - v) + b * u + c * v)
    }

    /// The radiance material `material` emits at barycentrics `(u, v)` of triangle
    /// `prim` of instance index `inst`: its emission, times its emissive texture where
    /// it has one and the surface has texture coordinates.
    pub fn emitted_at(&self, material: u32, inst: u32, prim: u32, u: f32, v: f32) -> Vec3 {
        let emitted = self.materials[material as usize].emitted();
        match self.material_maps.get(material as usize) {
            Some(maps) if maps.emissive.is_some() => match self.uv_at(inst, prim, u, v) {
                Some(uv) => maps.emitted(emitted, &self.images, uv),
                None => emitted,
            },
            _ => emitted,
        }
    }

    /// Whether any material has a texture or is not opaque.
    pub fn is_textured(&self) -> bool {
        self.textured_materials() > 0
    }

    /// Whether some material lets rays through where they meet it (glTF's MASK and
    /// BLEND alpha modes).
    pub fn has_see_through(&self) -> bool {
        self.material_maps.iter().any(|m| m.coverage.is_some())
    }

    /// The material index of what `hit` hit.
    #[inline]
    pub fn material_index(&self, hit: &Hit) -> u32 {
        match self.instance_of(hit.inst) {
            None => self.primitives[hit.prim as usize].material,
            Some(instance) => instance.material,
        }
    }

    /// Whether a ray stops at `hit`, or passes through a see-through part of the surface
    /// (`u` draws a uniform number for stochastic transparency).
    #[inline]
    pub fn stops_ray(&self, hit: &Hit, u: impl FnOnce() -> f32) -> bool {
        match self.material_maps.get(self.material_index(hit) as usize) {
            Some(maps) if maps.coverage.is_some() => maps.stops(&self.images, self.hit_uv(hit), u),
            _ => true,
        }
    }

    /// Materials with at least one texture or a coverage other than opaque.
    pub fn textured_materials(&self) -> usize {
        self.material_maps.iter().filter(|m| !m.is_empty()).count()
    }

    /// Memory the decoded images hold.
    pub fn image_bytes(&self) -> u64 {
        self.images.iter().map(|i| i.texels.len() as u64 * 4).sum()
    }

    /// The same scene with every mesh instance's triangles baked into world space as
    /// primitives (for renderers without instancing: the GPU's for now). Degenerate
    /// triangles in world space are left out.
    pub fn with_instances_baked(&self) -> Scene {
        let mut baked = Scene {
            meshes: Vec::new(),
            instances: Vec::new(),
            ..self.clone()
        };
        for instance in &self.instances {
            let triangles = self.meshes[instance.mesh as usize].mesh.indices().len() as u32;
            for prim in 0..triangles {
                let mut triangle = self.instance_triangle(instance, prim);
                if triangle.area() == 0.0 {
                    continue;
                }
                if let Some(normals) = self.instance_normals(instance, prim) {
                    triangle.normals = baked.vertex_normals.len() as u32;
                    baked.vertex_normals.push(normals);
                }
                Arc::make_mut(&mut baked.primitives).push(Primitive {
                    shape: Shape::Triangle(triangle),
                    material: instance.material,
                });
            }
        }
        baked
    }

    /// Triangles placed by instances (each counted once per instance).
    pub fn instanced_triangles(&self) -> u64 {
        self.instances
            .iter()
            .map(|i| self.meshes[i.mesh as usize].mesh.indices().len() as u64)
            .sum()
    }

    /// What is legal but probably not what the author meant, one sentence each.
    pub fn warnings(&self) -> Vec<String> {
        let mut warnings = self.notes.clone();
        if self.skipped_degenerate > 0 {
            warnings.push(format!(
                "{} zero-area mesh triangles were left out",
                self.skipped_degenerate
            ));
        }
        if self.primitives.is_empty() && self.instanced_triangles() == 0 {
            warnings.push("the scene has no primitives: nothing to see".into());
        }
        let emitters = self.materials.iter().any(|m| m.emitted() != Vec3::ZERO);
        if !emitters
            && self.lights.is_empty()
            && self.background == Background::Constant(Vec3::ZERO)
        {
            warnings.push(
                "no light: no emissive material and a black background give a black image".into(),
            );
        }
        if !self.lights.is_empty() && self.settings.integrator == Integrator::Bsdf {
            warnings.push(format!(
                "the bsdf integrator never finds the scene's {} point, spot or directional lights \
                 (only light sampling does): use the path integrator",
                self.lights.len()
            ));
        }
        warnings
    }

    /// Counts of spheres, triangles and cuboids.
    pub fn shape_counts(&self) -> ShapeCounts {
        let mut counts = ShapeCounts::default();
        for p in self.primitives.iter() {
            match p.shape {
                Shape::Sphere(_) => counts.spheres += 1,
                Shape::Triangle(_) => counts.triangles += 1,
                Shape::Cuboid(_) => counts.cuboids += 1,
            }
        }
        counts
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShapeCounts {
    pub spheres: usize,
    pub triangles: usize,
    pub cuboids: usize,
}
