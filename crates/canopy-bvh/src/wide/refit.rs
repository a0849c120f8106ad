//! Refitting a wide tree to primitives that moved: the same topology, every slot box
//! recomputed bottom-up, the triangle packs rewritten.

use super::{BvhN, WideNode};
use crate::{Aabb, RefitError};
use glam::Vec3;
use rayon::prelude::*;

impl<const N: usize> WideNode<N> {
    /// The union of the used slots' boxes.
    fn bounds(&self) -> Aabb {
        (0..self.len()).fold(Aabb::EMPTY, |b, i| b.union(self.slot_bounds(i)))
    }
}

impl<const N: usize> BvhN<N> {
    /// Recomputes every box from `boxes` (one per primitive) and the packed triangles'
    /// vertices from `triangle`, keeping the topology. Refuses a tree with spatial
    /// splits, whose leaf boxes are parts of primitives.
    pub fn refit(
        &mut self,
        boxes: &[Aabb],
        triangle: impl Fn(u32) -> Option<[Vec3; 3]> + Sync,
    ) -> Result<(), RefitError> {
        if self.spatial_splits {
            return Err(RefitError::SpatialSplits);
        }
        // Children come after their parent, so a reverse sweep sees children first.
        for i in (0..self.nodes.len()).rev() {
            let mut node = self.nodes[i];
            for slot in 0..node.len() {
                let (child, count) = (node.child[slot], node.count[slot]);
                let bounds = match count {
                    0 => self.nodes[child as usize].bounds(),
                    _ => self.prim_indices[child as usize..(child + count) as usize]
                        .iter()
                        .fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize])),
                };
                node.set_slot(slot, bounds, child, count);
            }
            self.nodes[i] = node;
        }
        self.packs.par_iter_mut().for_each(|pack| {
            for lane in 0..crate::PACK_LANES {
                if pack.triangles & (1 << lane) != 0 {
                    let prim = pack.prim[lane];
                    if let Some(v) = triangle(prim) {
                        pack.set_triangle(lane, prim, v);
                    }
                }
            }
        });
        Ok(())
    }
}
