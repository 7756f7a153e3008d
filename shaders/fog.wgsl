// The global-fog pass: fog in front of the terrain, from the bake's Fog,
// Shadowed Fog and Attenuation LUTs (the talk's "Global Fog
// Approximation"). A transcription of the CPU reference decoder
// (src/lut/decode_fog.rs `Luts::fog_of_sky`, the mappings of
// src/lut/fog.rs), tested against it by readback (tests/preview.rs).
//
// Where the terrain pass found a surface (`surface[i].w`, its depth in km,
// is positive) the picture becomes object * attenuation + fog, per basis
// sky k weighted by the weather rule:
// - fog: the Fog and Shadowed Fog LUTs read at the view's (u, v) (u the
//   azimuth from the sun folded into 0..180 degrees, v the square root of
//   elevation / 90 degrees; bilinear between texel centres at i / (n - 1)),
//   each slice's scale undone, blended by the cloud occlusion, the sun's two
//   slices interpolated as the sky's are (geometric where both are
//   positive), times the talk's depth falloff
//   (1 - e^(-k x)) / (1 - e^(-k)), k = a theta^p, x = depth / depth_max;
// - attenuation: the Attenuation LUT at (x^(1/3), v).
// The cloud occlusion is the caller's (header.w) or, with clouds, read
// from their occlusion grid along the view (occlusion_along).
// Elsewhere the picture (the sky pass's) is left as it is.

// header = (cos, sin of the sun's azimuth; number of active skies; cloud
// occlusion in [0, 1]). Per active sky k, four rows:
// sky[4k]     = (weight, fraction between slices, slice 0, slice 1),
// sky[4k + 1] = (Fog scale of slice 0, of slice 1, Shadowed Fog scale of
//                slice 0, of slice 1) (2^-scale_log2),
// sky[4k + 2] = (falloff a, falloff p, Attenuation layer, 0),
// sky[4k + 3] = (planet radius km, observer altitude km, ceiling km, 0).
// grid = (1: the cloud occlusion from the grid instead of header.w; the
// grid's half span km (x and y); its top km (the cloud base); the planet's
// radius km).
struct Params {
    header: vec4<f32>,
    sky: array<vec4<f32>, 12>,
    grid: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> directions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> surface: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> radiance: array<vec4<f32>>;
@group(0) @binding(4) var lit0: texture_2d_array<f32>;
@group(0) @binding(5) var shadowed0: texture_2d_array<f32>;
@group(0) @binding(6) var lit1: texture_2d_array<f32>;
@group(0) @binding(7) var shadowed1: texture_2d_array<f32>;
@group(0) @binding(8) var lit2: texture_2d_array<f32>;
@group(0) @binding(9) var shadowed2: texture_2d_array<f32>;
@group(0) @binding(10) var attenuation: texture_2d_array<f32>;
@group(0) @binding(11) var occlusion_grid: texture_3d<f32>;
@group(0) @binding(12) var clamped: sampler;

// The clouds' occlusion of the air along the view to the surface: the
// grid (clouds.wgsl `occlusion_volume`) averaged over 8 points spread
// along the view to the surface's depth. Each point's altitude on the
// sphere; points outside the grid read its edge.
fn occlusion_along(d: vec3<f32>, depth_km: f32) -> f32 {
    var sum = 0.0;
    let r = params.grid.w;
    for (var k = 0; k < 8; k++) {
        let t = (f32(k) + 0.5) / 8.0 * depth_km;
        let p = d * t;
        let altitude = length(p + vec3<f32>(0.0, 0.0, r)) - r;
        let f = vec3<f32>(p.xy / params.grid.y * 0.5 + 0.5, altitude / params.grid.z);
        sum += textureSampleLevel(occlusion_grid, clamped, f, 0.0).r;
    }
    return clamp(sum / 8.0, 0.0, 1.0);
}

// fog::bilinear_by's cell and weights: texel i of n at i / (n - 1).
struct Cell {
    ij: vec2<i32>,
    f: vec2<f32>,
}

fn cell(uv: vec2<f32>, n: vec2<i32>) -> Cell {
    let p = clamp(uv, vec2<f32>(0.0), vec2<f32>(1.0)) * vec2<f32>(n - 1);
    let ij = min(vec2<i32>(p), n - 2);
    return Cell(ij, p - vec2<f32>(ij));
}

// One of a slot's Fog or Shadowed Fog arrays, filtered. The array is a
// parameter, not picked by a branch on the slot: lavapipe runs every side
// of a branch it cannot prove uniform, which read all six arrays for each
// texel.
fn fog_bilinear(fog: texture_2d_array<f32>, layer: i32, uv: vec2<f32>) -> vec3<f32> {
    let c = cell(uv, vec2<i32>(textureDimensions(fog)));
    let a = textureLoad(fog, c.ij, layer, 0).rgb;
    let b = textureLoad(fog, c.ij + vec2<i32>(1, 0), layer, 0).rgb;
    let d = textureLoad(fog, c.ij + vec2<i32>(0, 1), layer, 0).rgb;
    let e = textureLoad(fog, c.ij + vec2<i32>(1, 1), layer, 0).rgb;
    return (1.0 - c.f.y) * ((1.0 - c.f.x) * a + c.f.x * b) + c.f.y * ((1.0 - c.f.x) * d + c.f.x * e);
}

fn attenuation_bilinear(layer: i32, uv: vec2<f32>) -> vec3<f32> {
    let c = cell(uv, vec2<i32>(textureDimensions(attenuation)));
    let a = textureLoad(attenuation, c.ij, layer, 0).rgb;
    let b = textureLoad(attenuation, c.ij + vec2<i32>(1, 0), layer, 0).rgb;
    let d = textureLoad(attenuation, c.ij + vec2<i32>(0, 1), layer, 0).rgb;
    let e = textureLoad(attenuation, c.ij + vec2<i32>(1, 1), layer, 0).rgb;
    return (1.0 - c.f.y) * ((1.0 - c.f.x) * a + c.f.x * b) + c.f.y * ((1.0 - c.f.x) * d + c.f.x * e);
}

// One slice's fog blended by the cloud occlusion, each LUT's scale undone:
// (1 - occlusion) Fog + occlusion Shadowed Fog, reading only the LUTs whose
// weight is not 0.
fn occluded(
    lit: texture_2d_array<f32>,
    shadowed: texture_2d_array<f32>,
    layer: i32,
    uv: vec2<f32>,
    lit_scale: f32,
    shadowed_scale: f32,
    occlusion: f32,
) -> vec3<f32> {
    var f = vec3<f32>(0.0);
    if occlusion < 1.0 {
        f += (1.0 - occlusion) * (fog_bilinear(lit, layer, uv) * lit_scale);
    }
    if occlusion > 0.0 {
        f += occlusion * (fog_bilinear(shadowed, layer, uv) * shadowed_scale);
    }
    return f;
}

// FogGeometry::depth_max_km for a view whose elevation has sine s (at
// least 0): the distance to the ceiling, in the form without cancellation,
// (rc^2 - r0^2) / (r0 s + sqrt(r0^2 s^2 + rc^2 - r0^2)) (the CPU's
// -r0 s + sqrt(...) subtracts numbers of 6000 km in f32).
fn depth_max_km(geometry: vec4<f32>, s: f32) -> f32 {
    let r0 = geometry.x + geometry.y;
    let rc = geometry.x + geometry.z;
    let gap = (geometry.z - geometry.y) * (rc + r0);
    return gap / (r0 * s + sqrt(r0 * r0 * s * s + max(gap, 0.0)));
}

// e^y - 1 without cancellation near 0 (WGSL has no expm1): three terms of
// the series below |y| = 1e-2 (error below y^4 / 24 relative, 4e-10).
fn expm1(y: f32) -> f32 {
    if abs(y) < 1e-2 {
        return y * (1.0 + y * (0.5 + y / 6.0));
    }
    return exp(y) - 1.0;
}

// Falloff::fraction.
fn falloff(a: f32, p: f32, x: f32, theta: f32) -> f32 {
    let k = a * pow(max(theta, 1e-6), p);
    if !(abs(k) > 1e-9) {
        return x;
    }
    return expm1(-k * x) / expm1(-k);
}

// decode::between_slices.
fn between(a: f32, b: f32, f: f32) -> f32 {
    if a > 0.0 && b > 0.0 {
        return exp((1.0 - f) * log(a) + f * log(b));
    }
    return (1.0 - f) * a + f * b;
}

// What a view shares across the active skies.
struct View {
    uv: vec2<f32>,
    sin_elevation: f32,
    theta: f32,
    occlusion: f32,
    depth_km: f32,
}

// The fog in front of the surface and its attenuation, weighted sums over
// the active skies.
struct FogSum {
    inscatter: vec3<f32>,
    transmitted: vec3<f32>,
}

fn add(a: FogSum, b: FogSum) -> FogSum {
    return FogSum(a.inscatter + b.inscatter, a.transmitted + b.transmitted);
}

// Active sky k's weighted fog and attenuation toward the view.
fn sky_fog(k: u32, lit: texture_2d_array<f32>, shadowed: texture_2d_array<f32>, view: View) -> FogSum {
    let slices = params.sky[4u * k];
    let scales = params.sky[4u * k + 1u];
    let fit = params.sky[4u * k + 2u];
    let geometry = params.sky[4u * k + 3u];
    let t = slices.y;
    let a = occluded(lit, shadowed, i32(slices.z), view.uv, scales.x, scales.z, view.occlusion);
    var b = a;
    if t > 0.0 {
        b = occluded(lit, shadowed, i32(slices.w), view.uv, scales.y, scales.w, view.occlusion);
    }
    let x = clamp(view.depth_km / depth_max_km(geometry, view.sin_elevation), 0.0, 1.0);
    let fraction = falloff(fit.x, fit.y, x, view.theta);
    let fog_k = vec3<f32>(between(a.x, b.x, t), between(a.y, b.y, t), between(a.z, b.z, t)) * fraction;
    var u_depth = 0.0;
    if x > 0.0 {
        u_depth = pow(x, 1.0 / 3.0);
    }
    let attenuation_k = attenuation_bilinear(i32(fit.z), vec2<f32>(u_depth, view.uv.y));
    return FogSum(slices.x * fog_k, slices.x * attenuation_k);
}

@compute @workgroup_size(64)
fn fog(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&directions) {
        return;
    }
    let depth_km = surface[i].w;
    if directions[i].w == 0.0 || depth_km <= 0.0 {
        return;
    }
    let d = normalize(directions[i].xyz);
    // The view in the frame with the sun at azimuth 0 (decode::rotate_to_sun_frame).
    let c = params.header.x;
    let s = params.header.y;
    let sun_frame = vec3<f32>(c * d.x + s * d.y, -s * d.x + c * d.y, d.z);
    let elevation_deg = degrees(asin(clamp(d.z, -1.0, 1.0)));
    // fog::fog_uv: the azimuth from the sun folded into [0, 180] degrees.
    let v = sqrt(clamp(elevation_deg, 0.0, 90.0) / 90.0);
    let uv = vec2<f32>(abs(atan2(sun_frame.y, sun_frame.x)) / 3.14159265358979, v);
    let sin_elevation = sin(radians(clamp(elevation_deg, 0.0, 90.0)));
    let theta = clamp(elevation_deg, 0.5, 90.0) / 90.0;
    var occlusion = clamp(params.header.w, 0.0, 1.0);
    if params.grid.x > 0.5 {
        occlusion = occlusion_along(d, depth_km);
    }
    let view = View(uv, sin_elevation, theta, occlusion, depth_km);
    // The active slots one by one, each with its own arrays.
    let count = u32(params.header.z);
    var sum = FogSum(vec3<f32>(0.0), vec3<f32>(0.0));
    if count > 0u {
        sum = add(sum, sky_fog(0u, lit0, shadowed0, view));
    }
    if count > 1u {
        sum = add(sum, sky_fog(1u, lit1, shadowed1, view));
    }
    if count > 2u {
        sum = add(sum, sky_fog(2u, lit2, shadowed2, view));
    }
    let inscatter = sum.inscatter;
    let transmitted = sum.transmitted;
    // w: the cloud occlusion used, for inspection (elsewhere w is 1).
    radiance[i] = vec4<f32>(surface[i].rgb * transmitted + inscatter, occlusion);
}
