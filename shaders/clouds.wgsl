// The cumulus clouds (the talk's "Run-time Cloud Rendering Method", after
// Schneider 2015 and 2017): the cumulus map, the distant-cloud shadow
// volume and the cloud G-buffer, ray-marched from the world's centre over
// the upper hemisphere. Lighting is deferred: the G-buffer holds factors
// that the lighting pass (cloud_lighting.wgsl) multiplies by the sun and
// sky of the frame, decoded from the bake's LUTs.
//
// World frame: km, z up, the observer at the origin on the ground of a
// sphere of radius params.planet.x; the cloud layer between the altitudes
// params.planet.y (base) and params.planet.z (top).
//
// Density at a point (our reading of the talk's "Coverage Texture"):
//   d2   = the cumulus map at the point's (x, y) (0 outside its 240 km),
//   c    = coverage(d2, h), h = (altitude - base) / (top - base):
//          R height modulation, G low- and B mid-frequency weights,
//          A the share of the sky's ambient light that reaches the point,
//   base = R + G * 3 * low(p / 5 km) + B * 3 * low(p / 2 km) - 0.1  (low: zero mean),
//   density = clamp(base - (1 - base) * 0.35 * high(p / 1.2 km), 0, 1),
//   extinction = density * params.optics.x per km (scattering albedo 1).

const PI: f32 = 3.14159265358979;

struct Params {
    // (planet radius, cloud base, cloud top, km; the map's half size, km)
    planet: vec4<f32>,
    // (unit vector toward the sun; cumulus cover in [0, 1])
    sun: vec4<f32>,
    // (wind offset x, y, km; G-buffer size in texels; samples per texel)
    wind: vec4<f32>,
    // (extinction of density 1, per km; Wrenninge octaves' a, b, c)
    optics: vec4<f32>,
    // (first sample index; seed; march steps; 0)
    frame: vec4<f32>,
    // The amortised G-buffer's (frame in the cycle, frames per sample,
    // first sample number, clear after resolving: 1).
    tiles: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var cumulus_out: texture_storage_2d<rgba16float, write>;
@group(0) @binding(2) var shadow_out: texture_storage_3d<rgba16float, write>;
@group(0) @binding(3) var gbuffer_out: texture_storage_2d<rgba16float, write>;
@group(0) @binding(4) var cumulus: texture_2d<f32>;
@group(0) @binding(5) var coverage: texture_2d<f32>;
@group(0) @binding(6) var low_noise: texture_3d<f32>;
@group(0) @binding(7) var high_noise: texture_3d<f32>;
@group(0) @binding(8) var shadow: texture_3d<f32>;
@group(0) @binding(9) var clamped: sampler;
@group(0) @binding(10) var repeating: sampler;
@group(0) @binding(12) var occlusion_out: texture_storage_3d<rgba16float, write>;

// The cumulus map's texel distribution: texel coordinate s in [-1, 1] to
// world x = half * s * (K + (1 - K) |s|), texels 4 times denser at the
// centre than a linear map's (0.23 km) and 1.75 times sparser at the edge.
const K: f32 = 0.25;

fn map_to_world(s: f32) -> f32 {
    return params.planet.w * s * (K + (1.0 - K) * abs(s));
}

fn world_to_map(x: f32) -> f32 {
    let a = min(abs(x) / params.planet.w, 1.0);
    let s = (-K + sqrt(K * K + 4.0 * (1.0 - K) * a)) / (2.0 * (1.0 - K));
    return sign(x) * s;
}

fn random2(c: vec2<i32>, salt: u32) -> vec2<f32> {
    return vec2<f32>(pcg3d(vec3<u32>(bitcast<vec2<u32>>(c), salt + u32(params.frame.y) * 131u)).xy >> vec2<u32>(8u)) / 16777216.0;
}

// 2-D gradient noise, about in [-1, 1].
fn perlin2(p: vec2<f32>, salt: u32) -> f32 {
    let c = vec2<i32>(floor(p));
    let f = p - floor(p);
    let u = f * f * f * (f * (f * 6.0 - 15.0) + 10.0);
    var corner: array<f32, 4>;
    for (var k = 0; k < 4; k++) {
        let o = vec2<i32>(k & 1, k >> 1);
        let g = normalize(random2(c + o, salt) * 2.0 - 1.0 + vec2<f32>(1e-6));
        corner[k] = dot(g, f - vec2<f32>(o));
    }
    return mix(mix(corner[0], corner[1], u.x), mix(corner[2], corner[3], u.x), u.y) * 1.4;
}

// The cumulus map (the talk's weather system stands in here as Perlin
// noise): three octaves over 30, 12 and 5 km, advected by the wind,
// thresholded by the cover.
@compute @workgroup_size(8, 8)
fn cumulus_map(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = textureDimensions(cumulus_out);
    if any(id.xy >= n) {
        return;
    }
    let s = (vec2<f32>(id.xy) + 0.5) / vec2<f32>(n) * 2.0 - 1.0;
    let world = vec2<f32>(map_to_world(s.x), map_to_world(s.y)) - params.wind.xy;
    let fbm = (perlin2(world / 30.0, 1u) + 0.5 * perlin2(world / 12.0, 2u) + 0.25 * perlin2(world / 5.0, 3u)) / 1.75;
    let cover = params.sun.w;
    // The noise's values lie mostly within 0.5 +- 0.25: the threshold moves
    // across that range with the cover, so that about the cover's share of
    // the map is cloud.
    let threshold = 0.5 + 0.25 * (1.0 - 2.0 * cover);
    var d = smoothstep(threshold, threshold + 0.1, 0.5 + 0.5 * fbm);
    if cover <= 0.0 {
        d = 0.0;
    }
    textureStore(cumulus_out, id.xy, vec4<f32>(d, 0.0, 0.0, 1.0));
}

fn altitude_of(p: vec3<f32>) -> f32 {
    return length(p + vec3<f32>(0.0, 0.0, params.planet.x)) - params.planet.x;
}

fn map_density(p: vec3<f32>) -> f32 {
    let s = vec2<f32>(world_to_map(p.x), world_to_map(p.y));
    if any(abs(vec2<f32>(p.x, p.y)) >= vec2<f32>(params.planet.w)) {
        return 0.0;
    }
    return textureSampleLevel(cumulus, clamped, 0.5 + 0.5 * s, 0.0).r;
}

// The coverage texture at a point: (height modulation, low weight, mid
// weight, ambient share); zero outside the layer and where the map has
// no cloud.
fn coverage_at(p: vec3<f32>) -> vec4<f32> {
    let h = (altitude_of(p) - params.planet.y) / (params.planet.z - params.planet.y);
    if h < 0.0 || h > 1.0 {
        return vec4<f32>(0.0);
    }
    let d2 = map_density(p);
    if d2 <= 0.0 {
        return vec4<f32>(0.0);
    }
    return textureSampleLevel(coverage, clamped, vec2<f32>(d2, h), 0.0);
}

// The full density: coverage, low, mid and high frequencies.
fn density(p: vec3<f32>, c: vec4<f32>) -> f32 {
    // No cover, no cloud: the noises only carve what the map and the
    // height modulation put there.
    if c.r <= 0.0 {
        return 0.0;
    }
    let low = textureSampleLevel(low_noise, repeating, p / 5.0, 0.0).r;
    let mid = textureSampleLevel(low_noise, repeating, p / 2.0, 0.0).r;
    let base = c.r + 3.0 * (c.g * low + c.b * mid) - 0.1;
    if base <= 0.0 {
        return 0.0;
    }
    let high = textureSampleLevel(high_noise, repeating, p / 1.2, 0.0).r;
    return clamp(base - (1.0 - base) * 0.35 * high, 0.0, 1.0);
}

// The coarse density's optical depth toward the sun from `cell`, between
// `start_km` along the sun's direction and the top of the layer (16
// midpoint steps through the cumulus map and the coverage's height
// modulation); the sun above the horizon.
fn coarse_depth_to_sun(cell: vec3<f32>, start_km: f32) -> f32 {
    let sun = params.sun.xyz;
    let length_km = max(params.planet.z - cell.z, 0.0) / sun.z;
    let start = min(start_km, length_km);
    let step = (length_km - start) / 16.0;
    var tau = 0.0;
    for (var k = 0; k < 16; k++) {
        tau += coverage_at(cell + sun * (start + (f32(k) + 0.5) * step)).r * params.optics.x * step;
    }
    return tau;
}

// The centre of cell `id` of an `n` grid over the map (x, y) and altitudes
// from the ground to `top_km`.
fn grid_cell(id: vec3<u32>, n: vec3<u32>, top_km: f32) -> vec3<f32> {
    let f = (vec3<f32>(id) + 0.5) / vec3<f32>(n);
    return vec3<f32>((2.0 * f.xy - 1.0) * params.planet.w, f.z * top_km);
}

// The distant-cloud shadow: each cell of a grid from the ground to the
// cloud top holds the transmittance toward the sun from 4 km along the
// sun's direction (nearer, the G-buffer's own march sees the clouds in
// detail) out of the layer, through the coarse density.
const NEAR_SHADOW_KM: f32 = 4.0;

@compute @workgroup_size(4, 4, 4)
fn shadow_volume(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = textureDimensions(shadow_out);
    if any(id >= n) {
        return;
    }
    var transmittance = 0.0;
    if params.sun.z > 0.0 {
        transmittance = exp(-coarse_depth_to_sun(grid_cell(id, n, params.planet.z), NEAR_SHADOW_KM));
    }
    textureStore(shadow_out, id, vec4<f32>(transmittance, 0.0, 0.0, 1.0));
}

// The clouds' occlusion of the air below them, for the global fog (the
// talk: "cloud occlusion is computed separately on the 3D grid that covers
// the world"): each cell of a grid from the ground to the cloud base holds
// 1 - the transmittance toward the sun through the coarse density out of
// the layer (0 with the sun below the horizon: no sunlight for clouds to
// take away).
@compute @workgroup_size(4, 4, 4)
fn occlusion_volume(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = textureDimensions(occlusion_out);
    if any(id >= n) {
        return;
    }
    var occlusion = 0.0;
    if params.sun.z > 0.0 {
        let cell = grid_cell(id, n, params.planet.y);
        occlusion = 1.0 - exp(-coarse_depth_to_sun(cell, max(params.planet.y - cell.z, 0.0) / params.sun.z));
    }
    textureStore(occlusion_out, id, vec4<f32>(occlusion, 0.0, 0.0, 1.0));
}

fn far_shadow(p: vec3<f32>) -> f32 {
    let f = vec3<f32>((p.xy / params.planet.w) * 0.5 + 0.5, altitude_of(p) / params.planet.z);
    if any(f.xy < vec2<f32>(0.0)) || any(f.xy > vec2<f32>(1.0)) {
        return 1.0;
    }
    return textureSampleLevel(shadow, clamped, f, 0.0).r;
}

// The talk's gbufferUVtoPolarCoordinates: (theta from the zenith, phi).
fn gbuffer_polar(uv: vec2<f32>) -> vec2<f32> {
    let q = uv - 0.5;
    let phi = atan2(q.y, q.x);
    let r = 0.5 / cos(((phi + PI / 4.0 + 2.0 * PI) % (PI / 2.0)) - PI / 4.0);
    let x01 = sqrt(length(q) / r);
    return vec2<f32>(x01 * (PI / 2.0), phi);
}

fn henyey_greenstein(cos_angle: f32, g: f32) -> f32 {
    let d = 1.0 + g * g - 2.0 * g * cos_angle;
    return (1.0 - g * g) / (4.0 * PI * d * sqrt(d));
}

// Distance along unit d from the origin (at radius planet.x) to the
// sphere of radius r above it.
fn to_sphere(d: vec3<f32>, r: f32) -> f32 {
    let r0 = params.planet.x;
    let b = r0 * d.z;
    let gap = (r - r0) * (r + r0);
    return gap / (b + sqrt(b * b + gap));
}

// One jittered march for G-buffer texel `texel` of an n x n buffer,
// numbered `sample` (its jitter within the texel and along the ray):
// (opacity to the sky, the absorbed-weighted sum of distances km, sun
// in-scatter per unit of sun irradiance (1/sr), ambient in-scatter per unit
// of the sky's mean radiance). The distance to the clouds is the second
// over the first.
fn march(texel: vec2<u32>, n: vec2<u32>, sample: u32) -> vec4<f32> {
    let steps = u32(params.frame.z);
    let sun = params.sun.xyz;
    let a = params.optics.y;
    let b = params.optics.z;
    let c = params.optics.w;
    let j = vec2<f32>(pcg3d(vec3<u32>(texel, sample)).xy >> vec2<u32>(8u)) / 16777216.0;
    let polar = gbuffer_polar((vec2<f32>(texel) + j) / vec2<f32>(n));
    let d = vec3<f32>(sin(polar.x) * cos(polar.y), sin(polar.x) * sin(polar.y), cos(polar.x));
    let t0 = to_sphere(d, params.planet.x + params.planet.y);
    let t1 = min(to_sphere(d, params.planet.x + params.planet.z), t0 + 1.5 * params.planet.w);
    let dt = (t1 - t0) / f32(steps);
    let cos_sun = dot(d, sun);
    var transmittance = 1.0;
    var sun_light = 0.0;
    var ambient = 0.0;
    var distance = 0.0;
    let jitter = fract(j.x + j.y * 1.618034);
    for (var k = 0u; k < steps; k++) {
        let t = t0 + (f32(k) + jitter) * dt;
        let p = d * t;
        let cov = coverage_at(p);
        let rho = density(p, cov);
        if rho <= 0.0 {
            continue;
        }
        let extinction = rho * params.optics.x;
        // Energy-conserving step (Hillaire 2016): the in-scatter times
        // (1 - e^(-sigma dt)) / sigma, here with albedo 1.
        let absorbed = transmittance * (1.0 - exp(-extinction * dt));
        // Toward the sun: six detailed steps over the first 4 km, then the
        // distant-cloud shadow volume.
        var tau = 0.0;
        if sun.z > -0.2 {
            var along = 0.0;
            for (var m = 0; m < 6; m++) {
                let step = NEAR_SHADOW_KM * (f32(m) + 1.0) / 21.0;
                let q = p + sun * (along + 0.5 * step);
                tau += density(q, coverage_at(q)) * params.optics.x * step;
                along += step;
            }
        }
        let far = far_shadow(p);
        // Wrenninge et al. 2013's multiple-scattering octaves: octave i
        // scatters b^i, is extinguished a^i, with the phase's eccentricity
        // c^i; a <= b keeps the sum within the energy of single
        // scattering's albedo-1 limit (Hillaire 2016).
        var octaves = 0.0;
        var ai = 1.0;
        var bi = 1.0;
        var ci = 1.0;
        for (var i = 0; i < 3; i++) {
            octaves += bi * henyey_greenstein(cos_sun, 0.6 * ci) * exp(-ai * tau) * pow(far, ai);
            ai *= a;
            bi *= b;
            ci *= c;
        }
        sun_light += absorbed * octaves;
        ambient += absorbed * cov.a;
        distance += absorbed * t;
        transmittance *= exp(-extinction * dt);
        if transmittance < 1e-3 {
            break;
        }
    }
    return vec4<f32>(1.0 - transmittance, distance, sun_light, ambient);
}

// The G-buffer texel from sums of marches and their count.
fn texel_of(sum: vec4<f32>, count: f32) -> vec4<f32> {
    var distance = 0.0;
    if sum.x > 0.0 {
        distance = sum.y / sum.x;
    }
    return vec4<f32>(sum.x / count, distance, sum.z / count, sum.w / count);
}

// The whole G-buffer at once: each texel the mean of `samples` marches
// numbered from params.frame.x.
@compute @workgroup_size(8, 8)
fn gbuffer(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = textureDimensions(gbuffer_out);
    if any(id.xy >= n) {
        return;
    }
    let samples = u32(params.wind.w);
    var sum = vec4<f32>(0.0);
    for (var s = 0u; s < samples; s++) {
        sum += march(id.xy, n, u32(params.frame.x) + s);
    }
    textureStore(gbuffer_out, id.xy, texel_of(sum, f32(samples)));
}

// The amortised G-buffer (the talk's "Implementation Detail"): the buffer
// in 8 x 8 tiles, one march per texel spread over F frames, F dividing 64:
// in frame f of a sample, each tile marches the 64 / F of its texels whose
// rank r is in [(f mod F) 64 / F, (f mod F + 1) 64 / F), rank r being the
// texel whose x and y interleave the bits of r reversed (x the even bits,
// y the odd), so that each frame's texels form a regular lattice over the
// tile (ranks 0 to 15: every other texel in both axes). Sums and counts
// accumulate in `accum` (two vec4 a texel: the march sums, then the count)
// until `resolve` turns them into a G-buffer.
// params.tiles = (frame in the cycle, F, first sample number, clear flag).
@group(0) @binding(11) var<storage, read_write> accum: array<vec4<f32>>;

fn reverse6(r: u32) -> u32 {
    return reverseBits(r) >> 26u;
}

@compute @workgroup_size(64)
fn gbuffer_tiles(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = textureDimensions(gbuffer_out);
    let frame = u32(params.tiles.x);
    let per_sample = u32(params.tiles.y);
    let slots = 64u / per_sample;
    let tiles = (n + 7u) / 8u;
    let tile = id.x / slots;
    if tile >= tiles.x * tiles.y {
        return;
    }
    let rank = (frame % per_sample) * slots + id.x % slots;
    let r = reverse6(rank);
    let within = vec2<u32>((r & 1u) | ((r >> 1u) & 2u) | ((r >> 2u) & 4u), ((r >> 1u) & 1u) | ((r >> 2u) & 2u) | ((r >> 3u) & 4u));
    let texel = vec2<u32>(tile % tiles.x, tile / tiles.x) * 8u + within;
    if any(texel >= n) {
        return;
    }
    let i = texel.y * n.x + texel.x;
    accum[2u * i] += march(texel, n, u32(params.tiles.z) + frame / per_sample);
    accum[2u * i + 1u].x += 1.0;
}

// The accumulated marches into the G-buffer (texels not yet marched: 0),
// and the sums cleared for the next cycle when tiles.w is 1.
@compute @workgroup_size(8, 8)
fn resolve(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = textureDimensions(gbuffer_out);
    if any(id.xy >= n) {
        return;
    }
    let i = id.y * n.x + id.x;
    let count = accum[2u * i + 1u].x;
    var texel = vec4<f32>(0.0);
    if count > 0.0 {
        texel = texel_of(accum[2u * i], count);
    }
    textureStore(gbuffer_out, id.xy, texel);
    if params.tiles.w > 0.5 {
        accum[2u * i] = vec4<f32>(0.0);
        accum[2u * i + 1u] = vec4<f32>(0.0);
    }
}
