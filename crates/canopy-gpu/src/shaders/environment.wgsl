// Environment maps on the GPU (appended with render.wgsl and path.wgsl): nearest-pixel
// lookup, and sampling by luminance × sin θ through the map's 2D distribution, as
// canopy-render's background.rs does (its CDFs normalised to f32 here).

// Per pixel, rows from the top: radiance.
@group(0) @binding(10) var<storage, read> env_pixels: array<vec4<f32>>;
// Per pixel: the end of its slice of its row's CDF (normalised) and its cell density.
@group(0) @binding(11) var<storage, read> env_cells: array<vec2<f32>>;
// Per row: the end of its slice of the marginal CDF (normalised).
@group(0) @binding(12) var<storage, read> env_rows: array<f32>;

fn env_local(dir: vec3<f32>) -> vec3<f32> {
    // The transpose of to_world (its columns env_x, env_y, env_z) takes world to map.
    let d = vec3<f32>(dot(frame.env_x.xyz, dir), dot(frame.env_y.xyz, dir), dot(frame.env_z.xyz, dir));
    return normalize_or(d, vec3<f32>(0.0, 1.0, 0.0));
}

fn env_uv(dir: vec3<f32>) -> vec2<f32> {
    let d = env_local(dir);
    let u = 0.5 + atan2(d.x, -d.z) / TAU;
    let v = acos(clamp(d.y, -1.0, 1.0)) / PI;
    return clamp(vec2<f32>(u, v), vec2<f32>(0.0), vec2<f32>(1.0));
}

fn env_cell(uv: vec2<f32>) -> u32 {
    let width = frame.env_size.x;
    let height = frame.env_size.y;
    let column = min(u32(uv.x * f32(width)), width - 1u);
    let row = min(u32(uv.y * f32(height)), height - 1u);
    return row * width + column;
}

fn env_radiance(dir: vec3<f32>) -> vec3<f32> {
    return env_pixels[env_cell(env_uv(dir))].xyz;
}

fn env_pdf(dir: vec3<f32>) -> f32 {
    let uv = env_uv(dir);
    let sin_theta = sin(PI * uv.y);
    if (sin_theta <= 0.0) {
        return 0.0;
    }
    return env_cells[env_cell(uv)].y / (TAU * PI * sin_theta);
}

// The index in [first, first + count) whose CDF slice holds `u`, and `u`'s place inside
// it in [0, 1).
fn env_search_rows(u: f32) -> vec2<f32> {
    var lo = 0u;
    var hi = frame.env_size.y - 1u;
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (env_rows[mid] <= u) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    var start = 0.0;
    if (lo > 0u) {
        start = env_rows[lo - 1u];
    }
    let rest = clamp((u - start) / (env_rows[lo] - start), 0.0, 0.99999994);
    return vec2<f32>(f32(lo), rest);
}

fn env_search_columns(row: u32, u: f32) -> vec2<f32> {
    let first = row * frame.env_size.x;
    var lo = 0u;
    var hi = frame.env_size.x - 1u;
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (env_cells[first + mid].x <= u) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    var start = 0.0;
    if (lo > 0u) {
        start = env_cells[first + lo - 1u].x;
    }
    let rest = clamp((u - start) / (env_cells[first + lo].x - start), 0.0, 0.99999994);
    return vec2<f32>(f32(lo), rest);
}

// A direction drawn by the map's distribution from `u` (xyz) and its density (w; zero
// when none could be drawn).
fn env_sample(u: vec2<f32>) -> vec4<f32> {
    let r = env_search_rows(u.y);
    let row = u32(r.x);
    let c = env_search_columns(row, u.x);
    let column = u32(c.x);
    let uv = vec2<f32>(
        (f32(column) + c.y) / f32(frame.env_size.x),
        (f32(row) + r.y) / f32(frame.env_size.y),
    );
    let pdf_uv = env_cells[row * frame.env_size.x + column].y;
    let sin_theta = sin(PI * uv.y);
    let cos_theta = cos(PI * uv.y);
    let phi = TAU * (uv.x - 0.5);
    let local = vec3<f32>(sin_theta * sin(phi), cos_theta, -sin_theta * cos(phi));
    let direction = local.x * frame.env_x.xyz + local.y * frame.env_y.xyz + local.z * frame.env_z.xyz;
    let pdf = pdf_uv / (TAU * PI * sin_theta);
    if (sin_theta > 0.0 && pdf > 0.0 && pdf < INF) {
        return vec4<f32>(direction, pdf);
    }
    return vec4<f32>(direction, 0.0);
}
