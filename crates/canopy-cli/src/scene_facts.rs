//! What `canopy render` and `canopy check` both report about a scene, in text and JSON.

use canopy_render::Scene;
use serde::Serialize;

/// The scene as given, its render settings and its primitive counts.
#[derive(Default, Serialize)]
pub struct SceneFacts {
    /// The scene as the command names it (built-in name or path).
    pub scene: String,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub max_depth: u32,
    pub seed: u64,
    /// `path` or `bsdf`.
    pub integrator: String,
    pub russian_roulette: bool,
    /// `sobol` or `independent`.
    pub sampler: String,
    pub primitives: usize,
    pub spheres: usize,
    pub triangles: usize,
    pub cuboids: usize,
    /// Meshes stored once and placed by instances.
    pub meshes: usize,
    pub instances: usize,
    /// Triangles the instances place, each counted once per instance.
    pub instanced_triangles: u64,
}

impl SceneFacts {
    pub fn of(source: &str, scene: &Scene) -> Self {
        let s = scene.settings;
        let counts = scene.shape_counts();
        Self {
            scene: source.to_owned(),
            width: s.width,
            height: s.height,
            spp: s.spp,
            max_depth: s.max_depth,
            seed: s.seed,
            integrator: s.integrator.to_string(),
            russian_roulette: s.russian_roulette,
            sampler: s.sampler.to_string(),
            primitives: scene.primitives.len(),
            spheres: counts.spheres,
            triangles: counts.triangles,
            cuboids: counts.cuboids,
            meshes: scene.meshes.len(),
            instances: scene.instances.len(),
            instanced_triangles: scene.instanced_triangles(),
        }
    }

    /// `WxH, N spp, depth D, seed S, I integrator`, and the sampler when not Sobol
    pub fn settings_text(&self) -> String {
        let roulette = match (self.integrator.as_str(), self.russian_roulette) {
            ("path", false) => " without Russian roulette",
            _ => "",
        };
        let sampler = match self.sampler.as_str() {
            "sobol" => String::new(),
            other => format!(", {other} sampler"),
        };
        format!(
            "{}x{}, {} spp, depth {}, seed {}, {} integrator{roulette}{sampler}",
            self.width, self.height, self.spp, self.max_depth, self.seed, self.integrator
        )
    }

    /// `N (a spheres, b triangles, c cuboids)`, and the instances if there are any.
    pub fn primitives_text(&self) -> String {
        let instances = match self.instances {
            0 => String::new(),
            n => format!(
                "; {n} instances of {} meshes placing {} triangles",
                self.meshes, self.instanced_triangles
            ),
        };
        format!(
            "{} ({} spheres, {} triangles, {} cuboids){instances}",
            self.primitives, self.spheres, self.triangles, self.cuboids
        )
    }
}
