//! What travels to a worker, in two parts, so that a worker never opens a
//! path a coordinator names and a bake of many views ships its optics once:
//!
//! - the optics: the atmosphere file with every data file it reads, the
//!   spectral settings and the prepared [`Scene`], named by their optics
//!   hash ([`optics_hash`]) and sent to a worker only when
//!   it lacks them;
//! - the view (camera, size, sun, samples), serde JSON, with every task.
//!
//! A job is one view rendered with one set of optics; its hash (of the
//! optics hash and the view) names it in tiles and journals.

use super::proto;
use crate::atmosphere::{Atmosphere, Bundle};
use crate::render::{Scene, Settings, SpectralSettings, View};
use std::sync::{Arc, OnceLock};

/// The name of an atmosphere's optics for one spectral setting: BLAKE3 of
/// the atmosphere's content hash (the file and every data file it reads)
/// and the spectral settings.
pub fn optics_hash(atm: &Atmosphere, spectral: &SpectralSettings) -> String {
    let key = serde_json::json!({ "atmosphere": atm.content_hash, "spectral": spectral, "build": crate::VERSION, "render_source": crate::RENDER_SOURCE });
    blake3::hash(key.to_string().as_bytes()).to_hex().to_string()
}

#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error("optics speak farm protocol {theirs}, this build speaks {ours}")]
    Protocol { theirs: u32, ours: u32 },
    #[error("optics are from sky {theirs}, this is sky {ours}: only the same build renders bit-identically")]
    Build { theirs: String, ours: String },
    #[error("task's view: {0}")]
    View(String),
    #[error("optics' spectral settings: {0}")]
    Spectral(String),
    #[error("optics' atmosphere: {0}")]
    Atmosphere(String),
    #[error("optics' prepared scene does not decode: {0}")]
    Scene(String),
    #[error("the optics hash to {actual}, not the {claimed} the task names")]
    Hash { claimed: String, actual: String },
}

/// An atmosphere's prepared optics as a coordinator holds them: the scene
/// (for the embedded worker) and, encoded on first use, the message for
/// remote workers.
pub struct Optics {
    /// [`optics_hash`] of the atmosphere and spectral settings.
    pub hash: String,
    pub scene: Arc<Scene>,
    bundle: Bundle,
    message: OnceLock<proto::Optics>,
}

impl Optics {
    pub fn new(atm: &Atmosphere, bundle: Bundle, scene: Arc<Scene>) -> Optics {
        Optics { hash: optics_hash(atm, &scene.spectral), scene, bundle, message: OnceLock::new() }
    }

    /// The optics message (with the prepared scene), encoded once.
    pub fn message(&self) -> &proto::Optics {
        self.message.get_or_init(|| message(&self.bundle, &self.scene.spectral, Some(&self.scene)))
    }
}

/// Builds an optics message (data files sorted by name, so equal optics
/// encode equally), with the prepared scene when given.
pub fn message(bundle: &Bundle, spectral: &SpectralSettings, scene: Option<&Scene>) -> proto::Optics {
    proto::Optics {
        protocol_version: super::PROTOCOL_VERSION,
        build_version: super::build_version(),
        atmosphere_name: bundle.name.clone(),
        atmosphere_toml: bundle.text.clone(),
        files: bundle
            .files
            .iter()
            .map(|(name, content)| proto::DataFile { name: name.clone(), content: content.clone() })
            .collect(),
        spectral_json: serde_json::to_string(spectral).expect("spectral settings serialise"),
        scene: scene.map(|s| postcard::to_stdvec(s).expect("scenes serialise")).unwrap_or_default(),
    }
}

/// One view of prepared optics, as the coordinator holds it.
pub struct FarmJob {
    /// [`job_hash`]: names the render in tiles and in the journal.
    pub hash: String,
    pub optics: Arc<Optics>,
    pub settings: Settings,
    /// The view as tasks carry it.
    pub view_json: String,
}

impl FarmJob {
    pub fn new(optics: Arc<Optics>, view: &View) -> FarmJob {
        let view_json = serde_json::to_string(view).expect("views serialise");
        let settings = Settings { spectral: optics.scene.spectral.clone(), view: view.clone() };
        FarmJob { hash: job_hash(&optics.hash, &view_json), optics, settings, view_json }
    }
}

/// The hash of the render of `view_json` with the optics `optics_hash`, hex.
pub fn job_hash(optics_hash: &str, view_json: &str) -> String {
    let mut h = blake3::Hasher::new();
    h.update(b"sky farm job\n");
    h.update(optics_hash.as_bytes());
    h.update(b"\n");
    h.update(view_json.as_bytes());
    h.finalize().to_hex().to_string()
}

/// Checks versions and unpacks optics: the atmosphere (from their own
/// files), the spectral settings, and the prepared scene if they carry it;
/// their hash must be the one claimed.
pub fn open_optics(
    o: &proto::Optics,
    claimed_hash: &str,
) -> Result<(Atmosphere, SpectralSettings, Option<Scene>), JobError> {
    if o.protocol_version != super::PROTOCOL_VERSION {
        return Err(JobError::Protocol { theirs: o.protocol_version, ours: super::PROTOCOL_VERSION });
    }
    if o.build_version != super::build_version() {
        return Err(JobError::Build { theirs: o.build_version.clone(), ours: super::build_version() });
    }
    let spectral: SpectralSettings =
        serde_json::from_str(&o.spectral_json).map_err(|e| JobError::Spectral(e.to_string()))?;
    let bundle = Bundle {
        name: o.atmosphere_name.clone(),
        text: o.atmosphere_toml.clone(),
        files: o.files.iter().map(|f| (f.name.clone(), f.content.clone())).collect(),
    };
    let atm = Atmosphere::from_bundle(&bundle).map_err(|e| JobError::Atmosphere(e.to_string()))?;
    let actual = optics_hash(&atm, &spectral);
    if actual != claimed_hash {
        return Err(JobError::Hash { claimed: claimed_hash.to_string(), actual });
    }
    if o.scene.is_empty() {
        return Ok((atm, spectral, None));
    }
    let scene: Scene = postcard::from_bytes(&o.scene).map_err(|e| JobError::Scene(e.to_string()))?;
    if scene.spectral != spectral {
        return Err(JobError::Scene("it was prepared for other spectral settings than the optics name".into()));
    }
    Ok((atm, spectral, Some(scene)))
}

/// Unpacks a task's view.
pub fn open_view(view_json: &str) -> Result<View, JobError> {
    let view: View = serde_json::from_str(view_json).map_err(|e| JobError::View(e.to_string()))?;
    view.check().map_err(JobError::View)?;
    Ok(view)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::directions::camera::Camera;
    use std::path::Path;

    #[test]
    fn optics_and_views_round_trip_without_touching_the_disk() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/clear.toml");
        let (atm, bundle) = Atmosphere::load_bundle(&path).unwrap();
        assert!(bundle.files.len() >= 3, "{:?}", bundle.files.keys());
        let mut s = Settings::directions(vec![(10.0, 20.0)], 60.0, vec![550.0], 4, 7, false);
        s.view.camera = Camera::Fisheye;
        let hash = optics_hash(&atm, &s.spectral);
        let o = message(&bundle, &s.spectral, None);
        let (atm2, spectral, scene) = open_optics(&o, &hash).unwrap();
        assert_eq!(atm2.content_hash, atm.content_hash);
        assert_eq!(spectral, s.spectral);
        assert!(scene.is_none());
        let view = open_view(&serde_json::to_string(&s.view).unwrap()).unwrap();
        assert_eq!(view, s.view);
        // A missing data file is an error naming the file, not a disk read.
        let mut broken = o.clone();
        broken.files.pop();
        let e = open_optics(&broken, &hash).err().expect("refused").to_string();
        assert!(e.contains("job:clear.toml") && e.contains("not among the job's files"), "{e}");
        let mut old = o.clone();
        old.build_version = "0.0.1".into();
        assert!(matches!(open_optics(&old, &hash), Err(JobError::Build { .. })));
        // Optics under another name, or another spectral setting under this one.
        assert!(matches!(open_optics(&o, "not-its-hash"), Err(JobError::Hash { .. })));
        let mut other = s.spectral.clone();
        other.spectral_nm = vec![450.0];
        assert!(matches!(open_optics(&message(&bundle, &other, None), &hash), Err(JobError::Hash { .. })));
        // The job's hash covers the optics and the view.
        let v = serde_json::to_string(&s.view).unwrap();
        let mut sun = s.view.clone();
        sun.sun_zenith_deg = 61.0;
        assert_ne!(job_hash(&hash, &v), job_hash(&hash, &serde_json::to_string(&sun).unwrap()));
        assert_ne!(job_hash(&hash, &v), job_hash(&optics_hash(&atm, &other), &v));
        assert!(open_view("{}").is_err());
    }

    #[test]
    fn prepared_optics_travel_bit_for_bit() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/analytic-hg.toml");
        let (atm, bundle) = Atmosphere::load_bundle(&path).unwrap();
        let mut s = Settings::directions(vec![(10.0, 20.0)], 60.0, vec![550.0], 4, 7, false);
        s.spectral.xyz = true;
        s.spectral.band_nm = 20.0;
        let scene = Arc::new(Scene::new(&atm, &s.spectral, &crate::mie::MieCache::shared_by_tests(), &|| {}));
        let optics = Arc::new(Optics::new(&atm, bundle, scene.clone()));
        let o = optics.message();
        assert_eq!(o.scene.len() as u64, scene.encoded_bytes());
        let (_, _, back) = open_optics(o, &optics.hash).unwrap();
        assert_eq!(postcard::to_stdvec(&back.expect("carried")).unwrap(), o.scene);
        let mut broken = o.clone();
        broken.scene.truncate(100);
        assert!(matches!(open_optics(&broken, &optics.hash), Err(JobError::Scene(_))));
        let job = FarmJob::new(optics.clone(), &s.view);
        assert_eq!(job.hash, job_hash(&optics.hash, &job.view_json));
        assert_eq!(job.settings, s);
    }
}
