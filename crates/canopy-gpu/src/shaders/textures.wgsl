// Textures, normal maps and coverage (glTF's alpha modes) on the GPU (appended to the
// render kernel's sources): ports of canopy-render's texture.rs (bilinear lookups, sRGB
// decoded per texel before filtering, wrap modes, KHR_texture_transform) and of
// Scene::shade, Scene::stops_ray and the integrator's see-through search.

struct TextureRef {
    // Offset (xy) and scale (zw) of the texture transform.
    transform: vec4<f32>,
    // Image (NO_IMAGE: none), wraps (s in bits 0..8, t in 8..16: 0 repeat, 1 clamp,
    // 2 mirror), and the bits of the rotation's sine and cosine.
    info: vec4<u32>,
}

struct MaterialMaps {
    base_color: TextureRef,
    metallic_roughness: TextureRef,
    normal: TextureRef,
    emissive: TextureRef,
    // Coverage (0 opaque, 1 mask, 2 blend), alpha factor, cutoff, normal map scale
    // (the last three as f32 bits).
    coverage: vec4<u32>,
}

@group(0) @binding(24) var<storage, read> material_maps: array<MaterialMaps>;
// Per image: first texel, width, height.
@group(0) @binding(25) var<storage, read> images: array<vec4<u32>>;
@group(0) @binding(26) var<storage, read> texels: array<u32>;
// Per textured mesh triangle (GpuPrimitive's header.w): uv0, uv1 | uv2, the bitangent's
// sign, 1 when the corners' tangents follow | the three tangents.
@group(0) @binding(27) var<storage, read> surface_data: array<vec4<f32>>;

const NO_IMAGE: u32 = 0xffffffffu;
const NO_SURFACE: u32 = 0xffffffffu;
const MAX_SEE_THROUGH_LAYERS: u32 = 256u;
// Texel indices are folded from at most this far out (beyond it a coordinate means
// nothing; the CPU saturates at i64's range).
const FAR_TEXEL: f32 = 1073741824.0;

fn srgb_to_linear(c: f32) -> f32 {
    if (c <= 0.04045) {
        return c / 12.92;
    }
    return pow((c + 0.055) / 1.055, 2.4);
}

fn rem_euclid(i: i32, n: i32) -> i32 {
    let r = i % n;
    return select(r, r + n, r < 0);
}

// Texel index `i` folded into 0..n by wrap mode `mode`.
fn fold(mode: u32, i: i32, n: i32) -> u32 {
    switch mode {
        case 0u: {
            return u32(rem_euclid(i, n));
        }
        case 1u: {
            return u32(clamp(i, 0, n - 1));
        }
        default: {
            let period = rem_euclid(i, 2 * n);
            return u32(select(2 * n - 1 - period, period, period < n));
        }
    }
}

fn texel(image: vec4<u32>, x: u32, y: u32, srgb: bool) -> vec4<f32> {
    let c = unpack4x8unorm(texels[image.x + y * image.y + x]);
    if (srgb) {
        return vec4<f32>(srgb_to_linear(c.x), srgb_to_linear(c.y), srgb_to_linear(c.z), c.w);
    }
    return c;
}

// The texture at `uv`, bilinearly filtered between texel centres; with `srgb` its colour
// channels decoded to linear first (alpha never is).
fn texture_lookup(t: TextureRef, uv_in: vec2<f32>, srgb: bool) -> vec4<f32> {
    let image = images[t.info.x];
    let scaled = uv_in * t.transform.zw;
    let sin = bitcast<f32>(t.info.z);
    let cos = bitcast<f32>(t.info.w);
    let uv = vec2<f32>(cos * scaled.x + sin * scaled.y, -sin * scaled.x + cos * scaled.y) + t.transform.xy;
    if (!all(abs(uv) < vec2<f32>(INF))) {
        return vec4<f32>(1.0);
    }
    // Texel centres sit at half-integers.
    let x = uv.x * f32(image.y) - 0.5;
    let y = uv.y * f32(image.z) - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let ix = i32(clamp(x0, -FAR_TEXEL, FAR_TEXEL));
    let iy = i32(clamp(y0, -FAR_TEXEL, FAR_TEXEL));
    let width = i32(image.y);
    let height = i32(image.z);
    let ws = t.info.y & 0xffu;
    let wt = t.info.y >> 8u;
    let xs = vec2<u32>(fold(ws, ix, width), fold(ws, ix + 1, width));
    let ys = vec2<u32>(fold(wt, iy, height), fold(wt, iy + 1, height));
    let a = texel(image, xs.x, ys.x, srgb);
    let b = texel(image, xs.y, ys.x, srgb);
    let c = texel(image, xs.x, ys.y, srgb);
    let d = texel(image, xs.y, ys.y, srgb);
    let top = a + (b - a) * fx;
    let bottom = c + (d - c) * fx;
    return top + (bottom - top) * fy;
}

fn has_image(t: TextureRef) -> bool {
    return t.info.x != NO_IMAGE;
}

// Where the texture data of the triangle `h` hit starts, for a mesh instance's
// triangle with texture coordinates; NO_SURFACE otherwise.
fn surface_index(h: SceneHit) -> u32 {
    if (instances[h.inst].info.z == NO_MATERIAL) {
        return NO_SURFACE;
    }
    return prim_at(h.hit.prim).header.w;
}

// The texture coordinates at barycentrics (u, v) of the triangle whose data starts at
// `index`.
fn hit_uv(index: u32, h: HitOut) -> vec2<f32> {
    let r0 = surface_data[index];
    let r1 = surface_data[index + 1u];
    return r0.xy * (1.0 - h.u - h.v) + r0.zw * h.u + r1.xy * h.v;
}

// Whether a ray stops at `h` or passes through a see-through part of the surface
// (drawing a number for stochastic transparency), as Scene::stops_ray.
fn stops_ray(h: SceneHit, rng: ptr<function, Rng>) -> bool {
    let maps = material_maps[material_index(h)];
    let mode = maps.coverage.x;
    if (mode == 0u) {
        return true;
    }
    var alpha = bitcast<f32>(maps.coverage.y);
    let index = surface_index(h);
    if (has_image(maps.base_color) && index != NO_SURFACE) {
        alpha *= texture_lookup(maps.base_color, hit_uv(index, h.hit), true).w;
    }
    if (mode == 1u) {
        return alpha >= bitcast<f32>(maps.coverage.z);
    }
    return alpha >= 1.0 || (alpha > 0.0 && next_f32(rng) < alpha);
}

// The next float above t (t is finite and not negative).
fn next_up(t: f32) -> f32 {
    if (t <= 0.0) {
        return bitcast<f32>(1u);
    }
    return bitcast<f32>(bitcast<u32>(t) + 1u);
}

// The first surface along `r` that stops it (with `first_ends`, any one: for shadow
// rays): where no surface is see-through (frame.top.z == 0), the closest hit (or the first
// found); otherwise the closest whose coverage stops the ray, the search going on past
// each that does not (at most MAX_SEE_THROUGH_LAYERS of them, as on the CPU). One call
// of the walk in one loop: WGSL compilers inline every call, so each call site is a
// copy of the traversal.
fn scene_search(r: RayIn, first_ends: bool, rng: ptr<function, Rng>) -> SceneHit {
    let see_through = frame.top.z != 0u;
    // A see-through surface found first may not be the one that stops the ray.
    let any_hit = first_ends && !see_through;
    var t_min = r.t_min;
    for (var layer = 0u; ; layer++) {
        let hit = scene_walk(RayIn(r.origin, t_min, r.dir, r.t_max), any_hit);
        if (!see_through || hit.hit.prim == NO_PRIM || layer == MAX_SEE_THROUGH_LAYERS || stops_ray(hit, rng)) {
            return hit;
        }
        t_min = next_up(hit.hit.t);
    }
    return SceneHit(HitOut(r.t_max, NO_PRIM, 0.0, 0.0), NO_INSTANCE);
}

fn scene_intersect(r: RayIn, rng: ptr<function, Rng>) -> SceneHit {
    return scene_search(r, false, rng);
}

// Whether a shadow ray is blocked.
fn scene_blocked(r: RayIn, rng: ptr<function, Rng>) -> bool {
    return scene_search(r, true, rng).hit.prim != NO_PRIM;
}

struct Shaded {
    material: Material,
    surface: Surface,
}

// `v` normalised; zero where it cannot be (as glam's try_normalize gives none).
fn try_normalize(v: vec3<f32>) -> vec3<f32> {
    return normalize_or(v, vec3<f32>(0.0));
}

// The shading normal of `s` bent by the normal map of `maps` at `uv`, where the mesh has
// tangents and the bent normal stays on the shading normal's side of the surface; the
// shading normal itself otherwise (Scene::normal_mapped and NormalMap::perturb).
fn normal_mapped(maps: MaterialMaps, h: SceneHit, index: u32, uv: vec2<f32>, s: Surface) -> vec3<f32> {
    let r1 = surface_data[index + 1u];
    if (r1.w == 0.0) {
        return s.shading;
    }
    let inst = instances[h.inst];
    let p = prim_at(h.hit.prim);
    let w = vec3<f32>(1.0 - h.hit.u - h.hit.v, h.hit.u, h.hit.v);
    let tangent = w.x * surface_data[index + 2u].xyz + w.y * surface_data[index + 3u].xyz
        + w.z * surface_data[index + 4u].xyz;
    // The bitangent in the mesh's own space, from its own normal there.
    var local_normal = cross(p.d1.xyz - p.d0.xyz, p.d2.xyz - p.d0.xyz);
    if (p.header.z != FLAT) {
        let n = 3u * p.header.z;
        local_normal = w.x * normal_at(n).xyz + w.y * normal_at(n + 1u).xyz + w.z * normal_at(n + 2u).xyz;
    }
    let bitangent = r1.z * cross(try_normalize(local_normal), tangent);
    let world_t = apply_vector(inst.to_world, tangent);
    let world_b = apply_vector(inst.to_world, bitangent);
    let n = s.shading;
    let t = try_normalize(world_t - n * dot(n, world_t));
    let b = try_normalize(world_b - n * dot(n, world_b) - t * dot(t, world_b));
    if (all(t == vec3<f32>(0.0)) || all(b == vec3<f32>(0.0))) {
        return s.shading;
    }
    let c = texture_lookup(maps.normal, uv, false);
    let scale = bitcast<f32>(maps.coverage.w);
    let local = vec3<f32>((2.0 * c.x - 1.0) * scale, (2.0 * c.y - 1.0) * scale, 2.0 * c.z - 1.0);
    let bent = try_normalize(t * local.x + b * local.y + n * local.z);
    if (dot(bent, s.geometric) * dot(s.shading, s.geometric) > 0.0) {
        return bent;
    }
    return s.shading;
}

// The surface where the ray from `origin` along `dir` hits (`h`) and its material there,
// textures applied (where the surface has texture coordinates), as Scene::shade.
fn scene_shade(origin: vec3<f32>, dir: vec3<f32>, h: SceneHit) -> Shaded {
    let material = material_index(h);
    var out = Shaded(materials[material], scene_surface(origin, dir, h));
    if (frame.top.w == 0u) {
        return out;
    }
    let index = surface_index(h);
    if (index == NO_SURFACE) {
        return out;
    }
    let maps = material_maps[material];
    let uv = hit_uv(index, h.hit);
    if (has_image(maps.normal)) {
        out.surface.shading = normal_mapped(maps, h, index, uv, out.surface);
    }
    // Only the metallic-roughness material has texture slots.
    if (out.material.kind.x != 4u) {
        return out;
    }
    if (has_image(maps.base_color)) {
        let c = texture_lookup(maps.base_color, uv, true);
        out.material.value = vec4<f32>(out.material.value.xyz * c.xyz, out.material.value.w);
    }
    if (has_image(maps.metallic_roughness)) {
        let c = texture_lookup(maps.metallic_roughness, uv, false);
        out.material.value.w *= c.y;
        out.material.kind.y = bitcast<u32>(bitcast<f32>(out.material.kind.y) * c.z);
    }
    if (has_image(maps.emissive)) {
        out.material.emission = vec4<f32>(emission_at(maps, out.material.emission.xyz, uv), 0.0);
    }
    return out;
}

// The emission `factor` times the emissive texture of `maps` at `uv`.
fn emission_at(maps: MaterialMaps, factor: vec3<f32>, uv: vec2<f32>) -> vec3<f32> {
    return factor * texture_lookup(maps.emissive, uv, true).xyz;
}

// The radiance light record `record` (a primitive, or an instance's triangle in world
// space with its mesh triangle's texture data) sends from barycentrics `bary`, as
// Scene::emitted_at.
fn light_emission(record: u32, bary: vec2<f32>) -> vec3<f32> {
    let p = prim_at(record);
    let factor = emitted(materials[p.header.y]);
    if (frame.top.w == 0u || p.header.w == NO_SURFACE || all(factor == vec3<f32>(0.0))) {
        return factor;
    }
    let maps = material_maps[p.header.y];
    if (!has_image(maps.emissive)) {
        return factor;
    }
    return emission_at(maps, factor, hit_uv(p.header.w, HitOut(0.0, record, bary.x, bary.y)));
}
