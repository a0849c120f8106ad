// The first words of some streams, for the test that CPU and GPU draw the same numbers
// (appended to rng.wgsl).

// Per stream: seed key, pixel, sample, Sobol dimensions.
@group(0) @binding(0) var<storage, read> streams: array<vec4<u32>>;
@group(0) @binding(1) var<storage, read_write> words: array<u32>;
// x: words per stream.
@group(0) @binding(2) var<uniform> params: vec4<u32>;

@compute @workgroup_size(64)
fn first_words(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= arrayLength(&streams)) {
        return;
    }
    let s = streams[id.x];
    var rng = rng_for_sample(s.x, s.y, s.z, s.w);
    for (var i = 0u; i < params.x; i++) {
        words[id.x * params.x + i] = next_u32(&rng);
    }
}
