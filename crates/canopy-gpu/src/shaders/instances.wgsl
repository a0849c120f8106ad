// Two-level traversal (appended to the render kernel's sources): the top tree over the
// instances' world boxes, then, at each instance it reaches, the instance's tree in the
// instance's own space, the ray carried there by the instance's inverse transform (its
// direction not normalised, so t is the same in both spaces), as canopy-bvh's Tlas does.
// A scene without mesh instances (frame.top.x == 0) is one tree walked from node 0.

struct Instance {
    // Affine maps by columns: x, y, z axes, translation (w unused).
    to_local: array<vec4<f32>, 4>,
    to_world: array<vec4<f32>, 4>,
    // Root node (EMPTY: nothing), first primitive, material (NO_MATERIAL: each
    // primitive's own), first light (NO_LIGHT: none).
    info: vec4<u32>,
}

const NO_MATERIAL: u32 = 0xffffffffu;
const NO_INSTANCE: u32 = 0xffffffffu;

@group(0) @binding(22) var<storage, read> instances: array<Instance>;

// A hit and the instance it is on (0: the scene's own primitives).
struct SceneHit {
    hit: HitOut,
    inst: u32,
}

fn apply_point(m: array<vec4<f32>, 4>, p: vec3<f32>) -> vec3<f32> {
    return m[0].xyz * p.x + m[1].xyz * p.y + m[2].xyz * p.z + m[3].xyz;
}

fn apply_vector(m: array<vec4<f32>, 4>, v: vec3<f32>) -> vec3<f32> {
    return m[0].xyz * v.x + m[1].xyz * v.y + m[2].xyz * v.z;
}

// A normal into world space: the transpose of the to-local map's linear part.
fn normal_to_world(inst: Instance, n: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(inst.to_local[0].xyz, n), dot(inst.to_local[1].xyz, n), dot(inst.to_local[2].xyz, n));
}

// Whether a hit at (t, inst, prim) comes before `best`: ties go to the lower instance,
// then the lower primitive, as on the CPU.
fn before(t: f32, inst: u32, prim: u32, best: SceneHit) -> bool {
    if (best.hit.prim == NO_PRIM) {
        return t <= best.hit.t;
    }
    return t < best.hit.t || (t == best.hit.t && (inst < best.inst || (inst == best.inst && prim < best.hit.prim)));
}

// The closest hit over every instance, or with `first_ends` the first found. The stack
// walk is `walk_tree`'s (common.wgsl); WGSL has no recursion, so the top level has its
// own, whose leaves are instances.
fn scene_walk(r: RayIn, first_ends: bool) -> SceneHit {
    if (frame.top.x == 0u) {
        return SceneHit(walk(r, first_ends), 0u);
    }
    var best = SceneHit(HitOut(r.t_max, NO_PRIM, 0.0, 0.0), NO_INSTANCE);
    let q = make_query(r);
    var stack: array<u32, STACK>;
    var sp = 0u;
    var node = frame.top.y;
    if (node == EMPTY) {
        return best;
    }
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
                t = slab(n.lmin, n.lmax, q, best.hit.t);
            } else {
                t = slab(n.rmin, n.rmax, q, best.hit.t);
            }
            if (t >= INF) {
                continue;
            }
            if (count == 0u) {
                entry[i] = t;
                continue;
            }
            for (var k = child; k < child + count; k++) {
                let index = prim_indices[k];
                let inst = instances[index];
                let local = RayIn(apply_point(inst.to_local, r.origin), r.t_min, apply_vector(inst.to_local, r.dir), best.hit.t);
                let h = walk_tree(inst.info.x, make_query(local), HitOut(best.hit.t, NO_PRIM, 0.0, 0.0), first_ends);
                if (h.prim != NO_PRIM && before(h.t, index, h.prim, best)) {
                    best = SceneHit(h, index);
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


// The material index of what `h` hit: its instance's, or for the scene's own
// primitives the primitive's.
fn material_index(h: SceneHit) -> u32 {
    let own = instances[h.inst].info.z;
    if (own == NO_MATERIAL) {
        return prim_at(h.hit.prim).header.y;
    }
    return own;
}

// The surface at a hit: an instance's triangle is taken into world space (its vertices
// by the instance's transform, its vertex normals by the inverse transpose), then
// treated as a world triangle, as the CPU's `Scene::hit_surface` does.
fn scene_surface(origin: vec3<f32>, dir: vec3<f32>, h: SceneHit) -> Surface {
    if (instances[h.inst].info.z == NO_MATERIAL) {
        return surface_of(h.hit.prim, origin, dir, h.hit);
    }
    let inst = instances[h.inst];
    let p = prim_at(h.hit.prim);
    let a = apply_point(inst.to_world, p.d0.xyz);
    let b = apply_point(inst.to_world, p.d1.xyz);
    let c = apply_point(inst.to_world, p.d2.xyz);
    var normals = array<vec3<f32>, 3>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    let shaded = p.header.z != FLAT;
    if (shaded) {
        for (var i = 0u; i < 3u; i++) {
            normals[i] = normalize_or(normal_to_world(inst, normal_at(3u * p.header.z + i).xyz), vec3<f32>(0.0));
        }
    }
    return triangle_surface(a, b, c, shaded, normals, h.hit.u, h.hit.v);
}

// The light a hit is on, or NO_LIGHT.
fn light_of(h: SceneHit) -> u32 {
    let inst = instances[h.inst];
    if (inst.info.z == NO_MATERIAL) {
        return light_of_prim[h.hit.prim];
    }
    if (inst.info.w == NO_LIGHT) {
        return NO_LIGHT;
    }
    return inst.info.w + (h.hit.prim - inst.info.y);
}
