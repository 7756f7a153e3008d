// The baseline the sky pass is measured against (`sky bench preview`): a
// plain textured full-screen pass, what drawing a sky from one ready
// texture costs. Per direction, one filtered sample (the sampler's
// bilinear filtering) of one layer of one R11G11B10F array at the
// direction's latitude-longitude (u, v), written out. Nothing is checked
// against its values: only its time is used.

@group(0) @binding(0) var<storage, read> directions: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read_write> radiance: array<vec4<f32>>;
@group(0) @binding(2) var sky: texture_2d_array<f32>;
@group(0) @binding(3) var linear: sampler;

@compute @workgroup_size(64)
fn plain(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&directions) {
        return;
    }
    let d = directions[i];
    let uv = vec2<f32>(abs(atan2(d.y, d.x)) / 3.14159265358979, acos(clamp(d.z, -1.0, 1.0)) / 3.14159265358979);
    radiance[i] = vec4<f32>(textureSampleLevel(sky, linear, uv, 0, 0.0).rgb * d.w, 1.0);
}
