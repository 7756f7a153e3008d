//! The reference decoder: what a runtime does with a bake, on the CPU. For
//! a sun elevation, haziness, cloudiness and view direction it takes, in
//! each basis sky the weather rule weights, the fractional slice of the sun
//! (the time mapping's inverse), the direction's (u, v) through the mapping
//! of the actual sun (each slice read in the region it was rendered in),
//! bilinear filtering at texel centres with clamp-to-edge (the mirror at
//! u = 0 and 1), each slice's scale, and interpolation between the two
//! slices (geometric where both are positive: [`between_slices`]); then it blends the basis skies. The GPU preview must match
//! it.

use super::manifest::{Manifest, SkyEntry};
use super::weather::basis_weights;
use crate::directions::mapping::{self, DirectionMapping};
use glam::DVec3;

/// One basis sky's texture array as stored (values before the slice scale).
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    pub width: usize,
    pub height: usize,
    /// By layer, row-major (rows of v, top to bottom), linear RGB.
    pub layers: Vec<Vec<[f32; 3]>>,
}

/// A bake, loaded.
#[derive(Debug, Clone)]
pub struct Luts {
    pub manifest: Manifest,
    /// In the manifest's sky order.
    pub textures: Vec<Texture>,
    /// The transmittance file's layers (per basis sky, see
    /// `SunEntry::transmittance_layer`), RGB, row-major; empty for a bake
    /// without one.
    pub transmittance: Vec<Vec<[f32; 3]>>,
    /// The global-fog files (`decode_fog`); None for a bake without them.
    pub fog: Option<super::decode_fog::FogTextures>,
    /// `ambient.ktx2`'s layers as stored (`bake::pack_ambient`: rows of
    /// slices, before the layer's scale); empty for a bake without it.
    pub ambient_texture: Vec<Vec<[f32; 3]>>,
}

/// The sun at the observer, decoded: what the sky texture leaves out.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Sun {
    /// Irradiance on a surface facing the sun, linear RGB of the manifest's
    /// colour space (Y-like units: lux for XYZ).
    pub irradiance_rgb: [f64; 3],
    /// The disk's radiance (irradiance over its solid angle).
    pub disk_radiance_rgb: [f64; 3],
    pub angular_diameter_deg: f64,
}

/// Where a direction is read: sun zenith angle, the direction in the frame
/// with the sun at azimuth 0.
fn rotate_to_sun_frame(d: DVec3, sun_azimuth_deg: f64) -> DVec3 {
    let (s, c) = (libm::sin(sun_azimuth_deg.to_radians()), libm::cos(sun_azimuth_deg.to_radians()));
    DVec3::new(c * d.x + s * d.y, -s * d.x + c * d.y, d.z)
}

impl Texture {
    /// Bilinear filtering of layer `layer` at (u, v), texel centres at
    /// ((x + 0.5) / width, (y + 0.5) / height), clamped to the edge.
    pub fn bilinear(&self, layer: usize, u: f64, v: f64) -> [f64; 3] {
        let (w, h) = (self.width, self.height);
        let x = u * w as f64 - 0.5;
        let y = v * h as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let clampi = |i: f64, n: usize| (i.max(0.0) as usize).min(n - 1);
        let (xa, xb) = (clampi(x0, w), clampi(x0 + 1.0, w));
        let (ya, yb) = (clampi(y0, h), clampi(y0 + 1.0, h));
        let t = &self.layers[layer];
        let at = |x: usize, y: usize| t[y * w + x];
        let mut out = [0.0; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let top = at(xa, ya)[c] as f64 * (1.0 - fx) + at(xb, ya)[c] as f64 * fx;
            let bottom = at(xa, yb)[c] as f64 * (1.0 - fx) + at(xb, yb)[c] as f64 * fx;
            *o = top * (1.0 - fy) + bottom * fy;
        }
        out
    }
}

/// One basis sky's linear RGB toward `dir` (world frame, z up) with the
/// sun at `sun_zenith_deg`, `sun_azimuth_deg`.
pub fn sample_sky(
    entry: &SkyEntry,
    texture: &Texture,
    sun_zenith_deg: f64,
    sun_azimuth_deg: f64,
    dir: DVec3,
) -> [f64; 3] {
    let (i0, i1, f) = slice_pair(entry, sun_zenith_deg);
    let d = rotate_to_sun_frame(dir, sun_azimuth_deg);
    // The mapping of the actual sun; each slice in its own region.
    let m = DirectionMapping::new(
        sun_zenith_deg.clamp(0.0, mapping::LOWEST_SUN_ZENITH_DEG),
        entry.threshold_sun_zenith_deg,
    );
    let read = |layer: usize| {
        let slice = &entry.slices[layer];
        let (u, v) = m.uv_in_region(d, slice.sun_zenith_deg <= entry.threshold_sun_zenith_deg);
        let scale = (-slice.scale_log2 as f64).exp2();
        texture.bilinear(layer, u, v).map(|x| x * scale)
    };
    if f == 0.0 {
        return read(i0);
    }
    if f == 1.0 {
        return read(i1);
    }
    let (a, b) = (read(i0), read(i1));
    [0, 1, 2].map(|c| between_slices(a[c], b[c], f))
}

/// The two slices a sun at `sun_zenith_deg` reads and the fraction of the
/// way from the first to the second.
pub fn slice_pair(entry: &SkyEntry, sun_zenith_deg: f64) -> (usize, usize, f64) {
    let s = mapping::slice_coordinate(sun_zenith_deg, entry.planet_radius_km, entry.top_km);
    let last = entry.layers - 1;
    let i0 = (s.floor() as usize).min(last.saturating_sub(1));
    let i1 = (i0 + 1).min(last);
    // The fraction of the way in sun zenith angle from slice i0 to i1 (not
    // in the slice coordinate, which is quadratic in the angle below the
    // horizon): with the geometric blend, a sky that changes exponentially
    // with the sun's angle decodes exactly.
    let (z0, z1) = (entry.slices[i0].sun_zenith_deg, entry.slices[i1].sun_zenith_deg);
    let f = if z1 > z0 {
        ((sun_zenith_deg.clamp(0.0, mapping::LOWEST_SUN_ZENITH_DEG) - z0) / (z1 - z0)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (i0, i1, f)
}

/// One channel between two slices at fraction `f`: geometric, a^(1−f) b^f,
/// where both are positive, else linear. Sky luminance changes by orders
/// of magnitude across the twilight slices (about 1.1° apart near −7°,
/// where it falls tenfold per degree or so); interpolated linearly, its
/// logarithm would bend at each slice, with local slopes up to
/// (r − 1) / ln r times the true one for a ratio r between slices (three
/// times for r = 10): steps a viewer sees. Geometrically, the logarithm is
/// the chord between slices, whose slope never exceeds the atmosphere's
/// own steepest (the mean value theorem), and in daylight, where adjacent
/// slices differ by a few percent, the two agree to a fraction of that.
pub fn between_slices(a: f64, b: f64, f: f64) -> f64 {
    if a > 0.0 && b > 0.0 {
        libm::exp((1.0 - f) * libm::log(a) + f * libm::log(b))
    } else {
        (1.0 - f) * a + f * b
    }
}

impl Luts {
    /// Linear RGB (the manifest's colour space) toward `dir` (world frame,
    /// z up) for a sun at `sun_elevation_deg` (and azimuth), haziness and
    /// cloudiness in [0, 1].
    pub fn sample(
        &self,
        sun_elevation_deg: f64,
        sun_azimuth_deg: f64,
        haziness: f64,
        cloudiness: f64,
        dir: DVec3,
    ) -> [f64; 3] {
        let w = basis_weights(haziness, cloudiness);
        let mut out = [0.0; 3];
        for (k, name) in super::weather::BASIS.iter().enumerate() {
            if w[k] == 0.0 {
                continue;
            }
            // A bake without this basis sky gives it no weight; the rest is
            // renormalised below.
            let Some(i) = self.manifest.skies.iter().position(|s| s.name == *name) else { continue };
            let rgb =
                sample_sky(&self.manifest.skies[i], &self.textures[i], 90.0 - sun_elevation_deg, sun_azimuth_deg, dir);
            for c in 0..3 {
                out[c] += w[k] * rgb[c];
            }
        }
        let present: f64 = super::weather::BASIS
            .iter()
            .enumerate()
            .filter(|(_, n)| self.manifest.skies.iter().any(|s| s.name == **n))
            .map(|(k, _)| w[k])
            .sum();
        if present > 0.0 && present < 1.0 {
            out = out.map(|x| x / present);
        }
        out
    }

    /// One basis sky alone, as CIE XYZ, for a sun at `sun_elevation_deg`
    /// and azimuth 0.
    pub fn sample_xyz_of(&self, entry: &SkyEntry, texture: &Texture, sun_elevation_deg: f64, dir: DVec3) -> [f64; 3] {
        crate::colour::apply(
            &self.manifest.colour.xyz_from_rgb,
            sample_sky(entry, texture, 90.0 - sun_elevation_deg, 0.0, dir),
        )
    }

    /// [`Luts::sample`] as CIE XYZ (Y in cd/m²).
    pub fn sample_xyz(
        &self,
        sun_elevation_deg: f64,
        sun_azimuth_deg: f64,
        haziness: f64,
        cloudiness: f64,
        dir: DVec3,
    ) -> [f64; 3] {
        crate::colour::apply(
            &self.manifest.colour.xyz_from_rgb,
            self.sample(sun_elevation_deg, sun_azimuth_deg, haziness, cloudiness, dir),
        )
    }
}

/// The layers of a 2-D array texture file in `container` of `width` ×
/// `height` × `layers` texels of `vk_format`, RGB, row-major; checked
/// against those ([`super::container::read`]).
pub(crate) fn read_rgb_array(
    path: &std::path::Path,
    container: super::container::Container,
    vk_format: u32,
    (width, height, layers): (usize, usize, usize),
) -> Result<Vec<Vec<[f32; 3]>>, LoadError> {
    let level = super::container::read(container, path).map_err(|m| load_error(path, m))?;
    if level.vk_format != vk_format || (level.width, level.height, level.layers) != (width, height, layers) {
        return Err(load_error(
            path,
            format!(
                "vkFormat {}, {} x {} x {} layers; the manifest says vkFormat {vk_format}, {width} x {height} x {layers} layers",
                level.vk_format, level.width, level.height, level.layers
            ),
        ));
    }
    level.rgb_layers().map_err(|m| load_error(path, m))
}

/// The direction through each pixel centre of a `width` × `height` image
/// through `camera`, row-major (None outside its view).
pub fn pixel_directions(camera: &crate::directions::camera::Camera, width: usize, height: usize) -> Vec<Option<DVec3>> {
    (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .map(|(x, y)| camera.direction(x as f64 + 0.5, y as f64 + 0.5, width, height))
        .collect()
}

/// Why a bake cannot be loaded.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error("{}: {message}", path.display())]
    File { path: std::path::PathBuf, message: String },
}

fn load_error(path: &std::path::Path, message: impl Into<String>) -> LoadError {
    LoadError::File { path: path.to_path_buf(), message: message.into() }
}

/// A bake's manifest: its text and what it says, in a format and version
/// this build reads.
pub fn read_manifest(manifest_path: &std::path::Path) -> Result<(String, Manifest), LoadError> {
    let text = std::fs::read_to_string(manifest_path).map_err(|e| load_error(manifest_path, e.to_string()))?;
    let manifest: Manifest =
        serde_json::from_str(&text).map_err(|e| load_error(manifest_path, format!("line {}: {e}", e.line())))?;
    if manifest.format != super::manifest::FORMAT || manifest.version != super::manifest::VERSION {
        return Err(load_error(
            manifest_path,
            format!(
                "a {} version {} manifest; this build reads {} version {}",
                manifest.format,
                manifest.version,
                super::manifest::FORMAT,
                super::manifest::VERSION
            ),
        ));
    }
    Ok((text, manifest))
}

impl Luts {
    /// Loads a bake: its manifest and every texture it names, once the
    /// files are as the manifest records them (`integrity::check`), each
    /// read in the manifest's container (KTX2 with the `ktx2` crate, a
    /// reader independent of our writer; or DDS) and checked against its
    /// manifest entry.
    pub fn load(manifest_path: &std::path::Path) -> Result<Luts, LoadError> {
        let (text, manifest) = read_manifest(manifest_path)?;
        // Nothing is read from a file the manifest does not vouch for.
        super::integrity::check(manifest_path, &text, &manifest)
            .map_err(|d| LoadError::File { path: d.path, message: d.message })?;
        let dir = manifest_path.parent().unwrap_or(std::path::Path::new("."));
        let container = super::container::Container::of_manifest(manifest.container.as_deref())
            .map_err(|m| load_error(manifest_path, format!("container: {m}")))?;
        const HALVES: u32 = super::ktx2::VK_FORMAT_R16G16B16A16_SFLOAT;
        let mut textures = Vec::new();
        for e in &manifest.skies {
            let path = dir.join(&e.file);
            if e.slices.len() != e.layers {
                return Err(load_error(
                    &path,
                    format!("{} layers but {} slices in the manifest", e.layers, e.slices.len()),
                ));
            }
            let layers = read_rgb_array(&path, container, e.vk_format, (e.width, e.height, e.layers))?;
            textures.push(Texture { width: e.width, height: e.height, layers });
        }
        let mut transmittance = Vec::new();
        if let Some(t) = &manifest.transmittance {
            let size = (super::transmittance::WIDTH, super::transmittance::HEIGHT, t.layers.len());
            transmittance = read_rgb_array(&dir.join(&t.file), container, HALVES, size)?;
        }
        let fog = match &manifest.fog {
            Some(f) => Some(super::decode_fog::FogTextures {
                fog: read_rgb_array(&dir.join(&f.file), container, HALVES, (f.width, f.height, f.layers))?,
                attenuation: read_rgb_array(
                    &dir.join(&f.attenuation.file),
                    container,
                    HALVES,
                    (f.attenuation.width, f.attenuation.height, f.attenuation.layers.len()),
                )?,
            }),
            None => None,
        };
        let ambient_texture = match &manifest.ambient_file {
            Some(a) => read_rgb_array(&dir.join(&a.file), container, HALVES, (a.width, a.height, a.layers.len()))?,
            None => Vec::new(),
        };
        Ok(Luts { manifest, textures, transmittance, fog, ambient_texture })
    }

    /// The transmittance toward the top of one basis sky (manifest index
    /// `sky`) from `altitude_km` along cosine `mu`, per channel; None
    /// without a transmittance file.
    pub fn sun_transmittance(&self, sky: usize, altitude_km: f64, mu: f64) -> Option<[f64; 3]> {
        let e = &self.manifest.skies[sky];
        let layer = self.transmittance.get(e.sun.as_ref()?.transmittance_layer)?;
        let mapping = super::transmittance::TransmittanceMapping::new(e.planet_radius_km, e.top_km);
        Some(super::transmittance::sample(&mapping, |i| layer[i].map(f64::from), altitude_km, mu))
    }

    /// Ambient light from the sky for a sun at `sun_elevation_deg`: each
    /// basis sky's between its two slices (linearly: the harmonics may be
    /// negative), blended by the weather rule; None without ambient data.
    pub fn ambient(&self, sun_elevation_deg: f64, haziness: f64, cloudiness: f64) -> Option<super::ambient::Ambient> {
        use super::ambient::Ambient;
        let w = basis_weights(haziness, cloudiness);
        let (mut out, mut present) = (Ambient::zero(), 0.0);
        for (k, name) in super::weather::BASIS.iter().enumerate() {
            let Some(e) = self.manifest.skies.iter().find(|s| s.name == *name) else { continue };
            let a = e.ambient.as_ref()?;
            let (i0, i1, f) = slice_pair(e, 90.0 - sun_elevation_deg);
            out.add_scaled(&Ambient::lerp(&a[i0], &a[i1], f), w[k]);
            present += w[k];
        }
        Some(if present > 0.0 && present < 1.0 { out.scaled(1.0 / present) } else { out })
    }

    /// A whole image through `camera` (`width` × `height`), CIE XYZ per
    /// pixel (row-major; 0 outside the camera's view), for the sun at
    /// `sun_elevation_deg`, `sun_azimuth_deg`. With `sun_disk`, the sun's
    /// disk is added from the transmittance file: its radiance in every
    /// pixel whose centre it covers, or, where it falls between pixel
    /// centres (a disk smaller than a pixel), its irradiance over the
    /// solid angle of the pixel nearest to it, so the image carries the
    /// sun's energy at any size. None if `sun_disk` and the bake has no sun.
    pub fn decode_image(
        &self,
        camera: &crate::directions::camera::Camera,
        width: usize,
        height: usize,
        sun_elevation_deg: f64,
        sun_azimuth_deg: f64,
        haziness: f64,
        cloudiness: f64,
        sun_disk: bool,
    ) -> Option<Vec<[f64; 3]>> {
        let dirs = pixel_directions(camera, width, height);
        let mut xyz: Vec<[f64; 3]> = dirs
            .iter()
            .map(|d| {
                d.map_or([0.0; 3], |d| self.sample_xyz(sun_elevation_deg, sun_azimuth_deg, haziness, cloudiness, d))
            })
            .collect();
        if !sun_disk {
            return Some(xyz);
        }
        let sun = self.sun(sun_elevation_deg, haziness, cloudiness)?;
        let to_xyz = |rgb: [f64; 3]| crate::colour::apply(&self.manifest.colour.xyz_from_rgb, rgb);
        let s = crate::directions::camera::direction_deg(90.0 - sun_elevation_deg, sun_azimuth_deg);
        let cos_radius = libm::cos(0.5 * sun.angular_diameter_deg.to_radians());
        let mut covered = false;
        for (p, d) in xyz.iter_mut().zip(&dirs) {
            if d.is_some_and(|d| d.dot(s) >= cos_radius) {
                let l = to_xyz(sun.disk_radiance_rgb);
                *p = std::array::from_fn(|c| p[c] + l[c]);
                covered = true;
            }
        }
        if !covered {
            if let Some((i, rgb)) = self.sub_pixel_sun(camera, width, height, &dirs, s, sun.irradiance_rgb) {
                let e = to_xyz(rgb);
                xyz[i] = std::array::from_fn(|k| xyz[i][k] + e[k]);
            }
        }
        Some(xyz)
    }

    /// A sun too small to cover any pixel centre (`dirs`, the pixels of
    /// `camera` at `width` x `height`; `toward` the unit vector to the sun):
    /// the pixel whose centre is nearest the sun and the radiance that puts
    /// the sun's irradiance `irradiance_rgb` into it (irradiance over the
    /// pixel's solid angle, from the directions through its corners); None
    /// when the sun lies off the image rather than within that pixel.
    pub fn sub_pixel_sun(
        &self,
        camera: &crate::directions::camera::Camera,
        width: usize,
        height: usize,
        dirs: &[Option<DVec3>],
        toward: DVec3,
        irradiance_rgb: [f64; 3],
    ) -> Option<(usize, [f64; 3])> {
        let (i, _) = dirs
            .iter()
            .enumerate()
            .filter_map(|(i, d)| d.map(|d| (i, d.dot(toward))))
            .max_by(|a, b| a.1.total_cmp(&b.1))?;
        let (x, y) = ((i % width) as f64, (i / width) as f64);
        let corner = |dx: f64, dy: f64| camera.direction(x + dx, y + dy, width, height);
        let (a, b, c) = (corner(0.0, 0.0)?, corner(1.0, 0.0)?, corner(0.0, 1.0)?);
        let omega = (b - a).cross(c - a).length();
        let half = 0.5 * (b - a).length().max((c - a).length());
        // Only when the sun is within the pixel, not off the image's edge.
        let within = dirs[i].is_some_and(|d| libm::acos(d.dot(toward).min(1.0)) <= half * std::f64::consts::SQRT_2);
        (omega > 0.0 && within).then(|| (i, irradiance_rgb.map(|e| e / omega)))
    }

    /// The sun at each basis sky's observer for a sun at
    /// `sun_elevation_deg`, blended by haziness and cloudiness as the sky
    /// is: Σ_k w_k top_k · T_k(observer, sun); None without sun data.
    pub fn sun(&self, sun_elevation_deg: f64, haziness: f64, cloudiness: f64) -> Option<Sun> {
        let w = basis_weights(haziness, cloudiness);
        let mu = libm::sin(sun_elevation_deg.to_radians());
        let (mut irradiance, mut present, mut diameter, mut omega) = ([0.0; 3], 0.0, 0.0, 1.0);
        for (k, name) in super::weather::BASIS.iter().enumerate() {
            let Some(i) = self.manifest.skies.iter().position(|s| s.name == *name) else { continue };
            let e = &self.manifest.skies[i];
            let sun = e.sun.as_ref()?;
            let t = self.sun_transmittance(i, e.altitude_m / 1000.0, mu)?;
            for c in 0..3 {
                irradiance[c] += w[k] * sun.top_irradiance_rgb[c] * t[c];
            }
            present += w[k];
            (diameter, omega) = (sun.angular_diameter_deg, sun.solid_angle_sr);
        }
        if present > 0.0 && present < 1.0 {
            irradiance = irradiance.map(|x| x / present);
        }
        Some(Sun {
            irradiance_rgb: irradiance,
            disk_radiance_rgb: irradiance.map(|x| x / omega),
            angular_diameter_deg: diameter,
        })
    }
}

#[cfg(test)]
mod tests;
