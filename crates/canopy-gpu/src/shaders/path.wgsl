// The path integrator on the GPU (canopy's default, `path`): next-event estimation to
// one point on an emitter and one background direction per non-delta vertex, each
// weighted against BSDF sampling by the power heuristic, and Russian roulette (appended
// to render.wgsl; ports of canopy-render's integrator/path.rs, lights.rs and the shapes'
// `sample_toward`/`pdf_toward`).

// A light: its primitive record (or for a punctual light its index in `punctual`), the
// probability of choosing it (by power), the end of its slice of the cumulative
// distribution, normalised to 1, and whether it is punctual (1).
struct Light {
    record: u32,
    pmf: f32,
    cdf_end: f32,
    punctual: u32,
}

// A point (kind.x 0), spot (1) or directional (2) light: position (w: a spot's outer
// cosine), the direction light travels (w: a spot's falloff scale), intensity or
// irradiance (w: the scene's radius).
struct Punctual {
    position: vec4<f32>,
    direction: vec4<f32>,
    strength: vec4<f32>,
    kind: vec4<u32>,
}

@group(0) @binding(8) var<storage, read> lights: array<Light>;
// Per primitive: its light, or NO_LIGHT.
@group(0) @binding(9) var<storage, read> light_of_prim: array<u32>;

@group(0) @binding(23) var<storage, read> punctual: array<Punctual>;

const NO_LIGHT: u32 = 0xffffffffu;
const SMALL_CONE_SIN2: f32 = 0.00068523;
const UNIFORM_SPHERE_PDF: f32 = 0.07957747154594767;
const ROULETTE_AFTER: u32 = 3u;
const ROULETTE_MAX_SURVIVAL: f32 = 0.95;
const SHADOW_SHORTENING: f32 = 1e-4;

struct LightPoint {
    p: vec3<f32>,
    normal: vec3<f32>,
    error: f32,
    pdf: f32,
    // A triangle's barycentrics at p (weights of vertices 1 and 2).
    bary: vec2<f32>,
}

fn area_to_solid_angle(area_pdf: f32, reference: vec3<f32>, p: vec3<f32>, normal: vec3<f32>) -> f32 {
    let to_reference = reference - p;
    let d2 = dot(to_reference, to_reference);
    let cos = abs(dot(normal, to_reference)) / sqrt(d2);
    let pdf = area_pdf * d2 / cos;
    if (pdf > 0.0 && pdf < INF) {
        return pdf;
    }
    return 0.0;
}

fn cuboid_areas(p: Primitive) -> vec3<f32> {
    let e = p.d4.xyz - vec3<f32>(p.d0.w, p.d1.w, p.d2.w);
    let faces = vec3<f32>(e.y * e.z, e.x * e.z, e.x * e.y);
    return select(faces, 2.0 * faces, e > vec3<f32>(0.0));
}

fn shape_area(p: Primitive) -> f32 {
    switch p.header.x {
        case 0u: {
            return 0.5 * length(cross(p.d1.xyz - p.d0.xyz, p.d2.xyz - p.d0.xyz));
        }
        case 1u: {
            return 4.0 * PI * p.d0.w * p.d0.w;
        }
        default: {
            let a = cuboid_areas(p);
            return a.x + a.y + a.z;
        }
    }
}

fn shape_error(p: Primitive) -> f32 {
    switch p.header.x {
        case 0u: {
            return POINT_ERROR_ULPS * max(max(max_abs(p.d0.xyz), max_abs(p.d1.xyz)), max_abs(p.d2.xyz));
        }
        case 1u: {
            return POINT_ERROR_ULPS * (max_abs(p.d0.xyz) + p.d0.w);
        }
        default: {
            let lo = vec3<f32>(p.d0.w, p.d1.w, p.d2.w);
            return POINT_ERROR_ULPS * (max_abs(p.d3.xyz) + max(max_abs(lo), max_abs(p.d4.xyz)));
        }
    }
}

fn uniform_sphere(u: vec2<f32>) -> vec3<f32> {
    let z = 1.0 - 2.0 * u.x;
    let r = sqrt(max(1.0 - z * z, 0.0));
    let phi = TAU * u.y;
    return vec3<f32>(r * cos(phi), r * sin(phi), z);
}

// The cone a sphere subtends from `reference`: (sin² of its half-angle, 1 - cos), or a
// negative sin² from inside it.
fn cone_of(p: Primitive, reference: vec3<f32>) -> vec2<f32> {
    let distance = length(p.d0.xyz - reference);
    let sin2_max = (p.d0.w / distance) * (p.d0.w / distance);
    if (!(sin2_max < 1.0)) {
        return vec2<f32>(-1.0);
    }
    let cos_max = sqrt(1.0 - sin2_max);
    var one_minus_cos = 1.0 - cos_max;
    if (sin2_max < SMALL_CONE_SIN2) {
        one_minus_cos = sin2_max / 2.0;
    }
    if (!(one_minus_cos > 0.0)) {
        return vec2<f32>(-1.0);
    }
    return vec2<f32>(sin2_max, one_minus_cos);
}

// A point on primitive `index` for light arriving at `reference`, drawn from `u`; a
// zero pdf when there is none.
fn sample_toward(index: u32, reference: vec3<f32>, u: vec2<f32>) -> LightPoint {
    let p = prim_at(index);
    var out = LightPoint(vec3<f32>(0.0), vec3<f32>(0.0, 1.0, 0.0), shape_error(p), 0.0, vec2<f32>(0.0));
    switch p.header.x {
        case 0u: {
            let s = sqrt(u.x);
            let b0 = 1.0 - s;
            let b1 = u.y * s;
            let b2 = max(1.0 - b0 - b1, 0.0);
            out.p = b0 * p.d0.xyz + b1 * p.d1.xyz + b2 * p.d2.xyz;
            out.bary = vec2<f32>(b1, b2);
            out.normal = normalize_or(cross(p.d1.xyz - p.d0.xyz, p.d2.xyz - p.d0.xyz), vec3<f32>(0.0, 1.0, 0.0));
            out.pdf = area_to_solid_angle(1.0 / shape_area(p), reference, out.p, out.normal);
        }
        case 1u: {
            let center = p.d0.xyz;
            let radius = p.d0.w;
            let cone = cone_of(p, reference);
            if (cone.x < 0.0) {
                out.normal = uniform_sphere(u);
                out.p = center + radius * out.normal;
                out.pdf = area_to_solid_angle(1.0 / shape_area(p), reference, out.p, out.normal);
                return out;
            }
            let sin2_max = cone.x;
            var sin2_theta = 0.0;
            var cos_theta = 0.0;
            if (sin2_max < SMALL_CONE_SIN2) {
                sin2_theta = sin2_max * u.x;
                cos_theta = sqrt(1.0 - sin2_theta);
            } else {
                let cos_max = sqrt(1.0 - sin2_max);
                cos_theta = (cos_max - 1.0) * u.x + 1.0;
                sin2_theta = 1.0 - cos_theta * cos_theta;
            }
            let cos_alpha = sin2_theta / sqrt(sin2_max)
                + cos_theta * sqrt(max(1.0 - sin2_theta / sin2_max, 0.0));
            let sin_alpha = sqrt(max(1.0 - cos_alpha * cos_alpha, 0.0));
            // Frame (Duff et al. 2017) with z from the reference to the centre.
            let z = (center - reference) / length(center - reference);
            let sign = select(-1.0, 1.0, z.z >= 0.0);
            let a = -1.0 / (sign + z.z);
            let b = z.x * z.y * a;
            let x = vec3<f32>(1.0 + sign * z.x * z.x * a, sign * b, -sign * z.x);
            let y = vec3<f32>(b, sign + z.y * z.y * a, -z.y);
            let phi = TAU * u.y;
            let local = vec3<f32>(sin_alpha * cos(phi), sin_alpha * sin(phi), cos_alpha);
            out.normal = -(local.x * x + local.y * y + local.z * z);
            out.p = center + radius * out.normal;
            out.pdf = 1.0 / (TAU * cone.y);
        }
        default: {
            let areas = cuboid_areas(p);
            var pick = u.x * (areas.x + areas.y + areas.z);
            var axis = 0u;
            while (axis < 2u && pick >= areas[axis]) {
                pick -= areas[axis];
                axis++;
            }
            if (areas[axis] <= 0.0) {
                return out;
            }
            let rest = clamp(pick / areas[axis], 0.0, 1.0);
            let lo = vec3<f32>(p.d0.w, p.d1.w, p.d2.w);
            let hi = p.d4.xyz;
            var positive = false;
            var along = 0.0;
            if (lo[axis] == hi[axis]) {
                let rel = reference - p.d3.xyz;
                let to_reference = vec3<f32>(dot(p.d0.xyz, rel), dot(p.d1.xyz, rel), dot(p.d2.xyz, rel));
                positive = to_reference[axis] >= lo[axis];
                along = rest;
            } else if (rest >= 0.5) {
                positive = true;
                along = 2.0 * rest - 1.0;
            } else {
                along = 2.0 * rest;
            }
            let a = (axis + 1u) % 3u;
            let b = (axis + 2u) % 3u;
            var local = vec3<f32>(0.0);
            var local_normal = vec3<f32>(0.0);
            local[axis] = select(lo[axis], hi[axis], positive);
            local[a] = lo[a] + min(along, 1.0) * (hi[a] - lo[a]);
            local[b] = lo[b] + u.y * (hi[b] - lo[b]);
            local_normal[axis] = select(-1.0, 1.0, positive);
            var columns = array<vec3<f32>, 3>(p.d0.xyz, p.d1.xyz, p.d2.xyz);
            out.p = local.x * columns[0] + local.y * columns[1] + local.z * columns[2] + p.d3.xyz;
            out.normal = local_normal.x * columns[0] + local_normal.y * columns[1] + local_normal.z * columns[2];
            out.pdf = area_to_solid_angle(1.0 / shape_area(p), reference, out.p, out.normal);
        }
    }
    return out;
}

fn pdf_toward(index: u32, reference: vec3<f32>, point: vec3<f32>, normal: vec3<f32>) -> f32 {
    let p = prim_at(index);
    if (p.header.x == 1u) {
        let cone = cone_of(p, reference);
        if (cone.x >= 0.0) {
            return 1.0 / (TAU * cone.y);
        }
    }
    return area_to_solid_angle(1.0 / shape_area(p), reference, point, normal);
}

fn light_pdf(hit: SceneHit, reference: vec3<f32>, point: vec3<f32>, normal: vec3<f32>) -> f32 {
    if (frame.options.x == 0u) {
        return 0.0;
    }
    let light = light_of(hit);
    if (light == NO_LIGHT) {
        return 0.0;
    }
    // The light's own record: the primitive, or an instance's triangle in world space.
    return lights[light].pmf * pdf_toward(lights[light].record, reference, point, normal);
}

// Where punctual light `index` shines on `reference` from (origin.xyz) and what it brings
// there at normal incidence (`irradiance`); w is 0 where it brings nothing (as
// canopy-render's PunctualLight::toward).
struct PunctualSample {
    origin: vec4<f32>,
    irradiance: vec3<f32>,
}

fn punctual_toward(index: u32, reference: vec3<f32>) -> PunctualSample {
    let l = punctual[index];
    var out = PunctualSample(vec4<f32>(0.0), vec3<f32>(0.0));
    switch l.kind.x {
        case 0u: {
            let d = l.position.xyz - reference;
            let d2 = dot(d, d);
            if (d2 > 0.0) {
                out = PunctualSample(vec4<f32>(l.position.xyz, 1.0), l.strength.xyz / d2);
            }
        }
        case 1u: {
            let to_reference = reference - l.position.xyz;
            let d2 = dot(to_reference, to_reference);
            if (d2 > 0.0) {
                let cd = dot(l.direction.xyz, to_reference / sqrt(d2));
                var falloff = clamp((cd - l.position.w) * l.direction.w, 0.0, 1.0);
                falloff = falloff * falloff;
                if (falloff > 0.0) {
                    out = PunctualSample(vec4<f32>(l.position.xyz, 1.0), l.strength.xyz * (falloff / d2));
                }
            }
        }
        default: {
            let origin = reference - 2.0 * l.strength.w * l.direction.xyz;
            out = PunctualSample(vec4<f32>(origin, 1.0), l.strength.xyz);
        }
    }
    return out;
}

// A direction towards the background (xyz) and its density (w; zero for none): by the
// map's distribution; none for the sky and constant colours, which are left to BSDF
// sampling (options.y is 1 then), as canopy-render's Background::is_sampled says.
fn sample_background(u: vec2<f32>) -> vec4<f32> {
    if (frame.options.y == 1u) {
        return vec4<f32>(0.0);
    }
    if (frame.samples.z == 2u) {
        return env_sample(u);
    }
    return vec4<f32>(uniform_sphere(u), UNIFORM_SPHERE_PDF);
}

fn background_pdf(dir: vec3<f32>) -> f32 {
    if (frame.options.y == 1u) {
        return 0.0;
    }
    if (frame.samples.z == 2u) {
        return env_pdf(dir);
    }
    return UNIFORM_SPHERE_PDF;
}

fn power_heuristic(own: f32, other: f32) -> f32 {
    if (own >= INF) {
        return 1.0;
    }
    let a = own * own;
    let b = other * other;
    if (a + b == 0.0 || !(a + b < INF)) {
        return select(1.0, 0.0, b >= INF);
    }
    return a / (a + b);
}

fn is_delta(m: Material) -> bool {
    return (m.kind.x == 1u && m.value.w == 0.0) || m.kind.x == 2u;
}

// BSDF times cosine (zero for delta lobes) and the density of sampling `wi`.
fn material_eval(m: Material, dir: vec3<f32>, s: Surface, wi: vec3<f32>) -> vec3<f32> {
    var geometric = s.geometric;
    var shading = s.shading;
    if (dot(dir, s.geometric) >= 0.0) {
        geometric = -geometric;
        shading = -shading;
    }
    if (dot(wi, geometric) <= 0.0) {
        return vec3<f32>(0.0);
    }
    if (m.kind.x == 0u) {
        return m.value.xyz * (max(dot(wi, shading), 0.0) * FRAC_1_PI);
    }
    if (m.kind.x == 1u && m.value.w > 0.0) {
        return m.value.xyz * fuzz_pdf(reflect_about(dir, shading), m.value.w, wi);
    }
    if (m.kind.x == 4u) {
        let f = frame_from_z(shading);
        return pbr_eval(pbr_of(m), to_local(f, -dir), to_local(f, wi));
    }
    return vec3<f32>(0.0);
}

fn material_pdf(m: Material, dir: vec3<f32>, s: Surface, wi: vec3<f32>) -> f32 {
    var shading = s.shading;
    if (dot(dir, s.geometric) >= 0.0) {
        shading = -shading;
    }
    if (m.kind.x == 0u) {
        return max(dot(wi, shading), 0.0) * FRAC_1_PI;
    }
    if (m.kind.x == 1u && m.value.w > 0.0) {
        return fuzz_pdf(reflect_about(dir, shading), m.value.w, wi);
    }
    if (m.kind.x == 4u) {
        let f = frame_from_z(shading);
        return pbr_pdf(pbr_of(m), to_local(f, -dir), to_local(f, wi));
    }
    return 0.0;
}

fn normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    return normalize_or(v, vec3<f32>(0.0));
}

// The shadow rays of light sampling at one vertex (an emitter sample, then a background
// sample; `has` says which there are) and the light each brings where nothing blocks it.
struct LightTests {
    rays: array<RayIn, 2>,
    light: array<vec3<f32>, 2>,
    has: vec2<bool>,
}

fn no_light_tests() -> LightTests {
    let none = RayIn(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    return LightTests(array<RayIn, 2>(none, none), array<vec3<f32>, 2>(vec3<f32>(0.0), vec3<f32>(0.0)), vec2<bool>(false));
}

// One sample of the emitters and one of the background, MIS-weighted, as shadow tests
// (traced later, after the BSDF sample, as the CPU draws its numbers).
fn light_tests(m: Material, dir: vec3<f32>, s: Surface, rng: ptr<function, Rng>) -> LightTests {
    var tests = no_light_tests();
    let light_count = frame.options.x;
    if (light_count > 0u) {
        let pick = next_f32(rng);
        let u = next_2d(rng);
        // The first light whose slice ends beyond `pick`.
        var lo = 0u;
        var hi = light_count - 1u;
        while (lo < hi) {
            let mid = (lo + hi) / 2u;
            if (lights[mid].cdf_end <= pick) {
                lo = mid + 1u;
            } else {
                hi = mid;
            }
        }
        let light = lights[lo];
        var point = LightPoint(vec3<f32>(0.0), vec3<f32>(0.0), 0.0, 0.0, vec2<f32>(0.0));
        var radiance = vec3<f32>(0.0);
        var pdf = 0.0;
        if (light.punctual == 1u) {
            // Its own point, found by no other strategy: chosen with probability pmf and
            // not weighted by MIS.
            let toward = punctual_toward(light.record, s.p);
            if (toward.origin.w > 0.0) {
                point = LightPoint(toward.origin.xyz, normalize_or_zero(s.p - toward.origin.xyz), 0.0, 1.0, vec2<f32>(0.0));
                radiance = toward.irradiance;
                pdf = light.pmf;
            }
        } else {
            point = sample_toward(light.record, s.p, u);
            radiance = light_emission(light.record, point.bary);
            pdf = point.pdf * light.pmf;
        }
        if (point.pdf > 0.0) {
            let to_light = point.p - s.p;
            let wi = normalize_or_zero(to_light);
            let f = material_eval(m, dir, s, wi);
            if (any(f != vec3<f32>(0.0))) {
                let lift = 2.0 * point.error * point.normal;
                var aim = point.p - lift;
                if (dot(point.normal, to_light) < 0.0) {
                    aim = point.p + lift;
                }
                let origin = offset_origin(s, wi);
                var weight = 1.0;
                if (light.punctual == 0u) {
                    weight = power_heuristic(pdf, material_pdf(m, dir, s, wi));
                }
                tests.rays[0] = RayIn(origin, 0.0, aim - origin, 1.0 - SHADOW_SHORTENING);
                tests.light[0] = f * radiance * (weight / pdf);
                tests.has.x = true;
            }
        }
    }
    // Random numbers only for a sampled background, as on the CPU, so that both draw
    // the same streams in the same order.
    if (frame.options.y == 1u) {
        return tests;
    }
    let u = next_2d(rng);
    let sky = sample_background(u);
    if (sky.w > 0.0) {
        let direction = sky.xyz;
        let f = material_eval(m, dir, s, direction);
        if (any(f != vec3<f32>(0.0))) {
            let weight = power_heuristic(sky.w, material_pdf(m, dir, s, direction));
            tests.rays[1] = RayIn(offset_origin(s, direction), 0.0, direction, INF);
            tests.light[1] = f * background(direction) * (weight / sky.w);
            tests.has.y = true;
        }
    }
    return tests;
}

// The light that arrives: the shadow rays traced in order.
fn arriving(tests: LightTests, rng: ptr<function, Rng>, rays: ptr<function, vec2<u32>>) -> vec3<f32> {
    var direct = vec3<f32>(0.0);
    for (var i = 0u; i < 2u; i++) {
        if (tests.has[i]) {
            *rays += vec2<u32>(1u, 1u);
            if (!scene_blocked(tests.rays[i], rng)) {
                direct += tests.light[i];
            }
        }
    }
    return direct;
}

// The path estimator; counts rays (x) and shadow rays among them (y). Random numbers
// are drawn in the CPU's order: see-through layers of the segment, light samples, the
// BSDF sample and roulette, then see-through layers of the shadow rays.
fn radiance_path(camera_origin: vec3<f32>, camera_dir: vec3<f32>, rng: ptr<function, Rng>, rays: ptr<function, vec2<u32>>) -> vec3<f32> {
    let sample_background = frame.options.y == 0u;
    var origin = camera_origin;
    var dir = camera_dir;
    var throughput = vec3<f32>(1.0);
    var total = vec3<f32>(0.0);
    var has_previous = false;
    var previous_p = vec3<f32>(0.0);
    var previous_pdf = 0.0;
    for (var segments = 1u; segments <= frame.size.w; segments++) {
        *rays += vec2<u32>(1u, 0u);
        let hit = scene_intersect(RayIn(origin, 0.0, dir, INF), rng);
        if (hit.hit.prim == NO_PRIM) {
            var weight = 1.0;
            if (has_previous && sample_background) {
                weight = power_heuristic(previous_pdf, background_pdf(dir));
            }
            total += throughput * weight * background(dir);
            break;
        }
        let shaded = scene_shade(origin, dir, hit);
        let material = shaded.material;
        let s = shaded.surface;
        let light = emitted(material);
        if (any(light != vec3<f32>(0.0))) {
            var weight = 1.0;
            if (has_previous) {
                weight = power_heuristic(previous_pdf, light_pdf(hit, previous_p, s.p, s.geometric));
            }
            total += throughput * weight * light;
        }
        if (material.kind.x == 3u || segments == frame.size.w) {
            break;
        }
        var tests = no_light_tests();
        if (!is_delta(material)) {
            tests = light_tests(material, dir, s, rng);
        }
        let vertex_throughput = throughput;
        let next = scatter(material, dir, s, rng);
        var goes_on = next.ok;
        if (goes_on) {
            throughput *= next.weight;
            has_previous = !next.delta;
            previous_p = s.p;
            previous_pdf = next.pdf;
            if (frame.options.w == 1u && segments >= ROULETTE_AFTER) {
                let survival = min(max(max(throughput.x, throughput.y), throughput.z), ROULETTE_MAX_SURVIVAL);
                if (next_f32(rng) >= survival) {
                    goes_on = false;
                } else {
                    throughput /= survival;
                }
            }
            goes_on = goes_on && any(throughput != vec3<f32>(0.0));
        }
        total += vertex_throughput * arriving(tests, rng, rays);
        if (!goes_on) {
            break;
        }
        origin = offset_origin(s, next.direction);
        dir = next.direction;
    }
    return total;
}
