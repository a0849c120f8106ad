// canopy's path tracers on the GPU, one invocation per pixel (appended to rng.wgsl and
// common.wgsl, followed by path.wgsl): the report's estimator (`bsdf`) here, light
// sampling (`path`) in path.wgsl. Materials, camera, background and random
// streams are ports of canopy-render's: the same numbers drive the same decisions, up to
// rounding.

// kind 0 Lambertian (value = albedo), 1 metal (albedo, fuzz in w), 2 dielectric (ior in
// w), 3 emissive (radiance), 4 glTF metallic-roughness (pbr.wgsl); emission.xyz the
// radiance it emits (emissive and metallic-roughness).
struct Material {
    kind: vec4<u32>,
    value: vec4<f32>,
    emission: vec4<f32>,
}

struct Frame {
    // xyz: camera origin, w: lens radius.
    origin: vec4<f32>,
    upper_left: vec4<f32>,
    horizontal: vec4<f32>,
    vertical: vec4<f32>,
    u: vec4<f32>,
    v: vec4<f32>,
    // width, height, seed key, max depth
    size: vec4<u32>,
    // first sample, samples, background kind (0 sky, 1 constant, 2 map), first row of
    // the band in the region
    samples: vec4<u32>,
    background: vec4<f32>,
    // lights, background is black (1), integrator (0 bsdf, 1 path; PATH_ESTIMATOR decides),
    // Russian roulette (1)
    options: vec4<u32>,
    // An environment map's rotation to the world, by columns, and its width and height.
    env_x: vec4<f32>,
    env_y: vec4<f32>,
    env_z: vec4<f32>,
    env_size: vec4<u32>,
    // The region of the image rendered: x, y, width, height.
    region: vec4<u32>,
    // Two-level traversal (1) or one tree from node 0 (0); the top tree's root node;
    // whether some surfaces let rays through (1); whether some material has textures (1).
    top: vec4<u32>,
    // The viewing direction; w: 1 for an orthographic camera.
    forward: vec4<f32>,
    // x: the Sobol dimensions of each sample's stream (0: independent numbers only).
    sampling: vec4<u32>,
}

// The estimator, fixed when the pipeline is made (the `path` integrator, or the
// report's `bsdf`), so that the kernel holds only one of them.
override PATH_ESTIMATOR: bool = true;

@group(0) @binding(3) var<storage, read> materials: array<Material>;
@group(0) @binding(4) var<uniform> frame: Frame;
// Per pixel of the band being rendered: radiance sums (xyz) and samples that were not
// finite (w).
@group(0) @binding(5) var<storage, read_write> accum: array<vec4<f32>>;
// Three per smooth-shaded triangle (`header.z` indexes them; FLAT = none), in up to four
// bindings as nodes and primitives are (common.wgsl).
override NORMAL_BITS: u32 = 31u;
override NORMAL_CHUNKS: u32 = 1u;
@group(0) @binding(6) var<storage, read> vertex_normals: array<vec4<f32>>;
@group(0) @binding(19) var<storage, read> vertex_normals1: array<vec4<f32>>;
@group(0) @binding(20) var<storage, read> vertex_normals2: array<vec4<f32>>;
@group(0) @binding(21) var<storage, read> vertex_normals3: array<vec4<f32>>;

fn normal_at(i: u32) -> vec4<f32> {
    if (NORMAL_CHUNKS == 1u) {
        return vertex_normals[i];
    }
    let local = i & ((1u << NORMAL_BITS) - 1u);
    switch (i >> NORMAL_BITS) {
        case 0u: { return vertex_normals[local]; }
        case 1u: { return vertex_normals1[local]; }
        case 2u: { return vertex_normals2[local]; }
        default: { return vertex_normals3[local]; }
    }
}
@group(0) @binding(7) var<storage, read_write> ray_count: array<atomic<u32>>;

const FLAT: u32 = 0xffffffffu;
const POINT_ERROR_ULPS: f32 = 1.9073486e-6; // 16 f32::EPSILON
const FRAC_1_PI: f32 = 0.3183098861837907;
const PI: f32 = 3.141592653589793;

struct Surface {
    p: vec3<f32>,
    geometric: vec3<f32>,
    shading: vec3<f32>,
    error: f32,
}

fn max_abs(v: vec3<f32>) -> f32 {
    let a = abs(v);
    return max(max(a.x, a.y), a.z);
}

fn normalize_or(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    if (l > 0.0 && l < INF) {
        return v / l;
    }
    return fallback;
}

// The surface of a world triangle a, b, c at barycentrics (u, v); with `shaded`, its
// shading normal interpolates the vertex `normals`.
fn triangle_surface(a: vec3<f32>, b: vec3<f32>, c: vec3<f32>, shaded: bool, normals: array<vec3<f32>, 3>, u: f32, v: f32) -> Surface {
    var s: Surface;
    let w0 = 1.0 - u - v;
    s.p = w0 * a + u * b + v * c;
    s.geometric = normalize_or(cross(b - a, c - a), vec3<f32>(0.0, 1.0, 0.0));
    s.shading = s.geometric;
    if (shaded) {
        let interpolated = w0 * normals[0] + u * normals[1] + v * normals[2];
        s.shading = normalize_or(interpolated, s.geometric);
        if (dot(s.shading, s.geometric) < 0.0) {
            s.shading = -s.shading;
        }
    }
    s.error = POINT_ERROR_ULPS * max(max(max_abs(a), max_abs(b)), max_abs(c));
    return s;
}

fn surface_of(index: u32, origin: vec3<f32>, dir: vec3<f32>, hit: HitOut) -> Surface {
    let p = prim_at(index);
    var s: Surface;
    switch p.header.x {
        case 0u: {
            var normals = array<vec3<f32>, 3>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
            let shaded = p.header.z != FLAT;
            if (shaded) {
                let n = 3u * p.header.z;
                normals = array<vec3<f32>, 3>(normal_at(n).xyz, normal_at(n + 1u).xyz, normal_at(n + 2u).xyz);
            }
            s = triangle_surface(p.d0.xyz, p.d1.xyz, p.d2.xyz, shaded, normals, hit.u, hit.v);
        }
        case 1u: {
            let center = p.d0.xyz;
            let normal = normalize(origin + hit.t * dir - center);
            s.p = center + normal * p.d0.w;
            s.geometric = normal;
            s.shading = normal;
            s.error = POINT_ERROR_ULPS * (max_abs(center) + p.d0.w);
        }
        default: {
            let rel = origin - p.d3.xyz;
            let o = vec3<f32>(dot(p.d0.xyz, rel), dot(p.d1.xyz, rel), dot(p.d2.xyz, rel));
            let d = vec3<f32>(dot(p.d0.xyz, dir), dot(p.d1.xyz, dir), dot(p.d2.xyz, dir));
            var local = o + hit.t * d;
            let lo = vec3<f32>(p.d0.w, p.d1.w, p.d2.w);
            let hi = p.d4.xyz;
            let center = 0.5 * (lo + hi);
            let half = 0.5 * (hi - lo);
            let offset = local - center;
            var axis = 0u;
            var best = -1.0;
            for (var i = 0u; i < 3u; i++) {
                var closeness = INF;
                if (half[i] > 0.0) {
                    closeness = abs(offset[i]) / half[i];
                }
                if (closeness > best) {
                    best = closeness;
                    axis = i;
                }
            }
            var positive = offset[axis] >= 0.0;
            if (half[axis] <= 0.0) {
                positive = d[axis] < 0.0;
            }
            var sign = -1.0;
            local[axis] = lo[axis];
            if (positive) {
                sign = 1.0;
                local[axis] = hi[axis];
            }
            // The rows stored for world-to-local are the rotation's columns.
            var columns = array<vec3<f32>, 3>(p.d0.xyz, p.d1.xyz, p.d2.xyz);
            let normal = sign * columns[axis];
            s.p = local.x * columns[0] + local.y * columns[1] + local.z * columns[2] + p.d3.xyz;
            s.geometric = normal;
            s.shading = normal;
            s.error = POINT_ERROR_ULPS * (max_abs(p.d3.xyz) + max(max_abs(lo), max_abs(hi)));
        }
    }
    return s;
}

fn reflect_about(v: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return v - 2.0 * dot(v, n) * n;
}

fn refract_through(v: vec3<f32>, n: vec3<f32>, eta: f32, cos_theta: f32) -> vec3<f32> {
    let perpendicular = eta * (v + cos_theta * n);
    let parallel = -sqrt(abs(1.0 - dot(perpendicular, perpendicular))) * n;
    return perpendicular + parallel;
}

fn schlick(cos_theta: f32, eta: f32) -> f32 {
    let r = (1.0 - eta) / (1.0 + eta);
    let r0 = r * r;
    let m = 1.0 - cos_theta;
    return r0 + (1.0 - r0) * m * m * m * m * m;
}

// The fuzzy-metal lobe's density (canopy-render's material/fuzz.rs).
fn fuzz_pdf(mirror: vec3<f32>, fuzz: f32, direction: vec3<f32>) -> f32 {
    let c = dot(direction, mirror);
    let disc = c * c - 1.0 + fuzz * fuzz;
    if (disc <= 0.0) {
        return 0.0;
    }
    let root = sqrt(disc);
    if (fuzz < 1.0) {
        if (c <= 0.0) {
            return 0.0;
        }
        return (c * c + disc) / (2.0 * PI * fuzz * root);
    }
    let t = c + root;
    return t * t / (4.0 * PI * fuzz * root);
}

struct Scatter {
    direction: vec3<f32>,
    weight: vec3<f32>,
    ok: bool,
    // Density per solid angle; meaningless when `delta`.
    pdf: f32,
    delta: bool,
}

fn scatter(m: Material, dir: vec3<f32>, s: Surface, rng: ptr<function, Rng>) -> Scatter {
    let entering = dot(dir, s.geometric) < 0.0;
    var geometric = s.geometric;
    var shading = s.shading;
    if (!entering) {
        geometric = -geometric;
        shading = -shading;
    }
    var out = Scatter(vec3<f32>(0.0), vec3<f32>(0.0), false, 0.0, false);
    switch m.kind.x {
        case 0u: {
            let d = shading + unit_vector(rng);
            var direction = shading;
            if (dot(d, d) >= 1e-12) {
                direction = normalize(d);
            }
            let cos = dot(direction, shading);
            out = Scatter(direction, m.value.xyz, dot(direction, geometric) > 0.0 && cos > 0.0, cos * FRAC_1_PI, false);
        }
        case 1u: {
            let fuzz = m.value.w;
            let reflected = reflect_about(dir, shading);
            let d = reflected + fuzz * unit_vector(rng);
            var direction = vec3<f32>(0.0);
            if (dot(d, d) > 0.0) {
                direction = normalize(d);
            }
            let delta = fuzz == 0.0;
            var pdf = 0.0;
            if (!delta) {
                pdf = fuzz_pdf(reflected, fuzz, direction);
            }
            out = Scatter(direction, m.value.xyz, dot(direction, geometric) > 0.0 && (delta || pdf > 0.0), pdf, delta);
        }
        case 2u: {
            let ior = m.value.w;
            var eta = ior;
            if (entering) {
                eta = 1.0 / ior;
            }
            let cos_theta = min(dot(-dir, shading), 1.0);
            let sin_theta = sqrt(max(1.0 - cos_theta * cos_theta, 0.0));
            let total_internal = eta * sin_theta > 1.0;
            // Drawn whether or not total internal reflection decides, as on the CPU.
            let choice = next_f32(rng);
            var direction = vec3<f32>(0.0);
            if (total_internal || schlick(cos_theta, eta) > choice) {
                direction = reflect_about(dir, shading);
            } else {
                direction = refract_through(dir, shading, eta, cos_theta);
            }
            out = Scatter(normalize(direction), vec3<f32>(1.0), true, 0.0, true);
        }
        case 4u: {
            let pbr = pbr_of(m);
            let f = frame_from_z(shading);
            let wo = to_local(f, -dir);
            let choice = next_f32(rng);
            let u = next_2d(rng);
            let wi = pbr_sample(pbr, wo, choice, u);
            if (wi.z > 0.0) {
                let pdf = pbr_pdf(pbr, wo, wi);
                let direction = f * wi;
                let weight = pbr_eval(pbr, wo, wi) / pdf;
                out = Scatter(direction, weight, dot(direction, geometric) > 0.0 && pdf > 0.0, pdf, false);
            }
        }
        default: {}
    }
    return out;
}

fn emitted(m: Material) -> vec3<f32> {
    return m.emission.xyz;
}

fn background(dir: vec3<f32>) -> vec3<f32> {
    if (frame.samples.z == 1u) {
        return frame.background.xyz;
    }
    if (frame.samples.z == 2u) {
        return env_radiance(dir);
    }
    let a = 0.5 * (normalize(dir).y + 1.0);
    return (1.0 - a) * vec3<f32>(1.0) + a * vec3<f32>(0.5, 0.7, 1.0);
}

fn offset_origin(s: Surface, direction: vec3<f32>) -> vec3<f32> {
    let offset = 2.0 * max(s.error, 1.17549435e-38);
    if (dot(direction, s.geometric) >= 0.0) {
        return s.p + offset * s.geometric;
    }
    return s.p - offset * s.geometric;
}

// The bsdf estimator; returns the radiance and counts the rays it traced.
fn radiance_bsdf(camera_origin: vec3<f32>, camera_dir: vec3<f32>, rng: ptr<function, Rng>, rays: ptr<function, vec2<u32>>) -> vec3<f32> {
    var origin = camera_origin;
    var dir = camera_dir;
    var throughput = vec3<f32>(1.0);
    var total = vec3<f32>(0.0);
    for (var depth = 0u; depth < frame.size.w; depth++) {
        *rays += vec2<u32>(1u, 0u);
        let hit = scene_intersect(RayIn(origin, 0.0, dir, INF), rng);
        if (hit.hit.prim == NO_PRIM) {
            total += throughput * background(dir);
            break;
        }
        let shaded = scene_shade(origin, dir, hit);
        let material = shaded.material;
        let s = shaded.surface;
        total += throughput * emitted(material);
        let next = scatter(material, dir, s, rng);
        if (!next.ok) {
            break;
        }
        throughput *= next.weight;
        if (all(throughput == vec3<f32>(0.0))) {
            break;
        }
        origin = offset_origin(s, next.direction);
        dir = next.direction;
    }
    return total;
}

@compute @workgroup_size(8, 8)
fn render(@builtin(global_invocation_id) id: vec3<u32>) {
    let width = frame.size.x;
    let height = frame.size.y;
    // This dispatch renders a band of the region's rows from frame.samples.w, as many
    // as `accum` holds (large regions come in several bands: render.rs).
    let region = frame.region;
    let row = id.y + frame.samples.w;
    let local = id.y * region.z + id.x;
    if (id.x >= region.z || row >= region.w || local >= arrayLength(&accum)) {
        return;
    }
    let x = region.x + id.x;
    let y = region.y + row;
    let pixel = y * width + x;
    var sum = accum[local];
    var rays = vec2<u32>(0u);
    for (var sample = frame.samples.x; sample < frame.samples.x + frame.samples.y; sample++) {
        var rng = rng_for_sample(frame.size.z, pixel, sample, frame.sampling.x);
        let jitter = next_2d(&rng);
        let s = (f32(x) + jitter.x) / f32(width);
        let t = (f32(y) + jitter.y) / f32(height);
        var origin = frame.origin.xyz;
        if (frame.origin.w > 0.0) {
            let disk = frame.origin.w * in_unit_disk(&rng);
            origin = origin + disk.x * frame.u.xyz + disk.y * frame.v.xyz;
        }
        let aim = frame.upper_left.xyz + s * frame.horizontal.xyz - t * frame.vertical.xyz;
        var dir = normalize(aim - origin);
        if (frame.forward.w > 0.0) {
            // Orthographic: parallel rays from the view's rectangle.
            origin = aim;
            dir = frame.forward.xyz;
        }
        var l = vec3<f32>(0.0);
        if (PATH_ESTIMATOR) {
            l = radiance_path(origin, dir, &rng, &rays);
        } else {
            l = radiance_bsdf(origin, dir, &rng, &rays);
        }
        let finite = all(l == l) && all(abs(l) < vec3<f32>(INF));
        if (finite) {
            sum = vec4<f32>(sum.xyz + l, sum.w);
        } else {
            sum.w += 1.0;
        }
    }
    accum[local] = sum;
    atomicAdd(&ray_count[0], rays.x);
    atomicAdd(&ray_count[1], rays.y);
}
