// The clouds' deferred lighting (the talk's reason for the cloud
// G-buffer: "the lighting of the sun and sky can change from frame to
// frame"): per view direction above the horizon, the G-buffer read at the
// direction's texel (the inverse of the talk's square-to-disk mapping,
// clouds.wgsl `gbuffer_polar`), lit by this frame's sun and sky from the
// bake's LUTs, over the sky decoded so far:
//   picture = sky * (1 - opacity) + sun_factor * E_sun + ambient_factor * L_sky,
// E_sun the sun's irradiance (the sunlight LUT), L_sky the sky's mean
// radiance over the upper hemisphere (the ambient LUT).

const PI: f32 = 3.14159265358979;

// sun_irradiance.rgb; ambient_radiance.rgb, w: how far the display has
// moved from the previous G-buffer to the current one (the talk:
// "interpolation between two buffers while switching").
struct Params {
    sun_irradiance: vec4<f32>,
    ambient_radiance: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> directions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> radiance: array<vec4<f32>>;
@group(0) @binding(3) var gbuffer: texture_2d<f32>;
@group(0) @binding(4) var clamped: sampler;
@group(0) @binding(5) var previous: texture_2d<f32>;

// The G-buffer's (u, v) of a direction (theta from the zenith, phi): the
// inverse of gbufferUVtoPolarCoordinates, |uv - 0.5| = R(phi) (theta / (pi/2))^2.
fn gbuffer_uv(theta: f32, phi: f32) -> vec2<f32> {
    let r = 0.5 / cos(((phi + PI / 4.0 + 2.0 * PI) % (PI / 2.0)) - PI / 4.0);
    let x01 = theta / (PI / 2.0);
    return 0.5 + r * x01 * x01 * vec2<f32>(cos(phi), sin(phi));
}

@compute @workgroup_size(64)
fn light(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&directions) {
        return;
    }
    let dir = directions[i];
    if dir.w == 0.0 || dir.z <= 0.0 {
        return;
    }
    let theta = atan2(length(dir.xy), dir.z);
    let phi = atan2(dir.y, dir.x);
    let uv = gbuffer_uv(theta, phi);
    let g = mix(textureSampleLevel(previous, clamped, uv, 0.0), textureSampleLevel(gbuffer, clamped, uv, 0.0), params.ambient_radiance.w);
    let sky = radiance[i].rgb;
    let clouds = g.z * params.sun_irradiance.rgb + g.w * params.ambient_radiance.rgb;
    radiance[i] = vec4<f32>(sky * (1.0 - clamp(g.x, 0.0, 1.0)) + clouds, 1.0);
}
