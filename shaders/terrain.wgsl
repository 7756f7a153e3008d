// The terrain pass: the depth buffer of the preview's landscape, rows of
// ridges at 2 to 100 km around the observer (src/lut/landscape.rs, whose
// `RIDGES` table arrives in `params.ridges`), and each ridge's surface lit
// by the decoded sun and sky: a grey Lambertian slope facing the camera,
// tilted 30 degrees up, under the sun's irradiance (the sunlight LUT) and
// the sky's irradiance on an upward surface (the ambient LUT). A
// transcription of `lut::landscape::decode_landscape`'s surface, tested
// against it by readback (tests/preview.rs).
//
// Writes `surface[i]` = (the surface's radiance, linear RGB; its depth
// along the view, km), or zero where the view meets no ridge.

const PI: f32 = 3.14159265358979;

// sun = (unit vector toward the sun, world frame; albedo);
// sun_irradiance.rgb, ambient_irradiance.rgb (w: the number of ridges);
// ridges[k] = (distance km, mean top elevation deg, phase, 0).
struct Params {
    sun: vec4<f32>,
    sun_irradiance: vec4<f32>,
    ambient_irradiance: vec4<f32>,
    ridges: array<vec4<f32>, 8>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> directions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> surface: array<vec4<f32>>;

// landscape::top_elevation_deg, `a` the azimuth in radians.
fn top_elevation_deg(ridge: vec4<f32>, a: f32) -> f32 {
    return ridge.y * (0.65 + 0.25 * sin(17.0 * a + ridge.z) + 0.1 * sin(43.0 * a + 2.0 * ridge.z));
}

@compute @workgroup_size(64)
fn terrain(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&directions) {
        return;
    }
    let dir = directions[i];
    surface[i] = vec4<f32>(0.0);
    if dir.w == 0.0 {
        return;
    }
    let d = dir.xyz;
    let elevation_deg = degrees(asin(clamp(d.z, -1.0, 1.0)));
    let azimuth = atan2(d.y, d.x);
    // landscape::ridge_depth_km: the nearest ridge whose top is above the view.
    var depth_km = 0.0;
    for (var k = 0u; k < u32(params.ambient_irradiance.w); k++) {
        let ridge = params.ridges[k];
        if elevation_deg <= top_elevation_deg(ridge, azimuth) {
            depth_km = ridge.x / max(cos(radians(elevation_deg)), 1e-3);
            break;
        }
    }
    if depth_km == 0.0 {
        return;
    }
    // The slope facing the camera, tilted 30 degrees up.
    var back = vec3<f32>(-d.x, -d.y, 0.0);
    if length(back) > 0.0 {
        back = normalize(back);
    }
    let n = normalize(back * cos(radians(30.0)) + vec3<f32>(0.0, 0.0, 1.0) * sin(radians(30.0)));
    let cos_sun = max(dot(n, params.sun.xyz), 0.0);
    let object = params.sun.w / PI * (params.sun_irradiance.rgb * cos_sun + params.ambient_irradiance.rgb);
    surface[i] = vec4<f32>(object, depth_km);
}
