//! The validated, in-memory scene that the integrator renders.

use crate::camera::CameraSpec;
use crate::geometry::Shape;
use crate::material::Material;
use canopy_bvh::Aabb;
use glam::Vec3;
use std::path::PathBuf;

/// What a ray that leaves the scene sees.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Background {
    /// The report's sky: white at the horizon blending to light blue overhead.
    #[default]
    Sky,
    Constant(Vec3),
}

impl Background {
    #[inline]
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        match *self {
            Background::Sky => {
                let a = 0.5 * (dir.normalize().y + 1.0);
                (1.0 - a) * Vec3::ONE + a * Vec3::new(0.5, 0.7, 1.0)
            }
            Background::Constant(c) => c,
        }
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
        }
    }
}

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
    pub primitives: Vec<Primitive>,
    /// Vertex normals of smooth triangles, indexed by `Triangle::normals`.
    pub vertex_normals: Vec<[Vec3; 3]>,
    /// Mesh triangles left out because they have no area (they can never be hit).
    pub skipped_degenerate: usize,
    /// The files the scene was read from (scene file, meshes): never to be written over.
    pub inputs: Vec<PathBuf>,
}

impl Scene {
    /// Bounding box of every primitive, in primitive order (the BVH builders' input).
    pub fn primitive_bounds(&self) -> Vec<Aabb> {
        self.primitives.iter().map(|p| p.shape.bounds()).collect()
    }

    /// What is legal but probably not what the author meant, one sentence each.
    pub fn warnings(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        if self.skipped_degenerate > 0 {
            warnings.push(format!(
                "{} zero-area mesh triangles were left out",
                self.skipped_degenerate
            ));
        }
        if self.primitives.is_empty() {
            warnings.push("the scene has no primitives".into());
        }
        let emitters = self
            .materials
            .iter()
            .any(|m| matches!(m, crate::material::Material::Emissive { .. }));
        if !emitters && self.background == Background::Constant(Vec3::ZERO) {
            warnings.push(
                "no light: no emissive material and a black background give a black image".into(),
            );
        }
        warnings
    }

    /// Counts of spheres, triangles and cuboids.
    pub fn shape_counts(&self) -> ShapeCounts {
        let mut counts = ShapeCounts::default();
        for p in &self.primitives {
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
