//! Linear BVH: a binary radix tree over the sorted Morton codes of the centroids, every
//! internal node found independently (Karras, "Maximizing parallelism in the construction
//! of BVHs, octrees, and k-d trees", HPG 2012), here in parallel with rayon.
//!
//! Equal codes are told apart by their position in the sorted order, as in the paper.

use super::merge_tree::MergeTree;
use super::morton::{morton_codes, morton_order};
use crate::{Aabb, BuildParams, Bvh2};
use rayon::prelude::*;

pub(crate) fn build(boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    let n = boxes.len();
    if n < 2 {
        return MergeTree::new(n).into_bvh2(boxes, params);
    }
    let codes = morton_codes(boxes);
    let order = morton_order(&codes);
    let sorted: Vec<u64> = order.iter().map(|&i| codes[i as usize]).collect();

    // Length of the common prefix of keys i and j (code, then position), or -1 outside.
    let delta = |i: i64, j: i64| -> i32 {
        if j < 0 || j >= n as i64 {
            return -1;
        }
        let (a, b) = (sorted[i as usize], sorted[j as usize]);
        if a == b {
            64 + ((i as u64) ^ (j as u64)).leading_zeros() as i32
        } else {
            (a ^ b).leading_zeros() as i32
        }
    };

    // Internal node i covers a range of sorted leaves with i at one end; its children are
    // given as ids: sorted leaf `p` is `Leaf(p)`, internal node `k` is `Node(k)`.
    let children: Vec<[Child; 2]> = (0..n as i64 - 1)
        .into_par_iter()
        .map(|i| {
            let d: i64 = if delta(i, i + 1) > delta(i, i - 1) {
                1
            } else {
                -1
            };
            let delta_min = delta(i, i - d);
            let mut l_max: i64 = 2;
            while delta(i, i + l_max * d) > delta_min {
                l_max *= 2;
            }
            let mut l = 0;
            let mut t = l_max / 2;
            while t >= 1 {
                if delta(i, i + (l + t) * d) > delta_min {
                    l += t;
                }
                t /= 2;
            }
            let j = i + l * d;
            let delta_node = delta(i, j);
            let mut s = 0;
            let mut t = l;
            loop {
                t = (t + 1) / 2;
                if delta(i, i + (s + t) * d) > delta_node {
                    s += t;
                }
                if t <= 1 {
                    break;
                }
            }
            let gamma = i + s * d + d.min(0);
            let left = if i.min(j) == gamma {
                Child::Leaf(gamma)
            } else {
                Child::Node(gamma)
            };
            let right = if i.max(j) == gamma + 1 {
                Child::Leaf(gamma + 1)
            } else {
                Child::Node(gamma + 1)
            };
            [left, right]
        })
        .collect();

    // Number the internal nodes in post-order so that children come before parents.
    let mut tree = MergeTree::new(n);
    let mut id_of_node = vec![u32::MAX; n - 1];
    let mut stack = vec![(0usize, false)];
    let id = |c: Child, id_of_node: &[u32]| match c {
        Child::Leaf(p) => order[p as usize],
        Child::Node(k) => id_of_node[k as usize],
    };
    while let Some((k, expanded)) = stack.pop() {
        if expanded {
            let [l, r] = children[k];
            id_of_node[k] = tree.merge(id(l, &id_of_node), id(r, &id_of_node));
            continue;
        }
        stack.push((k, true));
        for c in children[k] {
            if let Child::Node(child) = c {
                stack.push((child as usize, false));
            }
        }
    }
    tree.into_bvh2(boxes, params)
}

#[derive(Clone, Copy)]
enum Child {
    Leaf(i64),
    Node(i64),
}
