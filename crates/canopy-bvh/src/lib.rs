//! canopy-bvh: bounding volume hierarchies for ray tracing.
//!
//! Every builder produces the one binary format, [`Bvh2`]; statistics, validation and
//! traversal are written once against it. The library knows boxes, rays and primitive
//! indices only: the caller supplies the primitive test as a closure, so the same tree
//! serves spheres, triangles or anything else with a bounding box.
//!
//! ```
//! use canopy_bvh::{build, Aabb, BuildParams, Builder, Ray};
//! use glam::Vec3;
//!
//! let boxes: Vec<Aabb> = (0..100)
//!     .map(|i| Aabb::new(Vec3::splat(i as f32), Vec3::splat(i as f32 + 0.5)))
//!     .collect();
//! let bvh = build(Builder::BinnedSah, &boxes, &BuildParams::default());
//! bvh.validate(&boxes).unwrap();
//!
//! let ray = Ray::new(Vec3::new(-1.0, 10.25, 10.25), Vec3::X, 0.0, f32::INFINITY);
//! let hit = bvh.intersect(&ray, |prim, ray| boxes[prim as usize].ray_entry(ray));
//! assert_eq!(hit.map(|h| h.prim), Some(10));
//! ```

mod aabb;
mod blas;
pub mod build;
mod bvh2;
pub mod epo;
mod geometry;
mod gpu_layout;
mod instance;
mod isa;
#[cfg(target_arch = "x86_64")]
mod lanes;
mod layout;
pub mod optimize;
mod proximity;
mod query;
mod ray;
mod ray_order;
mod shapes;
mod stats;
mod tlas;
mod traverse;
mod triangle;
pub mod view;
mod wide;

pub use aabb::Aabb;
pub use blas::{packed_params, Blas, BlasParams, PACKED_LEAF_PACKS, PACKED_SHARE};
pub use build::{
    build, build_with_clipper, split_box, split_triangle, try_build, BuildParams, Builder, Clipper,
    ParamsError, Preset, SahCosts, SplitBoxes, UnknownBuilder,
};
pub use bvh2::{Bvh2, Bvh2Node, BvhError, RefitError};
pub use epo::{epo, triangle_area_in_box};
pub use geometry::{Boxes, Geometry, MeshError, TriangleMesh};
pub use gpu_layout::{GpuBvh, GpuNode, GPU_EMPTY};
pub use instance::{Instance, InstanceError, BOX_SLACK_ULPS, EVERY_RAY};
pub use isa::{Isa, IsaError};
pub use layout::{BvhWidth, Tree};
pub use optimize::{optimize, OptimizeBudget, OptimizeReport};
pub use proximity::{
    closest_point_on_triangle, solid_angle, HitsAlong, Nearest, Placement, SurfaceQuery,
    TriangleSurface, FAR_FIELD, INSIDE_FAR_FIELD,
};
pub use query::{
    trace_batch, Coherence, Forward, RayBatch, RayQuery, ALL_MASKS, BATCH_CHUNK, CLOSURE_CHUNK,
};
pub use ray::{Hit, IntoHit, PrimHit, Ray};
pub use ray_order::{AnswerSlots, RayOrder, SliceSlots, RAY_ORDER_MIN};
pub use shapes::{intersect_box, intersect_sphere, KnownShape};
pub use stats::TreeStats;
pub use tlas::Tlas;
pub use traverse::{TraversalCounter, TraversalStats};
pub use triangle::{
    crosses_triangle, intersect_triangle, ShearedRay, TrianglePack, TriangleTest, NO_PRIM,
    PACK_LANES,
};
pub use view::TreeView;
pub use wide::{Bvh4, Bvh8, BvhN, WideNode, EMPTY_SLOT, PACKET, PREFETCH_ABOVE_BYTES};
