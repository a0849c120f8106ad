//! Generalised winding numbers (Jacobson et al., SIGGRAPH 2013) over a tree, fast by
//! Barill et al.'s far-field expansion (SIGGRAPH 2018): a node far from the query point
//! (farther than [`FAR_FIELD`] times its radius) counts as its Taylor expansion to
//! second order about its area-weighted centre (a dipole, the triangles' summed area
//! vectors, and the first moment of those vectors about the centre); near nodes open
//! down to exact solid angles. The number is 1 inside a closed, outward-facing surface, 0 outside,
//! and degrades gracefully (fractional values) on holes, overlaps and open meshes,
//! where ray parity flips on a single missing triangle.

use super::triangle::solid_angle;
use super::walk::{box_distance_sq, Best};
use crate::view::{Child, ChildKind, TreeView};
use crate::Aabb;
use glam::{DMat3, DVec3, Mat3, Vec3};

/// How many radii away from a node's centre the query point must be for the node to
/// count as its expansion, for winding numbers as values: Barill et al.'s choice with
/// second-order terms. The worst error on the tests' torus is about 1e-2.
pub const FAR_FIELD: f32 = 2.0;

/// [`FAR_FIELD`] for inside tests, which need only the side of one half that a number
/// of 0 or 1 lies on: about twice as fast on points around the dragon, with a worst
/// error on the tests' torus (every builder and width) of about 0.08, against the
/// margin of 0.5.
pub const INSIDE_FAR_FIELD: f32 = 1.25;

/// What the far field of a node needs.
#[derive(Clone, Copy, Debug)]
struct Moment {
    /// Sum of the triangles' area vectors, `(v1 - v0) x (v2 - v0) / 2`.
    area_vector: DVec3,
    /// Area-weighted centre of the triangles.
    center: DVec3,
    /// Distance from `center` to the farthest vertex below.
    radius: f64,
    /// Sum of the triangles' areas (for combining centres).
    area: f64,
    /// `Σ a_i (c_i - center)ᵀ` over the triangles' area vectors `a_i` and centroids
    /// `c_i`: the second-order term's moment.
    spread: DMat3,
}

/// `a bᵀ`.
fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

impl Default for Moment {
    fn default() -> Self {
        Self {
            area_vector: DVec3::ZERO,
            center: DVec3::ZERO,
            radius: 0.0,
            area: 0.0,
            spread: DMat3::ZERO,
        }
    }
}

/// A node's (or leaf's) far field as queries read it: single precision, 64 bytes.
#[derive(Clone, Copy, Debug)]
struct FarField {
    center: Vec3,
    /// The radius squared (rounded up).
    radius_sq: f32,
    area_vector: Vec3,
    spread: Mat3,
}

impl FarField {
    /// Never far enough: the node is always opened.
    const OPEN: Self = Self {
        center: Vec3::ZERO,
        radius_sq: f32::INFINITY,
        area_vector: Vec3::ZERO,
        spread: Mat3::ZERO,
    };

    fn of(m: &Moment) -> Self {
        Self {
            center: m.center.as_vec3(),
            radius_sq: (m.radius * m.radius) as f32 * (1.0 + 1e-6),
            area_vector: m.area_vector.as_vec3(),
            spread: m.spread.as_mat3(),
        }
    }

    /// The expansion's value at `query` (times 4π), if `query` lies farther from the
    /// centre than `√reach_sq` radii.
    #[inline(always)]
    fn term(&self, query: Vec3, reach_sq: f32) -> Option<f64> {
        let d = self.center - query;
        let d2 = d.length_squared();
        let far = d2 > reach_sq * self.radius_sq;
        if !far {
            return None;
        }
        // The dipole a·r/|r|³ and its gradient at the centre, r = d.
        let r3 = d2 * d2.sqrt();
        let dipole = self.area_vector.dot(d) / r3;
        let s = &self.spread;
        let trace = s.x_axis.x + s.y_axis.y + s.z_axis.z;
        let second = trace / r3 - 3.0 * d.dot(*s * d) / (r3 * d2);
        Some((dipole + second) as f64)
    }
}

/// What a node of the flat tree holds below it.
#[derive(Clone, Copy, Debug)]
enum Below {
    /// Children `first..first + count` of [`PointTree::nodes`], side by side.
    Nodes { first: u32, count: u32 },
    /// Triangles `first..first + count` of [`PointTree::triangles`].
    Triangles { first: u32, count: u32 },
}

#[derive(Clone, Copy, Debug)]
struct FlatNode {
    bounds: Aabb,
    far: FarField,
    below: Below,
}

/// The tree laid out for point queries: every node's box and far field with its
/// children's side by side (one node's children are tested together), and the leaves'
/// triangles copied in leaf order with their indices (no index or vertex lookups).
/// Made from any layout once, at the first point query.
#[derive(Clone, Debug, Default)]
pub(crate) struct PointTree {
    /// Node 0 is the root.
    nodes: Vec<FlatNode>,
    triangles: Vec<[Vec3; 3]>,
    /// The primitive index of each of `triangles`.
    prims: Vec<u32>,
    /// Where spatial splits put a triangle in several leaves: each copy's share
    /// (1 / references), by position in `triangles`, so that every triangle counts once.
    shares: Option<Vec<f64>>,
}

impl PointTree {
    /// The flat tree of `view` over triangles `vertices(prim)` (`count` of them).
    pub fn new(view: &dyn TreeView, count: usize, vertices: &impl Fn(u32) -> [Vec3; 3]) -> Self {
        let references = view.has_spatial_splits().then(|| {
            let mut references = vec![0u32; count];
            // (Entries past the leaves' ranges, padding, name no triangle.)
            for &p in view.prim_indices() {
                if let Some(r) = references.get_mut(p as usize) {
                    *r += 1;
                }
            }
            references
        });
        let mut builder = Builder {
            view,
            vertices,
            references: references.as_deref(),
            tree: Self {
                shares: references.as_ref().map(|_| Vec::new()),
                ..Self::default()
            },
        };
        if let Some(root) = view.root() {
            builder.tree.nodes.push(FlatNode {
                bounds: root.bounds,
                far: FarField::OPEN,
                below: Below::Nodes { first: 0, count: 0 },
            });
            let moment = builder.fill(0, &root);
            builder.tree.nodes[0].far = FarField::of(&moment);
        }
        builder.tree
    }

    #[inline(always)]
    fn share(&self, slot: usize) -> f64 {
        self.shares.as_ref().map_or(1.0, |s| s[slot])
    }

    /// The winding number of the surface at `query`, nodes farther than `far_field`
    /// radii counted by their expansions.
    pub fn winding_number(&self, query: Vec3, far_field: f32) -> f64 {
        let reach_sq = far_field * far_field;
        let Some(root) = self.nodes.first() else {
            return 0.0;
        };
        if let Some(term) = root.far.term(query, reach_sq) {
            return term / (4.0 * std::f64::consts::PI);
        }
        let mut total = 0.0;
        let mut stack: Vec<Below> = Vec::with_capacity(64);
        stack.push(root.below);
        // Each node on the stack is near: its children are expanded where the query is
        // far from them, else opened (nodes onto the stack, triangles exactly).
        while let Some(below) = stack.pop() {
            match below {
                Below::Triangles { first, count } => {
                    let (first, count) = (first as usize, count as usize);
                    for (i, v) in self.triangles[first..first + count].iter().enumerate() {
                        total += solid_angle(query, v) * self.share(first + i);
                    }
                }
                Below::Nodes { first, count } => {
                    let (first, count) = (first as usize, count as usize);
                    for child in &self.nodes[first..first + count] {
                        match child.far.term(query, reach_sq) {
                            Some(term) => total += term,
                            None => stack.push(child.below),
                        }
                    }
                }
            }
        }
        total / (4.0 * std::f64::consts::PI)
    }
}

impl PointTree {
    /// The nearest triangle to `query` as [`super::walk::nearest`] finds it in any
    /// layout: `query_local` in the tree's space, boxes' distances times `stretch`
    /// bounding the measure, `measure(prim, vertices, best)` returning a triangle that
    /// beats `best`.
    pub fn nearest(
        &self,
        query_local: Vec3,
        stretch: f32,
        limit_sq: f32,
        mut measure: impl FnMut(u32, &[Vec3; 3], &Best) -> Best,
    ) -> Best {
        let root = self.nodes.first()?;
        let stretch_sq = stretch * stretch;
        let bound = |node: &FlatNode| box_distance_sq(&node.bounds, query_local) * stretch_sq;
        let mut best: Best = None;
        let reach = |best: &Best| best.map_or(limit_sq, |(d2, _)| d2);
        let mut stack: Vec<(f32, Below)> = Vec::with_capacity(64);
        stack.push((bound(root), root.below));
        let mut near: Vec<(f32, Below)> = Vec::with_capacity(8);
        while let Some((d2, below)) = stack.pop() {
            // Equal bounds are kept: a tie may still go to a lower index.
            if d2 > reach(&best) {
                continue;
            }
            match below {
                Below::Triangles { first, count } => {
                    let (first, count) = (first as usize, count as usize);
                    for i in first..first + count {
                        if let Some(found) = measure(self.prims[i], &self.triangles[i], &best) {
                            best = Some(found);
                        }
                    }
                }
                Below::Nodes { first, count } => {
                    let (first, count) = (first as usize, count as usize);
                    let within = reach(&best);
                    near.clear();
                    near.extend(
                        self.nodes[first..first + count]
                            .iter()
                            .map(|n| (bound(n), n.below))
                            .filter(|(d2, _)| *d2 <= within),
                    );
                    // Farthest first onto the stack, so the nearest is taken next.
                    near.sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
                    stack.extend_from_slice(&near);
                }
            }
        }
        best
    }
}

/// Lays a [`TreeView`] out as a [`PointTree`].
struct Builder<'a, V> {
    view: &'a dyn TreeView,
    vertices: &'a V,
    references: Option<&'a [u32]>,
    tree: PointTree,
}

impl<V: Fn(u32) -> [Vec3; 3]> Builder<'_, V> {
    /// Fills node `at` (already pushed) with what `child` holds, and returns its moment.
    fn fill(&mut self, at: usize, child: &Child) -> Moment {
        match child.kind {
            ChildKind::Leaf { first, count } => {
                let prims = &self.view.prim_indices()[first..first + count];
                let start = self.tree.triangles.len();
                for &p in prims {
                    self.tree.triangles.push((self.vertices)(p));
                    self.tree.prims.push(p);
                    if let (Some(shares), Some(references)) =
                        (&mut self.tree.shares, self.references)
                    {
                        shares.push(1.0 / references[p as usize].max(1) as f64);
                    }
                }
                self.tree.nodes[at].below = Below::Triangles {
                    first: start as u32,
                    count: count as u32,
                };
                self.leaf_moment(start, child)
            }
            ChildKind::Inner(node) => {
                let mut children = Vec::with_capacity(8);
                self.view.children(node, &mut children);
                // The children side by side, then each filled in turn.
                let first = self.tree.nodes.len();
                self.tree.nodes.extend(children.iter().map(|c| FlatNode {
                    bounds: c.bounds,
                    far: FarField::OPEN,
                    below: Below::Nodes { first: 0, count: 0 },
                }));
                self.tree.nodes[at].below = Below::Nodes {
                    first: first as u32,
                    count: children.len() as u32,
                };
                let parts: Vec<Moment> = children
                    .iter()
                    .enumerate()
                    .map(|(i, c)| {
                        let moment = self.fill(first + i, c);
                        self.tree.nodes[first + i].far = FarField::of(&moment);
                        moment
                    })
                    .collect();
                combine(&parts, child)
            }
        }
    }

    /// The moment of the triangles from `start` to the end of the list.
    fn leaf_moment(&self, start: usize, child: &Child) -> Moment {
        let triangles = &self.tree.triangles[start..];
        let share = |i: usize| self.tree.share(start + i);
        let mut m = Moment::default();
        let mut weighted = DVec3::ZERO;
        let area_vectors: Vec<DVec3> = triangles
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let v = t.map(|v| v.as_dvec3());
                0.5 * (v[1] - v[0]).cross(v[2] - v[0]) * share(i)
            })
            .collect();
        for (t, a) in triangles.iter().zip(&area_vectors) {
            let area = a.length();
            m.area_vector += *a;
            m.area += area;
            weighted += area * centroid(t);
        }
        m.center = match m.area > 0.0 {
            true => weighted / m.area,
            false => box_center(child),
        };
        for (t, a) in triangles.iter().zip(&area_vectors) {
            m.spread += outer(*a, centroid(t) - m.center);
            let farthest = t
                .iter()
                .map(|v| v.as_dvec3().distance(m.center))
                .fold(0.0, f64::max);
            m.radius = m.radius.max(farthest);
        }
        m
    }
}

fn centroid(t: &[Vec3; 3]) -> DVec3 {
    (t[0].as_dvec3() + t[1].as_dvec3() + t[2].as_dvec3()) / 3.0
}

fn box_center(child: &Child) -> DVec3 {
    (child.bounds.min.as_dvec3() + child.bounds.max.as_dvec3()) / 2.0
}

/// The moment of a node from its children's.
fn combine(parts: &[Moment], child: &Child) -> Moment {
    let mut m = Moment::default();
    let mut weighted = DVec3::ZERO;
    for part in parts {
        m.area_vector += part.area_vector;
        m.area += part.area;
        weighted += part.area * part.center;
    }
    m.center = match m.area > 0.0 {
        true => weighted / m.area,
        false => box_center(child),
    };
    for part in parts {
        m.spread += part.spread + outer(part.area_vector, part.center - m.center);
        m.radius = m.radius.max(part.center.distance(m.center) + part.radius);
    }
    m
}
