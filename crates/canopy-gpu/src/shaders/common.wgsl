// What every kernel shares: the scene's buffers (bindings 0..=2 of group 0) and the
// closest hit of a ray through a GpuBvh (child boxes in the parent) over canopy's
// primitives. The tests are ports of canopy-render's CPU ones: the watertight triangle
// test (Woop et al. 2013, without its float64 fallback for edge functions that are
// exactly zero), the precise sphere roots and the rotated box's slab test.

struct Node {
    lmin: vec3<f32>,
    left: u32,
    lmax: vec3<f32>,
    left_count: u32,
    rmin: vec3<f32>,
    right: u32,
    rmax: vec3<f32>,
    right_count: u32,
}

// kind in header.x: 0 triangle (d0..d2 = vertices), 1 sphere (d0 = centre, radius),
// 2 cuboid (d0..d2.xyz = rows of the world-to-local rotation, d0..d2.w = local min,
// d3.xyz = translation, d4.xyz = local max). header.y is the material.
struct Primitive {
    header: vec4<u32>,
    d0: vec4<f32>,
    d1: vec4<f32>,
    d2: vec4<f32>,
    d3: vec4<f32>,
    d4: vec4<f32>,
}

struct RayIn {
    origin: vec3<f32>,
    t_min: f32,
    dir: vec3<f32>,
    t_max: f32,
}

struct HitOut {
    t: f32,
    prim: u32,
    u: f32,
    v: f32,
}

const NO_PRIM: u32 = 0xffffffffu;
const EMPTY: u32 = 0xffffffffu;
const STACK: u32 = 64u;
// 1 + 2 gamma(3): the far slab distance's slack (Ize 2013), as on the CPU.
const FAR_SLACK: f32 = 1.0000003576;
const INF: f32 = 0x1p+127;

// Nodes and primitives may each come in up to four bindings of 2^<NAME>_BITS elements
// (chunked.rs), read through node_at and prim_at; the constants are set per scene when
// the pipeline is made, so a scene in one binding reads the plain array.
override NODE_BITS: u32 = 31u;
override NODE_CHUNKS: u32 = 1u;
override PRIM_BITS: u32 = 31u;
override PRIM_CHUNKS: u32 = 1u;

@group(0) @binding(0) var<storage, read> nodes: array<Node>;
@group(0) @binding(13) var<storage, read> nodes1: array<Node>;
@group(0) @binding(14) var<storage, read> nodes2: array<Node>;
@group(0) @binding(15) var<storage, read> nodes3: array<Node>;
@group(0) @binding(1) var<storage, read> prim_indices: array<u32>;
@group(0) @binding(2) var<storage, read> prims: array<Primitive>;
@group(0) @binding(16) var<storage, read> prims1: array<Primitive>;
@group(0) @binding(17) var<storage, read> prims2: array<Primitive>;
@group(0) @binding(18) var<storage, read> prims3: array<Primitive>;

fn node_at(i: u32) -> Node {
    if (NODE_CHUNKS == 1u) {
        return nodes[i];
    }
    let local = i & ((1u << NODE_BITS) - 1u);
    switch (i >> NODE_BITS) {
        case 0u: { return nodes[local]; }
        case 1u: { return nodes1[local]; }
        case 2u: { return nodes2[local]; }
        default: { return nodes3[local]; }
    }
}

fn prim_at(i: u32) -> Primitive {
    if (PRIM_CHUNKS == 1u) {
        return prims[i];
    }
    let local = i & ((1u << PRIM_BITS) - 1u);
    switch (i >> PRIM_BITS) {
        case 0u: { return prims[local]; }
        case 1u: { return prims1[local]; }
        case 2u: { return prims2[local]; }
        default: { return prims3[local]; }
    }
}


struct Query {
    origin: vec3<f32>,
    dir: vec3<f32>,
    inv_dir: vec3<f32>,
    t_min: f32,
    // The watertight test's axes and shear.
    kx: u32,
    ky: u32,
    kz: u32,
    shear: vec3<f32>,
}

fn reciprocal(d: vec3<f32>) -> vec3<f32> {
    // A zero component stands for an infinite reciprocal (WGSL leaves 1/0 undefined).
    let safe = select(d, vec3<f32>(1e-30), d == vec3<f32>(0.0));
    return 1.0 / safe;
}

fn make_query(r: RayIn) -> Query {
    var q: Query;
    q.origin = r.origin;
    q.dir = r.dir;
    q.inv_dir = reciprocal(r.dir);
    q.t_min = r.t_min;
    let a = abs(r.dir);
    var kz = 0u;
    if (a.y > a.x && a.y >= a.z) {
        kz = 1u;
    } else if (a.z > a.x && a.z > a.y) {
        kz = 2u;
    }
    var kx = (kz + 1u) % 3u;
    var ky = (kz + 2u) % 3u;
    if (r.dir[kz] < 0.0) {
        let k = kx;
        kx = ky;
        ky = k;
    }
    q.kx = kx;
    q.ky = ky;
    q.kz = kz;
    q.shear = vec3<f32>(r.dir[kx] / r.dir[kz], r.dir[ky] / r.dir[kz], 1.0 / r.dir[kz]);
    return q;
}

// Entry distance into the box within [t_min, t_max], or INF.
fn slab(lo: vec3<f32>, hi: vec3<f32>, q: Query, t_max: f32) -> f32 {
    let t0 = (lo - q.origin) * q.inv_dir;
    let t1 = (hi - q.origin) * q.inv_dir;
    let near = min(t0, t1);
    let far = max(t0, t1);
    let enter = max(max(near.x, near.y), max(near.z, q.t_min));
    let exit = min(min(min(far.x, far.y), far.z) * FAR_SLACK, t_max);
    return select(INF, enter, enter <= exit);
}

// (t, u, v) of a hit within [t_min, t_max], or t < 0 for none.
fn hit_triangle(p: Primitive, q: Query, t_max: f32) -> vec3<f32> {
    let a = p.d0.xyz - q.origin;
    let b = p.d1.xyz - q.origin;
    let c = p.d2.xyz - q.origin;
    let s = q.shear;
    let ax = a[q.kx] - s.x * a[q.kz];
    let ay = a[q.ky] - s.y * a[q.kz];
    let bx = b[q.kx] - s.x * b[q.kz];
    let by = b[q.ky] - s.y * b[q.kz];
    let cx = c[q.kx] - s.x * c[q.kz];
    let cy = c[q.ky] - s.y * c[q.kz];
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) {
        return vec3<f32>(-1.0);
    }
    let det = u + v + w;
    if (det == 0.0 || abs(det) >= INF) {
        return vec3<f32>(-1.0);
    }
    let t = (u * s.z * a[q.kz] + v * s.z * b[q.kz] + w * s.z * c[q.kz]) / det;
    if (t >= q.t_min && t <= t_max) {
        return vec3<f32>(t, v / det, w / det);
    }
    return vec3<f32>(-1.0);
}

fn in_range(t: f32, q: Query, t_max: f32) -> bool {
    return t >= q.t_min && t <= t_max;
}

fn hit_sphere(p: Primitive, q: Query, t_max: f32) -> f32 {
    let center = p.d0.xyz;
    let radius = p.d0.w;
    let f = q.origin - center;
    let d = q.dir;
    let a = dot(d, d);
    let b = -dot(f, d);
    let to_line = f + (b / a) * d;
    let r2 = radius * radius;
    let disc = r2 - dot(to_line, to_line);
    if (disc < 0.0) {
        return -1.0;
    }
    let c = dot(f, f) - r2;
    let q_root = b + select(-1.0, 1.0, b >= 0.0) * sqrt(a * disc);
    var t0 = 0.0;
    var t1 = 0.0;
    if (q_root != 0.0) {
        t0 = c / q_root;
        t1 = q_root / a;
    }
    let near = min(t0, t1);
    let far = max(t0, t1);
    if (in_range(near, q, t_max)) {
        return near;
    }
    if (in_range(far, q, t_max)) {
        return far;
    }
    return -1.0;
}

fn hit_cuboid(p: Primitive, q: Query, t_max: f32) -> f32 {
    let rel = q.origin - p.d3.xyz;
    let o = vec3<f32>(dot(p.d0.xyz, rel), dot(p.d1.xyz, rel), dot(p.d2.xyz, rel));
    let d = vec3<f32>(dot(p.d0.xyz, q.dir), dot(p.d1.xyz, q.dir), dot(p.d2.xyz, q.dir));
    let inv = reciprocal(d);
    let lo = vec3<f32>(p.d0.w, p.d1.w, p.d2.w);
    let t0 = (lo - o) * inv;
    let t1 = (p.d4.xyz - o) * inv;
    let near = min(t0, t1);
    let far = max(t0, t1);
    let enter = max(max(near.x, near.y), near.z);
    let exit = min(min(far.x, far.y), far.z);
    if (enter > exit) {
        return -1.0;
    }
    if (in_range(enter, q, t_max)) {
        return enter;
    }
    if (in_range(exit, q, t_max)) {
        return exit;
    }
    return -1.0;
}

// (t, u, v) of primitive `index`, or t < 0.
fn hit_primitive(index: u32, q: Query, t_max: f32) -> vec3<f32> {
    let p = prim_at(index);
    switch p.header.x {
        case 0u: {
            return hit_triangle(p, q, t_max);
        }
        case 1u: {
            return vec3<f32>(hit_sphere(p, q, t_max), 0.0, 0.0);
        }
        default: {
            return vec3<f32>(hit_cuboid(p, q, t_max), 0.0, 0.0);
        }
    }
}

// The closest hit (ties to the lower primitive index), or with `first_ends` the first
// hit found (for occlusion): the node stack walk both queries share.
fn walk(r: RayIn, first_ends: bool) -> HitOut {
    return walk_tree(0u, make_query(r), HitOut(r.t_max, NO_PRIM, 0.0, 0.0), first_ends);
}

// `walk` of the tree whose root is node `root`, for a hit before `best` (its t the
// range's end; NO_PRIM when there is none yet).
fn walk_tree(root: u32, q: Query, start: HitOut, first_ends: bool) -> HitOut {
    var best = start;
    var stack: array<u32, STACK>;
    var sp = 0u;
    var node = root;
    loop {
        let n = node_at(node);
        var children = array<vec3<u32>, 2>(
            vec3<u32>(n.left, n.left_count, 0u),
            vec3<u32>(n.right, n.right_count, 0u),
        );
        var entry = array<f32, 2>(INF, INF);
        for (var i = 0u; i < 2u; i++) {
            let child = children[i].x;
            let count = children[i].y;
            if (count == 0u && child == EMPTY) {
                continue;
            }
            var t = INF;
            if (i == 0u) {
                t = slab(n.lmin, n.lmax, q, best.t);
            } else {
                t = slab(n.rmin, n.rmax, q, best.t);
            }
            if (t >= INF) {
                continue;
            }
            if (count == 0u) {
                entry[i] = t;
                continue;
            }
            for (var k = child; k < child + count; k++) {
                let prim = prim_indices[k];
                let h = hit_primitive(prim, q, best.t);
                if (h.x >= 0.0 && (h.x < best.t || (h.x == best.t && prim < best.prim))) {
                    best = HitOut(h.x, prim, h.y, h.z);
                    if (first_ends) {
                        return best;
                    }
                }
            }
        }
        let l = entry[0] < INF;
        let rr = entry[1] < INF;
        if (l && rr) {
            var near = n.left;
            var far = n.right;
            if (entry[1] < entry[0]) {
                near = n.right;
                far = n.left;
            }
            if (sp < STACK) {
                stack[sp] = far;
                sp++;
            }
            node = near;
        } else if (l) {
            node = n.left;
        } else if (rr) {
            node = n.right;
        } else {
            if (sp == 0u) {
                break;
            }
            sp--;
            node = stack[sp];
        }
    }
    return best;
}

fn closest(r: RayIn) -> HitOut {
    return walk(r, false);
}

// Whether anything is hit within [t_min, t_max].
fn occluded(r: RayIn) -> bool {
    return walk(r, true).prim != NO_PRIM;
}
