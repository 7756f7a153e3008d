//! A render session: an atmosphere's optics prepared once for one spectral
//! setting, then any number of views rendered with them, on the embedded
//! worker or on `sky worker` daemons, with progress as farm events. What
//! `sky render` runs, and what a bake will loop over.
//!
//! Sessions share prepared optics through an [`OpticsCache`] keyed by
//! [`optics_hash`]: the atmosphere bundle's content hash and the spectral
//! settings, nothing of the view, so a second view of the same atmosphere
//! prepares nothing. The cache is bounded by memory (the same
//! [`MemoryLru`] a worker keeps its optics in). On the farm the optics
//! travel under that hash too, to each worker once.

use crate::atmosphere::{Atmosphere, Bundle};
use crate::farm::coordinator::{self, Farm, FarmError, FarmPart, Options, PartsOutcome, WorkerSpec};
use crate::farm::job::{optics_hash, FarmJob, Optics};
use crate::farm::journal::Journal;
use crate::farm::proto;
use crate::lru::MemoryLru;
use crate::mie::MieCache;
use crate::render::{Image, Scene, SpectralSettings, View};
use std::collections::BTreeMap;
use std::sync::atomic::AtomicBool;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// What the layers above see of the farm (the bake, `sky lut verify`): the
/// workers and options a session renders on, the farm's events, errors and
/// column journals. They reach the farm through sessions and these names
/// only.
pub mod farm {
    pub use crate::farm::build_version;
    pub use crate::farm::coordinator::{FarmError, FarmPart, Options, WorkerSpec};
    pub use crate::farm::events::{EventSink, FarmEvent};
    pub use crate::farm::journal::{Header, Journal, JournalError};
}

/// Prepared optics by [`optics_hash`], at most a budget of bytes of them
/// (least recently used evicted first; optics a session holds never).
pub struct OpticsCache {
    scenes: MemoryLru<Scene>,
    prepared: AtomicUsize,
}

impl Default for OpticsCache {
    /// A cache of [`crate::lru::DEFAULT_BUDGET_BYTES`].
    fn default() -> OpticsCache {
        OpticsCache::with_budget(crate::lru::DEFAULT_BUDGET_BYTES)
    }
}

impl OpticsCache {
    pub fn with_budget(bytes: u64) -> OpticsCache {
        OpticsCache { scenes: MemoryLru::new(bytes), prepared: AtomicUsize::new(0) }
    }

    /// The optics of `atm` for `spectral`, prepared (on the current rayon
    /// pool, calling `on_step` after each wavelength) only if the cache does
    /// not hold them yet.
    pub fn get(
        &self,
        atm: &Atmosphere,
        spectral: &SpectralSettings,
        mie: &MieCache,
        on_step: &(dyn Fn() + Sync),
    ) -> Arc<Scene> {
        let h = optics_hash(atm, spectral);
        if let Some(s) = self.scenes.get(&h) {
            return s;
        }
        let scene = Scene::new(atm, spectral, mie, on_step);
        self.prepared.fetch_add(1, Ordering::Relaxed);
        let bytes = scene.encoded_bytes();
        self.scenes.insert(h, Arc::new(scene), bytes)
    }

    /// How many times optics were prepared (not found in the cache).
    pub fn prepared(&self) -> usize {
        self.prepared.load(Ordering::Relaxed)
    }

    /// Bytes of prepared optics held.
    pub fn bytes(&self) -> u64 {
        self.scenes.bytes()
    }

    /// Whether the cache holds these optics.
    pub fn contains(&self, atm: &Atmosphere, spectral: &SpectralSettings) -> bool {
        self.scenes.contains(&optics_hash(atm, spectral))
    }
}

/// Workers and farm policy, with the farm (its runtime, its worker
/// connections, what optics each worker holds) made at the first render
/// and kept for the next: a worker is greeted once and gets each optics at
/// most once, however many views it renders. Sessions of several
/// atmospheres can share one, and render their views in one queue
/// ([`SharedFarm::render_parts`]).
pub struct SharedFarm {
    workers: Vec<WorkerSpec>,
    options: Options,
    farm: Mutex<Option<(tokio::runtime::Runtime, Farm)>>,
}

impl Drop for SharedFarm {
    fn drop(&mut self) {
        if let Some((rt, farm)) = self.farm.get_mut().ok().and_then(Option::take) {
            drop(farm);
            rt.shutdown_background();
        }
    }
}

impl SharedFarm {
    /// A farm of `workers` (the embedded worker when empty).
    pub fn new(workers: Vec<WorkerSpec>, options: Options) -> Arc<SharedFarm> {
        Arc::new(SharedFarm { workers, options, farm: Mutex::new(None) })
    }

    /// Renders `parts` (jobs of any sessions' optics) in one queue, in
    /// their order (see [`Farm::render_parts`]).
    pub fn render_parts(&self, parts: Vec<FarmPart>, cancel: Arc<AtomicBool>) -> Result<PartsOutcome, FarmError> {
        let mut farm = self.farm.lock().unwrap_or_else(|e| e.into_inner());
        if farm.is_none() {
            let workers = if self.workers.is_empty() {
                vec![WorkerSpec::Local { threads: rayon::current_num_threads() }]
            } else {
                self.workers.clone()
            };
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .map_err(FarmError::Runtime)?;
            *farm = Some((rt, Farm::new(workers)));
        }
        let (rt, farm) = farm.as_mut().expect("made above");
        rt.block_on(farm.render_parts(parts, &self.options, cancel))
    }
}

/// A view's image from its columns (each top to bottom).
pub fn image_of_columns(columns: &[Vec<crate::render::PixelResult>], width: usize, height: usize) -> Image {
    let mut pixels = Vec::with_capacity(width * height);
    for y in 0..height {
        for col in columns {
            pixels.push(col[y].clone());
        }
    }
    Image { width, height, pixels }
}

/// One atmosphere and spectral setting with their prepared optics, and the
/// farm its views render on (its own, or one shared with other sessions).
pub struct Session {
    pub atmosphere: Atmosphere,
    pub spectral: SpectralSettings,
    pub scene: Arc<Scene>,
    /// The optics as they travel, under their hash.
    optics: Arc<Optics>,
    farm: Arc<SharedFarm>,
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
        Session::on_farm(atmosphere, bundle, spectral, cache, mie, SharedFarm::new(workers, options), on_step)
    }

    /// A session rendering on `farm`, which other sessions may share.
    pub fn on_farm(
        atmosphere: Atmosphere,
        bundle: Bundle,
        spectral: SpectralSettings,
        cache: &OpticsCache,
        mie: &MieCache,
        farm: Arc<SharedFarm>,
        on_step: &(dyn Fn() + Sync),
    ) -> Session {
        let scene = cache.get(&atmosphere, &spectral, mie, on_step);
        let optics = Arc::new(Optics::new(&atmosphere, bundle, scene.clone()));
        Session { atmosphere, spectral, scene, optics, farm }
    }

    /// The hash the session's optics travel under ([`optics_hash`]).
    pub fn optics_hash(&self) -> &str {
        &self.optics.hash
    }

    /// The farm job of a view (its hash names the journal's header).
    pub fn job(&self, view: &View) -> Arc<FarmJob> {
        Arc::new(FarmJob::new(self.optics.clone(), view))
    }

    /// Renders one view of `job` (from [`Session::job`]), with columns of
    /// an earlier run already in `resumed` and new ones going to `journal`.
    pub fn render(
        &self,
        job: Arc<FarmJob>,
        resumed: BTreeMap<u32, proto::Tile>,
        journal: Option<Journal>,
        cancel: Arc<AtomicBool>,
    ) -> Result<Rendered, FarmError> {
        let (width, height) = (job.settings.view.width, job.settings.view.height);
        let outcome = self.farm.render_parts(vec![FarmPart { job, resumed, journal }], cancel)?;
        Ok(Rendered { image: image_of_columns(&outcome.parts[0], width, height), stats: outcome.stats })
    }

    /// [`Session::render`] of a view from scratch.
    pub fn render_view(&self, view: &View, cancel: Arc<AtomicBool>) -> Result<Rendered, FarmError> {
        self.render(self.job(view), BTreeMap::new(), None, cancel)
    }
}
