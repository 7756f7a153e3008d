//! A render session: an atmosphere's optics prepared once for one spectral
//! setting, then any number of views rendered with them, on the embedded
//! worker or on `sky worker` daemons, with progress as farm events. What
//! `sky render` runs, and what a bake will loop over.
//!
//! Sessions share prepared optics through an [`OpticsCache`] keyed by
//! [`optics_hash`]: the atmosphere bundle's content hash and the spectral
//! settings, nothing of the view, so a second view of the same atmosphere
//! prepares nothing.

use crate::atmosphere::{Atmosphere, Bundle};
use crate::farm::coordinator::{self, FarmError, FarmJob, Options, Outcome, WorkerSpec};
use crate::farm::journal::Journal;
use crate::farm::{job, proto};
use crate::mie::MieCache;
use crate::render::{Image, Scene, Settings, SpectralSettings, View};
use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

/// The name of an atmosphere's optics for one spectral setting: BLAKE3 of
/// the atmosphere's content hash (the file and every data file it reads)
/// and the spectral settings.
pub fn optics_hash(atm: &Atmosphere, spectral: &SpectralSettings) -> String {
    let key = serde_json::json!({ "atmosphere": atm.content_hash, "spectral": spectral, "build": crate::VERSION });
    blake3::hash(key.to_string().as_bytes()).to_hex().to_string()
}

/// Prepared optics by [`optics_hash`], kept for the life of the cache.
#[derive(Default)]
pub struct OpticsCache {
    scenes: Mutex<HashMap<String, Arc<Scene>>>,
    prepared: Mutex<usize>,
}

impl OpticsCache {
    /// The optics of `atm` for `spectral`, prepared (on the current rayon
    /// pool, calling `on_step` after each wavelength) only if the cache does
    /// not hold them yet.
    pub fn get(&self, atm: &Atmosphere, spectral: &SpectralSettings, mie: &MieCache, on_step: &(dyn Fn() + Sync)) -> Arc<Scene> {
        let h = optics_hash(atm, spectral);
        if let Some(s) = self.scenes.lock().unwrap().get(&h) {
            return s.clone();
        }
        let scene = Arc::new(Scene::new(atm, spectral, mie, on_step));
        *self.prepared.lock().unwrap() += 1;
        self.scenes.lock().unwrap().entry(h).or_insert(scene).clone()
    }

    /// How many times optics were prepared (not found in the cache).
    pub fn prepared(&self) -> usize {
        *self.prepared.lock().unwrap()
    }
}

/// One atmosphere and spectral setting with their prepared optics, and the
/// workers and farm policy its views render with.
pub struct Session {
    pub atmosphere: Atmosphere,
    bundle: Bundle,
    pub spectral: SpectralSettings,
    pub scene: Arc<Scene>,
    workers: Vec<WorkerSpec>,
    options: Options,
}

/// A view's pixels as the farm delivered them.
pub struct Rendered {
    pub image: Image,
    pub stats: coordinator::Stats,
}

impl Session {
    /// A session on `workers` (the embedded worker when empty) with the
    /// optics from `cache`.
    pub fn new(
        atmosphere: Atmosphere,
        bundle: Bundle,
        spectral: SpectralSettings,
        cache: &OpticsCache,
        mie: &MieCache,
        workers: Vec<WorkerSpec>,
        options: Options,
        on_step: &(dyn Fn() + Sync),
    ) -> Session {
        let scene = cache.get(&atmosphere, &spectral, mie, on_step);
        Session { atmosphere, bundle, spectral, scene, workers, options }
    }

    /// The farm job of a view (its hash names the journal's header).
    pub fn job(&self, view: &View) -> Arc<FarmJob> {
        let settings = Settings { spectral: self.spectral.clone(), view: view.clone() };
        let message = job::make(&self.bundle, &settings, Some(&self.scene));
        Arc::new(FarmJob { hash: job::hash(&message), message, settings })
    }

    /// Renders one view of `job` (from [`Session::job`]), with columns of
    /// an earlier run already in `resumed` and new ones going to `journal`.
    pub fn render(&self, job: Arc<FarmJob>, resumed: BTreeMap<u32, proto::Tile>, journal: Option<Journal>, cancel: Arc<AtomicBool>) -> Result<Rendered, FarmError> {
        let (width, height) = (job.settings.view.width, job.settings.view.height);
        let workers = if self.workers.is_empty() { vec![WorkerSpec::Local { threads: rayon::current_num_threads() }] } else { self.workers.clone() };
        let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().map_err(FarmError::Runtime)?;
        let outcome: Result<Outcome, FarmError> = rt.block_on(coordinator::run(job, workers, Some(self.scene.clone()), resumed, journal, self.options.clone(), cancel));
        rt.shutdown_background();
        let outcome = outcome?;
        let mut pixels = Vec::with_capacity(width * height);
        for y in 0..height {
            for col in &outcome.columns {
                pixels.push(col[y].clone());
            }
        }
        Ok(Rendered { image: Image { width, height, pixels }, stats: outcome.stats })
    }

    /// [`Session::render`] of a view from scratch.
    pub fn render_view(&self, view: &View, cancel: Arc<AtomicBool>) -> Result<Rendered, FarmError> {
        self.render(self.job(view), BTreeMap::new(), None, cancel)
    }
}
