//! Closest-hit and any-hit traversal of a [`Bvh2`], generic over the primitive test.

use crate::aabb::SlabRay;
use crate::{Bvh2, Bvh2Node, Hit, IntoHit, Ray};
use std::mem::MaybeUninit;

/// Entries a [`TraversalStack`] holds before it spills to the heap: a wide walk's room
/// ([`crate::wide::BvhN`]'s `stack_room`) for 18 levels of 8-wide nodes (the 202k dragon
/// has 7), so that walks of one ray (counts, lists) make their room without allocating.
const STACK_INLINE: usize = 128;

/// Traversal stack: a fixed array for the common case, spilling to the heap only for
/// trees deeper than its capacity (degenerate inputs can make very deep trees). The array
/// is left uninitialised: clearing it would cost more than a short traversal. Spilled
/// entries sit above a full array, so `pop` looks at the heap only when the array is full.
pub(crate) struct TraversalStack<T: Copy> {
    inline: [MaybeUninit<T>; STACK_INLINE],
    len: usize,
    spill: Vec<T>,
}

impl<T: Copy> TraversalStack<T> {
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self {
            inline: [const { MaybeUninit::uninit() }; STACK_INLINE],
            len: 0,
            spill: Vec::new(),
        }
    }

    /// An empty stack with room for `entries` entries in all, which
    /// [`TraversalStack::push_in_room`] fills without allocating. Its spill is allocated before the stack is
    /// made, so that no call sees the stack's address: made empty and then given room,
    /// a stack returned to its walk was copied there, 1.5 KB of unused entries through
    /// `memcpy` for every packet.
    #[inline(always)]
    pub(crate) fn with_room(entries: usize) -> Self {
        let heap = entries.saturating_sub(STACK_INLINE);
        Self {
            inline: [const { MaybeUninit::uninit() }; STACK_INLINE],
            len: 0,
            spill: if heap == 0 {
                Vec::new()
            } else {
                spill_with_room(heap)
            },
        }
    }

    /// Empties the stack (a walk that stopped early leaves entries behind), keeping its
    /// memory for the next walk.
    #[inline(always)]
    pub(crate) fn clear(&mut self) {
        self.len = 0;
        self.spill.clear();
    }

    #[inline(always)]
    pub(crate) fn push(&mut self, item: T) {
        if self.len < STACK_INLINE {
            self.inline[self.len].write(item);
            self.len += 1;
        } else {
            self.spill.push(item);
        }
    }

    /// [`TraversalStack::push`] without a call that returns: the entry goes into the room
    /// made by [`TraversalStack::with_room`], so that a walk's loop holds no call and the
    /// compiler keeps the walk's values in registers through it (a call in the loop, even
    /// one never made, had them all reloaded from the stack at every node).
    ///
    /// # Panics
    /// If no room is left: the room made was too small for the walk (a bug; a panic,
    /// whose call never returns, keeps the walk's values in registers as no allocating
    /// call would).
    #[inline(always)]
    pub(crate) fn push_in_room(&mut self, item: T) {
        if self.len < STACK_INLINE {
            self.inline[self.len].write(item);
            self.len += 1;
        } else {
            let at = self.spill.len();
            assert!(at < self.spill.capacity(), "no room made for a stack entry");
            // SAFETY: `at` is below the capacity (checked), and the entry is written
            // before the length counts it.
            unsafe {
                self.spill.as_mut_ptr().add(at).write(item);
                self.spill.set_len(at + 1);
            }
        }
    }

    /// Pushes `entry(i)` for every set bit `i` of `mask` (below `N`), lowest first.
    /// Where the array has room for `N` more, every entry is written and only the set
    /// ones are counted: no branch per entry, whose outcome (which slots a ray enters)
    /// is a coin toss.
    #[inline(always)]
    pub(crate) fn push_masked<const N: usize>(&mut self, mask: u32, entry: impl Fn(usize) -> T) {
        if self.len + N <= STACK_INLINE {
            let mut len = self.len;
            for i in 0..N {
                // SAFETY: `len` stays below `self.len + N`, within the array (checked).
                unsafe { self.inline.get_unchecked_mut(len) }.write(entry(i));
                len += (mask >> i & 1) as usize;
            }
            self.len = len;
        } else {
            let mut rest = mask;
            while rest != 0 {
                self.push_in_room(entry(rest.trailing_zeros() as usize));
                rest &= rest - 1;
            }
        }
    }

    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        if self.len == STACK_INLINE {
            if let Some(item) = self.spill.pop() {
                return Some(item);
            }
        }
        self.len -= 1;
        // SAFETY: entries below `len` were written by `push` and not yet popped.
        Some(unsafe { self.inline[self.len].assume_init() })
    }
}

/// The state of a closest-hit search: the ray (its `t_max` shrinking to the best hit so
/// far), the same ray prepared for slab tests, and the best hit.
pub(crate) struct ClosestHitSearch {
    pub ray: Ray,
    pub slab: SlabRay,
    pub best: Option<Hit>,
}

impl ClosestHitSearch {
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        Self {
            ray: *ray,
            slab: SlabRay::new(ray),
            best: None,
        }
    }

    /// Tests a leaf's primitives, keeping the closest hit (ties to the lower index).
    #[inline(always)]
    pub fn test_leaf<F, P, C>(&mut self, prims: &[u32], hit_prim: &mut F, counter: &mut C)
    where
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
        C: TraversalCounter,
    {
        for &prim in prims {
            counter.test_primitive();
            if let Some(hit) = hit_prim(prim, &self.ray) {
                self.offer(hit.into_hit(prim));
            }
        }
    }

    /// Keeps `hit` if it comes before the best so far.
    #[inline(always)]
    pub fn offer(&mut self, hit: Hit) {
        if self.best.is_none_or(|b| hit.is_before(&b)) {
            self.ray.t_max = hit.t;
            self.slab.t_max = hit.t;
            self.best = Some(hit);
        }
    }
}

/// Receives traversal events; `()` ignores them and compiles to nothing.
pub trait TraversalCounter {
    /// Whether the counter keeps anything (queries may skip their counting then).
    const COUNTS: bool = true;
    /// A node's children were box-tested (interior) or its primitives tested (leaf).
    #[inline(always)]
    fn visit_node(&mut self) {}
    /// One primitive test.
    #[inline(always)]
    fn test_primitive(&mut self) {}
}

impl TraversalCounter for () {
    const COUNTS: bool = false;
}

/// Counts of traversal work, summed over any number of rays.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TraversalStats {
    pub nodes_visited: u64,
    pub primitives_tested: u64,
}

impl TraversalStats {
    /// Reports these counts to `counter`, event by event.
    pub fn replay<C: TraversalCounter>(&self, counter: &mut C) {
        for _ in 0..self.nodes_visited {
            counter.visit_node();
        }
        for _ in 0..self.primitives_tested {
            counter.test_primitive();
        }
    }
}

impl TraversalCounter for TraversalStats {
    #[inline(always)]
    fn visit_node(&mut self) {
        self.nodes_visited += 1;
    }
    #[inline(always)]
    fn test_primitive(&mut self) {
        self.primitives_tested += 1;
    }
}

impl Bvh2 {
    /// Closest hit along `ray` within `[t_min, t_max]`.
    ///
    /// `hit_prim(prim, ray)` tests one primitive and returns its hit distance (`f32`) or
    /// [`PrimHit`], if any, in `[ray.t_min, ray.t_max]`; the `ray` it sees has `t_max`
    /// shrunk to the closest hit so far. Equal distances resolve to the lower primitive index (see [`Hit::is_before`]),
    /// so the answer matches a brute-force loop exactly.
    #[inline]
    pub fn intersect<F, P>(&self, ray: &Ray, hit_prim: F) -> Option<Hit>
    where
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
    {
        self.intersect_counted(ray, hit_prim, &mut ())
    }

    /// [`Bvh2::intersect`], reporting its work to `counter`.
    pub fn intersect_counted<F, P, C>(
        &self,
        ray: &Ray,
        mut hit_prim: F,
        counter: &mut C,
    ) -> Option<Hit>
    where
        F: FnMut(u32, &Ray) -> Option<P>,
        P: IntoHit,
        C: TraversalCounter,
    {
        let root = self.nodes.first().filter(|_| ray.is_traceable())?;
        let mut search = ClosestHitSearch::new(ray);
        if search.slab.entry_or_inf(root.min, root.max) == f32::INFINITY {
            return None;
        }
        let mut stack = TraversalStack::<(u32, f32)>::new();
        let mut node = root;
        loop {
            counter.visit_node();
            if node.is_leaf() {
                search.test_leaf(self.leaf_prims(node), &mut hit_prim, counter);
            } else {
                let [(near, t_near), (far, t_far)] = self.children_near_first(node, &search.slab);
                if t_near != f32::INFINITY {
                    if t_far != f32::INFINITY {
                        stack.push((far, t_far));
                    }
                    node = &self.nodes[near as usize];
                    continue;
                }
            }
            // Pop the next subtree that can still hold a closer (or equally close) hit.
            loop {
                match stack.pop() {
                    None => return search.best,
                    Some((index, t_entry)) if t_entry <= search.ray.t_max => {
                        node = &self.nodes[index as usize];
                        break;
                    }
                    Some(_) => {}
                }
            }
        }
    }

    /// The two children of interior `node`, nearer first, each with the ray's entry
    /// distance (infinity where the ray misses its box).
    #[inline(always)]
    fn children_near_first(&self, node: &Bvh2Node, slab: &SlabRay) -> [(u32, f32); 2] {
        let (left, right) = (node.first, node.first + 1);
        let (l, r) = (&self.nodes[left as usize], &self.nodes[right as usize]);
        let t_left = slab.entry_or_inf(l.min, l.max);
        let t_right = slab.entry_or_inf(r.min, r.max);
        if t_left <= t_right {
            [(left, t_left), (right, t_right)]
        } else {
            [(right, t_right), (left, t_left)]
        }
    }

    /// Whether anything blocks `ray` within `[t_min, t_max]` (any hit; for shadow rays).
    pub fn occluded<F>(&self, ray: &Ray, mut hit_prim: F) -> bool
    where
        F: FnMut(u32, &Ray) -> bool,
    {
        let Some(root) = self.nodes.first().filter(|_| ray.is_traceable()) else {
            return false;
        };
        let slab = SlabRay::new(ray);
        if slab.entry_or_inf(root.min, root.max) == f32::INFINITY {
            return false;
        }
        let mut stack = TraversalStack::<u32>::new();
        let mut node = root;
        loop {
            if node.is_leaf() {
                if self.leaf_prims(node).iter().any(|&p| hit_prim(p, ray)) {
                    return true;
                }
            } else {
                // Nearer child first, where a blocker is likeliest.
                let [(near, t_near), (far, t_far)] = self.children_near_first(node, &slab);
                if t_near != f32::INFINITY {
                    if t_far != f32::INFINITY {
                        stack.push(far);
                    }
                    node = &self.nodes[near as usize];
                    continue;
                }
            }
            match stack.pop() {
                Some(index) => node = &self.nodes[index as usize],
                None => return false,
            }
        }
    }
}

/// A stack's spill with room for `heap` entries, made out of line: most walks need none.
#[cold]
#[inline(never)]
fn spill_with_room<T>(heap: usize) -> Vec<T> {
    Vec::with_capacity(heap)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stack_spills_past_inline_capacity_and_stays_lifo() {
        let mut s = TraversalStack::<u32>::new();
        for i in 0..200 {
            s.push(i);
        }
        for i in (0..200).rev() {
            assert_eq!(s.pop(), Some(i));
        }
        assert_eq!(s.pop(), None);
    }

    #[test]
    fn a_stack_made_with_room_takes_that_many_entries_in_its_room() {
        for room in [0, 1, STACK_INLINE, STACK_INLINE + 1, 300] {
            let mut s = TraversalStack::<u32>::with_room(room);
            let spill = s.spill.as_ptr();
            for i in 0..room as u32 {
                s.push_in_room(i);
            }
            assert_eq!(s.spill.as_ptr(), spill, "no reallocation within the room");
            for i in (0..room as u32).rev() {
                assert_eq!(s.pop(), Some(i));
            }
            assert_eq!(s.pop(), None);
        }
    }
}
