//! `sky bake-luts`: argument handling and the display of the bake's events;
//! the bake itself is `sky::bake`.

use super::farm_args::{farm_plan, FarmArgs};
use super::progress::{fmt_duration, Style};
use super::{usage, EXIT_INVALID};
use anyhow::Result;
use indicatif::{ProgressBar, ProgressStyle};
use sky::bake::{self, BakeEvent, BakeFile, BakeOptions, BakeSink, Quality, SliceCache, SliceId};
use sky::colour::ColourSpace;
use sky::farm::coordinator::{Options, WorkerSpec};
use sky::lut::container::{Container, Encoding, TextureFormat};
use sky::mie::MieCache;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  sky bake-luts bakes/basis-skies.toml --out luts/ --quality draft\n  sky bake-luts bakes/basis-skies.toml --out luts/ --quality final --farm farm/farm.toml\n  sky bake-luts bakes/basis-skies.toml --out job/ --plan openjd    # a job for AWS Deadline Cloud or `openjd run`\n\nA re-run with nothing changed renders nothing: rendered slices are kept in a content-addressed cache (--cache, default OUT/cache), so a bake that was stopped resumes where it stopped."
)]
pub struct BakeArgs {
    /// The bake file: basis skies, atmosphere files, slice sizes, quality presets
    #[arg(value_name = "BAKE.toml")]
    bake: PathBuf,
    /// Output folder for the LUT files and manifest.json
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Quality preset of the bake file
    #[arg(long, value_enum, default_value = "draft")]
    quality: QualityArg,
    /// How the sky and fog slices' light is computed: deterministic (the transport solver: no noise; the slices of a basis sky share one solution, on this machine's cores; a draft costs minutes, see docs/bakes.md "The method") or monte-carlo (the path tracer, the talk's way and the referee: noise that the samples bring down; on the embedded worker or the farm). The fog LUTs and their depth falloff's references come from the same method
    #[arg(long, value_enum, default_value = "deterministic")]
    method: MethodArg,
    /// Linear RGB space of the textures: rec709, rec2020, acescg or xyz (the manifest records its matrix)
    #[arg(long, default_value = "rec709", value_parser = parse_colour_space)]
    colour_space: ColourSpace,
    /// Texel format of the basis skies' arrays: r11g11b10 (4 bytes, the talk's; Bevy and Vulkan/Direct3D engines load it) or rgba16f (8 bytes, for Godot 4 and Unreal 5, which cannot import R11G11B10 arrays; docs/manifest.md "Engines"). The fog, transmittance and ambient files are RGBA16F either way
    #[arg(long, default_value = "r11g11b10", value_name = "FORMAT", value_parser = parse_texture_format)]
    texture_format: TextureFormat,
    /// Container of every texture file: ktx2 (KTX 2.0, the default, with each file's manifest entry inside) or dds (DDS with the DX10 header, for engines and tools that take DDS)
    #[arg(long, default_value = "ktx2", value_name = "CONTAINER", value_parser = parse_container)]
    container: Container,
    /// The slice cache (default: OUT/cache)
    #[arg(long, value_name = "DIR")]
    cache: Option<PathBuf>,
    /// Only these slices, NAME:INDEX or a fog slice NAME:fog:INDEX (repeatable or comma-separated), into the cache; nothing is packed
    #[arg(long, value_delimiter = ',', value_name = "NAME:INDEX")]
    slice: Vec<SliceId>,
    /// Pack the cached slices only: render no slice (the fog falloff's few reference renders excepted), and fail naming the slices the cache lacks
    #[arg(long, conflicts_with = "slice")]
    pack_only: bool,
    /// Write a job for a farm manager instead of baking: `openjd` writes OUT/bake.openjd.yaml (Open Job Description), a task per slice and a pack step
    #[arg(long, value_enum, value_name = "FORMAT", conflicts_with_all = ["slice", "pack_only", "json_progress"])]
    plan: Option<PlanFormat>,
    /// With --plan: the sky command the farm's hosts run (default: this program's absolute path)
    #[arg(long, value_name = "COMMAND", requires = "plan")]
    sky_executable: Option<String>,
    /// Threads of the embedded worker (default: all cores)
    #[arg(long)]
    threads: Option<usize>,
    /// Print a JSON summary on stdout (files, sizes, per-slice cost, errors)
    #[arg(long)]
    json: bool,
    /// Progress as JSON lines on stdout instead of a bar or lines on stderr
    #[arg(long)]
    json_progress: bool,
    #[command(flatten)]
    farm: FarmArgs,
}

impl BakeArgs {
    fn encoding(&self) -> Encoding {
        Encoding { texture_format: self.texture_format, container: self.container }
    }
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum PlanFormat {
    /// An Open Job Description job template (AWS Deadline Cloud; `openjd` runs it locally)
    Openjd,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub(super) enum MethodArg {
    Deterministic,
    MonteCarlo,
}

impl MethodArg {
    pub(super) fn method(self) -> bake::Method {
        match self {
            MethodArg::Deterministic => bake::Method::Deterministic,
            MethodArg::MonteCarlo => bake::Method::MonteCarlo,
        }
    }
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum QualityArg {
    Draft,
    Final,
}

/// Seconds between plain progress lines.
const LINE_PERIOD: Duration = Duration::from_secs(5);

/// Turns bake events into a bar (terminal), plain lines (a log) or JSON lines.
fn sink(style: Style, bar: Arc<Mutex<Option<ProgressBar>>>) -> BakeSink {
    let last_line: Mutex<Option<Instant>> = Mutex::new(None);
    BakeSink::new(move |e| {
        // Whether a plain line is due (LINE_PERIOD since the last, or
        // `now`), counting it as printed if so.
        let line_due = |now: bool| {
            let mut last = last_line.lock().unwrap();
            let due = now || last.is_none_or(|t| t.elapsed() >= LINE_PERIOD);
            if due {
                *last = Some(Instant::now());
            }
            due
        };
        if style == Style::Json {
            if let Ok(s) = serde_json::to_string(e) {
                outln!("{s}");
            }
            return;
        }
        let say = |text: String| match bar.lock().unwrap().as_ref() {
            Some(b) => b.println(text),
            None => eprintln!("{text}"),
        };
        match e {
            BakeEvent::Planned { skies, slices_total, slices_cached, fog_slices, texels_to_render } => {
                say(format!(
                    "sky bake-luts: {skies} basis skies, {slices_total} slices ({fog_slices} of them fog slices to render), {slices_cached} in the cache, {texels_to_render} texels to render"
                ));
                if style == Style::Bars && *texels_to_render > 0 {
                    let b = ProgressBar::new(*texels_to_render);
                    b.set_style(
                        ProgressStyle::with_template("{bar:40} {percent:>3}% {pos}/{len} texels  {msg}").unwrap(),
                    );
                    *bar.lock().unwrap() = Some(b);
                }
            }
            BakeEvent::Preparing { sky } => {
                if style == Style::Lines {
                    eprintln!("sky bake-luts: {sky}: preparing the optics");
                }
            }
            BakeEvent::Forecast { from, core_seconds, samples, planning_core_seconds, saved } => {
                let saved = if *saved > 0 {
                    format!("; {saved} of them saved in the cache folder by an earlier run")
                } else {
                    String::new()
                };
                // The solver's pilots forecast no samples.
                let samples = if *samples > 0 { format!("{samples} samples, ") } else { String::new() };
                say(format!("sky bake-luts: the {from} forecast {samples}{:.3} core-hours ({:.3} core-hours spent on them{saved})", core_seconds / 3600.0, planning_core_seconds / 3600.0));
            }
            BakeEvent::Planning { from, sky, index, fog, done, total, elapsed_s, eta_s, .. } => {
                let what = format!(
                    "planning: {from} {done}/{total} ({sky}:{}{index}), ETA {}",
                    if *fog { "fog:" } else { "" },
                    fmt_duration(*eta_s)
                );
                match style {
                    Style::Bars => {
                        if let Some(b) = bar.lock().unwrap().as_ref() {
                            b.set_message(what);
                        }
                    }
                    _ => {
                        if line_due(done == total) {
                            eprintln!("sky bake-luts: {what}, elapsed {}", fmt_duration(*elapsed_s));
                        }
                    }
                }
            }
            BakeEvent::Slice { .. } => {}
            BakeEvent::SkyDone { sky, slices_rendered, slices_cached, core_seconds } => {
                say(format!(
                    "sky bake-luts: {sky}: {slices_rendered} slices rendered ({:.1} core-s, {:.2} core-s per slice), {slices_cached} from the cache",
                    core_seconds,
                    core_seconds / (*slices_rendered).max(1) as f64
                ));
            }
            BakeEvent::Progress(p) => {
                let eta = p.eta_s.map_or("unknown".to_string(), fmt_duration);
                let msg = match &p.stalled {
                    Some(why) => format!("waiting: {why}"),
                    None => format!("{}:{}  ETA {eta}", p.sky, p.index),
                };
                match style {
                    Style::Bars => {
                        if let Some(b) = bar.lock().unwrap().as_ref() {
                            b.set_position(p.texels_done);
                            b.set_message(msg);
                        }
                    }
                    _ => {
                        if line_due(false) {
                            let pct = 100.0 * p.texels_done as f64 / p.texels_total.max(1) as f64;
                            eprintln!(
                                "sky bake-luts: {pct:.0} % ({}/{} texels, {}/{} slices), elapsed {}, {msg}",
                                p.texels_done,
                                p.texels_total,
                                p.slices_done,
                                p.slices_total,
                                fmt_duration(p.elapsed_s)
                            );
                        }
                    }
                }
            }
            BakeEvent::FogSlice { sky, done, total } => {
                if style == Style::Lines {
                    if line_due(false) {
                        eprintln!("sky bake-luts: {sky}: fog slice {done}/{total}");
                    }
                } else if let Some(b) = bar.lock().unwrap().as_ref() {
                    b.set_message(format!("{sky}: fog {done}/{total}"));
                }
            }
            BakeEvent::FogDone {
                sky,
                slices_rendered,
                slices_cached,
                core_seconds,
                falloff_a,
                falloff_p,
                fit_median,
                fit_p99,
            } => {
                say(format!(
                    "sky bake-luts: {sky}: fog and shadowed fog: {slices_rendered} slices rendered ({core_seconds:.1} core-s), {slices_cached} from the cache; falloff a = {falloff_a:.3}, p = {falloff_p:.3} (fit error median {:.1} %, p99 {:.1} %)",
                    100.0 * fit_median,
                    100.0 * fit_p99
                ));
            }
            BakeEvent::Farm { sky, index, farm } => {
                say(format!("sky bake-luts: {sky}:{index}: {}", serde_json::to_string(farm).unwrap_or_default()))
            }
        }
    })
}

fn parse_texture_format(s: &str) -> Result<TextureFormat, String> {
    s.parse()
}

fn parse_container(s: &str) -> Result<Container, String> {
    s.parse()
}

/// `--colour-space`: one of [`ColourSpace::ALL`] by its name.
fn parse_colour_space(s: &str) -> Result<ColourSpace, String> {
    s.parse().map_err(|e: sky::colour::UnknownColourSpace| e.to_string())
}

/// The bake file at `path`, or None after printing its located errors
/// (the caller exits with [`EXIT_INVALID`]).
pub(super) fn load_bake(path: &std::path::Path) -> Option<BakeFile> {
    BakeFile::load(path).map_err(|e| eprintln!("{e}")).ok()
}

pub fn run(a: BakeArgs) -> Result<ExitCode> {
    if a.threads == Some(0) {
        return usage("--threads must be at least 1");
    }
    let Some(bake) = load_bake(&a.bake) else { return Ok(ExitCode::from(EXIT_INVALID)) };
    let quality = match a.quality {
        QualityArg::Draft => Quality::Draft,
        QualityArg::Final => Quality::Final,
    };
    if let Some(PlanFormat::Openjd) = a.plan {
        return write_openjd_plan(&a, &bake, quality);
    }
    let threads = a.threads.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1));
    let (workers, farm) = match farm_plan(&a.farm)? {
        Some(plan) => plan,
        None => (vec![WorkerSpec::Local { threads }], Options::default()),
    };
    let cores =
        workers.iter().map(|w| if let WorkerSpec::Local { threads } = w { *threads } else { 0 }).sum::<usize>().max(1);
    let cache_dir = a.cache.clone().unwrap_or_else(|| a.out.join("cache"));
    let cache = match SliceCache::open(&cache_dir) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("sky bake-luts: {e}");
            return Ok(ExitCode::from(EXIT_INVALID));
        }
    };
    let style = Style::choose(a.json_progress);
    let bar = Arc::new(Mutex::new(None));
    let opts = BakeOptions {
        quality,
        method: a.method.method(),
        cache,
        workers,
        farm,
        cores,
        only: (!a.slice.is_empty()).then(|| a.slice.clone()),
        pack_only: a.pack_only,
        events: Some(sink(style, bar.clone())),
    };
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        let _ = ctrlc::set_handler(move || c.store(true, Ordering::SeqCst));
    }
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let started = Instant::now();
    let result = pool.install(|| bake::render_slices(&bake, &opts, &MieCache::from_env(), cancel));
    if let Some(b) = bar.lock().unwrap().take() {
        b.finish_and_clear();
    }
    let skies = match result {
        Ok(s) => s,
        Err(e) if e.is_cancelled() => {
            eprintln!(
                "sky bake-luts: cancelled; nothing was packed. The finished slices are in the cache {} and the columns of the basis sky being rendered in its journal there: the same command resumes",
                opts.cache.dir().display()
            );
            return Ok(ExitCode::from(130));
        }
        Err(e) => return failed(a.json, quality, &e),
    };
    let rendered = report_rendered(&skies, started);
    if !a.slice.is_empty() {
        // A part of a bake (a farm manager's task) fills the cache only.
        if a.json {
            let slices: Vec<_> = skies
                .iter()
                .flat_map(|s| s.slices.iter().enumerate().filter_map(move |(i, r)| r.as_ref().map(|r| (s, i, r))))
                .map(|(s, i, r)| slice_json(format!("{}:{i}", s.sky.name), r))
                .chain(skies.iter().flat_map(|s| {
                    s.fog_rendered.iter().map(move |(i, r)| slice_json(format!("{}:fog:{i}", s.sky.name), r))
                }))
                .collect();
            outln!("{}", serde_json::json!({ "slices": slices, "rendered": rendered, "cache": opts.cache.dir() }));
        }
        return Ok(ExitCode::SUCCESS);
    }
    pack(&a, &skies, quality)
}

/// A failed bake: the error on stderr and, with --json, in the summary.
fn failed(json: bool, quality: Quality, e: &dyn std::fmt::Display) -> Result<ExitCode> {
    eprintln!("sky bake-luts: {e}");
    if json {
        outln!("{}", serde_json::json!({ "manifest": null, "quality": quality.name(), "errors": [e.to_string()] }));
    }
    Ok(ExitCode::from(EXIT_INVALID))
}

/// Says on stderr how many slices were rendered and what they cost;
/// returns how many.
fn report_rendered(skies: &[bake::SkySlices], started: Instant) -> usize {
    // The sky's slices and the fog's, rendered now (a whole bake's fog, or
    // the fog slices a part of a bake names).
    let rendered: usize =
        skies.iter().map(|s| s.rendered + s.fog.as_ref().map_or(0, |f| f.rendered) + s.fog_rendered.len()).sum();
    let fog_core_s: f64 = skies
        .iter()
        .map(|s| {
            s.fog.as_ref().map_or(0.0, |f| f.core_seconds)
                + s.fog_rendered.iter().map(|(_, f)| f.core_seconds).sum::<f64>()
        })
        .sum();
    // (+ 0.0: an empty sum is −0.0, which would print as "-0.000")
    let core_s: f64 =
        skies.iter().flat_map(|s| s.slices.iter().flatten()).map(|s| s.core_seconds).sum::<f64>() + fog_core_s + 0.0;
    eprintln!(
        "sky bake-luts: {rendered} slices rendered in {:.1} s; the slices cost {:.3} core-hours when rendered",
        started.elapsed().as_secs_f64(),
        core_s / 3600.0
    );
    rendered
}

/// Packs the rendered skies into the LUT files and manifest.json in --out,
/// and reports them (on stderr; with --json, the summary on stdout).
fn pack(a: &BakeArgs, skies: &[bake::SkySlices], quality: Quality) -> Result<ExitCode> {
    let (manifest, stats) = match bake::pack::write_bake(
        skies,
        (quality.name(), a.method.method()),
        (a.colour_space, a.encoding()),
        &a.out,
    ) {
        Ok(m) => m,
        Err(e) => return failed(a.json, quality, &e),
    };
    let total_bytes: u64 = manifest.skies.iter().map(|s| s.bytes).sum();
    for (e, st) in manifest.skies.iter().zip(&stats) {
        eprintln!(
            "sky bake-luts: {:<8} {} ({} bytes, {}x{}x{}), {} texels clamped, {} denormal, {} with negative RGB",
            e.name,
            e.file,
            e.bytes,
            e.width,
            e.height,
            e.layers,
            st.clamped_texels,
            st.denormal_texels,
            e.texels_negative_rgb
        );
    }
    eprintln!(
        "sky bake-luts: {} files, {:.2} MiB, and {}",
        manifest.skies.len(),
        total_bytes as f64 / 1048576.0,
        a.out.join("manifest.json").display()
    );
    if let Some(f) = &manifest.fog {
        eprintln!(
            "sky bake-luts: global fog: {} ({} bytes, {}x{}x{}: Fog and Shadowed Fog of every sky) and {} ({} bytes, {}x{}x{})",
            f.file,
            f.bytes,
            f.width,
            f.height,
            f.layers,
            f.attenuation.file,
            f.attenuation.bytes,
            f.attenuation.width,
            f.attenuation.height,
            f.attenuation.layers.len()
        );
    }
    if a.json {
        let fog_json = manifest.fog.as_ref().map(|f| {
            let fogs: Vec<_> = skies
                .iter()
                .filter_map(|s| s.fog.as_ref().map(|g| (s, g)))
                .map(|(s, g)| {
                    serde_json::json!({ "name": s.sky.name, "slices_rendered": g.rendered, "slices_cached": g.cached, "core_seconds": g.core_seconds,
                        "falloff_a": g.extras.falloff.a, "falloff_p": g.extras.falloff.p, "falloff_error": g.extras.fit_error, "depth_free_error": g.extras.depth_free_error })
                })
                .collect();
            serde_json::json!({ "file": f.file, "bytes": f.bytes, "layers": f.layers, "attenuation_file": f.attenuation.file, "attenuation_bytes": f.attenuation.bytes, "skies": fogs })
        });
        let skies_json: Vec<_> = manifest
            .skies
            .iter()
            .zip(skies)
            .zip(&stats)
            .map(|((e, s), st)| {
                let cost: Vec<f64> = s.slices.iter().flatten().map(|x| x.core_seconds).collect();
                serde_json::json!({
                    "name": e.name, "file": e.file, "bytes": e.bytes, "width": e.width, "height": e.height, "layers": e.layers,
                    "slices_rendered": s.rendered, "slices_cached": s.cached, "columns_resumed": s.columns_resumed,
                    "core_seconds": cost.iter().sum::<f64>(), "core_seconds_per_slice": cost,
                    "texels_clamped": st.clamped_texels, "texels_denormal": st.denormal_texels, "texels_underflow": st.underflow_texels, "texels_negative_rgb": e.texels_negative_rgb,
                })
            })
            .collect();
        outln!(
            "{}",
            serde_json::json!({ "manifest": a.out.join("manifest.json"), "quality": quality.name(), "method": a.method.method().name(), "colour_space": a.colour_space.name(), "texture_format": a.texture_format.name(), "container": a.container.name(), "total_bytes": total_bytes, "skies": skies_json, "fog": fog_json, "errors": [] })
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// `--plan openjd`: the bake as an Open Job Description job template in
/// the output folder, its paths relative to it.
fn write_openjd_plan(a: &BakeArgs, bake: &BakeFile, quality: Quality) -> Result<ExitCode> {
    if a.farm.farm.is_some() || !a.farm.workers.is_empty() {
        return usage("--plan writes a job for another farm manager: it takes no --farm or --workers");
    }
    let fail = |what: String| -> Result<ExitCode> {
        eprintln!("sky bake-luts: {what}");
        Ok(ExitCode::from(EXIT_INVALID))
    };
    if let Err(e) = std::fs::create_dir_all(&a.out) {
        return fail(format!("cannot create {}: {e}", a.out.display()));
    }
    let canonical = |p: &std::path::Path| std::fs::canonicalize(p).map_err(|e| format!("{}: {e}", p.display()));
    let cache_dir = a.cache.clone().unwrap_or_else(|| a.out.join("cache"));
    if let Err(e) = std::fs::create_dir_all(&cache_dir) {
        return fail(format!("cannot create the cache {}: {e}", cache_dir.display()));
    }
    let (out, bake_path, cache) = match (canonical(&a.out), canonical(&a.bake), canonical(&cache_dir)) {
        (Ok(o), Ok(b), Ok(c)) => (o, b, c),
        (Err(e), _, _) | (_, Err(e), _) | (_, _, Err(e)) => return fail(e),
    };
    let within = |p: &std::path::Path| bake::openjd::default_within(&out, p);
    let sky_executable = match &a.sky_executable {
        Some(s) => s.clone(),
        None => match std::env::current_exe() {
            Ok(p) => p.to_string_lossy().into_owned(),
            Err(_) => "sky".to_string(),
        },
    };
    let defaults = bake::openjd::PlanDefaults {
        sky_executable,
        bake_file: within(&bake_path),
        out_dir: ".".into(),
        cache_dir: within(&cache),
        quality,
        method: a.method.method(),
        colour_space: a.colour_space,
        encoding: a.encoding(),
    };
    let stem = bake_path.file_stem().map_or("bake".into(), |s| s.to_string_lossy().into_owned());
    let text = bake::openjd::job_template(bake, &format!("sky bake-luts {stem}"), &defaults);
    let path = out.join(bake::openjd::TEMPLATE_FILE);
    if let Err(e) = sky::atomic::write_atomically(&path, text.as_bytes()) {
        return fail(format!("cannot write {}: {e}", path.display()));
    }
    // This machine's values of the path parameters, for `openjd run -p file://...`.
    let params = serde_json::json!({ "BakeFile": bake_path, "OutDir": out, "CacheDir": cache });
    let params_path = out.join(bake::openjd::PARAMS_FILE);
    if let Err(e) = sky::atomic::write_atomically(&params_path, format!("{params:#}\n").as_bytes()) {
        return fail(format!("cannot write {}: {e}", params_path.display()));
    }
    let tasks = bake::openjd::render_tasks(bake, a.method.method()).len();
    eprintln!("sky bake-luts: {} (Open Job Description): {tasks} render tasks, one per sky slice and one per fog slice, then a pack step", path.display());
    eprintln!("sky bake-luts: check it with `openjd check {}`; run it here with `openjd run {} -p file://{} --step Pack --run-dependencies`", path.display(), path.display(), params_path.display());
    if a.json {
        outln!(
            "{}",
            serde_json::json!({ "plan": "openjd", "template": path, "parameters": params_path, "render_tasks": tasks, "quality": quality.name(), "cache": cache })
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// A slice a part of a bake rendered, for its `--json` summary.
fn slice_json(slice: String, r: &bake::RenderedSlice) -> serde_json::Value {
    serde_json::json!({ "slice": slice, "sun_zenith_deg": r.sun_zenith_deg, "texels": r.width * r.height, "core_seconds": r.core_seconds, "mean_samples": r.mean_samples() })
}
