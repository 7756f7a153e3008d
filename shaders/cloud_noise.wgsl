// The cloud noise textures (the talk's "Modeling of Clouds", after
// Schneider 2015 and 2017), built on the GPU, all tileable so that they
// repeat over the world without seams:
// - low frequency, 128^3 over about 5 km: Perlin noise dilated by
//   inverted Worley noise ("Perlin-inverted Worley"), then shifted to a
//   zero mean (the talk: "the amount of clouds does not vary with the
//   intensity of the noise") by three passes: the values, partial sums, the
//   mean, and the store;
// - high frequency, 32^3 over about 1.2 km: inverted Worley noise (cells of
//   about 300 m), in [0, 1].
// The middle frequency is the low texture read at a smaller scale.
//
// Every value is a function of the integer lattice and a seed only (the
// integer hash `pcg3d` of hash.wgsl, which the preview puts before this
// file), so the textures are the same on every adapter up to its float
// arithmetic.

struct Params {
    // Texels per side; seed.
    size: u32,
    seed: u32,
    // Values per partial sum (partial_sums).
    chunk: u32,
    count: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> values: array<f32>;
@group(0) @binding(2) var<storage, read_write> partial: array<f32>;
@group(0) @binding(3) var noise: texture_storage_3d<rgba16float, write>;

// A point of the unit cube from lattice cell c (wrapped by `period`) and
// the seed: three uniform numbers in [0, 1).
fn random3(c: vec3<i32>, period: i32, salt: u32) -> vec3<f32> {
    let w = vec3<u32>(((c % period) + period) % period);
    return vec3<f32>(pcg3d(w + vec3<u32>(params.seed, salt, 0u) * 977u) >> vec3<u32>(8u)) / 16777216.0;
}

fn fade(t: vec3<f32>) -> vec3<f32> {
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
}

// Gradient noise (Perlin 2002's quintic fade) with `period` cells across
// the unit cube, about in [-1, 1].
fn perlin(p: vec3<f32>, period: i32, salt: u32) -> f32 {
    let q = p * f32(period);
    let c = vec3<i32>(floor(q));
    let f = q - floor(q);
    var corners: array<f32, 8>;
    for (var k = 0; k < 8; k++) {
        let o = vec3<i32>(k & 1, (k >> 1) & 1, (k >> 2) & 1);
        let g = normalize(random3(c + o, period, salt) * 2.0 - 1.0 + vec3<f32>(1e-6));
        corners[k] = dot(g, f - vec3<f32>(o));
    }
    let u = fade(f);
    let x0 = mix(corners[0], corners[1], u.x);
    let x1 = mix(corners[2], corners[3], u.x);
    let x2 = mix(corners[4], corners[5], u.x);
    let x3 = mix(corners[6], corners[7], u.x);
    return mix(mix(x0, x1, u.y), mix(x2, x3, u.y), u.z) * 1.5;
}

// Inverted Worley noise with `period` cells across the unit cube: 1 at a
// feature point, falling to 0 a cell away.
fn worley(p: vec3<f32>, period: i32, salt: u32) -> f32 {
    let q = p * f32(period);
    let c = vec3<i32>(floor(q));
    var nearest = 1.0;
    for (var k = 0; k < 27; k++) {
        let o = vec3<i32>(k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1);
        let feature = vec3<f32>(c + o) + random3(c + o, period, salt);
        nearest = min(nearest, length(feature - q));
    }
    return 1.0 - nearest;
}

fn texel_position(id: vec3<u32>) -> vec3<f32> {
    return (vec3<f32>(id) + 0.5) / f32(params.size);
}

// Low frequency: three octaves of Perlin noise (4, 8, 16 cells) in [0, 1],
// dilated by three octaves of inverted Worley noise (Schneider 2015's
// remap(perlin, worley - 1, 1, 0, 1)).
@compute @workgroup_size(4, 4, 4)
fn low_values(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id >= vec3<u32>(params.size)) {
        return;
    }
    let p = texel_position(id);
    let fbm = (perlin(p, 4, 1u) + 0.5 * perlin(p, 8, 2u) + 0.25 * perlin(p, 16, 3u)) / 1.75;
    let perlin01 = clamp(0.5 + 0.5 * fbm, 0.0, 1.0);
    let cells = 0.625 * worley(p, 4, 4u) + 0.25 * worley(p, 8, 5u) + 0.125 * worley(p, 16, 6u);
    let dilated = (perlin01 - (cells - 1.0)) / (1.0 - (cells - 1.0));
    values[id.x + params.size * (id.y + params.size * id.z)] = dilated;
}

// Invocation i sums `chunk` values from i * chunk.
@compute @workgroup_size(64)
fn partial_sums(@builtin(global_invocation_id) id: vec3<u32>) {
    let start = id.x * params.chunk;
    if start >= params.count {
        return;
    }
    var sum = 0.0;
    for (var k = 0u; k < params.chunk; k++) {
        sum += values[start + k];
    }
    partial[id.x] = sum;
}

// One invocation: the mean of every value, into partial[0].
@compute @workgroup_size(1)
fn mean(@builtin(global_invocation_id) id: vec3<u32>) {
    var sum = 0.0;
    let n = params.count / params.chunk;
    for (var k = 0u; k < n; k++) {
        sum += partial[k];
    }
    partial[0] = sum / f32(params.count);
}

// The low-frequency texture: each value less the mean.
@compute @workgroup_size(4, 4, 4)
fn store_low(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id >= vec3<u32>(params.size)) {
        return;
    }
    let v = values[id.x + params.size * (id.y + params.size * id.z)] - partial[0];
    textureStore(noise, id, vec4<f32>(v, 0.0, 0.0, 1.0));
}

// High frequency: three octaves of inverted Worley noise (4, 8, 16 cells).
@compute @workgroup_size(4, 4, 4)
fn high(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id >= vec3<u32>(params.size)) {
        return;
    }
    let p = texel_position(id);
    let v = 0.625 * worley(p, 4, 7u) + 0.25 * worley(p, 8, 8u) + 0.125 * worley(p, 16, 9u);
    textureStore(noise, id, vec4<f32>(v, 0.0, 0.0, 1.0));
}
