//! A scene flattened for the GPU's two-level traversal: every structure's tree (the
//! scene's own primitives, then each mesh, stored once, then the top tree over the
//! instances) in one node array, their primitives in one primitive array, and one record
//! per instance with its transforms, root node, first primitive, material and lights.
//! A scene without mesh instances is flattened as before: one tree, walked from node 0.

use crate::lights::{gpu_lights, GpuLight, GpuPunctual, NO_LIGHT};
use crate::scene::{GpuPrimitive, GpuScene, FLAT, MAX_TREE_DEPTH};
use crate::textures::push_surface;
use crate::GpuError;
use bytemuck::{Pod, Zeroable};
use canopy_bvh::{Aabb, BuildParams, Builder, Bvh2, GpuBvh, GpuNode, SahCosts, Tree, GPU_EMPTY};
use canopy_render::geometry::Shape;
use canopy_render::scene::Primitive;
use canopy_render::{Accel, Scene};
use glam::Affine3A;

/// An instance for the GPU: 144 bytes; WGSL `Instance` in `instances.wgsl`. The
/// transforms are affine maps by columns (x, y, z axes, translation; `w` unused).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuInstance {
    to_local: [[f32; 4]; 4],
    to_world: [[f32; 4]; 4],
    /// Root node (`GPU_EMPTY`: nothing to hit), first primitive, material
    /// (`NO_MATERIAL`: each primitive's own), first light (`NO_LIGHT`: none).
    info: [u32; 4],
}

const NO_MATERIAL: u32 = u32::MAX;

fn columns(m: &Affine3A) -> [[f32; 4]; 4] {
    let c = |v: glam::Vec3A| [v.x, v.y, v.z, 0.0];
    [
        c(m.matrix3.x_axis),
        c(m.matrix3.y_axis),
        c(m.matrix3.z_axis),
        c(m.translation),
    ]
}

/// Everything the render kernel's scene bindings hold.
pub(crate) struct Flat {
    pub nodes: Vec<GpuNode>,
    pub prim_indices: Vec<u32>,
    pub primitives: Vec<GpuPrimitive>,
    /// Three per smooth triangle, as `GpuPrimitive::normals` indexes them.
    pub normals: Vec<[f32; 4]>,
    /// Textured mesh triangles' texture coordinates and tangents, as
    /// `GpuPrimitive::surface` indexes them (`textures::push_surface`).
    pub surface: Vec<[f32; 4]>,
    pub instances: Vec<GpuInstance>,
    /// The top tree's root node, when the scene has mesh instances.
    pub top: Option<u32>,
    pub lights: Vec<GpuLight>,
    pub light_of_prim: Vec<u32>,
    pub punctual: Vec<GpuPunctual>,
}

fn check_depth(bvh: &Bvh2) -> Result<(), GpuError> {
    let depth = bvh.stats(&SahCosts::default()).max_depth;
    if depth > MAX_TREE_DEPTH {
        return Err(GpuError::TooDeep {
            depth,
            max: MAX_TREE_DEPTH,
        });
    }
    Ok(())
}

fn scene_normals(scene: &Scene) -> Vec<[f32; 4]> {
    scene
        .vertex_normals
        .iter()
        .flat_map(|n| n.map(|v| [v.x, v.y, v.z, 0.0]))
        .collect()
}

impl Flat {
    /// A scene without mesh instances and a tree over its primitives.
    pub fn single(scene: &Scene, bvh: &Bvh2) -> Result<Self, GpuError> {
        let flat = GpuScene::with_bvh(&scene.primitives, bvh)?;
        let lights = gpu_lights(scene, &mut Vec::new(), &[]);
        Ok(Self {
            nodes: flat.upload_nodes().into_owned(),
            prim_indices: flat.bvh.prim_indices().to_vec(),
            primitives: flat.primitives,
            normals: scene_normals(scene),
            surface: Vec::new(),
            instances: vec![GpuInstance {
                to_local: columns(&Affine3A::IDENTITY),
                to_world: columns(&Affine3A::IDENTITY),
                info: [0, 0, NO_MATERIAL, NO_LIGHT],
            }],
            top: None,
            lights: lights.table,
            light_of_prim: lights.light_of_prim,
            punctual: lights.punctual,
        })
    }

    /// A scene with mesh instances, through the structures of `accel` (binary trees:
    /// built with width 2): instance 0 the scene's primitives, instance k + 1 the
    /// scene's mesh instance k, as on the CPU.
    pub fn two_level(scene: &Scene, accel: &Accel) -> Result<Self, GpuError> {
        let world = accel.world();
        let binary = |tree: Option<&Tree>| match tree {
            Some(Tree::Binary(bvh)) => Ok(bvh.clone()),
            _ => Err(GpuError::Unsupported(
                "a structure that is not a binary tree (build with width 2)",
            )),
        };
        let mut flat = Self {
            nodes: Vec::new(),
            prim_indices: Vec::new(),
            primitives: scene.primitives.iter().map(GpuPrimitive::new).collect(),
            normals: scene_normals(scene),
            surface: Vec::new(),
            instances: Vec::new(),
            top: None,
            lights: Vec::new(),
            light_of_prim: Vec::new(),
            punctual: Vec::new(),
        };
        // Each structure's root node (or none), and its first primitive.
        let mut roots = Vec::new();
        for (s, blas) in world.blases().iter().enumerate() {
            let bvh = binary(blas.tree())?;
            check_depth(&bvh)?;
            let prim_base = match s {
                0 => 0,
                _ => {
                    let mesh = &scene.meshes[s - 1];
                    let base = flat.primitives.len() as u32;
                    let smooth = !mesh.normals.is_empty();
                    for (t, &[a, b, c]) in mesh.mesh.indices().iter().enumerate() {
                        let [va, vb, vc] = mesh.mesh.vertices_of(t as u32);
                        let mut triangle = canopy_render::geometry::Triangle::new(va, vb, vc);
                        if smooth {
                            triangle.normals = (flat.normals.len() / 3) as u32;
                            for v in [a, b, c] {
                                let n = mesh.normals[v as usize];
                                flat.normals.push([n.x, n.y, n.z, 0.0]);
                            }
                        }
                        let mut primitive = GpuPrimitive::new(&Primitive {
                            shape: Shape::Triangle(triangle),
                            material: 0,
                        });
                        primitive.surface = push_surface(&mut flat.surface, mesh, t);
                        flat.primitives.push(primitive);
                    }
                    base
                }
            };
            let root = flat.append(&GpuBvh::from_bvh2(&bvh), |p| p + prim_base);
            roots.push((root, prim_base));
        }
        // Each mesh's first triangle (structure s is mesh s - 1).
        let mesh_first: Vec<u32> = roots.iter().skip(1).map(|&(_, base)| base).collect();
        let lights = gpu_lights(scene, &mut flat.primitives, &mesh_first);
        let first_light = lights.first_of_instance;
        (flat.lights, flat.light_of_prim) = (lights.table, lights.light_of_prim);
        flat.punctual = lights.punctual;
        // The top tree holds the instances that can be hit.
        let (mut boxes, mut placed) = (Vec::new(), Vec::new());
        for (i, instance) in world.instances().iter().enumerate() {
            let (root, prim_base) = roots[instance.blas as usize];
            let material = match i {
                0 => NO_MATERIAL,
                k => scene.instances[k - 1].material,
            };
            flat.instances.push(GpuInstance {
                to_local: columns(instance.to_local()),
                to_world: columns(instance.to_world()),
                info: [root, prim_base, material, first_light[i]],
            });
            let local: Aabb = canopy_bvh::RayQuery::bounds(&world.blases()[instance.blas as usize]);
            let bounds = instance.world_bounds(local);
            if root != GPU_EMPTY && !bounds.is_empty() {
                boxes.push(bounds);
                placed.push(i as u32);
            }
        }
        let top = canopy_bvh::build(Builder::BinnedSah, &boxes, &BuildParams::default());
        check_depth(&top)?;
        // The top tree's leaves list instances, not primitives.
        flat.top = Some(flat.append(&GpuBvh::from_bvh2(&top), |p| placed[p as usize]));
        if flat.nodes.is_empty() {
            flat.nodes = GpuScene::empty_nodes();
        }
        Ok(flat)
    }

    /// Appends a tree's nodes and its primitive indices (each mapped by `index`), its
    /// child links moved to where they now lie; returns its root, or `GPU_EMPTY` for an
    /// empty tree.
    fn append(&mut self, tree: &GpuBvh, index: impl Fn(u32) -> u32) -> u32 {
        if tree.nodes().is_empty() {
            return GPU_EMPTY;
        }
        let node_base = self.nodes.len() as u32;
        let index_base = self.prim_indices.len() as u32;
        let moved = |child: u32, count: u32| match (child, count) {
            (GPU_EMPTY, 0) => GPU_EMPTY,
            (node, 0) => node + node_base,
            (first, _) => first + index_base,
        };
        self.nodes.extend(tree.nodes().iter().map(|n| GpuNode {
            left: moved(n.left, n.left_count),
            right: moved(n.right, n.right_count),
            ..*n
        }));
        self.prim_indices
            .extend(tree.prim_indices().iter().map(|&p| index(p)));
        node_base
    }
}

/// `FLAT` is the normals index of a flat triangle here too.
const _: () = assert!(FLAT == canopy_render::geometry::Triangle::FLAT);
