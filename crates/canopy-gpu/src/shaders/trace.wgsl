// Closest hits for a batch of rays (appended to common.wgsl).

@group(0) @binding(3) var<storage, read> rays: array<RayIn>;
@group(0) @binding(4) var<storage, read_write> hits: array<HitOut>;
// x: rays in this dispatch, y: first ray.
@group(0) @binding(5) var<uniform> params: vec4<u32>;

@compute @workgroup_size(64)
fn trace(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i >= params.x) {
        return;
    }
    let ray = rays[params.y + i];
    var hit = closest(ray);
    if (hit.prim == NO_PRIM) {
        hit.t = INF;
    }
    hits[params.y + i] = hit;
}
