//! A farm job: the atmosphere file with every data file it reads, and the
//! render settings, so a worker never opens a path a coordinator names. Its
//! hash (BLAKE3 of the encoded message) names it in tasks and tiles.

use super::proto;
use crate::atmosphere::{Atmosphere, Bundle};
use crate::render::{Scene, Settings};
use prost::Message;

#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error("job speaks farm protocol {theirs}, this build speaks {ours}")]
    Protocol { theirs: u32, ours: u32 },
    #[error("job is from sky {theirs}, this is sky {ours}: only the same build renders bit-identically")]
    Build { theirs: String, ours: String },
    #[error("job's settings: {0}")]
    Settings(String),
    #[error("job's atmosphere: {0}")]
    Atmosphere(String),
    #[error("job's prepared optics do not decode: {0}")]
    Scene(String),
}

/// Builds the job message (data files sorted by name, so equal jobs encode
/// equally), with the prepared optics when given.
pub fn make(bundle: &Bundle, settings: &Settings, scene: Option<&Scene>) -> proto::Job {
    proto::Job {
        protocol_version: super::PROTOCOL_VERSION,
        build_version: super::build_version(),
        atmosphere_name: bundle.name.clone(),
        atmosphere_toml: bundle.text.clone(),
        files: bundle.files.iter().map(|(name, content)| proto::DataFile { name: name.clone(), content: content.clone() }).collect(),
        settings_json: serde_json::to_string(settings).expect("settings serialise"),
        scene: scene.map(|s| postcard::to_stdvec(s).expect("scenes serialise")).unwrap_or_default(),
    }
}

/// The job's prepared optics, if it carries them.
pub fn scene(job: &proto::Job) -> Result<Option<Scene>, JobError> {
    if job.scene.is_empty() {
        return Ok(None);
    }
    postcard::from_bytes(&job.scene).map(Some).map_err(|e| JobError::Scene(e.to_string()))
}

/// The job's hash, hex.
pub fn hash(job: &proto::Job) -> String {
    blake3::hash(&job.encode_to_vec()).to_hex().to_string()
}

/// Checks versions and unpacks a job.
pub fn open(job: &proto::Job) -> Result<(Atmosphere, Settings), JobError> {
    if job.protocol_version != super::PROTOCOL_VERSION {
        return Err(JobError::Protocol { theirs: job.protocol_version, ours: super::PROTOCOL_VERSION });
    }
    if job.build_version != super::build_version() {
        return Err(JobError::Build { theirs: job.build_version.clone(), ours: super::build_version() });
    }
    let settings: Settings = serde_json::from_str(&job.settings_json).map_err(|e| JobError::Settings(e.to_string()))?;
    if settings.view.width == 0 || settings.view.height == 0 || settings.view.spp == 0 {
        return Err(JobError::Settings(format!("empty image {}x{} at {} spp", settings.view.width, settings.view.height, settings.view.spp)));
    }
    let bundle = Bundle { name: job.atmosphere_name.clone(), text: job.atmosphere_toml.clone(), files: job.files.iter().map(|f| (f.name.clone(), f.content.clone())).collect() };
    let atm = Atmosphere::from_bundle(&bundle).map_err(|e| JobError::Atmosphere(e.to_string()))?;
    Ok((atm, settings))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::camera::Camera;
    use std::path::Path;

    #[test]
    fn jobs_round_trip_without_touching_the_disk() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/clear.toml");
        let (atm, bundle) = Atmosphere::load_bundle(&path).unwrap();
        assert!(bundle.files.len() >= 3, "{:?}", bundle.files.keys());
        let mut s = Settings::directions(vec![(10.0, 20.0)], 60.0, vec![550.0], 4, 7, false);
        s.view.camera = Camera::Fisheye;
        let job = make(&bundle, &s, None);
        assert_eq!(hash(&job), hash(&make(&bundle, &s, None)));
        assert!(scene(&job).unwrap().is_none());
        let (atm2, s2) = open(&job).unwrap();
        assert_eq!(atm2.content_hash, atm.content_hash);
        assert_eq!(s2, s);
        // A missing data file is an error naming the job, not a disk read.
        let mut broken = job.clone();
        broken.files.pop();
        let e = open(&broken).unwrap_err().to_string();
        assert!(e.contains("job:clear.toml") && e.contains("not among the job's files"), "{e}");
        let mut old = job.clone();
        old.build_version = "0.0.1".into();
        assert!(matches!(open(&old), Err(JobError::Build { .. })));
    }

    #[test]
    fn prepared_optics_travel_bit_for_bit() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("atmospheres/analytic-hg.toml");
        let (atm, bundle) = Atmosphere::load_bundle(&path).unwrap();
        let mut s = Settings::directions(vec![(10.0, 20.0)], 60.0, vec![550.0], 4, 7, false);
        s.spectral.xyz = true;
        s.spectral.band_nm = 20.0;
        let scene = Scene::new(&atm, &s.spectral, &crate::mie::MieCache::new(None), &|| {});
        let job = make(&bundle, &s, Some(&scene));
        let back = super::scene(&job).unwrap().expect("carried");
        assert_eq!(postcard::to_stdvec(&back).unwrap(), job.scene);
        let mut broken = job.clone();
        broken.scene.truncate(100);
        assert!(matches!(super::scene(&broken), Err(JobError::Scene(_))));
    }
}
