//! `sky render`: the path tracer, on the local cores (the embedded worker)
//! or across `sky worker` daemons, through the same farm coordinator.
//!
//! [`run`] goes in phases: the flags are checked into a [`Checked`] (camera,
//! image size, farm plan) before any work starts, the settings are built
//! from them, the optics are prepared in a session, the view is rendered
//! (locally or on the farm, journaled next to the output), and the outputs
//! and the summary are written by `render_output`.

use super::render_output::Outputs;
use super::{usage, EXIT_INVALID};
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use sky::atmosphere::{Atmosphere, Bundle};
use sky::directions::camera::Camera;
use sky::farm::coordinator::{FarmError, Options, WorkerSpec};
use sky::farm::job::FarmJob;
use sky::farm::journal;
use sky::farm::proto::Tile;
use sky::mie::MieCache;
use sky::render::fog::Fog;
use sky::render::tracer::Estimator;
use sky::render::{Scene, Settings, SingleScatter, SpectralSettings, View, WavelengthSampling};
use sky::session::{OpticsCache, Session};
use sky::table::Table;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

#[derive(Clone, Copy, clap::ValueEnum)]
enum CameraKind {
    /// Full sphere, azimuth across, zenith angle down
    Equirect,
    /// Upper hemisphere, equidistant, zenith at the centre
    Fisheye,
    /// Perspective view (--look-azimuth-deg, --look-elevation-deg, --fov-deg)
    Pinhole,
    /// A LUT slice through the talk's adaptive (u, v) mapping: u across, v down (--size 32x128 like the talk's)
    Lut,
    /// A CSV of zenith_deg,azimuth_deg rows (--directions FILE)
    Directions,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum SingleArg {
    Quadrature,
    MonteCarlo,
}

/// How `sky render` computes the light.
#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
enum Method {
    /// The path tracer: the project's referee, noise with a standard error per pixel
    MonteCarlo,
    /// The transport solver: no noise (zero standard errors); from the ground, suns down to 99 deg from the zenith (at twilight a spherical source, about twenty times slower than by day); the global fog too (--fog-distance-km)
    Deterministic,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum Sampling {
    Luminance,
    Tristimulus,
    Hero,
}

#[derive(clap::Args)]
#[command(after_help = "Units: X, Y, Z are CIE 1931 tristimulus values of the sky radiance times 683 lm/W \
(Y is luminance in cd/m^2); spectral channels are radiance in W m^-2 sr^-1 nm^-1; stderr.* channels are \
the per-pixel standard errors of the mean. An atmosphere file without a [sun] table is lit by the shipped \
ASTM G173-03 extraterrestrial sun with a 0.533 degree disk.\n\nExamples:\n  sky render atmospheres/clear.toml --camera fisheye --size 256x256 \
--sun-zenith-deg 80 --spp 64 --out sky.exr --png sky.png\n  sky render atmospheres/hazed.toml --camera directions --directions dirs.csv \
--sun-zenith-deg 60 --spectral-nm 450,550,650 --spp 1000 --json")]
pub struct RenderArgs {
    /// Atmosphere TOML file
    atmosphere: PathBuf,
    /// Camera model
    #[arg(long, value_enum, default_value = "fisheye")]
    camera: CameraKind,
    /// Image size WIDTHxHEIGHT
    #[arg(long, default_value = "128x128", value_parser = parse_size)]
    size: (usize, usize),
    /// Sun zenith angle in degrees (90 is the horizon; up to 120)
    #[arg(long, allow_hyphen_values = true)]
    sun_zenith_deg: f64,
    /// Sun azimuth in degrees (0 = +x, 90 = +y)
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    sun_azimuth_deg: f64,
    /// Observer altitude above the ground in metres
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    altitude_m: f64,
    /// Samples per pixel (with --max-rel-error: the most a pixel may take)
    #[arg(long, default_value_t = 64)]
    spp: u32,
    /// Adaptive sampling: each pixel takes as many samples as a 32-sample pilot says it needs for this relative standard error of Y, at most --spp (the pilot's samples are then set aside, so stopping does not bias the mean)
    #[arg(long)]
    max_rel_error: Option<f64>,
    /// Random seed; a pixel's samples depend only on (seed, pixel, sample)
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output OpenEXR file
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also write spectral radiance channels at these wavelengths (nm)
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    spectral_nm: Vec<f64>,
    /// Only the spectral channels of --spectral-nm, without the X, Y, Z estimate (validation against spectral references need not pay for colour)
    #[arg(long, requires = "spectral_nm")]
    no_xyz: bool,
    /// Also write a tonemapped PNG
    #[arg(long)]
    png: Option<PathBuf>,
    /// Exposure adjustment of the PNG in stops
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    exposure_ev: f64,
    /// Machine-readable summary (with --camera directions: per-direction radiances)
    #[arg(long)]
    json: bool,
    /// Directions CSV for --camera directions (columns zenith_deg,azimuth_deg)
    #[arg(long)]
    directions: Option<PathBuf>,
    /// Pinhole: view azimuth, degrees
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    look_azimuth_deg: f64,
    /// Pinhole: view elevation above the horizon, degrees
    #[arg(long, default_value_t = 10.0, allow_hyphen_values = true)]
    look_elevation_deg: f64,
    /// Pinhole: horizontal field of view, degrees
    #[arg(long, default_value_t = 60.0)]
    fov_deg: f64,
    /// Width of the spectral bands in nm
    #[arg(long, default_value_t = 5.0)]
    band_nm: f64,
    /// How samples pick their wavelength bands (hero: four bands per path, the least colour noise per second; see `sky bench spectral`)
    #[arg(long, value_enum, default_value = "hero")]
    wavelength_sampling: Sampling,
    /// Worker threads (default: all cores)
    #[arg(long)]
    threads: Option<usize>,
    /// Denoise X, Y, Z with the standard-error-aware filter (the noisy image is kept in noisy.X/Y/Z)
    #[arg(long)]
    denoise: bool,
    /// Hide the sun's disk from camera rays (diffuse sky only)
    #[arg(long)]
    hide_sun_disk: bool,
    /// With --camera lut: the sun zenith angle beyond which the slice switches to latitude-longitude (default: where the sun-centred mapping's texels break down at this --size; the talk leaves it open)
    #[arg(long, value_name = "DEG")]
    lut_threshold_deg: Option<f64>,
    /// The naive estimator (analog tracking, no next-event estimation), for comparisons
    #[arg(long, hide = true)]
    naive: bool,
    /// How sunlight scattered once is estimated: by deterministic quadrature along each pixel's ray (no noise; the lut and directions cameras, whose pixels are single directions) or by the path tracer (always for the jittered cameras)
    #[arg(long, value_enum, default_value = "quadrature")]
    single_scatter: SingleArg,
    /// Render the talk's global fog instead of the sky: the light the air scatters toward the camera in front of a black object at this distance (`inf`: none; the ground, where a ray meets it first, is black too); the sun's disk is never seen
    #[arg(long, value_name = "KM")]
    fog_distance_km: Option<f64>,
    /// With --fog-distance-km: only the air below this altitude (the cloud base) scatters toward the camera
    #[arg(long, value_name = "KM", requires = "fog_distance_km")]
    fog_ceiling_km: Option<f64>,
    /// With --fog-distance-km: the Shadowed Fog, without the sunlight scattered once toward the camera
    #[arg(long, requires = "fog_distance_km")]
    shadowed_fog: bool,
    /// How the light is computed: monte-carlo (the path tracer) or deterministic (the transport solver, no noise; --spp, --seed and --max-rel-error do not apply)
    #[arg(long, value_enum, default_value = "monte-carlo")]
    method: Method,
    /// Discrete-ordinate streams a hemisphere for --method deterministic: 16 agree with DISORT within 0.05 % in the Rayleigh and HG test slabs; Mie aerosols and cloud layers want 32
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(2..=128))]
    streams: u32,
    #[command(flatten)]
    farm: super::farm_args::FarmArgs,
    /// Render this fraction of the columns a second time on another worker and compare bit for bit
    #[arg(long, value_name = "F", help_heading = "Farm")]
    verify_fraction: Option<f64>,
    /// Seconds a worker may stay silent (no heartbeat) before its task is re-queued [default: 20]
    #[arg(long, value_name = "S", help_heading = "Farm")]
    lease_s: Option<f64>,
    /// Continue an interrupted render from OUT.exr.journal (renders only the missing columns)
    #[arg(long, help_heading = "Farm")]
    resume: bool,
    /// Progress as JSON lines on stdout, one a second, then a summary line (for pipelines)
    #[arg(long, help_heading = "Farm")]
    json_progress: bool,
    /// Fault injection for the farm's tests: SIGKILL this coordinator once N columns are journaled
    #[arg(long, hide = true)]
    fault_kill_after_columns: Option<u32>,
}

pub(super) fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("`{s}`: expected WIDTHxHEIGHT, e.g. 256x128"))?;
    let w: usize = w.trim().parse().map_err(|_| format!("`{s}`: bad width"))?;
    let h: usize = h.trim().parse().map_err(|_| format!("`{s}`: bad height"))?;
    if w == 0 || h == 0 || w * h > 1 << 26 {
        return Err(format!("`{s}`: width and height must be positive and the image at most 64 Mpixel"));
    }
    Ok((w, h))
}

fn read_directions(path: &std::path::Path) -> Result<Vec<(f64, f64)>> {
    let t = Table::read(path).map_err(anyhow::Error::new)?;
    let z = t.column("zenith_deg").map_err(anyhow::Error::new)?;
    let a = t.column("azimuth_deg").map_err(anyhow::Error::new)?;
    Ok(z.iter().copied().zip(a.iter().copied()).collect())
}

/// The checked flags and what they name: the "high args" a render runs from.
struct Checked {
    camera: Camera,
    width: usize,
    height: usize,
    /// The farm's workers and options (`None`: the embedded worker alone).
    plan: Option<(Vec<WorkerSpec>, Options)>,
    outputs: Outputs,
}

pub fn run(a: RenderArgs) -> Result<ExitCode> {
    let Checked { camera, width, height, plan, outputs } = check(&a)?;
    let (atm, bundle) = match Atmosphere::load_bundle(&a.atmosphere) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("{e}");
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    };
    let settings = settings(&a, camera, width, height);
    if let (Some(_), Err(e)) = (settings.view.fog, settings.view.check()) {
        return usage(e);
    }
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        let _ = ctrlc::set_handler(move || c.store(true, Ordering::SeqCst));
    }
    let threads = a
        .threads
        .filter(|&t| t > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1));
    if a.method == Method::Deterministic {
        if let Err(e) = sky::transport::render::check_for_users(atm.planet.geometry, &settings.view) {
            return usage(format!("--method deterministic: {e}"));
        }
        return run_deterministic(&a, &outputs, threads, (atm, bundle), &settings);
    }
    let start = Instant::now();
    let (farm, style, view) = farm_options(&a, plan, threads);
    let session = prepare_session(threads, atm, bundle, &settings, farm, style, start)?;
    let atm = &session.atmosphere;
    let prep_s = start.elapsed().as_secs_f64();
    let job = session.job(&settings.view);
    // The journal next to the output: every accepted column, synced.
    let (journal, resumed) = open_journal(&a, &job, width, height)?;
    let journal_path = journal.as_ref().map(|j| j.path().to_path_buf());
    let t0 = Instant::now();
    let outcome = session.render(job.clone(), resumed, journal, cancel.clone());
    view.finish();
    let rendered = match outcome {
        Ok(r) => r,
        Err(FarmError::Cancelled) => {
            match &journal_path {
                Some(j) => eprintln!(
                    "sky render: cancelled; no image was written ({} keeps the finished columns: --resume continues)",
                    j.display()
                ),
                None => eprintln!("sky render: cancelled; nothing was written"),
            }
            return Ok(ExitCode::from(130));
        }
        Err(e) => {
            eprintln!("sky render: {e}");
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    };
    super::render_output::finish(&outputs, &settings, atm, rendered, prep_s, t0, journal_path)
}

/// `--method deterministic`: the transport solver on the local cores; no
/// farm, no journal, the same outputs.
fn run_deterministic(
    a: &RenderArgs,
    outputs: &Outputs,
    threads: usize,
    (atm, bundle): (Atmosphere, Bundle),
    settings: &Settings,
) -> Result<ExitCode> {
    let start = Instant::now();
    let style = super::progress::Style::choose(a.json_progress);
    let local = (vec![WorkerSpec::Local { threads }], Options::default());
    let session = prepare_session(threads, atm, bundle, settings, local, style, start)?;
    let prep_s = start.elapsed().as_secs_f64();
    let resolution = sky::transport::render::Resolution { streams: a.streams as usize, ..Default::default() };
    let steps = sky::transport::render::wavelengths_solved(&session.scene, &resolution);
    let bar = ProgressBar::new(steps as u64);
    bar.set_style(
        ProgressStyle::with_template("solving [{bar:30}] {pos}/{len} wavelengths, eta {eta}")
            .unwrap()
            .progress_chars("=> "),
    );
    if style == super::progress::Style::Lines {
        eprintln!("sky render: solving the transport at {steps} wavelengths ({} streams a hemisphere)", a.streams);
    }
    let t0 = Instant::now();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let image = pool
        .install(|| sky::transport::render::render(&session.scene, &settings.view, &resolution, &|| bar.inc(1)))
        .map_err(|e| super::UsageError(format!("--method deterministic: {e}")))?;
    bar.finish_and_clear();
    let rendered = sky::session::Rendered { image, stats: Default::default() };
    super::render_output::finish(outputs, settings, &session.atmosphere, rendered, prep_s, t0, None)
}

/// Checks the flags (in the order the command always has, so that the same
/// mistake gets the same message) and works out the camera and the farm plan.
fn check(a: &RenderArgs) -> Result<Checked> {
    check_flags(a)?;
    let (camera, (width, height)) = camera(a)?;
    if let Some(v) = a.verify_fraction {
        if !(0.0..=1.0).contains(&v) {
            return usage(format!("--verify-fraction must be between 0 and 1, got {v}"));
        }
    }
    if let Some(l) = a.lease_s {
        if !(l > 0.0 && l.is_finite()) {
            return usage(format!("--lease-s must be a positive number of seconds, got {l}"));
        }
    }
    if a.method == Method::Deterministic {
        let farm = !a.farm.workers.is_empty() || a.farm.farm.is_some();
        if farm || a.resume || a.denoise {
            return usage("--method deterministic renders on the local cores in one go: no --workers, --farm, --resume or --denoise");
        }
    }
    if a.resume && a.out.is_none() {
        return usage("--resume continues OUT.exr.journal and needs --out");
    }
    let plan = super::farm_args::farm_plan(&a.farm)?;
    let outputs = Outputs {
        out: a.out.clone(),
        png: a.png.clone(),
        exposure_ev: a.exposure_ev,
        json: a.json,
        json_progress: a.json_progress,
        denoise: a.denoise,
        method: match a.method {
            Method::MonteCarlo => "monte-carlo".to_string(),
            Method::Deterministic => format!("deterministic ({} streams a hemisphere)", a.streams),
        },
    };
    Ok(Checked { camera, width, height, plan, outputs })
}

/// The flags' own ranges and combinations.
fn check_flags(a: &RenderArgs) -> Result<()> {
    super::faults_allowed(a.fault_kill_after_columns.is_some())?;
    if let Some(e) = a.max_rel_error {
        if !(e > 0.0 && e < 1.0) {
            return usage(format!("--max-rel-error must be between 0 and 1, got {e}"));
        }
    }
    if !(0.0..=120.0).contains(&a.sun_zenith_deg) {
        return usage(format!("--sun-zenith-deg must be between 0 and 120, got {}", a.sun_zenith_deg));
    }
    if !(a.altitude_m >= 0.0 && a.altitude_m.is_finite()) {
        return usage(format!("--altitude-m must be at least 0, got {}", a.altitude_m));
    }
    if a.spp == 0 {
        return usage("--spp must be at least 1");
    }
    if !(a.band_nm >= 1.0 && a.band_nm <= 470.0) {
        return usage(format!("--band-nm must be between 1 and 470, got {}", a.band_nm));
    }
    if let Some(l) = a.spectral_nm.iter().find(|l| !(360.0..=830.0).contains(*l)) {
        return usage(format!("--spectral-nm: {l} is outside 360 to 830 nm"));
    }
    if a.no_xyz && (a.png.is_some() || a.denoise) {
        return usage("--no-xyz renders spectral channels only: --png and --denoise need X, Y, Z");
    }
    if !(a.fov_deg > 0.0 && a.fov_deg < 179.0) {
        return usage(format!("--fov-deg must be between 0 and 179, got {}", a.fov_deg));
    }
    if a.out.is_none() && !a.json {
        return usage("give --out FILE.exr (or --json)");
    }
    if let Some(o) = &a.out {
        if o.extension().is_none_or(|e| e != "exr") {
            return usage(format!("--out {}: the output is OpenEXR and must end in .exr", o.display()));
        }
    }
    Ok(())
}

/// The camera of --camera and its image size (a --directions file's rows
/// make one row of pixels).
fn camera(a: &RenderArgs) -> Result<(Camera, (usize, usize))> {
    Ok(match a.camera {
        CameraKind::Equirect => (Camera::Equirect, a.size),
        CameraKind::Fisheye => (Camera::Fisheye, a.size),
        CameraKind::Pinhole => (
            Camera::Pinhole {
                azimuth_deg: a.look_azimuth_deg,
                elevation_deg: a.look_elevation_deg,
                fov_deg: a.fov_deg,
            },
            a.size,
        ),
        CameraKind::Lut => {
            let (w, h) = a.size;
            let threshold_deg = match a.lut_threshold_deg {
                Some(t) if (0.0..=90.0).contains(&t) => t,
                Some(t) => return usage(format!("--lut-threshold-deg must be between 0 and 90, got {t}")),
                None => sky::directions::mapping::default_threshold_deg(w, h),
            };
            let mapping = sky::directions::mapping::DirectionMapping::new(a.sun_zenith_deg, threshold_deg);
            (Camera::Lut { mapping, sun_azimuth_deg: a.sun_azimuth_deg }, a.size)
        }
        CameraKind::Directions => {
            let Some(f) = &a.directions else { return usage("--camera directions needs --directions FILE.csv") };
            let list = read_directions(f).with_context(|| format!("--directions {}", f.display()))?;
            let n = list.len();
            (Camera::Directions(list), (n, 1))
        }
    })
}

/// The render's settings from the checked flags.
fn settings(a: &RenderArgs, camera: Camera, width: usize, height: usize) -> Settings {
    Settings {
        spectral: SpectralSettings {
            spectral_nm: a.spectral_nm.clone(),
            xyz: !a.no_xyz,
            band_nm: a.band_nm,
            wavelength_sampling: match a.wavelength_sampling {
                Sampling::Luminance => WavelengthSampling::Luminance,
                Sampling::Tristimulus => WavelengthSampling::Tristimulus,
                Sampling::Hero => WavelengthSampling::Hero,
            },
        },
        view: View {
            camera,
            width,
            height,
            sun_zenith_deg: a.sun_zenith_deg,
            sun_azimuth_deg: a.sun_azimuth_deg,
            altitude_m: a.altitude_m,
            spp: a.spp,
            seed: a.seed,
            estimator: if a.naive { Estimator::Naive } else { Estimator::Full },
            sun_disk: !a.hide_sun_disk,
            max_rel_error: a.max_rel_error,
            single_scatter: match a.single_scatter {
                SingleArg::Quadrature => SingleScatter::Quadrature,
                SingleArg::MonteCarlo => SingleScatter::MonteCarlo,
            },
            fog: a.fog_distance_km.map(|d| Fog {
                max_distance_km: d,
                ceiling_km: a.fog_ceiling_km,
                shadowed: a.shadowed_fog,
            }),
        },
    }
}

/// The farm's workers and options (the embedded worker on `threads` cores
/// without a farm plan), with the progress view listening to its events.
fn farm_options(
    a: &RenderArgs,
    plan: Option<(Vec<WorkerSpec>, Options)>,
    threads: usize,
) -> ((Vec<WorkerSpec>, Options), super::progress::Style, super::progress::View) {
    let (workers, mut opts) = match plan {
        Some((w, o)) => (w, o),
        None => (vec![WorkerSpec::Local { threads }], Options::default()),
    };
    if let Some(v) = a.verify_fraction {
        opts.verify_fraction = v;
    }
    if let Some(l) = a.lease_s {
        opts.lease = std::time::Duration::from_secs_f64(l);
    }
    let style = super::progress::Style::choose(a.json_progress);
    let view = super::progress::View::new(style);
    opts.events = Some(view.sink.clone());
    opts.faults.kill_after_columns = a.fault_kill_after_columns;
    ((workers, opts), style, view)
}

/// The session: the optics prepared once; a farm job carries them, so
/// every worker renders with the same numbers whatever its maths library.
fn prepare_session(
    threads: usize,
    atm: Atmosphere,
    bundle: Bundle,
    settings: &Settings,
    (workers, opts): (Vec<WorkerSpec>, Options),
    style: super::progress::Style,
    start: Instant,
) -> Result<Session> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let cache = MieCache::from_env();
    let steps = Scene::steps(&atm, &settings.spectral);
    let prep = ProgressBar::new(steps as u64);
    prep.set_style(
        ProgressStyle::with_template("optics [{bar:30}] {pos}/{len} wavelengths, eta {eta}")
            .unwrap()
            .progress_chars("=> "),
    );
    if style == super::progress::Style::Lines {
        eprintln!("sky render: preparing the optics at {steps} wavelengths");
    }
    let optics = OpticsCache::default();
    let s = pool.install(|| {
        Session::new(atm, bundle, settings.spectral.clone(), &optics, &cache, workers, opts, &|| prep.inc(1))
    });
    prep.finish_and_clear();
    if style == super::progress::Style::Lines {
        eprintln!("sky render: optics prepared in {:.1} s", start.elapsed().as_secs_f64());
    }
    Ok(s)
}

/// The journal next to --out, created or (with --resume) continued, and
/// the columns it already holds.
fn open_journal(
    a: &RenderArgs,
    job: &FarmJob,
    width: usize,
    height: usize,
) -> Result<(Option<journal::Journal>, BTreeMap<u32, Tile>)> {
    Ok(match &a.out {
        None => (None, BTreeMap::new()),
        Some(o) => {
            let jp = journal::path_for(o);
            let header = journal::Header { job_hash: job.hash.clone(), width: width as u32, height: height as u32 };
            if a.resume && jp.exists() {
                let (j, cols) = journal::Journal::resume(&jp, &header)?;
                if !a.json_progress {
                    eprintln!(
                        "sky render: resuming {}: {} of {width} columns already rendered",
                        jp.display(),
                        cols.len()
                    );
                }
                (Some(j), cols)
            } else {
                if a.resume {
                    eprintln!("sky render: --resume: there is no {}; rendering from the start", jp.display());
                } else if jp.exists() {
                    eprintln!(
                        "sky render: replacing {} from an earlier run (use --resume to continue it)",
                        jp.display()
                    );
                }
                (Some(journal::Journal::create(&jp, &header)?), BTreeMap::new())
            }
        }
    })
}
