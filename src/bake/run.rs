//! Rendering a bake's slices: for every basis sky, its 64 sun elevations
//! (`directions::mapping::slice_sun_zenith_deg`) through the LUT camera with
//! the sun disk hidden, each slice taken from the cache when it is there and
//! rendered through a [`Session`](crate::session::Session) (optics prepared
//! once per basis sky) when it is not.
//!
//! A bake goes through three rooms, in this order:
//!
//! 1. [`plan`](super::plan): every slice's view and key, what the cache
//!    holds, the fog slices to render, the counts (nothing rendered);
//! 2. [`queue`](super::queue): the sessions, the forecast from pilots
//!    ([`forecast`](super::forecast)), then one queue of farm jobs for every
//!    basis sky: its strip of slices side by side
//!    ([`Camera::LutStrip`](crate::directions::Camera::LutStrip)) and its
//!    fog slices, on one farm (its workers greeted once, each sky's optics
//!    sent to each worker once), each job journaled in the cache folder so
//!    that a bake killed anywhere resumes from the columns it had;
//! 3. [`finish`](super::finish): each sky's slices into the cache, its
//!    lighting and its fog LUTs.
//!
//! The words they share (slice names, options, views, keys) are in
//! [`slices`](super::slices).

use super::finish::Finisher;
use super::forecast::{forecast, Forecasts};
use super::plan::{plan, Plan};
use super::queue::{prepare_sessions, render_queue, Rendered};
use super::solver::render_strips;
use super::tracker::{farm_options, Tracker};
use super::BakeError;
use super::BakeEvent;
use super::BakeFile;
use crate::mie::MieCache;
use crate::session::{OpticsCache, SharedFarm};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

pub(super) use super::plan::Planned;
pub(crate) use super::slices::slice_of_image;
pub use super::slices::{
    sky_slice_key, slice_view, spectral_settings, strip_view, BakeOptions, Method, SkySlices, SliceId, BAKE_SEED,
};

/// Renders (or finds in the cache) every slice the options ask for, basis
/// sky after basis sky.
pub fn render_slices(
    bake: &BakeFile,
    opts: &BakeOptions,
    mie: &MieCache,
    cancel: Arc<AtomicBool>,
) -> Result<Vec<SkySlices>, BakeError> {
    let plan = plan(bake, opts)?;
    let tracker = start_tracker(&plan, opts);
    let optics = OpticsCache::default();
    // One farm for the whole bake: its workers are greeted once and get
    // each basis sky's optics once.
    let farm = SharedFarm::new(opts.workers.clone(), farm_options(opts, &tracker));
    // Every basis sky's session first (optics prepared once), then, where
    // the quality samples adaptively, every slice's pilot: the forecast
    // behind the ETA, before the first slice is rendered.
    let sessions = prepare_sessions(&plan, &optics, mie, &farm, &tracker);
    let (forecasts, mut rendered) = match opts.method {
        Method::MonteCarlo => {
            let forecasts = forecast(&plan.skies, &plan.fog, &sessions, bake, (&opts.cache, &tracker), &cancel)?;
            let rendered = render_queue(&plan, &sessions, &forecasts, &farm, opts, &tracker, &cancel)?;
            (forecasts, rendered)
        }
        // The sky's slices and the fog's by the solver here, each sky's
        // in one render (no queue, no farm); the ETA from the pace of the
        // texels.
        Method::Deterministic => {
            let references = opts.only.is_none().then_some((&opts.cache, bake.fog.ceiling_km));
            let s = render_strips(&plan, &sessions, opts.quality, references, &tracker, &cancel)?;
            let mut forecasts = Forecasts::zero(&plan.skies);
            for (k, priced) in s.fog_after.iter().enumerate() {
                for &(index, core_seconds) in priced {
                    forecasts.fog_after[k][index] = core_seconds;
                }
            }
            let rendered = Rendered {
                grids: s.strips.iter().map(|_| Default::default()).collect(),
                strips: s.strips,
                fog: s.fogs.into_iter().map(std::sync::Mutex::new).collect(),
            };
            (forecasts, rendered)
        }
    };
    drop(sessions);
    let finisher =
        Finisher { bake, opts, mie, optics: &optics, tracker: &tracker, forecasts: &forecasts, cancel: &cancel };
    let Plan { skies, fog, .. } = plan;
    let mut done = Vec::new();
    for (k, p) in skies.into_iter().enumerate() {
        done.push(finisher.finish_sky(k, p, &fog[k], &mut rendered)?);
    }
    Ok(done)
}

/// The bake's progress tracker, sized by the plan, with its `planned` event sent.
fn start_tracker(plan: &Plan, opts: &BakeOptions) -> Arc<Mutex<Tracker>> {
    let c = plan.counts;
    let cores_known = opts.workers.iter().all(|w| matches!(w, crate::session::farm::WorkerSpec::Local { .. }));
    let tracker = Arc::new(Mutex::new(Tracker::new(
        (c.texels_to_render, c.slices_total, c.slices_cached),
        (opts.cores, cores_known),
        opts.events.clone(),
    )));
    tracker.lock().unwrap().emit(BakeEvent::Planned {
        skies: plan.skies.len(),
        slices_total: c.slices_total,
        slices_cached: c.slices_cached,
        fog_slices: c.fog_slices,
        texels_to_render: c.texels_to_render,
    });
    tracker
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::atmosphere::Atmosphere;
    use crate::bake::ms_grid::MsGrid;
    use crate::bake::{BasisSky, Sampling};
    use crate::render::segments::Standpoint;
    use crate::render::{render, PixelResult, Scene};
    use crate::render::{Image, View};

    /// The DISORT Rayleigh + HG slab as a basis sky of `width` × `height`
    /// texels sampled as `sampling`, with its prepared optics.
    pub(in crate::bake) fn test_sky(width: usize, height: usize, sampling: &Sampling) -> (Atmosphere, Scene, BasisSky) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/atmospheres/disort_rayleigh_hg.toml");
        let atm = Atmosphere::load(&path).unwrap();
        let scene = Scene::new(&atm, &spectral_settings(sampling), &MieCache::shared_by_tests(), &|| {});
        let sky = BasisSky {
            name: "t".into(),
            atmosphere: path,
            width,
            height,
            slices: 64,
            altitude_m: 0.0,
            threshold_deg: 87.5,
            line: 1,
            draft: sampling.clone(),
            final_: sampling.clone(),
        };
        (atm, scene, sky)
    }

    /// `--slice` names a sky slice as NAME:INDEX and a fog slice as
    /// NAME:fog:INDEX, and writes them back the same way.
    #[test]
    fn slice_ids_name_sky_and_fog_slices() {
        let fog: SliceId = "clear:fog:12".parse().unwrap();
        assert_eq!(fog, SliceId { sky: "clear".into(), index: 12, fog: true });
        assert_eq!(fog.to_string(), "clear:fog:12");
        let sky: SliceId = "clear:12".parse().unwrap();
        assert_eq!((sky.fog, sky.to_string().as_str()), (false, "clear:12"));
        for bad in ["clear:fog:64", ":fog:3", "clear:fog", "clear"] {
            assert!(bad.parse::<SliceId>().is_err(), "{bad}");
        }
    }

    /// A slice renders the nodes of its grid that its texels take, each
    /// direction once (the zenith's, the nadir's and the sun's rows are
    /// one each): at the talk's 32 x 128 texels fewer as the sun sets, the
    /// sun patch's cells that reach below the horizon left out (all of
    /// them with the sun 6° below it); every texel's nodes among them.
    #[test]
    fn a_slice_renders_only_the_grid_nodes_its_texels_take() {
        let sampling = Sampling {
            band_nm: 40.0,
            spp: 16,
            max_rel_error: None,
            ms_grid: Some([16, 13]),
            fog_ms_size: None,
            streams: None,
        };
        let (atm, _, sky) = test_sky(32, 128, &sampling);
        let grid = MsGrid::new([16, 13], Standpoint::new(atm.planet.geometry, atm.planet.radius_km, 0.0));
        let patch = super::super::ms_grid::SUN_PATCH_ROWS * super::super::ms_grid::SUN_PATCH_COLS;
        let mut counts = Vec::new();
        for index in [4, 28, 45, 53, 60] {
            let view = View {
                sun_azimuth_deg: 25.0,
                ..slice_view(&sky, &sampling, index, atm.planet.radius_km, atm.planet.top_km, sky.threshold_deg)
            };
            let r = grid.rendered_nodes(&view);
            let sun = (view.sun_zenith_deg, view.sun_azimuth_deg);
            let direction = |k: usize| {
                let (z, a) = grid.node_deg(k, sun);
                crate::directions::camera::direction_deg(z, a)
            };
            // Ascending, distinct directions, each node at its own pixel.
            assert!(r.nodes.windows(2).all(|w| w[0] < w[1]));
            for (i, &k) in r.nodes.iter().enumerate() {
                assert_eq!(r.at[k], Some(i));
                assert!(
                    r.nodes[..i].iter().all(|&j| direction(j).distance(direction(k)) > 1e-9),
                    "slice {index}: node {k} twice"
                );
            }
            // Every texel's nodes of positive weight are rendered, and a node
            // shares a pixel only with its own direction.
            for i in 0..view.width * view.height {
                let d = view
                    .camera
                    .direction((i % view.width) as f64 + 0.5, (i / view.width) as f64 + 0.5, view.width, view.height)
                    .unwrap();
                for (k, w) in grid.weights(d, sun) {
                    if w > 0.0 {
                        let at =
                            r.at[k].unwrap_or_else(|| panic!("slice {index}: texel {i} takes node {k}, not rendered"));
                        assert!(direction(r.nodes[at]).distance(direction(k)) < 1e-9);
                    }
                }
            }
            let patch_rendered = r.nodes.iter().filter(|&&k| k >= grid.nodes() - patch).count();
            eprintln!(
                "slice {index} (sun zenith {:.1}°): {} of {} nodes, {patch_rendered} of the patch's",
                view.sun_zenith_deg,
                r.nodes.len(),
                grid.nodes()
            );
            counts.push((r.nodes.len(), patch_rendered));
        }
        // Fewer nodes as the sun sets (measured: 238, 236, 217, 207, 194),
        // the patch's among them (40, 37, 23, 13, 0): by day fewer than the
        // 30 copies of the zenith's, nadir's and sun's rows alone leave out,
        // none of the patch with the sun 6° below the horizon.
        assert!(counts[0].0 < grid.nodes() - 30 && counts[0].1 > 0 && counts[4].1 == 0, "{counts:?}");
        assert!(counts.windows(2).all(|w| w[0].0 >= w[1].0), "{counts:?}");
    }

    /// Nodes of one direction share one noise in a texel's standard error:
    /// with every rendered node's standard error 1, a texel's is the root of
    /// the sum over rendered pixels of its weights on each, squared, which
    /// for a texel by the zenith (its cell's two upper nodes one pixel) is
    /// more than the sum of the squared weights node by node.
    #[test]
    fn nodes_of_one_direction_share_their_noise() {
        let sampling = Sampling {
            band_nm: 40.0,
            spp: 16,
            max_rel_error: None,
            ms_grid: Some([16, 13]),
            fog_ms_size: None,
            streams: None,
        };
        let (atm, scene, sky) = test_sky(8, 32, &sampling);
        let grid = MsGrid::new([16, 13], Standpoint::new(atm.planet.geometry, atm.planet.radius_km, 0.0));
        let view = slice_view(&sky, &sampling, 4, atm.planet.radius_km, atm.planet.top_km, sky.threshold_deg);
        let nodes_view = grid.view(&view);
        let single = crate::render::single_per_pixel(&scene, &nodes_view);
        let pixels = single
            .iter()
            .map(|&xyz| PixelResult { xyz_stderr: [1.0; 3], samples: 1, ..PixelResult::from_xyz(xyz) })
            .collect();
        let resampled = grid.resample(&Image { width: nodes_view.width, height: 1, pixels }, &scene, &view);
        let at = grid.rendered_nodes(&view).at;
        let mut merged_somewhere = false;
        for (i, texel) in resampled.pixels.iter().enumerate() {
            let d = view
                .camera
                .direction((i % view.width) as f64 + 0.5, (i / view.width) as f64 + 0.5, view.width, view.height)
                .unwrap();
            let weights: Vec<(usize, f64)> = grid
                .weights(d, (view.sun_zenith_deg, view.sun_azimuth_deg))
                .into_iter()
                .filter(|w| w.1 > 0.0)
                .collect();
            let mut by_pixel = std::collections::BTreeMap::new();
            for &(k, w) in &weights {
                *by_pixel.entry(at[k].unwrap()).or_insert(0.0) += w;
            }
            let shared: f64 = by_pixel.values().map(|w| w * w).sum();
            let apart: f64 = weights.iter().map(|(_, w)| w * w).sum();
            merged_somewhere |= shared > apart + 1e-9;
            assert!(
                (texel.xyz_stderr[1] - shared.sqrt()).abs() < 1e-12,
                "texel {i}: {} against {}",
                texel.xyz_stderr[1],
                shared.sqrt()
            );
        }
        assert!(merged_somewhere, "no texel took two nodes of one direction");
    }

    /// A slice from its grid of multiple scattering (`ms_grid`) agrees with
    /// the slice rendered texel by texel: each texel's difference within
    /// the Sidak threshold for a family-wise false alarm of 1e-3 over every
    /// texel of both slices (z = 4.47 for 128; Gaussian means of 512
    /// samples), its standard error the two renders' together plus an
    /// allowance of 2 % of Y for the interpolation (the worst the bench
    /// measured for a 16 x 13 grid: 1.7 %, hazed at a sun zenith of 85°); and
    /// the mean relative difference over each slice within its own
    /// standard error times 3.48 (Sidak, 1e-3 over the two slices) plus
    /// 0.5 %. That standard error is the grid's nodes' (the texels share
    /// them: each node weighs in the mean by its weights over the texels)
    /// and the whole slice's texels' together, from their own standard
    /// errors, which at 512 samples of heavy-tailed paths run small: over
    /// 30 seeds the grid's mean scattered by 1.9 % at slice 20 where that
    /// estimate said at most 1.5 %, so it is taken 1.5 times. Leaving out the single
    /// scattering, or mirroring the grid the wrong way, misses by far more.
    #[test]
    fn a_slice_from_its_grid_agrees_with_the_slice_rendered_whole() {
        let sampling = Sampling {
            band_nm: 40.0,
            spp: 512,
            max_rel_error: None,
            ms_grid: Some([16, 13]),
            fog_ms_size: None,
            streams: None,
        };
        let (atm, scene, sky) = test_sky(4, 16, &sampling);
        let cancel = AtomicBool::new(false);
        let grid = MsGrid::new([16, 13], Standpoint::new(atm.planet.geometry, atm.planet.radius_km, 0.0));
        let z_crit = 4.47;
        for index in [4, 20] {
            let view = View {
                sun_azimuth_deg: 25.0,
                ..slice_view(&sky, &sampling, index, atm.planet.radius_km, atm.planet.top_km, sky.threshold_deg)
            };
            let nodes = render(&scene, &grid.view(&view), &cancel, &|| {}).unwrap();
            let from_grid = grid.resample(&nodes, &scene, &view);
            let whole = render(&scene, &view, &cancel, &|| {}).unwrap();
            let n = whole.pixels.len() as f64;
            let at = grid.rendered_nodes(&view).at;
            // Each node's weight in the slice's mean relative difference.
            let mut in_mean = vec![0.0; nodes.pixels.len()];
            let (mut worst, mut mean, mut whole_var) = (0.0f64, 0.0, 0.0);
            for (i, (g, w)) in from_grid.pixels.iter().zip(&whole.pixels).enumerate() {
                let (a, b) = (g.xyz[1], w.xyz[1]);
                let sigma = (g.xyz_stderr[1].powi(2) + w.xyz_stderr[1].powi(2) + (0.02 * b).powi(2)).sqrt();
                worst = worst.max((a - b).abs() / sigma);
                mean += (a - b) / b / n;
                whole_var += (a / b * w.xyz_stderr[1] / b / n).powi(2);
                assert!(g.samples > 0 && g.samples <= 512, "{}", g.samples);
                let d = view
                    .camera
                    .direction((i % view.width) as f64 + 0.5, (i / view.width) as f64 + 0.5, view.width, view.height)
                    .unwrap();
                for (k, wk) in
                    grid.weights(d, (view.sun_zenith_deg, view.sun_azimuth_deg)).into_iter().filter(|&(_, wk)| wk > 0.0)
                {
                    in_mean[at[k].unwrap()] += wk / b / n;
                }
            }
            let grid_var: f64 = in_mean.iter().zip(&nodes.pixels).map(|(c, p)| (c * p.xyz_stderr[1]).powi(2)).sum();
            let se = 1.5 * (grid_var + whole_var).sqrt();
            eprintln!(
                "slice {index}: worst z {worst:.2}, mean relative difference {:.3} % (standard error {:.3} %)",
                100.0 * mean,
                100.0 * se
            );
            assert!(worst < z_crit, "slice {index}: a texel {worst:.2} standard errors off");
            assert!(
                mean.abs() < 3.48 * se + 0.005,
                "slice {index}: mean relative difference {mean}, standard error {se}"
            );
        }
    }

    /// A strip of slices (one farm job) renders each slice's texels bit for
    /// bit as the slice rendered alone, also in a task that crosses from one
    /// slice into the next, and with an adaptive sample count.
    #[test]
    fn a_strip_renders_each_slice_as_it_renders_alone() {
        let sampling = Sampling {
            band_nm: 40.0,
            spp: 128,
            max_rel_error: Some(0.3),
            ms_grid: None,
            fog_ms_size: None,
            streams: None,
        };
        let (atm, scene, sky) = test_sky(3, 8, &sampling);
        let cancel = AtomicBool::new(false);
        // Day, the sun-centred mapping's last slices, twilight.
        let views: Vec<View> = [20, 47, 52, 60]
            .iter()
            .map(|&i| slice_view(&sky, &sampling, i, atm.planet.radius_km, atm.planet.top_km, sky.threshold_deg))
            .collect();
        let strip = strip_view(&views.iter().collect::<Vec<_>>());
        assert_eq!((strip.width, strip.height), (12, 8));
        assert!(strip.check().is_ok());
        assert!(View { width: 13, ..strip.clone() }.check().is_err());
        let whole = render(&scene, &strip, &cancel, &|| {}).unwrap();
        // Columns 2 to 7: the end of slice 0, all of slice 1, the start of slice 2.
        let task = crate::render::render_columns(&scene, &strip, 2, 6, &cancel, &|| {}).unwrap();
        for (k, v) in views.iter().enumerate() {
            let alone = render(&scene, v, &cancel, &|| {}).unwrap();
            for y in 0..8 {
                for x in 0..3 {
                    let (a, b) = (&alone.pixels[y * 3 + x], &whole.pixels[y * 12 + k * 3 + x]);
                    assert!(
                        a.xyz.iter().zip(&b.xyz).all(|(p, q)| p.to_bits() == q.to_bits()) && a.samples == b.samples,
                        "slice {k}, texel ({x}, {y})"
                    );
                    if let Some(col) = (k * 3 + x).checked_sub(2).and_then(|c| task.get(c)) {
                        assert_eq!(col[y].xyz.map(f64::to_bits), a.xyz.map(f64::to_bits), "task column {}", k * 3 + x);
                    }
                }
            }
        }
        // The texels took different sample counts (adaptive sampling), each as in its own slice.
        let counts: std::collections::BTreeSet<u32> = whole.pixels.iter().map(|p| p.samples).collect();
        assert!(counts.len() > 1, "{counts:?}");
    }
}
