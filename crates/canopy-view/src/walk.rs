//! The BVH explorer's answer: the walk of one primary ray through the whole structure,
//! node by node, as a closest-hit traversal makes it (nearest child first, subtrees
//! beyond the hit so far skipped): the top tree over the instances, where the scene has
//! one, and into each instance it reaches, the tree of that instance's structure (the
//! scene's own primitives, or a mesh), in the instance's space, over any layout through
//! its [`TreeView`].

use crate::protocol::{corners, PickHit, WalkStep};
use canopy_bvh::view::{ChildKind, TreeView};
use canopy_bvh::{Geometry, Instance, Ray, RayQuery, ShearedRay, TriangleTest};
use canopy_render::accel::SceneBlas;
use canopy_render::camera::{Camera, CameraSpec};
use canopy_render::{Accel, RenderSettings, Scene};

/// Most steps a walk reports (a pathological tree's walk is cut there).
pub const MAX_STEPS: usize = 4096;

/// A picked pixel's walk and hit.
#[derive(Debug, PartialEq)]
pub struct Walk {
    pub steps: Vec<WalkStep>,
    pub primitives_tested: u32,
    /// The closest hit in the whole scene.
    pub hit: Option<PickHit>,
    /// Whether some structure the ray reached has no tree to show (its primitives are
    /// then not listed).
    pub partial: bool,
}

/// The primary ray through the centre of pixel `(x, y)` of an image of `settings`' size
/// seen by `camera`.
pub fn primary_ray(camera: &CameraSpec, s: &RenderSettings, x: u32, y: u32) -> Ray {
    Camera::new(camera, s.width, s.height).pixel_centre_ray(x, y, s.seed)
}

/// Walks `ray` through `accel`: its top tree, then each instance's tree it reaches.
pub fn walk(scene: &Scene, accel: &Accel, ray: &Ray) -> Walk {
    let world = accel.world();
    let mut walker = Walker {
        ray: *ray,
        closest: ray.t_max,
        steps: Vec::new(),
        tested: 0,
        partial: false,
        blases: world.blases(),
        instances: world.instances(),
        triangle_test: accel.triangle_test(),
    };
    match world.tree() {
        Some(top) => walker.tree(top.view(), None, 0),
        // Every instance is tested.
        None => (0..walker.instances.len() as u32).for_each(|k| walker.instance(k, 0)),
    }
    let hit = accel.intersect(ray).map(|h| {
        let material = match h.inst {
            0 => accel.primitives().get(h.prim as usize).map(|p| p.material),
            k => scene.instances.get(k as usize - 1).map(|i| i.material),
        };
        PickHit {
            t: h.t,
            instance: h.inst,
            primitive: h.prim,
            material: material
                .and_then(|m| scene.materials.get(m as usize))
                .map(material_kind),
        }
    });
    Walk {
        steps: walker.steps,
        primitives_tested: walker.tested,
        hit,
        partial: walker.partial,
    }
}

/// A material's kind in a word (`Lambertian`, `Metal`, ...): its variant's name.
fn material_kind(material: &canopy_render::material::Material) -> String {
    let debug = format!("{material:?}");
    debug
        .split(|c: char| !c.is_alphanumeric())
        .next()
        .unwrap_or_default()
        .to_owned()
}

/// A walk in progress: the world ray, its closest hit so far, and the steps made.
struct Walker<'a> {
    ray: Ray,
    /// The closest hit so far, as the world ray's `t` (an instance's ray shares it).
    closest: f32,
    steps: Vec<WalkStep>,
    tested: u32,
    partial: bool,
    blases: &'a [SceneBlas],
    instances: &'a [Instance],
    triangle_test: TriangleTest,
}

impl<'a> Walker<'a> {
    /// Walks one tree: the top one (`instance` `None`: its leaves hold instances) or the
    /// tree of instance `instance`'s structure (its leaves hold primitives, tested in the
    /// instance's space). `level` is its root's level.
    fn tree(&mut self, view: &dyn TreeView, instance: Option<u32>, level: u32) {
        let Some(root) = view.root() else {
            return;
        };
        let (instances, world_ray) = (self.instances, self.ray);
        let placed = instance.map(|k| &instances[k as usize]);
        // The ray in this tree's space, up to the closest hit so far.
        let ray = |closest: f32| {
            let world = Ray::new(world_ray.origin, world_ray.dir, world_ray.t_min, closest);
            placed.map_or(world, |p| p.ray_to_local(&world))
        };
        let to_world = |b: &canopy_bvh::Aabb| corners(&placed.map_or(*b, |p| p.world_bounds(*b)));
        let mut children = Vec::new();
        // (child, its level, its entry distance)
        let mut stack = vec![(root, level, 0.0f32)];
        while let Some((node, level, entry)) = stack.pop() {
            if entry > self.closest || self.steps.len() >= MAX_STEPS {
                continue;
            }
            match node.kind {
                ChildKind::Leaf { first, count } => {
                    let held = view.prim_indices()[first..first + count].to_vec();
                    self.steps.push(WalkStep {
                        instance,
                        level,
                        bounds: to_world(&node.bounds),
                        leaf: Some(held.clone()),
                        entered: 0,
                        skipped: 0,
                    });
                    for item in held {
                        match instance {
                            None => self.instance(item, level + 1),
                            Some(k) => self.primitive(k, item, &ray(self.closest)),
                        }
                    }
                }
                ChildKind::Inner(index) => {
                    view.children(index, &mut children);
                    let within = ray(self.closest);
                    let mut entered: Vec<_> = children
                        .iter()
                        .filter_map(|c| c.bounds.ray_entry(&within).map(|t| (*c, t)))
                        .collect();
                    self.steps.push(WalkStep {
                        instance,
                        level,
                        bounds: to_world(&node.bounds),
                        leaf: None,
                        entered: entered.len() as u32,
                        skipped: (children.len() - entered.len()) as u32,
                    });
                    // Nearest on top of the stack.
                    entered.sort_by(|a, b| b.1.total_cmp(&a.1));
                    stack.extend(entered.into_iter().map(|(c, t)| (c, level + 1, t)));
                }
            }
        }
    }

    /// Walks the tree of instance `k`'s structure, its root at `level`.
    fn instance(&mut self, k: u32, level: u32) {
        let blas = &self.blases[self.instances[k as usize].blas as usize];
        match blas.tree() {
            Some(tree) => self.tree(tree.view(), Some(k), level),
            None => self.partial = true,
        }
    }

    /// Tests primitive `prim` of instance `k`'s structure against `ray` (in its space).
    fn primitive(&mut self, k: u32, prim: u32, ray: &Ray) {
        self.tested += 1;
        let sheared = ShearedRay::with_test(ray, self.triangle_test);
        let hit = match &self.blases[self.instances[k as usize].blas as usize] {
            SceneBlas::Shapes(b) => b.geometry().intersect(prim, ray, &sheared),
            SceneBlas::Mesh(b) => b.geometry().intersect(prim, ray, &sheared),
        };
        if let Some(hit) = hit {
            self.closest = self.closest.min(hit.t);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use canopy_bvh::{BuildParams, Builder};
    use canopy_render::{AccelKind, BvhWidth};

    /// Over a scene of mesh instances, in every layout: each pixel's hit is a primitive
    /// of a leaf the walk tested, in the hit instance's own tree, reached through the top
    /// tree's leaf that holds that instance.
    #[test]
    fn every_hit_is_in_a_leaf_the_walk_tested_instances_included() {
        let mut scene = canopy_render::load_scene("teapots").unwrap();
        (scene.settings.width, scene.settings.height) = (32, 24);
        for width in [BvhWidth::Two, BvhWidth::Eight] {
            let accel = Accel::for_scene(
                &scene,
                AccelKind::Bvh(Builder::default()),
                width,
                &BuildParams::default(),
                None,
            );
            let mut in_meshes = 0;
            for (x, y) in (0..24).flat_map(|y| (0..32).map(move |x| (x, y))) {
                let ray = primary_ray(&scene.camera, &scene.settings, x, y);
                let walk = walk(&scene, &accel, &ray);
                assert!(!walk.partial);
                let Some(hit) = walk.hit else { continue };
                let holds = |tree: Option<u32>, item: u32| {
                    walk.steps.iter().any(|s| {
                        s.instance == tree && s.leaf.as_ref().is_some_and(|l| l.contains(&item))
                    })
                };
                assert!(
                    holds(Some(hit.instance), hit.primitive),
                    "({x}, {y}): {hit:?}"
                );
                assert!(holds(None, hit.instance), "({x}, {y}): {hit:?}");
                in_meshes += u32::from(hit.instance > 0);
            }
            assert!(in_meshes > 50, "{in_meshes} pixels hit a teapot");
        }
    }
}
