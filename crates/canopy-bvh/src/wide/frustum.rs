//! Packets of nearly parallel rays (a pixel's samples, shadow rays from one pixel's points)
//! walked as one: each node's slots are tested once, against bounds that hold every ray
//! of the packet, instead of once per ray (interval arithmetic over the packet's origins
//! and reciprocal directions, as in Wald, Boulos and Shirley, "Ray Tracing Deformable
//! Scenes Using Dynamic Bounding Volume Hierarchies", 2007). A node then costs what it
//! costs one ray, whatever the packet's size; the leaves are tested for every ray of the
//! packet, each against its own range, as [`super::packet`]'s leaves are.
//!
//! The bounds are conservative in floating point, not only in exact arithmetic: where
//! one ray's slab test ([`super::kernels`]) enters a slot, so does the packet's (rounding
//! is monotonic, and each bound is a corner of the products' intervals). The walk thus
//! visits every leaf that any of its rays would visit alone with the same closest hit so
//! far, and each ray gets the hit a single-ray query gives, bit for bit.
//!
//! It applies where every ray runs the same way along each axis (the planes that rays
//! meet first are the same for all) with a finite reciprocal direction ([`Frustum::new`]);
//! other packets walk lane by lane.

use super::kernels::NodeKernel;
use super::packet::{lane_mask, reduce_lanes, Lanes, PacketRays, PACKET};
use super::traverse::{lanes, PacketLeaves, WalkNodes};
use super::WideNode;
use crate::aabb::{fast_max, fast_min, FAR_SLACK};
use crate::{Hit, Ray};

/// Bounds on a packet's rays for slab tests: per axis, the interval of the origins and of
/// the reciprocal directions, and which plane of a box the rays meet first.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Frustum {
    /// Index into [`WideNode::bounds`] of each axis's near plane (below 6).
    near: [usize; 3],
    /// Each axis's far plane, likewise.
    far: [usize; 3],
    /// The origin coordinate that gives the least distance to the near plane (the
    /// largest along a rising axis, the least along a falling one), and to the far one.
    near_origin: [f32; 3],
    far_origin: [f32; 3],
    /// The least and largest reciprocal direction.
    inv_low: [f32; 3],
    inv_high: [f32; 3],
    /// The least `t_min`.
    t_min: f32,
}

/// The least cosine between the first traced ray's direction and another's for a packet
/// to walk as one (about 1.1 degrees). A pixel's samples qualify; shadow rays from one
/// pixel's points towards a quad light over the 202k-triangle dragon did not pay: their
/// bounds, loose by the spread of their reciprocal directions, held so many slots that
/// the walk ran at 0.04x the single rays' speed (`examples/packet_speed.rs --shadows`).
const LEAST_COSINE: f32 = 0.9998;

impl Frustum {
    /// Bounds on the rays of `traceable` (a non-empty lane mask), or `None` where two of
    /// them run opposite ways along an axis, or one runs across an axis (an infinite
    /// reciprocal direction), where the bounds would hold every distance, or where their
    /// directions spread wider than [`LEAST_COSINE`] allows.
    #[inline(always)]
    pub fn new(rays: &[Ray], traceable: u32) -> Option<Self> {
        let first = rays[traceable.trailing_zeros() as usize].dir.normalize();
        let parallel = lanes(traceable).all(|lane| {
            let dir = rays[lane].dir;
            first.dot(dir) >= LEAST_COSINE * dir.length()
        });
        if !parallel {
            return None;
        }
        let mut origin_low = [f32::INFINITY; 3];
        let mut origin_high = [f32::NEG_INFINITY; 3];
        let mut inv_low = [f32::INFINITY; 3];
        let mut inv_high = [f32::NEG_INFINITY; 3];
        let mut t_min = f32::INFINITY;
        for lane in lanes(traceable) {
            let ray = &rays[lane];
            for axis in 0..3 {
                let (o, inv) = (ray.origin[axis], ray.inv_dir[axis]);
                origin_low[axis] = origin_low[axis].min(o);
                origin_high[axis] = origin_high[axis].max(o);
                inv_low[axis] = inv_low[axis].min(inv);
                inv_high[axis] = inv_high[axis].max(inv);
            }
            t_min = t_min.min(ray.t_min);
        }
        let mut frustum = Self {
            near: [0; 3],
            far: [0; 3],
            near_origin: [0.0; 3],
            far_origin: [0.0; 3],
            inv_low,
            inv_high,
            t_min,
        };
        for axis in 0..3 {
            let (low, high) = (inv_low[axis], inv_high[axis]);
            let rising = low > 0.0 && high.is_finite();
            let falling = high < 0.0 && low.is_finite();
            if !(rising || falling) {
                return None;
            }
            // A ray running down an axis meets its max plane first (as `OctRay`).
            let down = falling as usize;
            frustum.near[axis] = axis + 3 * down;
            frustum.far[axis] = axis + 3 - 3 * down;
            // `plane - origin` is least for the largest origin, largest for the least.
            (frustum.near_origin[axis], frustum.far_origin[axis]) = match falling {
                false => (origin_high[axis], origin_low[axis]),
                true => (origin_low[axis], origin_high[axis]),
            };
        }
        Some(frustum)
    }

    /// The slots of `node` that some ray of the packet may enter within its range, whose
    /// `t_max` is at most `reach`, with a lower bound on each one's entry distance.
    ///
    /// Per axis and slot, `d * inv` over the intervals of `d = plane - origin` and of the
    /// reciprocal direction (one sign) is least at `d`'s least end, times the least
    /// `inv` where that end is not negative and the largest where it is; and largest at
    /// `d`'s largest end, likewise. The lane loops compile to vector instructions in the
    /// dispatch's AVX2 and AVX-512 functions.
    #[inline(always)]
    fn enter<const N: usize>(&self, node: &WideNode<N>, reach: f32) -> (u32, [f32; N]) {
        let b = &node.bounds;
        let mut entry = [self.t_min; N];
        let mut exit = [f32::INFINITY; N];
        for axis in 0..3 {
            let (near, far) = (&b[self.near[axis]], &b[self.far[axis]]);
            let (low, high) = (self.inv_low[axis], self.inv_high[axis]);
            for slot in 0..N {
                let d = near[slot] - self.near_origin[axis];
                let least = d * if d >= 0.0 { low } else { high };
                entry[slot] = fast_max(entry[slot], least);
                let d = far[slot] - self.far_origin[axis];
                let largest = d * if d >= 0.0 { high } else { low };
                exit[slot] = fast_min(exit[slot], largest);
            }
        }
        let mut hit = [false; N];
        for slot in 0..N {
            hit[slot] = entry[slot] <= fast_min(exit[slot] * FAR_SLACK, reach);
        }
        let mask = (0..N).fold(0u32, |mask, slot| mask | (hit[slot] as u32) << slot);
        (mask, entry)
    }
}

/// The walk of [`super::packet::walk_packet`] for a packet that `frustum` bounds: the same
/// answers, from one node test a node. `traceable` holds the lanes to trace; `packet` is
/// `rays` laid out by lane, for the leaves.
///
/// # Safety
/// `K`'s instruction set must be available.
#[inline(always)]
pub(crate) unsafe fn walk_frustum<const N: usize, K, L, const ANY: bool>(
    nodes: WalkNodes<'_, N>,
    rays: &[Ray],
    packet: &PacketRays,
    frustum: &Frustum,
    traceable: u32,
    leaves: &mut L,
) -> ([Option<Hit>; PACKET], u32)
where
    K: NodeKernel<N>,
    L: PacketLeaves,
{
    let mut t_max = [0.0; PACKET];
    for (t_max, ray) in t_max.iter_mut().zip(rays) {
        *t_max = ray.t_max;
    }
    let mut best = [None; PACKET];
    // The lanes still looking: every traced lane for closest hits; for any-hit, those
    // not yet blocked.
    let mut live = traceable;
    // The largest `t_max` of the live lanes: a subtree entered farther holds nothing
    // for any of them.
    let mut reach = farthest(&t_max, live);
    let mut stack = nodes.stack::<(u32, u32, f32)>();
    let (mut child, mut count) = (0u32, 0u32);
    loop {
        if count > 0 {
            let lanes = Lanes {
                active: live,
                rays,
                packet,
            };
            leaves.closest_lanes(child, count, lanes, &mut t_max, &mut best);
            if ANY {
                let mut found = [false; PACKET];
                for (found, best) in found.iter_mut().zip(&best) {
                    *found = best.is_some();
                }
                live &= !lane_mask(&found);
                if live == 0 {
                    break;
                }
            }
            reach = farthest(&t_max, live);
        } else {
            // SAFETY: `child` is the root or an interior slot's child.
            let node = unsafe { nodes.node(child) };
            let (mask, t) = frustum.enter(node, reach);
            if mask != 0 {
                // Nearest first, as the single-ray walk orders them.
                // SAFETY: the caller guarantees the instruction set.
                let slots = unsafe { K::far_to_near(mask, &t) };
                let n = mask.count_ones() as usize;
                for &slot in &slots[..n - 1] {
                    let slot = slot as usize;
                    stack.push_in_room((node.child[slot], node.count[slot], t[slot]));
                }
                let nearest = slots[n - 1] as usize;
                (child, count) = (node.child[nearest], node.count[nearest]);
                continue;
            }
        }
        match next_within(&mut stack, reach) {
            Some(entry) => (child, count) = entry,
            None => break,
        }
    }
    let stopped = if ANY { traceable & !live } else { 0 };
    (best, stopped)
}

/// The largest `t_max` of the lanes in `mask` (zero if none: nothing is entered then).
#[inline(always)]
fn farthest(t_max: &[f32; PACKET], mask: u32) -> f32 {
    reduce_lanes(t_max, mask, 0.0, fast_max)
}

/// Pops the next subtree entered no farther than `reach`.
#[inline(always)]
fn next_within(
    stack: &mut crate::traverse::TraversalStack<(u32, u32, f32)>,
    reach: f32,
) -> Option<(u32, u32)> {
    while let Some((child, count, entry)) = stack.pop() {
        if entry <= reach {
            return Some((child, count));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::aabb::Aabb;
    use glam::Vec3;

    use crate::wide::test_numbers::Numbers;

    /// Every slot one of the packet's rays enters by the single-ray test, the frustum
    /// enters too, with an entry bound no farther than that ray's: packets of rays from
    /// nearby points in nearby directions, boxes all about them (some touching the
    /// rays' origins, some flat).
    #[test]
    fn the_frustum_enters_every_slot_its_rays_enter_no_later() {
        let mut numbers = Numbers(0x9e37_79b9_7f4a_7c15);
        let (mut packets, mut entered) = (0, 0);
        for _ in 0..3000 {
            let spread = [0.0, 1e-5, 1e-4, 2e-3][(numbers.next() * 4.0) as usize % 4];
            let (origin, dir) = (numbers.vec(2.0), numbers.vec(1.0));
            let rays: Vec<Ray> = (0..PACKET)
                .map(|_| {
                    let o = origin + numbers.vec(spread);
                    let d = dir + numbers.vec(spread);
                    Ray::new(o, d, numbers.next() * 0.1, 1.0 + numbers.next() * 10.0)
                })
                .collect();
            let Some(frustum) = Frustum::new(&rays, u16::MAX as u32) else {
                continue;
            };
            packets += 1;
            let mut node = WideNode::<8>::empty();
            for slot in 0..7 {
                // Along the rays, or about their origins.
                let along = dir * (numbers.next() * 8.0 - 0.5);
                let a = origin + along + numbers.vec(0.6);
                let mut b = a + numbers.vec(0.6).abs();
                if slot == 3 {
                    b.y = a.y; // flat
                }
                node.set_slot(slot, Aabb { min: a, max: b }, 0, 1);
            }
            let reach = rays.iter().map(|r| r.t_max).fold(0.0, f32::max);
            let (mask, entry) = frustum.enter(&node, reach);
            assert_eq!(mask >> 7, 0, "the empty slot is never entered");
            let packet = PacketRays::new(&rays);
            let t_max: [f32; PACKET] = std::array::from_fn(|lane| rays[lane].t_max);
            for (slot, &bound) in entry.iter().enumerate() {
                let (lanes, t) = packet.enter(&node, slot, &t_max);
                for lane in super::lanes(lanes) {
                    entered += 1;
                    assert!(mask >> slot & 1 == 1, "slot {slot} missed, lane {lane}");
                    assert!(bound <= t[lane], "entry {bound} > {}", t[lane]);
                }
            }
        }
        assert!(
            packets > 2000 && entered > 10_000,
            "{packets} packets, {entered}"
        );
    }

    #[test]
    fn packets_running_both_ways_across_an_axis_or_apart_have_no_frustum() {
        let ray = |d: Vec3| Ray::new(Vec3::ZERO, d, 0.0, 1.0);
        let both = [
            ray(Vec3::new(1.0, 2.0, -3.0)),
            ray(Vec3::new(-1e-6, 2.0, -3.0)),
        ];
        assert!(Frustum::new(&both, 0b11).is_none());
        assert!(
            Frustum::new(&both, 0b01).is_some(),
            "only traced lanes count"
        );
        let across = [ray(Vec3::new(1.0, 0.0, -3.0))];
        assert!(Frustum::new(&across, 0b1).is_none());
        let apart = [
            ray(Vec3::new(1.0, 2.0, -3.0)),
            ray(Vec3::new(1.0, 2.1, -3.0)),
        ];
        assert!(Frustum::new(&apart, 0b11).is_none(), "two degrees apart");
        let near = [
            ray(Vec3::new(1.0, 2.0, -3.0)),
            ray(Vec3::new(1.0, 2.01, -3.0)),
        ];
        assert!(
            Frustum::new(&near, 0b11).is_some(),
            "a fifth of a degree apart"
        );
    }
}
