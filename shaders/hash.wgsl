// An integer hash for the cloud shaders' noise and jitter: pcg3d of
// Jarzynski and Olano 2020, "Hash Functions for GPU Rendering", JCGT 9(3).
// WGSL has no includes: the preview puts this file before each shader that
// uses it (src/preview/mod.rs, `shaders`).

fn pcg3d(v_in: vec3<u32>) -> vec3<u32> {
    var v = v_in * 1664525u + 1013904223u;
    v.x += v.y * v.z;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v ^= v >> vec3<u32>(16u);
    v.x += v.y * v.z;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    return v;
}
