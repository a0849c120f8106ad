//! The BVH explorer's answer: the walk of one primary ray through the tree of the scene's
//! own primitives, node by node, as a closest-hit traversal makes it (nearest child
//! first, subtrees beyond the hit so far skipped), over any layout through its
//! [`TreeView`].

use crate::protocol::{corners, PickHit, WalkStep};
use canopy_bvh::view::{ChildKind, TreeView};
use canopy_bvh::{Ray, RayQuery};
use canopy_render::camera::{Camera, CameraSpec};
use canopy_render::{Accel, RenderSettings, Scene};

/// Most steps a walk reports (a pathological tree's walk is cut there).
pub const MAX_STEPS: usize = 4096;

/// A picked pixel's walk and hit.
#[derive(Debug, PartialEq)]
pub struct Walk {
    pub steps: Vec<WalkStep>,
    pub primitives_tested: u32,
    /// The closest hit in the whole scene (mesh instances included).
    pub hit: Option<PickHit>,
    /// Whether the scene has mesh instances, whose trees the walk does not enter.
    pub partial: bool,
}

/// The primary ray through the centre of pixel `(x, y)` of an image of `settings`' size
/// seen by `camera`.
pub fn primary_ray(camera: &CameraSpec, s: &RenderSettings, x: u32, y: u32) -> Ray {
    Camera::new(camera, s.width, s.height).pixel_centre_ray(x, y, s.seed)
}

/// Walks `ray` through the tree over the scene's own primitives in `accel`.
pub fn walk(scene: &Scene, accel: &Accel, ray: &Ray) -> Walk {
    let mut steps = Vec::new();
    let mut tested = 0;
    if let Some(tree) = accel.tree() {
        walk_view(tree.view(), accel, ray, &mut steps, &mut tested);
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
        steps,
        primitives_tested: tested,
        hit,
        partial: !scene.instances.is_empty(),
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

fn walk_view(
    view: &dyn TreeView,
    accel: &Accel,
    ray: &Ray,
    steps: &mut Vec<WalkStep>,
    tested: &mut u32,
) {
    let Some(root) = view.root() else {
        return;
    };
    let primitives = accel.primitives();
    let mut closest = ray.t_max;
    let mut children = Vec::new();
    // (child, its level, its entry distance)
    let mut stack = vec![(root, 0u32, 0.0f32)];
    while let Some((node, level, entry)) = stack.pop() {
        if entry > closest || steps.len() >= MAX_STEPS {
            continue;
        }
        let bounds = corners(&node.bounds);
        match node.kind {
            ChildKind::Leaf { first, count } => {
                let prims = view.prim_indices()[first..first + count].to_vec();
                for &p in &prims {
                    *tested += 1;
                    let within = Ray::new(ray.origin, ray.dir, ray.t_min, closest);
                    if let Some(t) = primitives[p as usize].shape.intersect(&within) {
                        closest = closest.min(t);
                    }
                }
                steps.push(WalkStep {
                    level,
                    bounds,
                    leaf: Some(prims),
                    entered: 0,
                    skipped: 0,
                });
            }
            ChildKind::Inner(index) => {
                view.children(index, &mut children);
                let within = Ray::new(ray.origin, ray.dir, ray.t_min, closest);
                let mut entered: Vec<_> = children
                    .iter()
                    .filter_map(|c| c.bounds.ray_entry(&within).map(|t| (*c, t)))
                    .collect();
                steps.push(WalkStep {
                    level,
                    bounds,
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
