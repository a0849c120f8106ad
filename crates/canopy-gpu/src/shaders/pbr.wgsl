// glTF's metallic-roughness BRDF: a port of canopy-render's material/ggx.rs and
// material/pbr.rs (the same formulas in the same order). Material kind 4: value.xyz the
// base colour, value.w the roughness, kind.y the metallic factor's bits.

const MIN_ALPHA: f32 = 1e-3;
const DIELECTRIC_F0: f32 = 0.04;

struct Pbr {
    base_color: vec3<f32>,
    metallic: f32,
    alpha: f32,
}

fn pbr_of(m: Material) -> Pbr {
    let roughness = m.value.w;
    return Pbr(m.value.xyz, bitcast<f32>(m.kind.y), max(roughness * roughness, MIN_ALPHA));
}

// The orthonormal basis of Duff et al. 2017 around unit `z`, as the columns x, y, z.
fn frame_from_z(z: vec3<f32>) -> mat3x3<f32> {
    // copysign(1, z.z), as the CPU: -0.0 counts as negative.
    let sign = select(1.0, -1.0, (bitcast<u32>(z.z) & 0x80000000u) != 0u);
    let a = -1.0 / (sign + z.z);
    let b = z.x * z.y * a;
    return mat3x3<f32>(
        vec3<f32>(1.0 + sign * z.x * z.x * a, sign * b, -sign * z.x),
        vec3<f32>(b, sign + z.y * z.y * a, -z.y),
        z,
    );
}

fn to_local(f: mat3x3<f32>, w: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(w, f[0]), dot(w, f[1]), dot(w, f[2]));
}

fn ggx_d(alpha: f32, h: vec3<f32>) -> f32 {
    if (h.z <= 0.0) {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let t = (h.x * h.x + h.y * h.y) + a2 * h.z * h.z;
    return a2 / (PI * t * t);
}

fn ggx_lambda(alpha: f32, w: vec3<f32>) -> f32 {
    let cos2 = w.z * w.z;
    let sin2 = w.x * w.x + w.y * w.y;
    let a2_tan2 = alpha * alpha * sin2 / cos2;
    return 0.5 * (sqrt(1.0 + a2_tan2) - 1.0);
}

fn ggx_sample_visible(alpha: f32, wo: vec3<f32>, u: vec2<f32>) -> vec3<f32> {
    let v = normalize(vec3<f32>(alpha * wo.x, alpha * wo.y, wo.z));
    let len2 = v.x * v.x + v.y * v.y;
    var t1 = vec3<f32>(1.0, 0.0, 0.0);
    if (len2 > 0.0) {
        t1 = vec3<f32>(-v.y, v.x, 0.0) / sqrt(len2);
    }
    let t2 = cross(v, t1);
    let r = sqrt(u.x);
    let phi = 2.0 * PI * u.y;
    let p1 = r * cos(phi);
    let s = 0.5 * (1.0 + v.z);
    let p2 = (1.0 - s) * sqrt(max(1.0 - p1 * p1, 0.0)) + s * r * sin(phi);
    let n = p1 * t1 + p2 * t2 + sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0)) * v;
    return normalize(vec3<f32>(alpha * n.x, alpha * n.y, max(n.z, 1e-6)));
}

fn schlick_weight(cos: f32) -> f32 {
    let m = clamp(1.0 - cos, 0.0, 1.0);
    let m2 = m * m;
    return m2 * m2 * m;
}

fn rgb_luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

fn pbr_specular_probability(m: Pbr, wo: vec3<f32>) -> f32 {
    let fresnel = schlick_weight(wo.z);
    let dielectric_specular = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * fresnel;
    let metal_specular = rgb_luminance(m.base_color + (vec3<f32>(1.0) - m.base_color) * fresnel);
    let specular = dielectric_specular + (metal_specular - dielectric_specular) * m.metallic;
    let diffuse = (1.0 - m.metallic) * (1.0 - DIELECTRIC_F0) * rgb_luminance(m.base_color);
    if (specular + diffuse > 0.0) {
        return specular / (specular + diffuse);
    }
    return 1.0;
}

// BRDF times wi.z for local directions.
fn pbr_eval(m: Pbr, wo: vec3<f32>, wi: vec3<f32>) -> vec3<f32> {
    if (wo.z <= 0.0 || wi.z <= 0.0) {
        return vec3<f32>(0.0);
    }
    let h = normalize(wo + wi);
    let specular = ggx_d(m.alpha, h) / (1.0 + ggx_lambda(m.alpha, wo) + ggx_lambda(m.alpha, wi)) / (4.0 * wo.z * wi.z);
    let weight = schlick_weight(clamp(dot(wo, h), 0.0, 1.0));
    let dielectric_fresnel = DIELECTRIC_F0 + (1.0 - DIELECTRIC_F0) * weight;
    let metal_fresnel = m.base_color + (vec3<f32>(1.0) - m.base_color) * weight;
    let dielectric = m.base_color * ((1.0 - dielectric_fresnel) * FRAC_1_PI) + vec3<f32>(dielectric_fresnel * specular);
    let metal = metal_fresnel * specular;
    return (dielectric * (1.0 - m.metallic) + metal * m.metallic) * wi.z;
}

fn pbr_pdf(m: Pbr, wo: vec3<f32>, wi: vec3<f32>) -> f32 {
    if (wo.z <= 0.0 || wi.z <= 0.0) {
        return 0.0;
    }
    let p = pbr_specular_probability(m, wo);
    let h = normalize(wo + wi);
    let reflection = ggx_d(m.alpha, h) / (1.0 + ggx_lambda(m.alpha, wo)) / (4.0 * wo.z);
    return p * reflection + (1.0 - p) * wi.z * FRAC_1_PI;
}

// A local direction to the light, or one with z <= 0 when the draw fell below the surface.
fn pbr_sample(m: Pbr, wo: vec3<f32>, choice: f32, u: vec2<f32>) -> vec3<f32> {
    if (wo.z <= 0.0) {
        return vec3<f32>(0.0);
    }
    if (choice < pbr_specular_probability(m, wo)) {
        let h = ggx_sample_visible(m.alpha, wo, u);
        return 2.0 * dot(wo, h) * h - wo;
    }
    let r = sqrt(u.x);
    let phi = 2.0 * PI * u.y;
    return vec3<f32>(r * cos(phi), r * sin(phi), sqrt(max(1.0 - u.x, 0.0)));
}
