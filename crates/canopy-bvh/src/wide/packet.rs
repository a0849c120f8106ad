//! Closest hits and occlusion of coherent rays (camera rays of neighbouring pixels and
//! samples, shadow rays from neighbouring points towards one light) as packets of
//! [`PACKET`] rays: the packet walks the tree once, each node's slots tested
//! against all its rays at once (one SIMD lane per ray), and each leaf is tested for the
//! rays that entered it. A single ray pays a node's branches and stack work alone; a
//! packet shares them among rays that go the same way (Wald et al., "Interactive
//! Rendering with Coherent Ray Tracing", 2001; Áfra, "Faster Incoherent Ray Traversal
//! Using 8-Wide AVX Instructions", 2013, for the wide nodes).
//!
//! Each lane's slab test is the single-ray kernel's arithmetic ([`super::kernels`]), and
//! a subtree is skipped for a ray only where that ray's closest hit so far is nearer
//! than the subtree's box, so every ray gets the closest hit a single-ray query gives
//! (ties go to the lower index whatever the order of the tests).
//!
//! Rays that part ways (bounces, shadow rays towards a large light over a large mesh) soon
//! leave a packet with few rays in each subtree; where [`ALONE_AT`] or fewer enter a node,
//! each goes on from there alone through the single-ray walk ([`super::traverse`]), with
//! its closest hit so far, as Embree's hybrid kernels do.
//!
//! The lane loops are plain arrays: compiled inside the dispatch's AVX2 or AVX-512
//! function they become vector instructions, and elsewhere they are the scalar twin.

use super::frustum::{walk_frustum, Frustum};
use super::kernels::NodeKernel;
use super::traverse::{lanes, AloneWalk, Closest, ClosestLeaves, PacketLeaves, WalkNodes};
use super::{WideNode, EMPTY_SLOT};
use crate::aabb::{fast_max, fast_min, FAR_SLACK};
use crate::{Hit, Ray};

/// Rays in a packet.
pub const PACKET: usize = 16;

/// A packet's rays by lane, prepared for slab tests.
pub(crate) struct PacketRays {
    pub origin: [[f32; PACKET]; 3],
    pub dir: [[f32; PACKET]; 3],
    pub inv: [[f32; PACKET]; 3],
    /// Whether the ray runs down each axis (it meets the max plane first).
    down: [[bool; PACKET]; 3],
    pub t_min: [f32; PACKET],
}

impl PacketRays {
    /// Lanes past the end of `rays` copy its first ray.
    #[inline(always)]
    pub(super) fn new(rays: &[Ray]) -> Self {
        let mut packet = Self {
            origin: [[0.0; PACKET]; 3],
            dir: [[0.0; PACKET]; 3],
            inv: [[0.0; PACKET]; 3],
            down: [[false; PACKET]; 3],
            t_min: [0.0; PACKET],
        };
        for lane in 0..PACKET {
            let r = rays.get(lane).unwrap_or(&rays[0]);
            for axis in 0..3 {
                packet.origin[axis][lane] = r.origin[axis];
                packet.dir[axis][lane] = r.dir[axis];
                packet.inv[axis][lane] = r.inv_dir[axis];
                packet.down[axis][lane] = r.inv_dir[axis].is_sign_negative();
            }
            packet.t_min[lane] = r.t_min;
        }
        packet
    }

    /// The lanes whose rays enter `slot` of `node` within `[t_min, t_max]`, and each
    /// lane's entry distance: [`super::kernels::ScalarNode`]'s test, lane by lane.
    #[inline(always)]
    pub(super) fn enter<const N: usize>(
        &self,
        node: &WideNode<N>,
        slot: usize,
        t_max: &[f32; PACKET],
    ) -> (u32, [f32; PACKET]) {
        let b = &node.bounds;
        let low = [b[0][slot], b[1][slot], b[2][slot]];
        let high = [b[3][slot], b[4][slot], b[5][slot]];
        let mut entry = [0.0; PACKET];
        let mut hit = [false; PACKET];
        for lane in 0..PACKET {
            let plane = |axis: usize, near: bool| {
                let plane = match self.down[axis][lane] == near {
                    true => high[axis],
                    false => low[axis],
                };
                (plane - self.origin[axis][lane]) * self.inv[axis][lane]
            };
            let enter = fast_max(
                fast_max(plane(0, true), plane(1, true)),
                fast_max(plane(2, true), self.t_min[lane]),
            );
            let exit = fast_min(fast_min(plane(0, false), plane(1, false)), plane(2, false));
            let exit = fast_min(exit * FAR_SLACK, t_max[lane]);
            entry[lane] = enter;
            hit[lane] = enter <= exit;
        }
        (lane_mask(&hit), entry)
    }
}

/// Bit `lane` set where `set[lane]`: eight lanes at a time, each byte's bit carried into
/// the top byte by one multiplication.
#[inline(always)]
pub(crate) fn lane_mask(set: &[bool; PACKET]) -> u32 {
    // Byte k (0 or 1) times byte 7 - k of the multiplier (2^k) lands on bit 56 + k,
    // and no sum of the other products carries into the top byte.
    const GATHER: u64 = 0x0102_0408_1020_4080;
    set.chunks_exact(8).rev().fold(0, |mask, eight| {
        let mut bytes = [0u8; 8];
        for (byte, &set) in bytes.iter_mut().zip(eight) {
            *byte = set as u8;
        }
        let bits = (u64::from_le_bytes(bytes).wrapping_mul(GATHER) >> 56) as u8;
        mask << 8 | bits as u32
    })
}

/// The least of `values` over the lanes in `mask` (infinity if none).
#[inline(always)]
fn least(values: &[f32; PACKET], mask: u32) -> f32 {
    reduce_lanes(values, mask, f32::INFINITY, fast_min)
}

/// `pick` folded over the `values` of the lanes in `mask` (`none` if there are none),
/// reduced pairwise across halves so that it compiles to vector shuffles.
#[inline(always)]
pub(super) fn reduce_lanes(
    values: &[f32; PACKET],
    mask: u32,
    none: f32,
    pick: impl Fn(f32, f32) -> f32,
) -> f32 {
    let mut m = [none; PACKET];
    for (lane, m) in m.iter_mut().enumerate() {
        if mask >> lane & 1 == 1 {
            *m = values[lane];
        }
    }
    let mut half = PACKET / 2;
    while half > 0 {
        for lane in 0..half {
            m[lane] = pick(m[lane], m[lane + half]);
        }
        half /= 2;
    }
    m[0]
}

/// The rays of a packet that a leaf is tested for.
pub(crate) struct Lanes<'a> {
    /// Bit `lane` set for each ray to test.
    pub active: u32,
    pub rays: &'a [Ray],
    pub packet: &'a PacketRays,
}

impl Lanes<'_> {
    /// Tests the leaf for one lane at a time through `leaves`' single-ray test (told of
    /// each change of ray).
    #[inline(always)]
    pub fn each<L: ClosestLeaves + ?Sized>(
        &self,
        leaves: &mut L,
        first: u32,
        count: u32,
        t_max: &mut [f32; PACKET],
        best: &mut [Option<Hit>; PACKET],
    ) {
        for lane in lanes(self.active) {
            let mut search = Closest {
                ray: Ray {
                    t_max: t_max[lane],
                    ..self.rays[lane]
                },
                best: best[lane],
            };
            leaves.new_ray();
            leaves.closest(first, count, &mut search, &mut ());
            (t_max[lane], best[lane]) = (search.ray.t_max, search.best);
        }
    }
}

/// A subtree on the stack: a slot's `child` and `count` (see [`WideNode`]), the lanes
/// that entered it and their entry distances.
#[derive(Clone, Copy)]
struct Entry {
    child: u32,
    count: u32,
    lanes: u32,
    entry: [f32; PACKET],
}

/// A packet goes on ray by ray once this few of its rays (or fewer) enter a node
/// together: a node's test for the packet costs about what it costs a ray alone, so
/// with few rays left the packet's stack work and box tests of absent lanes outweigh
/// what they share (Embree's hybrid kernels switch likewise; Benthin et al., "Combining
/// Single and Packet-Ray Tracing for Arbitrary Ray Distributions on the Intel MIC
/// Architecture", 2012). 2 to 6 measured alike on the 202k dragon's camera, shadow and
/// bounce rays; never switching left its bounce rays at 0.68x the single-ray walk's
/// speed, 4 at 0.81x (docs/performance.md, "Packets that go on ray by ray").
const ALONE_AT: u32 = 4;

/// The walk of `rays` (at most [`PACKET`]) through `nodes` (non-empty) with the node
/// kernel `K`. Without `ANY`, each ray goes on to the closest hit
/// [`super::traverse::closest`] gives it; with `ANY`, each stops at its first hit
/// (any-hit, as [`super::traverse::any`] answers), leaving the packet, and the walk ends
/// when every ray has. Returns each lane's closest hit (without `ANY`) and the lanes that
/// stopped (with `ANY`). Where [`ALONE_AT`] rays or fewer enter a node, each goes on
/// alone from there ([`PacketLeaves::closest_alone`]).
///
/// # Safety
/// `K`'s instruction set must be available.
#[inline(always)]
pub(crate) unsafe fn walk_packet<const N: usize, K, L, const ANY: bool>(
    nodes: WalkNodes<'_, N>,
    rays: &[Ray],
    leaves: &mut L,
) -> ([Option<Hit>; PACKET], u32)
where
    K: NodeKernel<N>,
    L: PacketLeaves,
{
    debug_assert!(rays.len() <= PACKET);
    // A NaN or degenerate ray misses everything (see Ray); so do the lanes past the end.
    let traceable = rays.iter().enumerate().fold(0u32, |mask, (lane, r)| {
        mask | (r.is_traceable() as u32) << lane
    });
    let packet = PacketRays::new(rays);
    if traceable == 0 {
        return ([None; PACKET], 0);
    }
    // Nearly parallel rays walk as one.
    if let Some(frustum) = Frustum::new(rays, traceable) {
        // SAFETY: the caller's guarantee.
        return unsafe {
            walk_frustum::<N, K, L, ANY>(nodes, rays, &packet, &frustum, traceable, leaves)
        };
    }
    // Each ray's range, shrunk to its closest hit so far, and that hit.
    let mut t_max = [0.0; PACKET];
    for (t_max, ray) in t_max.iter_mut().zip(rays) {
        *t_max = ray.t_max;
    }
    let mut best = [None; PACKET];
    // The lanes that stopped (any-hit only): they take no further part.
    let mut stopped = 0u32;
    let mut stack = nodes.stack::<Entry>();
    let mut alone = AloneWalk::new(nodes);
    let (mut child, mut count, mut active) = (0u32, 0u32, traceable);
    while active != 0 {
        if count > 0 {
            let lanes = Lanes {
                active,
                rays,
                packet: &packet,
            };
            leaves.closest_lanes(child, count, lanes, &mut t_max, &mut best);
            if ANY {
                let mut found = [false; PACKET];
                for (found, best) in found.iter_mut().zip(&best) {
                    *found = best.is_some();
                }
                stopped |= lane_mask(&found) & active;
                if stopped == traceable {
                    break;
                }
            }
        } else if active.count_ones() <= ALONE_AT {
            for lane in lanes(active) {
                let ray = Ray {
                    t_max: t_max[lane],
                    ..rays[lane]
                };
                let start = (child, count);
                if ANY {
                    // SAFETY: the caller guarantees the instruction set; `child` is the
                    // root or a node's slot.
                    if unsafe { leaves.any_alone::<N, K>(nodes, start, &ray, &mut alone) } {
                        stopped |= 1 << lane;
                    }
                } else {
                    let search = Closest {
                        ray,
                        best: best[lane],
                    };
                    // SAFETY: as above.
                    let search =
                        unsafe { leaves.closest_alone::<N, K>(nodes, start, search, &mut alone) };
                    (t_max[lane], best[lane]) = (search.ray.t_max, search.best);
                }
            }
            if ANY && stopped == traceable {
                break;
            }
        } else {
            // SAFETY: `child` is the root or an interior slot's child.
            let node = unsafe { nodes.node(child) };
            // Entered slots, by the nearest entry of their rays.
            let mut entered = [(0usize, 0u32, 0f32); N];
            let mut entries = [[0f32; PACKET]; N];
            let mut n = 0;
            for slot in 0..N {
                if node.count[slot] == EMPTY_SLOT {
                    break;
                }
                let (mask, entry) = packet.enter(node, slot, &t_max);
                let mask = mask & active;
                if mask == 0 {
                    continue;
                }
                entered[n] = (slot, mask, least(&entry, mask));
                entries[n] = entry;
                n += 1;
            }
            if n > 0 {
                // Far to near (insertion sort of a few); all but the nearest go on the
                // stack, and the packet descends into the nearest.
                let mut order: [usize; N] = std::array::from_fn(|i| i);
                for i in 1..n {
                    let mut j = i;
                    while j > 0 && entered[order[j - 1]].2 < entered[order[j]].2 {
                        order.swap(j - 1, j);
                        j -= 1;
                    }
                }
                for &k in &order[..n - 1] {
                    let (slot, mask, _) = entered[k];
                    stack.push_in_room(Entry {
                        child: node.child[slot],
                        count: node.count[slot],
                        lanes: mask,
                        entry: entries[k],
                    });
                }
                let (slot, mask, _) = entered[order[n - 1]];
                (child, count, active) = (node.child[slot], node.count[slot], mask);
                continue;
            }
        }
        // Pop the next subtree that can still hold a closer hit for one of its rays
        // (or, any-hit, that holds rays still looking).
        active = 0;
        while let Some(e) = stack.pop() {
            let mut open = [false; PACKET];
            for lane in 0..PACKET {
                open[lane] = e.entry[lane] <= t_max[lane];
            }
            let live = lane_mask(&open) & e.lanes & !stopped;
            if live != 0 {
                (child, count, active) = (e.child, e.count, live);
                break;
            }
        }
    }
    (best, stopped)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lane_masks_carry_each_lane_to_its_bit() {
        for pattern in [0u32, 1, 0x8000, 0xffff, 0xa5c3, 0x0180, 0x7ffe] {
            let set: [bool; PACKET] = std::array::from_fn(|lane| pattern >> lane & 1 == 1);
            assert_eq!(lane_mask(&set), pattern);
        }
    }

    #[test]
    fn least_takes_the_lanes_in_the_mask() {
        let values: [f32; PACKET] = std::array::from_fn(|lane| 20.0 - lane as f32);
        assert_eq!(least(&values, 0), f32::INFINITY);
        assert_eq!(least(&values, 0b101), 18.0);
        assert_eq!(least(&values, 1 << 15), 5.0);
        assert_eq!(least(&values, 0xffff), 5.0);
    }
}
