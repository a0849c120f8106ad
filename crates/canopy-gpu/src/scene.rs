//! A scene flattened into GPU buffers: primitives as tagged records, rays, and the BVH in
//! the GPU layout ([`GpuBvh`]).

use crate::chunked::CHUNKS;
use crate::GpuError;
use bytemuck::{Pod, Zeroable};
use canopy_bvh::{
    Aabb, BuildParams, Builder, Bvh2, GpuBvh, GpuNode, Ray, SahCosts, TreeView, GPU_EMPTY,
};
use canopy_render::geometry::Shape;
use canopy_render::scene::Primitive;
use std::borrow::Cow;

/// The bindings of the chunks of the nodes and of the primitives (common.wgsl).
pub(crate) const NODE_BINDINGS: [u32; CHUNKS] = [0, 13, 14, 15];
pub(crate) const PRIM_BINDINGS: [u32; CHUNKS] = [2, 16, 17, 18];

/// Deepest tree the GPU traversal's stack of pending nodes can walk.
pub const MAX_TREE_DEPTH: usize = 64;

/// A primitive for the GPU: 96 bytes, `#[repr(C)]`, `Pod`; WGSL reads it as
/// `struct { header: vec4<u32>, d0: vec4<f32>, ..., d4: vec4<f32> }`.
///
/// Byte layout: `kind` (0..4), `material` (4..8), `normals` (8..12), `surface` (12..16),
/// `data` (16..96) as five `[f32; 4]`:
/// - kind 0, triangle: `data[0..3]` the vertices (`.w` unused); `normals` indexes the
///   scene's vertex-normal triples ([`FLAT`]: none); a textured mesh's triangle has its
///   texture coordinates and tangents at `surface` in the render kernel's surface data
///   ([`FLAT`]: none);
/// - kind 1, sphere: `data[0]` centre and radius;
/// - kind 2, cuboid: `data[0..3].xyz` the rows of the world-to-local rotation,
///   `data[0..3].w` the local box's min, `data[3].xyz` the translation, `data[4].xyz`
///   the local box's max.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GpuPrimitive {
    pub kind: u32,
    pub material: u32,
    pub normals: u32,
    pub surface: u32,
    pub data: [[f32; 4]; 5],
}

/// `normals` of a primitive without vertex normals.
pub const FLAT: u32 = u32::MAX;

const _: () = assert!(std::mem::size_of::<GpuPrimitive>() == 96);

impl GpuPrimitive {
    pub const TRIANGLE: u32 = 0;
    pub const SPHERE: u32 = 1;
    pub const CUBOID: u32 = 2;

    pub fn new(p: &Primitive) -> Self {
        let mut data = [[0.0; 4]; 5];
        let mut normals = FLAT;
        let kind = match &p.shape {
            Shape::Triangle(t) => {
                for (d, v) in data.iter_mut().zip(t.v) {
                    *d = [v.x, v.y, v.z, 0.0];
                }
                normals = t.normals;
                Self::TRIANGLE
            }
            Shape::Sphere(s) => {
                data[0] = [s.center.x, s.center.y, s.center.z, s.radius];
                Self::SPHERE
            }
            Shape::Cuboid(c) => {
                // Row i of the world-to-local rotation (its transpose) is column i.
                for (i, d) in data.iter_mut().take(3).enumerate() {
                    let row = c.rotation().col(i);
                    *d = [row.x, row.y, row.z, c.local.min[i]];
                }
                let t = c.translation;
                data[3] = [t.x, t.y, t.z, 0.0];
                let m = c.local.max;
                data[4] = [m.x, m.y, m.z, 0.0];
                Self::CUBOID
            }
        };
        Self {
            kind,
            material: p.material,
            normals,
            surface: FLAT,
            data,
        }
    }
}

/// A ray for the GPU: 32 bytes, `#[repr(C)]`, `Pod`; WGSL `struct { origin: vec3<f32>,
/// t_min: f32, dir: vec3<f32>, t_max: f32 }`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GpuRay {
    pub origin: [f32; 3],
    pub t_min: f32,
    pub dir: [f32; 3],
    pub t_max: f32,
}

impl From<&Ray> for GpuRay {
    fn from(r: &Ray) -> Self {
        Self {
            origin: r.origin.into(),
            t_min: r.t_min,
            dir: r.dir.into(),
            t_max: r.t_max,
        }
    }
}

/// Primitives and their BVH, flattened for upload.
pub struct GpuScene {
    pub(crate) bvh: GpuBvh,
    pub(crate) primitives: Vec<GpuPrimitive>,
}

impl GpuScene {
    /// Builds a binned-SAH tree over `primitives` and flattens both.
    pub fn new(primitives: &[Primitive], params: &BuildParams) -> Result<Self, GpuError> {
        let boxes: Vec<_> = primitives.iter().map(|p| p.shape.bounds()).collect();
        let bvh = canopy_bvh::build_with_clipper(
            Builder::BinnedSah,
            &boxes,
            params,
            &canopy_render::clipper(primitives),
        );
        Self::with_bvh(primitives, &bvh)
    }

    /// Flattens `primitives` and a tree built over them.
    pub fn with_bvh(primitives: &[Primitive], bvh: &Bvh2) -> Result<Self, GpuError> {
        let depth = bvh.stats(&SahCosts::default()).max_depth;
        if depth > MAX_TREE_DEPTH {
            return Err(GpuError::TooDeep {
                depth,
                max: MAX_TREE_DEPTH,
            });
        }
        Ok(Self {
            bvh: GpuBvh::from_bvh2(bvh),
            primitives: primitives.iter().map(GpuPrimitive::new).collect(),
        })
    }

    /// The tree as uploaded (validate it, or walk it with its CPU twin).
    pub fn bvh(&self) -> &GpuBvh {
        &self.bvh
    }

    /// The nodes to upload: the tree's, or for an empty tree one node with two empty
    /// slots (a binding cannot be empty), in which the kernels find nothing.
    pub(crate) fn upload_nodes(&self) -> Cow<'_, [GpuNode]> {
        if !self.bvh.nodes().is_empty() {
            return Cow::Borrowed(self.bvh.nodes());
        }
        Cow::Owned(Self::empty_nodes())
    }

    /// One node with two empty slots, for a binding that has no tree to hold.
    pub(crate) fn empty_nodes() -> Vec<GpuNode> {
        let empty = Aabb::EMPTY;
        vec![GpuNode {
            left_min: empty.min,
            left: GPU_EMPTY,
            left_max: empty.max,
            left_count: 0,
            right_min: empty.min,
            right: GPU_EMPTY,
            right_max: empty.max,
            right_count: 0,
        }]
    }

    /// Bytes of the buffers this scene uploads.
    pub fn bytes(&self) -> usize {
        self.bvh.memory_bytes() + std::mem::size_of_val(self.primitives.as_slice())
    }
}
