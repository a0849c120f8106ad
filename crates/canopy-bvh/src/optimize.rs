//! Tree optimisation by reinsertion (Bittner, Hapala & Havran, "Fast insertion-based
//! optimization of bounding volume hierarchies", 2013), usable after any builder.
//!
//! A pass takes every subtree in turn, the largest first: it cuts the subtree out (its
//! sibling takes its parent's place), puts it back where it adds the least surface area —
//! the area of the new parent plus what every ancestor grows by — under its old parent
//! node. Putting it back where it was is always a candidate, so a pass never makes the SAH
//! worse. Leaves keep their primitives, so the result is emitted as a new [`Bvh2`] in
//! depth-first order.
//!
//! The search for the best place (branch and bound from the root) is the expensive part,
//! so it runs in parallel, in the manner of Meister & Bittner ("Parallel reinsertion for
//! bounding volume hierarchy optimization", 2018): for a batch of subtrees at a time,
//! every search reads the tree as the batch found it; the moves are then made one by one,
//! each priced again on the tree as it stands and made only where it beats putting the
//! subtree back. The batches are fixed, so the result does not depend on the threads.

use crate::{Aabb, Bvh2, Bvh2Node, SahCosts};
use rayon::prelude::*;
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::time::{Duration, Instant};

/// How long the optimiser may work.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OptimizeBudget {
    /// At most this many passes over all nodes (stops early when a pass gains < 0.1%).
    Passes(u32),
    /// Passes until this much time has gone (checked between batches of 256 subtrees), or
    /// until a pass gains < 0.1%.
    Time(Duration),
}

/// What optimisation did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OptimizeReport {
    pub sah_before: f32,
    pub sah_after: f32,
    pub passes: u32,
    /// Subtrees that moved.
    pub moves: u64,
}

const NONE: u32 = u32::MAX;

/// Subtrees whose places are searched for together, on one state of the tree.
const BATCH: usize = 256;

/// A node of the editable tree: a parent link, and children or a leaf's primitives.
#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    parent: u32,
    /// Children, or `[first, count]` of a leaf's primitives when `leaf`.
    links: [u32; 2],
    leaf: bool,
}

struct Tree {
    nodes: Vec<Node>,
    root: u32,
}

/// Optimises `bvh` by reinsertion within `budget`; returns the new tree and what changed.
/// The SAH never increases. Primitives stay in the same leaves.
pub fn optimize(bvh: &Bvh2, costs: &SahCosts, budget: OptimizeBudget) -> (Bvh2, OptimizeReport) {
    let sah_before = bvh.stats(costs).sah_cost;
    let mut report = OptimizeReport {
        sah_before,
        sah_after: sah_before,
        passes: 0,
        moves: 0,
    };
    if bvh.nodes().len() < 5 {
        return (bvh.clone(), report);
    }
    let mut tree = Tree::from_bvh2(bvh);
    let start = Instant::now();
    let (max_passes, deadline) = match budget {
        OptimizeBudget::Passes(n) => (n, None),
        OptimizeBudget::Time(t) => (u32::MAX, Some(t)),
    };
    let out_of_time = || deadline.is_some_and(|d| start.elapsed() >= d);
    let mut area = tree.internal_area();
    while report.passes < max_passes && !out_of_time() {
        report.passes += 1;
        // The largest subtrees first: their misplacement costs the most.
        let mut order: Vec<u32> = (0..tree.nodes.len() as u32)
            .filter(|&n| n != tree.root && tree.nodes[n as usize].parent != tree.root)
            .collect();
        order.sort_by(|&a, &b| {
            let area = |n: u32| tree.nodes[n as usize].bounds.surface_area();
            area(b).total_cmp(&area(a))
        });
        for batch in order.chunks(BATCH) {
            if out_of_time() {
                break;
            }
            let targets: Vec<u32> = batch
                .par_iter()
                .map_init(Search::default, |search, &n| tree.best_place(n, search))
                .collect();
            for (&n, target) in batch.iter().zip(targets) {
                report.moves += tree.reinsert(n, target) as u64;
            }
        }
        let new_area = tree.internal_area();
        let gained = (area - new_area) / area.max(f64::MIN_POSITIVE);
        area = new_area;
        if gained < 1e-3 {
            break;
        }
    }
    let optimized = tree.to_bvh2(bvh);
    report.sah_after = optimized.stats(costs).sah_cost;
    (optimized, report)
}

/// What a search for a subtree's place works in, kept from one search to the next.
#[derive(Default)]
struct Search {
    path: Vec<(u32, Aabb)>,
    heap: BinaryHeap<Candidate>,
}

/// A candidate sibling in the search, ordered by the cost it inherits from its ancestors;
/// `path` is its place among the ancestors of the subtree being placed, or `NONE`.
struct Candidate {
    node: u32,
    inherited: f32,
    path: u32,
}

impl PartialEq for Candidate {
    fn eq(&self, other: &Self) -> bool {
        self.inherited == other.inherited
    }
}
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Candidate {
    fn cmp(&self, other: &Self) -> Ordering {
        // A min-heap on the inherited cost.
        other.inherited.total_cmp(&self.inherited)
    }
}

impl Tree {
    fn from_bvh2(bvh: &Bvh2) -> Self {
        let mut nodes: Vec<Node> = bvh
            .nodes()
            .iter()
            .map(|n| Node {
                bounds: n.bounds(),
                parent: NONE,
                links: if n.is_leaf() {
                    [n.first, n.count]
                } else {
                    [n.first, n.first + 1]
                },
                leaf: n.is_leaf(),
            })
            .collect();
        for i in 0..nodes.len() {
            if !nodes[i].leaf {
                for c in nodes[i].links {
                    nodes[c as usize].parent = i as u32;
                }
            }
        }
        Self { nodes, root: 0 }
    }

    /// Sum of the interior nodes' surface areas (what reinsertion changes).
    fn internal_area(&self) -> f64 {
        self.nodes
            .iter()
            .filter(|n| !n.leaf)
            .map(|n| n.bounds.surface_area() as f64)
            .sum()
    }

    fn sibling(&self, n: u32) -> u32 {
        let p = &self.nodes[self.nodes[n as usize].parent as usize];
        if p.links[0] == n {
            p.links[1]
        } else {
            p.links[0]
        }
    }

    fn replace_child(&mut self, parent: u32, old: u32, new: u32) {
        let links = &mut self.nodes[parent as usize].links;
        if links[0] == old {
            links[0] = new;
        } else {
            debug_assert_eq!(links[1], old);
            links[1] = new;
        }
        self.nodes[new as usize].parent = parent;
    }

    /// Recomputes boxes from `n` up to the root.
    fn refit_up(&mut self, mut n: u32) {
        while n != NONE {
            let node = self.nodes[n as usize];
            let [a, b] = node.links;
            self.nodes[n as usize].bounds = self.nodes[a as usize]
                .bounds
                .union(self.nodes[b as usize].bounds);
            n = node.parent;
        }
    }

    /// Whether `a` is `n` or lies below it.
    fn is_within(&self, mut a: u32, n: u32) -> bool {
        while a != NONE {
            if a == n {
                return true;
            }
            a = self.nodes[a as usize].parent;
        }
        false
    }

    /// What putting a box `b` beside node `t` adds to the interior area: the new parent,
    /// plus the growth of every ancestor of `t`.
    fn insertion_cost(&self, t: u32, b: Aabb) -> f32 {
        let mut cost = self.nodes[t as usize].bounds.union(b).surface_area();
        let mut a = self.nodes[t as usize].parent;
        while a != NONE {
            let bounds = self.nodes[a as usize].bounds;
            cost += bounds.union(b).surface_area() - bounds.surface_area();
            a = self.nodes[a as usize].parent;
        }
        cost
    }

    /// Moves subtree `n` beside `target` if that adds less area than putting it back
    /// beside its sibling; whether it moved. A target the tree no longer allows (inside
    /// `n`, or `n`'s parent, which the cut removes) means putting it back.
    fn reinsert(&mut self, n: u32, target: u32) -> bool {
        // The root and its children cannot move (the root may have changed this pass).
        if n == self.root || self.nodes[n as usize].parent == self.root {
            return false;
        }
        let parent = self.nodes[n as usize].parent;
        let sibling = self.sibling(n);
        // Most subtrees are best where they are; a target inside `n` (or its parent, which
        // the cut removes) is one that earlier moves of the batch have made impossible.
        if target == sibling || target == parent || self.is_within(target, n) {
            return false;
        }
        let grand = self.nodes[parent as usize].parent;
        // Cut: the sibling takes the parent's place.
        self.replace_child(grand, parent, sibling);
        self.refit_up(grand);
        let b = self.nodes[n as usize].bounds;
        let target = match self.insertion_cost(target, b) < self.insertion_cost(sibling, b) {
            true => target,
            false => sibling,
        };
        // Insert under the old parent node, as the target's sibling.
        let above = self.nodes[target as usize].parent;
        if above == NONE {
            self.root = parent;
            self.nodes[parent as usize].parent = NONE;
        } else {
            self.replace_child(above, target, parent);
        }
        self.nodes[parent as usize].links = [target, n];
        self.nodes[target as usize].parent = parent;
        self.nodes[n as usize].parent = parent;
        self.refit_up(parent);
        target != sibling
    }

    /// The node beside which subtree `n` adds the least area once cut out (branch and
    /// bound from the root over the area of the new parent plus the growth of every
    /// ancestor). The tree is only read: `n`'s ancestors are priced with the boxes the
    /// cut would leave them, its parent (which the cut removes) is no candidate, nor is
    /// anything in `n`'s subtree.
    fn best_place(&self, n: u32, search: &mut Search) -> u32 {
        let parent = self.nodes[n as usize].parent;
        if parent == NONE || self.nodes[parent as usize].parent == NONE {
            return self.root; // `reinsert` leaves these where they are
        }
        // `n`'s ancestors, root first, each with its box once `n` is cut out; the
        // parent last (its box unused).
        let path = &mut search.path;
        path.clear();
        let (mut child, mut bounds) = (parent, self.nodes[self.sibling(n) as usize].bounds);
        let mut a = self.nodes[parent as usize].parent;
        while a != NONE {
            let [l, r] = self.nodes[a as usize].links;
            let other = if l == child { r } else { l };
            bounds = bounds.union(self.nodes[other as usize].bounds);
            path.push((a, bounds));
            (child, a) = (a, self.nodes[a as usize].parent);
        }
        path.reverse();
        path.push((parent, Aabb::EMPTY));
        let b = self.nodes[n as usize].bounds;
        let own = b.surface_area();
        let mut best = (f32::INFINITY, self.root);
        let heap = &mut search.heap;
        heap.clear();
        heap.push(Candidate {
            node: self.root,
            inherited: 0.0,
            path: 0,
        });
        while let Some(Candidate {
            node,
            inherited,
            path: on,
        }) = heap.pop()
        {
            // Every placement in this subtree costs at least the new parent's own area.
            if inherited + own >= best.0 {
                break;
            }
            let x = &self.nodes[node as usize];
            if node == parent {
                // Cut out, it leaves the sibling in its place at no cost of its own.
                let sibling = x.links.into_iter().filter(|&c| c != n);
                heap.extend(sibling.map(|node| Candidate {
                    node,
                    inherited,
                    path: NONE,
                }));
                continue;
            }
            let bounds = match on {
                NONE => x.bounds,
                i => path[i as usize].1,
            };
            let merged = bounds.union(b).surface_area();
            let cost = inherited + merged;
            if cost < best.0 {
                best = (cost, node);
            }
            if !x.leaf {
                let inherited = inherited + merged - bounds.surface_area();
                if inherited + own < best.0 {
                    for c in x.links {
                        let next = on.wrapping_add(1);
                        let on_path =
                            on != NONE && path.get(next as usize).is_some_and(|p| p.0 == c);
                        heap.push(Candidate {
                            node: c,
                            inherited,
                            path: if on_path { next } else { NONE },
                        });
                    }
                }
            }
        }
        best.1
    }

    /// The tree as a [`Bvh2`] in depth-first order, leaves' primitives copied from `old`.
    fn to_bvh2(&self, old: &Bvh2) -> Bvh2 {
        let mut nodes = Vec::with_capacity(self.nodes.len());
        let mut prims = Vec::with_capacity(old.prim_indices().len());
        nodes.push(Bvh2Node::leaf(self.nodes[self.root as usize].bounds, 0, 1));
        // (slot in `nodes`, node of this tree)
        let mut stack = vec![(0usize, self.root)];
        while let Some((slot, n)) = stack.pop() {
            let node = &self.nodes[n as usize];
            if node.leaf {
                let [first, count] = node.links;
                let start = prims.len() as u32;
                prims.extend_from_slice(
                    &old.prim_indices()[first as usize..(first + count) as usize],
                );
                nodes[slot] = Bvh2Node::leaf(node.bounds, start, count);
            } else {
                let left = nodes.len();
                nodes[slot] = Bvh2Node::interior(node.bounds, left as u32);
                for c in node.links {
                    nodes.push(Bvh2Node::leaf(self.nodes[c as usize].bounds, 0, 1));
                }
                stack.push((left + 1, node.links[1]));
                stack.push((left, node.links[0]));
            }
        }
        let mut bvh = Bvh2::from_parts(nodes, prims);
        bvh.spatial_splits = old.has_spatial_splits();
        bvh
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{build, BuildParams, Builder, Ray};
    use glam::Vec3;

    fn random_boxes(n: usize, seed: u64) -> Vec<Aabb> {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        (0..n)
            .map(|_| {
                let c = Vec3::new(next(), next(), next()) * 10.0;
                let e = Vec3::new(next(), next(), next()) * 0.3;
                Aabb::new(c - e, c + e)
            })
            .collect()
    }

    #[test]
    fn optimizing_keeps_a_valid_tree_and_never_raises_the_sah() {
        let costs = SahCosts::default();
        for (n, seed) in [(1, 1), (2, 2), (3, 3), (7, 4), (100, 5), (2000, 6)] {
            let boxes = random_boxes(n, seed);
            for builder in [
                Builder::Lbvh,
                Builder::Ploc,
                Builder::MortonMedian,
                Builder::BinnedSah,
            ] {
                let bvh = build(builder, &boxes, &BuildParams::default());
                let (opt, report) = optimize(&bvh, &costs, OptimizeBudget::Passes(3));
                assert_eq!(opt.validate(&boxes), Ok(()), "{builder} n={n}");
                assert!(
                    report.sah_after <= report.sah_before * (1.0 + 1e-5),
                    "{builder} n={n}: {report:?}"
                );
                assert_eq!(report.sah_after, opt.stats(&costs).sah_cost);
                // The same closest hits as before.
                for i in 0..50 {
                    let o = Vec3::new(i as f32 * 0.2, -1.0, 5.0);
                    let ray = Ray::new(
                        o,
                        Vec3::new(0.1, 1.0, 0.05 * i as f32 - 1.0),
                        0.0,
                        f32::INFINITY,
                    );
                    let hit = |t: &Bvh2| {
                        t.intersect(&ray, |p, r| boxes[p as usize].ray_entry(r))
                            .map(|h| (h.prim, h.t))
                    };
                    assert_eq!(hit(&opt), hit(&bvh), "{builder} n={n} ray {i}");
                }
            }
        }
    }

    #[test]
    fn a_badly_built_tree_improves_a_lot() {
        let boxes = random_boxes(3000, 9);
        let costs = SahCosts::default();
        let bad = build(Builder::MortonMedian, &boxes, &BuildParams::default());
        let good = build(Builder::SweepSah, &boxes, &BuildParams::default());
        let (_, report) = optimize(&bad, &costs, OptimizeBudget::Passes(10));
        let target = good.stats(&costs).sah_cost;
        // Measured: 99.7 to 77.2 (sweep SAH: 44.4); the median split's leaves stay.
        assert!(report.sah_after < report.sah_before * 0.85, "{report:?}");
        assert!(report.sah_after > target, "{report:?}");
        assert!(report.moves > 0 && report.passes >= 1);
    }

    #[test]
    fn the_optimised_tree_does_not_depend_on_the_threads() {
        // Enough subtrees for several batches, searched in parallel.
        let boxes = random_boxes(5000, 11);
        let bvh = build(Builder::Lbvh, &boxes, &BuildParams::default());
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| optimize(&bvh, &SahCosts::default(), OptimizeBudget::Passes(2)))
        };
        let (one, report) = run(1);
        assert!(report.moves > 0, "{report:?}");
        for threads in [2, 3] {
            let (many, _) = run(threads);
            assert_eq!(many.nodes(), one.nodes(), "{threads} threads");
            assert_eq!(many.prim_indices(), one.prim_indices(), "{threads} threads");
        }
    }
}
