//! Bake files: which basis skies a bake renders, from which atmosphere
//! files, at what size and quality. Parsed like the atmosphere files: every
//! error names the file and the line of the offending key, and unknown keys
//! are errors.
//!
//! ```toml
//! [quality.draft]            # --quality draft
//! band_nm = 20.0
//! spp = 8
//! [quality.final]            # --quality final
//! band_nm = 5.0
//! spp = 16384                # the most a texel may take
//! max_rel_error = 0.01       # adaptive: stop at this standard error of Y
//! ms_grid = "16x13"          # optional: multiple scattering on a grid of its own
//!                            # (rows x azimuths), interpolated (bake::ms_grid)
//! fog_ms_size = "16x16"      # optional: the Shadowed Fog rendered at this size
//! streams = 16               # optional: the transport solver's streams a hemisphere
//!                            # (width x height) and resampled to the Fog LUT's
//!
//! [[sky]]                    # in the talk's order: clear, hazed, cloudy0 ... cloudy5
//! name = "clear"
//! atmosphere = "clear.toml"  # relative to the bake file
//! width = 32                 # texels along u (heading around the sun)
//! height = 128               # texels along v (angle from the sun)
//! slices = 64                # the talk's time mapping: 48 above the horizon, 16 below
//! altitude_m = 0.0           # the observer
//! threshold_deg = 87.9       # sun zenith beyond which slices are latitude-longitude
//!                            # (default: mapping::default_threshold_deg; measure it
//!                            # with `sky lut interpolation ATMOSPHERE --size WxH`)
//!
//! [fog]                      # the global-fog LUTs of every basis sky (optional)
//! ceiling_km = 3.0           # only the air below makes fog: the cloud base
//! width = 32                 # Fog LUT texels along u (azimuth from the sun)
//! height = 32                # along v (elevation)
//! ```

use crate::atmosphere::Located;
use crate::directions::mapping;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use toml::Spanned as S;

/// How carefully a bake renders: the two presets of a bake file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quality {
    /// Minutes on a laptop: for demos, CI and checking a pipeline.
    Draft,
    /// The shipping quality.
    Final,
}

impl Quality {
    pub fn name(self) -> &'static str {
        match self {
            Quality::Draft => "draft",
            Quality::Final => "final",
        }
    }
}

/// The sampling of one quality preset.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sampling {
    /// Width of the spectral bands, nm (hero-wavelength sampling).
    pub band_nm: f64,
    /// Samples per texel; with `max_rel_error`, the most a texel may take.
    pub spp: u32,
    /// Adaptive sampling's target standard error of Y, relative.
    pub max_rel_error: Option<f64>,
    /// Multiple scattering rendered on a grid of its own of [rows,
    /// columns] over the sky and interpolated to the texels
    /// ([`super::ms_grid`]); None: every texel rendered.
    #[serde(default)]
    pub ms_grid: Option<[usize; 2]>,
    /// The Shadowed Fog (the fog slices' Monte Carlo: light scattered two
    /// or more times) rendered at [width, height] texels of the Fog LUT's
    /// mapping and resampled bilinearly in (u, v) to the LUT's size
    /// ([`super::fog_resample::resample_shadowed`]); None: at the LUT's size.
    #[serde(default)]
    pub fog_ms_size: Option<[usize; 2]>,
    /// The transport solver's discrete-ordinate streams a hemisphere
    /// (`--method deterministic`); None: its default, 16.
    #[serde(default)]
    pub streams: Option<usize>,
}

/// One basis sky of a bake.
#[derive(Debug, Clone, PartialEq)]
pub struct BasisSky {
    pub name: String,
    pub atmosphere: PathBuf,
    /// Texels along u (heading around the sun).
    pub width: usize,
    /// Texels along v (angle from the sun).
    pub height: usize,
    pub slices: usize,
    pub altitude_m: f64,
    /// The sun zenith angle beyond which a slice uses the latitude-longitude
    /// mapping instead of the sun-centred one, degrees.
    pub threshold_deg: f64,
    /// The line of its `[[sky]]` table, for messages.
    pub line: usize,
    pub draft: Sampling,
    pub final_: Sampling,
}

impl BasisSky {
    pub fn sampling(&self, q: Quality) -> &Sampling {
        match q {
            Quality::Draft => &self.draft,
            Quality::Final => &self.final_,
        }
    }
}

/// The global-fog LUTs of a bake (`lut::fog`): one ceiling and one size
/// for every basis sky.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FogSettings {
    /// Only the air below this altitude makes fog (the talk: "only
    /// low-altitude atmosphere affects our global fog"), km.
    pub ceiling_km: f64,
    /// Fog LUT texels along u (azimuth from the sun) and v (elevation).
    pub width: usize,
    pub height: usize,
}

/// The ceiling of the fog by default: the base of the cloud layer of the
/// shipped cloudy skies (`atmospheres/cloudy*.toml`: 3 to 5 km).
pub const DEFAULT_FOG_CEILING_KM: f64 = 3.0;

impl Default for FogSettings {
    /// The talk's 32 × 32 under the cloudy skies' cloud base.
    fn default() -> FogSettings {
        FogSettings {
            ceiling_km: DEFAULT_FOG_CEILING_KM,
            width: crate::lut::fog::FOG_WIDTH,
            height: crate::lut::fog::FOG_HEIGHT,
        }
    }
}

/// A parsed bake file.
#[derive(Debug, Clone, PartialEq)]
pub struct BakeFile {
    pub path: PathBuf,
    pub skies: Vec<BasisSky>,
    pub fog: FogSettings,
}

/// Every error found in a bake file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}", errors.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("\n"))]
pub struct BakeFileError {
    pub errors: Vec<Located>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    #[serde(default)]
    quality: BTreeMap<String, S<RawSampling>>,
    #[serde(default)]
    sky: Vec<S<RawSky>>,
    fog: Option<S<RawFog>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFog {
    ceiling_km: Option<S<f64>>,
    width: Option<S<i64>>,
    height: Option<S<i64>>,
}

#[derive(Deserialize, Clone, Default)]
#[serde(deny_unknown_fields)]
struct RawSampling {
    band_nm: Option<S<f64>>,
    spp: Option<S<i64>>,
    max_rel_error: Option<S<f64>>,
    ms_grid: Option<S<String>>,
    fog_ms_size: Option<S<String>>,
    streams: Option<S<i64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSky {
    name: S<String>,
    atmosphere: S<String>,
    width: S<i64>,
    height: S<i64>,
    slices: Option<S<i64>>,
    altitude_m: Option<S<f64>>,
    threshold_deg: Option<S<f64>>,
    #[serde(default)]
    quality: BTreeMap<String, S<RawSampling>>,
}

/// The presets when a bake file names none: a draft that bakes all eight
/// basis skies in minutes on two cores, and a final at the R11G11B10F
/// rounding error (about 1 %).
pub fn default_sampling(q: Quality) -> Sampling {
    match q {
        Quality::Draft => {
            Sampling { band_nm: 20.0, spp: 4, max_rel_error: None, ms_grid: None, fog_ms_size: None, streams: None }
        }
        Quality::Final => Sampling {
            band_nm: 5.0,
            spp: 16384,
            max_rel_error: Some(0.01),
            ms_grid: None,
            fog_ms_size: None,
            streams: None,
        },
    }
}

/// "RxC" with R and C from 2 to 1024.
fn parse_grid(text: &str) -> Option<[usize; 2]> {
    let (r, c) = text.trim().split_once(['x', 'X'])?;
    let (r, c): (usize, usize) = (r.trim().parse().ok()?, c.trim().parse().ok()?);
    ((2..=1024).contains(&r) && (2..=1024).contains(&c)).then_some([r, c])
}

struct Ctx<'a> {
    path: &'a Path,
    text: &'a str,
    errors: Vec<Located>,
}

impl Ctx<'_> {
    fn line(&self, offset: usize) -> usize {
        self.text[..offset.min(self.text.len())].bytes().filter(|&b| b == b'\n').count() + 1
    }

    fn err<T>(&mut self, at: &S<T>, message: impl Into<String>) {
        let line = self.line(at.span().start);
        self.errors.push(Located { path: self.path.to_path_buf(), line: Some(line), message: message.into() });
    }

    /// A preset: `base`, with what `raw` sets replaced and checked.
    fn sampling(&mut self, base: &Sampling, raw: &RawSampling, what: &str) -> Sampling {
        let mut s = base.clone();
        if let Some(b) = &raw.band_nm {
            if b.get_ref().is_finite() && *b.get_ref() >= 1.0 && *b.get_ref() <= 100.0 {
                s.band_nm = *b.get_ref();
            } else {
                self.err(b, format!("{what}.band_nm: must be between 1 and 100 nm, got {}", b.get_ref()));
            }
        }
        if let Some(n) = &raw.spp {
            match u32::try_from(*n.get_ref()) {
                Ok(v) if v >= 1 => s.spp = v,
                _ => self
                    .err(n, format!("{what}.spp: must be a whole number from 1 to {}, got {}", u32::MAX, n.get_ref())),
            }
        }
        if let Some(e) = &raw.max_rel_error {
            let e_v = *e.get_ref();
            if e_v > 0.0 && e_v < 1.0 {
                s.max_rel_error = Some(e_v);
            } else {
                self.err(
                    e,
                    format!("{what}.max_rel_error: must be between 0 and 1 (a fraction, e.g. 0.01), got {e_v}"),
                );
            }
        }
        if let Some(g) = &raw.ms_grid {
            match parse_grid(g.get_ref()) {
                Some(grid) => s.ms_grid = Some(grid),
                None => self.err(
                    g,
                    format!(
                        "{what}.ms_grid: expected \"ROWSxCOLUMNS\", each from 2 to 1024 (e.g. \"16x13\"), got {:?}",
                        g.get_ref()
                    ),
                ),
            }
        }
        if let Some(n) = &raw.streams {
            match usize::try_from(*n.get_ref()) {
                Ok(v) if (2..=128).contains(&v) => s.streams = Some(v),
                _ => self.err(n, format!("{what}.streams: must be a whole number from 2 to 128, got {}", n.get_ref())),
            }
        }
        if let Some(g) = &raw.fog_ms_size {
            match parse_grid(g.get_ref()) {
                Some(size) => s.fog_ms_size = Some(size),
                None => self.err(
                    g,
                    format!(
                        "{what}.fog_ms_size: expected \"WIDTHxHEIGHT\", each from 2 to 1024 (e.g. \"16x16\"), got {:?}",
                        g.get_ref()
                    ),
                ),
            }
        }
        s
    }

    fn presets(&mut self, base: [&Sampling; 2], raw: &BTreeMap<String, S<RawSampling>>, prefix: &str) -> [Sampling; 2] {
        let mut out = [base[0].clone(), base[1].clone()];
        for (name, r) in raw {
            let i = match name.as_str() {
                "draft" => 0,
                "final" => 1,
                other => {
                    self.err(r, format!("{prefix}quality.{other}: unknown preset (the presets are draft and final)"));
                    continue;
                }
            };
            out[i] = self.sampling(base[i], r.get_ref(), &format!("{prefix}quality.{name}"));
        }
        out
    }
}

fn positive_size(ctx: &mut Ctx, v: &S<i64>, key: &str, sky: &str) -> usize {
    match usize::try_from(*v.get_ref()) {
        Ok(n) if (1..=4096).contains(&n) => n,
        _ => {
            ctx.err(v, format!("sky {sky:?}: {key} must be from 1 to 4096 texels, got {}", v.get_ref()));
            1
        }
    }
}

impl BakeFile {
    pub fn load(path: &Path) -> Result<BakeFile, BakeFileError> {
        let text = std::fs::read(path).map_err(|e| BakeFileError {
            errors: vec![Located {
                path: path.to_path_buf(),
                line: None,
                message: format!("cannot read the bake file: {e}"),
            }],
        })?;
        let text = String::from_utf8(text).map_err(|e| {
            let line = e.as_bytes()[..e.utf8_error().valid_up_to()].iter().filter(|&&b| b == b'\n').count() + 1;
            BakeFileError {
                errors: vec![Located { path: path.to_path_buf(), line: Some(line), message: "not UTF-8 text".into() }],
            }
        })?;
        BakeFile::parse(path, &text)
    }

    /// Parses bake-file text; `path` names it in errors and anchors the
    /// atmosphere paths.
    pub fn parse(path: &Path, text: &str) -> Result<BakeFile, BakeFileError> {
        let raw: RawFile = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| text[..s.start.min(text.len())].bytes().filter(|&b| b == b'\n').count() + 1);
            BakeFileError {
                errors: vec![Located { path: path.to_path_buf(), line, message: e.message().trim().to_string() }],
            }
        })?;
        let mut ctx = Ctx { path, text, errors: Vec::new() };
        let defaults = [default_sampling(Quality::Draft), default_sampling(Quality::Final)];
        let global = ctx.presets([&defaults[0], &defaults[1]], &raw.quality, "");
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let mut skies: Vec<BasisSky> = Vec::new();
        if raw.sky.is_empty() {
            ctx.errors.push(Located {
                path: path.to_path_buf(),
                line: None,
                message: "no [[sky]] tables: a bake needs at least one basis sky".into(),
            });
        }
        for s in &raw.sky {
            let r = s.get_ref();
            let name = r.name.get_ref().clone();
            if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
                ctx.err(&r.name, format!("sky name {name:?}: use letters, digits, '-' and '_' (it names files)"));
            }
            if skies.iter().any(|k| k.name == name) {
                ctx.err(&r.name, format!("sky {name:?} appears twice"));
            }
            let atmosphere = dir.join(r.atmosphere.get_ref());
            if !atmosphere.is_file() {
                ctx.err(&r.atmosphere, format!("sky {name:?}: atmosphere file {} not found", atmosphere.display()));
            }
            let width = positive_size(&mut ctx, &r.width, "width", &name);
            let height = positive_size(&mut ctx, &r.height, "height", &name);
            let slices = match &r.slices {
                None => mapping::SLICES,
                Some(n) if *n.get_ref() == mapping::SLICES as i64 => mapping::SLICES,
                Some(n) => {
                    ctx.err(
                        n,
                        format!(
                            "sky {name:?}: slices must be {} (the talk's time mapping: {} above the horizon, {} below), got {}",
                            mapping::SLICES,
                            mapping::UPPER_SLICES,
                            mapping::LOWER_SLICES,
                            n.get_ref()
                        ),
                    );
                    mapping::SLICES
                }
            };
            let altitude_m = match &r.altitude_m {
                None => 0.0,
                Some(a) if a.get_ref().is_finite() && *a.get_ref() >= 0.0 && *a.get_ref() <= 20_000.0 => *a.get_ref(),
                Some(a) => {
                    ctx.err(a, format!("sky {name:?}: altitude_m must be from 0 to 20000 m, got {}", a.get_ref()));
                    0.0
                }
            };
            let threshold_deg = match &r.threshold_deg {
                None => mapping::default_threshold_deg(width.max(1), height.max(1)),
                Some(t) if (0.0..=90.0).contains(t.get_ref()) => *t.get_ref(),
                Some(t) => {
                    ctx.err(
                        t,
                        format!(
                            "sky {name:?}: threshold_deg must be a sun zenith angle from 0 to 90 degrees, got {}",
                            t.get_ref()
                        ),
                    );
                    90.0
                }
            };
            let [draft, final_] = ctx.presets([&global[0], &global[1]], &r.quality, &format!("sky {name:?}: "));
            let line = ctx.line(s.span().start);
            skies.push(BasisSky {
                name,
                atmosphere,
                width,
                height,
                slices,
                altitude_m,
                threshold_deg,
                line,
                draft,
                final_,
            });
        }
        let mut fog = FogSettings::default();
        if let Some(f) = &raw.fog {
            let f = f.get_ref();
            if let Some(c) = &f.ceiling_km {
                let highest = skies.iter().map(|s| s.altitude_m / 1000.0).fold(0.0, f64::max);
                if c.get_ref().is_finite() && *c.get_ref() > highest && *c.get_ref() <= 20.0 {
                    fog.ceiling_km = *c.get_ref();
                } else {
                    ctx.err(c, format!("fog.ceiling_km: must be above every sky's observer ({highest} km) and at most 20 km, got {}", c.get_ref()));
                }
            }
            for (raw, key, out) in [(&f.width, "width", &mut fog.width), (&f.height, "height", &mut fog.height)] {
                let Some(v) = raw else { continue };
                match usize::try_from(*v.get_ref()) {
                    Ok(n) if (2..=1024).contains(&n) => *out = n,
                    _ => ctx.err(v, format!("fog.{key}: must be from 2 to 1024 texels, got {}", v.get_ref())),
                }
            }
        }
        if ctx.errors.is_empty() {
            Ok(BakeFile { path: path.to_path_buf(), skies, fog })
        } else {
            Err(BakeFileError { errors: ctx.errors })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<BakeFile, BakeFileError> {
        // Anchored in atmospheres/ so that the shipped files exist.
        BakeFile::parse(&Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/test-bake.toml"), text)
    }

    #[test]
    fn a_bake_file_parses_with_its_presets() {
        let b = parse("[quality.draft]\nspp = 4\n[[sky]]\nname = \"clear\"\natmosphere = \"clear.toml\"\nwidth = 32\nheight = 128\n[sky.quality.final]\nmax_rel_error = 0.02\n").unwrap();
        assert_eq!(b.skies.len(), 1);
        let s = &b.skies[0];
        assert_eq!((s.width, s.height, s.slices, s.line), (32, 128, 64, 3));
        assert_eq!(
            s.draft,
            Sampling { band_nm: 20.0, spp: 4, max_rel_error: None, ms_grid: None, fog_ms_size: None, streams: None }
        );
        assert_eq!(
            s.final_,
            Sampling {
                band_nm: 5.0,
                spp: 16384,
                max_rel_error: Some(0.02),
                ms_grid: None,
                fog_ms_size: None,
                streams: None
            }
        );
        assert_eq!(b.fog, FogSettings { ceiling_km: 3.0, width: 32, height: 32 });
        let b = parse("[[sky]]\nname = \"clear\"\natmosphere = \"clear.toml\"\nwidth = 32\nheight = 128\n[fog]\nceiling_km = 2.5\nwidth = 8\nheight = 4\n").unwrap();
        assert_eq!(b.fog, FogSettings { ceiling_km: 2.5, width: 8, height: 4 });
        let b = parse("[quality.final]\nms_grid = \"16x13\"\nfog_ms_size = \"16x8\"\n[[sky]]\nname = \"clear\"\natmosphere = \"clear.toml\"\nwidth = 32\nheight = 128\n").unwrap();
        assert_eq!((b.skies[0].final_.ms_grid, b.skies[0].draft.ms_grid), (Some([16, 13]), None));
        assert_eq!((b.skies[0].final_.fog_ms_size, b.skies[0].draft.fog_ms_size), (Some([16, 8]), None));
    }

    #[test]
    fn a_bad_grid_is_named_with_its_line() {
        for bad in ["16", "1x13", "16x0", "ax3", "2000x4"] {
            let e = parse(&format!("[[sky]]\nname = \"a\"\natmosphere = \"clear.toml\"\nwidth = 1\nheight = 1\n[sky.quality.draft]\nms_grid = \"{bad}\"\n")).unwrap_err();
            assert!(
                e.to_string().contains("test-bake.toml:7: ")
                    && e.to_string().contains("ms_grid: expected \"ROWSxCOLUMNS\""),
                "{bad}: {e}"
            );
        }
        assert_eq!(parse_grid(" 8 x 5 "), Some([8, 5]));
    }

    #[test]
    fn errors_name_the_line_and_the_key() {
        let text = "[[sky]]\nname = \"clear\"\natmosphere = \"nope.toml\"\nwidth = 0\nheight = 128\nslices = 32\n[sky.quality.final]\nmax_rel_error = 2.0\n[sky.quality.best]\nspp = 1\n";
        let e = parse(text).unwrap_err();
        let lines: Vec<String> = e.errors.iter().map(|l| l.to_string()).collect();
        let has = |line: usize, what: &str| {
            lines.iter().any(|l| l.contains(&format!("test-bake.toml:{line}: ")) && l.contains(what))
        };
        assert!(has(3, "nope.toml not found"), "{lines:?}");
        assert!(has(4, "width must be"), "{lines:?}");
        assert!(has(6, "slices must be 64"), "{lines:?}");
        assert!(has(8, "max_rel_error"), "{lines:?}");
        assert!(has(9, "quality.best: unknown preset"), "{lines:?}");
        assert_eq!(lines.len(), 5, "{lines:?}");
        let unknown = parse("[[sky]]\nname = \"a\"\natmosphere = \"clear.toml\"\nwidth = 1\nheight = 1\ncolour = 3\n")
            .unwrap_err();
        assert!(unknown.to_string().contains("test-bake.toml:6: unknown field `colour`"), "{unknown}");
        let twice = parse("[[sky]]\nname = \"a\"\natmosphere = \"clear.toml\"\nwidth = 1\nheight = 1\n[[sky]]\nname = \"a\"\natmosphere = \"clear.toml\"\nwidth = 1\nheight = 1\n").unwrap_err();
        assert!(twice.to_string().contains("test-bake.toml:7: sky \"a\" appears twice"), "{twice}");
        let threshold =
            parse("[[sky]]\nname = \"a\"\natmosphere = \"clear.toml\"\nwidth = 1\nheight = 1\nthreshold_deg = 95.0\n")
                .unwrap_err();
        assert!(threshold.to_string().contains("test-bake.toml:6: sky \"a\": threshold_deg must be"), "{threshold}");
        let fog = parse("[[sky]]\nname = \"a\"\natmosphere = \"clear.toml\"\nwidth = 1\nheight = 1\naltitude_m = 500.0\n[fog]\nceiling_km = 0.2\nheight = 0\nshape = 1\n").unwrap_err();
        assert!(fog.to_string().contains("test-bake.toml:10: unknown field `shape`"), "{fog}");
        let fog = parse("[[sky]]\nname = \"a\"\natmosphere = \"clear.toml\"\nwidth = 1\nheight = 1\naltitude_m = 500.0\n[fog]\nceiling_km = 0.2\nheight = 0\n").unwrap_err();
        assert!(
            fog.to_string().contains("test-bake.toml:8: fog.ceiling_km: must be above every sky's observer (0.5 km)"),
            "{fog}"
        );
        assert!(fog.to_string().contains("test-bake.toml:9: fog.height: must be from 2"), "{fog}");
        let b =
            parse("[[sky]]\nname = \"a\"\natmosphere = \"clear.toml\"\nwidth = 32\nheight = 128\nthreshold_deg = 85.3\n[[sky]]\nname = \"b\"\natmosphere = \"clear.toml\"\nwidth = 32\nheight = 128\n")
                .unwrap();
        assert_eq!(b.skies[0].threshold_deg, 85.3);
        assert_eq!(b.skies[1].threshold_deg, mapping::default_threshold_deg(32, 128));
    }

    #[test]
    fn the_shipped_bake_is_the_talks() {
        let b = BakeFile::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("bakes/basis-skies.toml")).unwrap();
        let names: Vec<&str> = b.skies.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["clear", "hazed", "cloudy0", "cloudy1", "cloudy2", "cloudy3", "cloudy4", "cloudy5"]);
        // The talk's "Memory Budget of Look-up Table": sunny 32 x 128, cloudy 16 x 64, 64 slices.
        for s in &b.skies {
            let size = if s.name.starts_with("cloudy") { (16, 64) } else { (32, 128) };
            assert_eq!((s.width, s.height, s.slices), (size.0, size.1, 64), "{}", s.name);
            // Multiple scattering on a grid of its own for the sunny skies'
            // final bake only (README: measured against whole slices).
            let grid = if s.name.starts_with("cloudy") { None } else { Some([16, 13]) };
            assert_eq!(
                (s.sampling(Quality::Final).ms_grid, s.sampling(Quality::Draft).ms_grid),
                (grid, None),
                "{}",
                s.name
            );
            // And their Shadowed Fog at 16 x 16 (README: measured against whole fog slices).
            let fog = if s.name.starts_with("cloudy") { None } else { Some([16, 16]) };
            assert_eq!(
                (s.sampling(Quality::Final).fog_ms_size, s.sampling(Quality::Draft).fog_ms_size),
                (fog, None),
                "{}",
                s.name
            );
        }
        // And the other shipped bakes parse.
        for f in ["bakes/demo.toml", "bakes/tiny.toml", "bakes/cost-probe.toml", "tests/bakes/tiny.toml"] {
            BakeFile::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        }
    }
}
