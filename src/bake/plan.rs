//! The bake's first room: the plan. Which slices of which basis skies the
//! options ask for, each one's view and cache key, which the cache already
//! holds, which share a view with an earlier one, the fog slices to render,
//! and the counts that size the bake's progress. It renders nothing (it
//! loads the atmosphere files and reads the cache's index), so it can be
//! tested without a renderer.

use super::cache::SliceCache;
use super::file::{BakeFile, BasisSky};
use super::fog::FogTodo;
use super::ms_grid::MsGrid;
use super::slices::{sky_slice_key, slice_view, spectral_settings, BakeOptions, Method, SkySlices};
use super::BakeError;
use crate::atmosphere::Atmosphere;
use crate::render::segments::Standpoint;
use crate::render::View;

/// A basis sky in a bake's plan: its slices' views, and which the cache
/// holds.
pub(super) struct Planned {
    pub(super) atm: Atmosphere,
    pub(super) bundle: crate::atmosphere::Bundle,
    pub(super) out: SkySlices,
    pub(super) views: Vec<Option<(View, String)>>,
    /// Multiple scattering on a grid of its own (`ms_grid`): each slice
    /// is then rendered as its grid's nodes and resampled.
    pub(super) grid: Option<MsGrid>,
    /// What the queue renders of each slice in `views`: its view, or
    /// its grid's.
    pub(super) jobs: Vec<Option<View>>,
    /// For a slice whose view an earlier one to render has too (47 and
    /// 48 are both the horizon in the talk's layout): that slice.
    pub(super) same_as: Vec<Option<usize>>,
}

impl Planned {
    /// A slice's texels, or with a grid its nodes: what the queue renders
    /// of each slice (0 for a slice it does not render).
    pub(super) fn job_texels(&self) -> Vec<u64> {
        self.jobs.iter().map(|v| v.as_ref().map_or(0, |v| (v.width * v.height) as u64)).collect()
    }

    /// The slices the queue renders: wanted, not cached, and not the same
    /// view as an earlier one.
    pub(super) fn to_render(&self) -> Vec<usize> {
        (0..self.views.len()).filter(|&i| self.views[i].is_some() && self.same_as[i].is_none()).collect()
    }
}

/// A bake's plan: every basis sky's, its fog slices to render, and the counts.
pub(super) struct Plan {
    pub(super) skies: Vec<Planned>,
    /// By basis sky, the fog slices to render (a whole bake's, or those
    /// `only` names).
    pub(super) fog: Vec<Vec<FogTodo>>,
    pub(super) counts: Counts,
}

/// What a bake has to do, for its progress and its `planned` event.
#[derive(Debug, Clone, Copy)]
pub(super) struct Counts {
    /// Slices of the sky LUTs and of the fog, cached or not.
    pub(super) slices_total: usize,
    pub(super) slices_cached: usize,
    /// Fog slices to render.
    pub(super) fog_slices: usize,
    /// Texels (or grid nodes) the queue renders.
    pub(super) texels_to_render: u64,
}

/// The plan of `bake` under `opts`: fails on a slice `only` names that the
/// bake lacks, an atmosphere that does not load, or, with `pack_only`, a
/// slice the cache lacks (naming them all).
pub(super) fn plan(bake: &BakeFile, opts: &BakeOptions) -> Result<Plan, BakeError> {
    if let Some(only) = &opts.only {
        for id in only {
            if !bake.skies.iter().any(|s| s.name == id.sky && id.index < s.slices) {
                return Err(BakeError::NoSuchSlice(id.to_string()));
            }
        }
    }
    // First the plan: every slice's key, and which the cache holds.
    let mut plan: Vec<Planned> = Vec::new();
    for sky in &bake.skies {
        plan.push(plan_sky(sky, opts)?);
    }
    // The fog slices to render: a whole bake's, or those `only` names.
    let fog_plan: Vec<Vec<FogTodo>> = plan
        .iter()
        .map(|p| {
            let mut todo = super::fog::to_render(&p.out, &bake.fog, &opts.cache, (opts.quality, opts.method));
            if let Some(only) = &opts.only {
                todo.retain(|f| only.iter().any(|id| id.fog && id.sky == p.out.sky.name && id.index == f.index));
            }
            todo
        })
        .collect();
    if opts.pack_only {
        check_cached(&plan, &fog_plan, &opts.cache)?;
    }
    let counts = count(&plan, &fog_plan, opts);
    Ok(Plan { skies: plan, fog: fog_plan, counts })
}

/// One basis sky's plan: its slices' views and keys, those the cache
/// holds, and those that repeat an earlier slice's view.
fn plan_sky(sky: &BasisSky, opts: &BakeOptions) -> Result<Planned, BakeError> {
    let (atm, bundle) = Atmosphere::load_bundle(&sky.atmosphere)
        .map_err(|error| BakeError::Atmosphere { sky: sky.name.clone(), error })?;
    let sampling = sky.sampling(opts.quality).clone();
    let spectral = spectral_settings(&sampling);
    let (radius_km, top_km) = (atm.planet.radius_km, atm.planet.top_km);
    let threshold_deg = sky.threshold_deg;
    let mut views: Vec<Option<(View, String)>> = Vec::new();
    let mut same_as = Vec::new();
    let mut slices = Vec::new();
    let mut cached = 0;
    for index in 0..sky.slices {
        let wanted =
            opts.only.as_ref().is_none_or(|o| o.iter().any(|id| !id.fog && id.sky == sky.name && id.index == index));
        if !wanted {
            views.push(None);
            same_as.push(None);
            slices.push(None);
            continue;
        }
        let view = slice_view(sky, &sampling, index, radius_km, top_km, threshold_deg);
        let key = sky_slice_key(&atm.content_hash, &spectral, &view, (opts.quality, opts.method), &sampling);
        let hit = opts.cache.get(&key);
        cached += hit.is_some() as usize;
        same_as.push(if hit.is_some() {
            None
        } else {
            views.iter().position(|v| v.as_ref().is_some_and(|(_, k)| *k == key))
        });
        views.push(if hit.is_some() { None } else { Some((view, key)) });
        slices.push(hit);
    }
    // The transport solver renders whole slices (no grid of multiple scattering).
    let grid = sampling
        .ms_grid
        .filter(|_| opts.method == Method::MonteCarlo)
        .map(|g| MsGrid::new(g, Standpoint::new(atm.planet.geometry, radius_km, sky.altitude_m / 1000.0)));
    let out = SkySlices {
        sky: sky.clone(),
        atmosphere_name: bundle.name.clone(),
        atmosphere_hash: atm.content_hash.clone(),
        radius_km,
        top_km,
        threshold_deg,
        spectral,
        sampling,
        slices,
        rendered: 0,
        cached,
        columns_resumed: 0,
        lighting: None,
        fog: None,
        fog_rendered: Vec::new(),
    };
    let jobs = views.iter().map(|v| v.as_ref().map(|(v, _)| grid.map_or_else(|| v.clone(), |g| g.view(v)))).collect();
    Ok(Planned { atm, bundle, out, views, grid, jobs, same_as })
}

/// With `pack_only`: every slice to render must be in the cache; the
/// error names those that are not.
fn check_cached(plan: &[Planned], fog_plan: &[Vec<FogTodo>], cache: &SliceCache) -> Result<(), BakeError> {
    let sky_missing = plan.iter().flat_map(|p| {
        p.views.iter().enumerate().filter(|(_, v)| v.is_some()).map(|(i, _)| format!("{}:{i}", p.out.sky.name))
    });
    let fog_missing =
        plan.iter().zip(fog_plan).flat_map(|(p, f)| f.iter().map(|f| format!("{}:fog:{}", p.out.sky.name, f.index)));
    let missing: Vec<String> = sky_missing.chain(fog_missing).collect();
    if !missing.is_empty() {
        return Err(BakeError::NotInCache { cache: cache.dir().to_path_buf(), missing });
    }
    Ok(())
}

/// The bake's counts: slices in all and cached, fog slices and texels to render.
fn count(plan: &[Planned], fog_plan: &[Vec<FogTodo>], opts: &BakeOptions) -> Counts {
    let fog_slices = fog_plan.iter().map(Vec::len).sum::<usize>();
    let fog_texels: u64 = fog_plan.iter().flatten().map(|f| (f.view.width * f.view.height) as u64).sum();
    // Of the fog, a whole bake's slices; those not rendered count as cached
    // (a slice that shares its sun with an earlier one among them).
    let fog_total: usize = match &opts.only {
        Some(only) => only.iter().filter(|id| id.fog).count(),
        None => plan.iter().map(|p| p.out.sky.slices).sum(),
    };
    let slices_total: usize = plan
        .iter()
        .map(|p| p.out.slices.iter().filter(|s| s.is_some()).count() + p.views.iter().filter(|v| v.is_some()).count())
        .sum::<usize>()
        + fog_total;
    let slices_cached: usize = plan.iter().map(|p| p.out.cached).sum::<usize>() + fog_total.saturating_sub(fog_slices);
    let texels_to_render: u64 = plan.iter().map(|p| p.job_texels().iter().sum::<u64>()).sum::<u64>() + fog_texels;
    Counts { slices_total, slices_cached, fog_slices, texels_to_render }
}
