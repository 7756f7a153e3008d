// The basis-sky LUTs decoded on the GPU, in two passes.
//
// The composition (`compose`, run when the sun's elevation or the weather
// changes) decodes the bake into one frame sky texture (4 texels a LUT
// texel each way, `sky_pass::FRAME_SKY_OVERSAMPLING`): per texel, the
// direction of its centre in the mapping of the actual sun, decoded as the
// CPU reference decoder does (src/lut/decode.rs `sample_sky`,
// src/directions/mapping.rs `DirectionMapping::uv_in_region`): each active
// basis sky's two slices, bilinear filtering at texel centres with
// clamp-to-edge done by hand with textureLoad in f32 (the CPU's arithmetic,
// not the sampler's fixed-point weights), the geometric blend between
// slices and the weather rule's sum. What a frame shares is computed once
// on the CPU and passed in `params`: each active sky's weight
// (`lut::weather::basis_weights`, renormalised over the bake's skies), its
// two slices, their scales (2^-scale_log2) and regions, and the fraction
// between them; the mapping's trigonometry of the sun.
//
// The sky pass (`sky`, every frame) reads that texture once per direction:
// the direction's (u, v) in the same mapping, one sample with the
// sampler's bilinear filtering, and the sun's disk on top. Its value is a
// convex combination of the CPU decoder's values at the four texel centres
// around the direction, each to the half float's rounding (the test in
// tests/preview.rs); against the CPU decoder's value at the direction
// itself it adds the resampling error of a bilinear of bilinears (measured
// at FRAME_SKY_OVERSAMPLING).
//
// The sky pass: one invocation per direction. `directions[i].xyz` is a unit
// vector in the world frame (z up), `.w` is 1 where the pixel sees the sky
// and 0 outside the camera's view; `radiance[i].rgb` is linear RGB of the
// manifest's colour space.

const PI: f32 = 3.14159265358979;
// The concept code's knots of the upper region's v transform
// (lut::mapping::{A, B, C, D}).
const KA: f32 = 0.50;
const KB: f32 = 0.80;
const KC: f32 = 0.25;
const KD: f32 = 0.50;

// header: (sun zenith, radians, clamped to [0, 100 degrees]; cos and sin of
// the sun's azimuth; number of active skies). frame: the frame sky
// texture's mapping and scale: (1 for the sun-centred region, 0 for the
// latitude-longitude one; the scale, value = stored * scale; 1 / scale;
// 0). mapping: the actual sun's (sin, cos and tan of its zenith angle, the
// angle itself, radians), as in header, worked out in f64. Per active sky
// k, two rows:
// sky[2k] = (weight, fraction between slices, layer 0, layer 1),
// sky[2k + 1] = (scale 0, scale 1, slice 0 sun-centred (1) or not (0),
// slice 1 likewise). The sun's disk (decode::Luts::decode_image's, from the
// bake's sunlight): sun = (unit vector toward it, world frame; sine of its
// angular radius), disk = (its radiance, linear RGB; 1 to draw it, 0 not).
// point = (radiance, linear RGB; the bits of direction index + 1) of a sun
// smaller than a pixel, put into the pixel nearest it (decode_image's
// fallback, worked out on the CPU); w's bits 0: none.
struct Params {
    header: vec4<f32>,
    frame: vec4<f32>,
    mapping: vec4<f32>,
    sky: array<vec4<f32>, 6>,
    sun: vec4<f32>,
    disk: vec4<f32>,
    point: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
// The sky pass's region, fixed per pipeline (`sky_pass::SkyPass` builds one
// of each and picks by `frame.x`), so that its mapping has no branch on it.
override SKY_SUN_CENTRED: bool = false;
// The sky pass's.
@group(0) @binding(1) var<storage, read> directions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> radiance: array<vec4<f32>>;
@group(0) @binding(7) var frame_sky: texture_2d<f32>;
@group(0) @binding(8) var linear: sampler;
// The composition's.
@group(0) @binding(3) var sky0: texture_2d_array<f32>;
@group(0) @binding(4) var sky1: texture_2d_array<f32>;
@group(0) @binding(5) var sky2: texture_2d_array<f32>;
@group(0) @binding(6) var frame_out: texture_storage_2d<rgba16float, write>;

// Texture::bilinear: texel centres at ((x + 0.5) / w, (y + 0.5) / h),
// clamped to the edge.
// The array is a parameter, not picked by a branch on the sky's slot
// (lavapipe runs every side of a branch it cannot prove uniform).
fn bilinear(sky: texture_2d_array<f32>, layer: i32, uv: vec2<f32>) -> vec3<f32> {
    let n = vec2<i32>(textureDimensions(sky));
    let p = uv * vec2<f32>(n) - 0.5;
    let p0 = floor(p);
    let f = p - p0;
    let a = clamp(vec2<i32>(p0), vec2<i32>(0), n - 1);
    let b = clamp(vec2<i32>(p0) + 1, vec2<i32>(0), n - 1);
    let top = textureLoad(sky, vec2<i32>(a.x, a.y), layer, 0).rgb * (1.0 - f.x)
        + textureLoad(sky, vec2<i32>(b.x, a.y), layer, 0).rgb * f.x;
    let bottom = textureLoad(sky, vec2<i32>(a.x, b.y), layer, 0).rgb * (1.0 - f.x)
        + textureLoad(sky, vec2<i32>(b.x, b.y), layer, 0).rgb * f.x;
    return top * (1.0 - f.y) + bottom * f.y;
}

// mapping::upper_v_inverse.
fn upper_v_inverse(vp: f32) -> f32 {
    // Each of the three pieces is a + b sqrt(c): the piece chosen first,
    // then one square root (no branches for a SIMD lane to wait on).
    let s = (1.0 - vp) / (1.0 - KD);
    var abc = vec3<f32>(KB, 1.0 - KB, 1.0 - s * s);
    if vp <= KD {
        abc = vec3<f32>(KB, -(KB - KA), 1.0 - (vp - KC) / (KD - KC));
    }
    if vp <= KC {
        abc = vec3<f32>(0.0, KA, vp / KC);
    }
    return abc.x + abc.y * sqrt(max(abc.z, 0.0));
}

// mapping::lower_v_inverse.
fn lower_v_inverse(vp: f32, theta_sun: f32) -> f32 {
    let k = min(theta_sun / PI, 0.5);
    if vp <= k {
        return k - sqrt(max(k * k - vp * vp, 0.0));
    }
    return k + sqrt(max((1.0 - k) * (1.0 - k) - (1.0 - vp) * (1.0 - vp), 0.0));
}

// mapping::upper_v.
fn upper_v(v: f32) -> f32 {
    if v <= KA {
        let k = v / KA;
        return KC * k * k;
    } else if v <= KB {
        let k = (v - KB) / (KB - KA);
        return KC + (KD - KC) * (1.0 - k * k);
    }
    let k = (v - KB) / (1.0 - KB);
    return 1.0 - (1.0 - KD) * sqrt(max(1.0 - k * k, 0.0));
}

// mapping::lower_v.
fn lower_v(v: f32, theta_sun: f32) -> f32 {
    let k = min(theta_sun / PI, 0.5);
    if v <= k {
        return sqrt(max(k * k - (v - k) * (v - k), 0.0));
    }
    return 1.0 - sqrt(max((1.0 - k) * (1.0 - k) - (v - k) * (v - k), 0.0));
}

// The angle from the sun to the horizon along a heading whose cosine is
// `cos_phi` (mapping::horizon_edge).
fn horizon_edge(cos_phi: f32, tan_theta_sun: f32) -> f32 {
    return PI / 2.0 - atan(cos_phi * tan_theta_sun);
}

// DirectionMapping::direction: the direction of texture position uv in
// the frame with the sun at azimuth 0 (y >= 0).
fn direction_in_region(uv: vec2<f32>, sun_centred: bool) -> vec3<f32> {
    let phi = uv.x * PI;
    if sun_centred {
        let vp = upper_v(uv.y);
        let edge = horizon_edge(cos(phi), params.mapping.z);
        var theta = (vp / 0.5 - 1.0) * (PI - edge) + edge;
        if vp <= 0.5 {
            theta = vp / 0.5 * edge;
        }
        let s = vec3<f32>(params.mapping.x, 0.0, params.mapping.y);
        let t = vec3<f32>(params.mapping.y, 0.0, -params.mapping.x);
        let b = vec3<f32>(0.0, 1.0, 0.0);
        return normalize(s * cos(theta) + (t * cos(phi) + b * sin(phi)) * sin(theta));
    }
    let theta = lower_v(uv.y, params.mapping.w) * PI;
    return vec3<f32>(sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta));
}

// atan2(y, x) for y >= 0, in [0, pi]: on the negative x axis (y = 0) it is
// pi, as in f64 on the CPU; a GPU's atan2 may not give pi there (lavapipe's
// gives 0 or -pi: WGSL leaves atan2 at a zero y loosely specified), which
// would read the opposite edge of the texture.
fn heading(y: f32, x: f32) -> f32 {
    return select(clamp(atan2(y, x), 0.0, PI), select(0.0, PI, x < 0.0), y == 0.0);
}

// DirectionMapping::uv_in_region, `d` in the frame with the sun at azimuth
// 0. Angles from the sun and the zenith are taken with atan2 (the CPU's
// acos of a dot product, in f32, would lose half its digits near the sun).
// Every angle here is a ratio of components, so `d` need not be of unit
// length (the CPU normalises it).
fn uv_in_region(d_in: vec3<f32>, sun_centred: bool) -> vec2<f32> {
    let d = vec3<f32>(d_in.x, abs(d_in.y), d_in.z);
    if sun_centred {
        let s = vec3<f32>(params.mapping.x, 0.0, params.mapping.y);
        let t = vec3<f32>(params.mapping.y, 0.0, -params.mapping.x);
        // d's components across the sun (x toward the horizon below it, y
        // sideways): their length is |d x s|, the sine of the angle from
        // the sun.
        let x = dot(d, t);
        let y = d.y;
        let r = length(vec2<f32>(x, y));
        let theta = atan2(r, dot(d, s));
        // The heading phi and its cosine (1 on the sun's axis, where the
        // CPU takes phi = 0).
        let phi = select(0.0, heading(y, x), r > 0.0);
        let cos_phi = select(1.0, x / r, r > 0.0);
        let edge = horizon_edge(cos_phi, params.mapping.z);
        var vp = 0.5 + 0.5 * (theta - edge) / (PI - edge);
        if theta <= edge {
            vp = 0.5 * theta / edge;
        }
        return vec2<f32>(phi / PI, upper_v_inverse(clamp(vp, 0.0, 1.0)));
    }
    let theta = atan2(length(d.xy), d.z);
    let phi = heading(d.y, d.x);
    return vec2<f32>(phi / PI, lower_v_inverse(theta / PI, params.mapping.w));
}

// decode::between_slices: geometric where both are positive.
fn between(a: f32, b: f32, f: f32) -> f32 {
    if a > 0.0 && b > 0.0 {
        return exp((1.0 - f) * log(a) + f * log(b));
    }
    return (1.0 - f) * a + f * b;
}

// decode::sample_sky for active sky k.
fn sample_sky(k: u32, sky: texture_2d_array<f32>, d: vec3<f32>) -> vec3<f32> {
    let r0 = params.sky[2u * k];
    let r1 = params.sky[2u * k + 1u];
    let f = r0.y;
    let a = bilinear(sky, i32(r0.z), uv_in_region(d, r1.z > 0.5)) * r1.x;
    if f == 0.0 {
        return a;
    }
    let b = bilinear(sky, i32(r0.w), uv_in_region(d, r1.w > 0.5)) * r1.y;
    if f == 1.0 {
        return b;
    }
    return vec3<f32>(between(a.x, b.x, f), between(a.y, b.y, f), between(a.z, b.z, f));
}

// The composition: one invocation per texel of the frame sky texture.
@compute @workgroup_size(8, 8)
fn compose(@builtin(global_invocation_id) id: vec3<u32>) {
    let n = textureDimensions(frame_out);
    if id.x >= n.x || id.y >= n.y {
        return;
    }
    let uv = (vec2<f32>(id.xy) + 0.5) / vec2<f32>(n);
    let d = direction_in_region(uv, params.frame.x > 0.5);
    // The active slots one by one, each with its own array.
    var rgb = vec3<f32>(0.0);
    let count = u32(params.header.w);
    if count > 0u {
        rgb += params.sky[0].x * sample_sky(0u, sky0, d);
    }
    if count > 1u {
        rgb += params.sky[2].x * sample_sky(1u, sky1, d);
    }
    if count > 2u {
        rgb += params.sky[4].x * sample_sky(2u, sky2, d);
    }
    textureStore(frame_out, id.xy, vec4<f32>(rgb * params.frame.z, 1.0));
}

// The sky pass: one invocation per direction, one sample of the frame sky.
@compute @workgroup_size(64)
fn sky(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&directions) {
        return;
    }
    let dir = directions[i];
    if dir.w == 0.0 {
        radiance[i] = vec4<f32>(0.0, 0.0, 0.0, 0.0);
        return;
    }
    // decode::rotate_to_sun_frame.
    let c = params.header.y;
    let s = params.header.z;
    let d = vec3<f32>(c * dir.x + s * dir.y, -s * dir.x + c * dir.y, dir.z);
    let uv = uv_in_region(d, SKY_SUN_CENTRED);
    var rgb = textureSampleLevel(frame_sky, linear, uv, 0.0).rgb * params.frame.y;
    // Inside the disk: within its angular radius of the sun, tested by the
    // sine (a cosine this close to 1 has too few digits in f32).
    // A cheap test first (within about 30 degrees) leaves the exact one to
    // the few directions near the sun.
    let toward = params.sun.xyz;
    let along = dot(dir.xyz, toward);
    if params.disk.w > 0.5 && along > 0.866 {
        if length(cross(dir.xyz, toward)) <= params.sun.w {
            rgb += params.disk.rgb;
        }
    }
    let point = bitcast<u32>(params.point.w);
    if point != 0u && i == point - 1u {
        rgb += params.point.rgb;
    }
    radiance[i] = vec4<f32>(rgb, 1.0);
}
