//! The library's render session: optics prepared once per atmosphere and
//! spectral setting, any number of views rendered with them, bit-identical
//! to rendering each view directly.

use sky::atmosphere::Atmosphere;
use sky::directions::camera::Camera;
use sky::farm::coordinator::{Options, WorkerSpec};
use sky::farm::job::optics_hash;
use sky::mie::MieCache;
use sky::render::{self, Settings};
use sky::session::{OpticsCache, Session};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

#[test]
fn a_session_prepares_optics_once_for_many_views() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("atmospheres/analytic-hg.toml");
    let (atm, bundle) = Atmosphere::load_bundle(&path).unwrap();
    let mut s = Settings::directions(vec![], 40.0, vec![550.0], 8, 3, false);
    s.spectral.xyz = true;
    s.spectral.band_nm = 47.0;
    s.view.camera = Camera::Fisheye;
    (s.view.width, s.view.height) = (6, 4);
    let mie = MieCache::shared_by_tests();
    let cache = OpticsCache::default();
    let local = vec![WorkerSpec::Local { threads: 2 }];
    let session = Session::new(
        atm.clone(),
        bundle.clone(),
        s.spectral.clone(),
        &cache,
        &mie,
        local.clone(),
        Options::default(),
        &|| {},
    );
    // Three views (sun zenith 20, 60, 85): the same optics, and each view
    // bit-identical to a direct render with those optics.
    for sun in [20.0, 60.0, 85.0] {
        let mut view = s.view.clone();
        view.sun_zenith_deg = sun;
        let got = session.render_view(&view, Arc::new(AtomicBool::new(false))).unwrap();
        let want = render::render(&session.scene, &view, &AtomicBool::new(false), &|| {}).unwrap();
        assert!(got.image == want, "sun zenith {sun}: the session's render differs from a direct one");
    }
    // A second session of the same atmosphere and spectral setting prepares
    // nothing; another spectral setting does.
    let again = Session::new(
        atm.clone(),
        bundle.clone(),
        s.spectral.clone(),
        &cache,
        &mie,
        local.clone(),
        Options::default(),
        &|| {},
    );
    assert!(Arc::ptr_eq(&again.scene, &session.scene));
    assert_eq!(cache.prepared(), 1);
    let mut other = s.spectral.clone();
    other.spectral_nm = vec![450.0];
    assert_ne!(optics_hash(&atm, &other), optics_hash(&atm, &s.spectral));
    let _ = Session::new(atm, bundle, other, &cache, &mie, local, Options::default(), &|| {});
    assert_eq!(cache.prepared(), 2);
}

/// What a farm job of one view weighs: the optics and the view, as protocol
/// 1 sent them with the first task of every view, so a bake-shaped run (64
/// views of one atmosphere) sent 64 copies to each worker; protocol 2 sends
/// the optics once (tests/farm.rs counts it). A figure for the farm's issue
/// (`cargo test --release --test suite -- session:: --ignored --nocapture`).
#[test]
#[ignore = "a measurement: prints the bytes of one view's job for the shipped clear sky"]
fn job_bytes_per_view() {
    use prost::Message;
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("atmospheres/clear.toml");
    let (atm, bundle) = Atmosphere::load_bundle(&path).unwrap();
    let mut s = Settings::directions(vec![], 60.0, vec![], 8, 3, false);
    s.spectral.xyz = true;
    s.spectral.wavelength_sampling = render::WavelengthSampling::Hero;
    s.view.camera = Camera::Equirect;
    (s.view.width, s.view.height) = (32, 128);
    let session = Session::new(
        atm,
        bundle,
        s.spectral.clone(),
        &OpticsCache::default(),
        &MieCache::shared_by_tests(),
        vec![],
        Options::default(),
        &|| {},
    );
    let job = session.job(&s.view);
    let optics = job.optics.message();
    let bytes = optics.encoded_len() + job.view_json.len();
    eprintln!(
        "one view's job: {bytes} bytes ({:.1} MB; prepared optics {:.1} MB); 64 views as protocol 1 sent them: {:.0} MB per worker",
        bytes as f64 / 1e6,
        optics.scene.len() as f64 / 1e6,
        64.0 * bytes as f64 / 1e6
    );
}

/// The session's optics cache is bounded by memory like a worker's: past
/// its budget the least recently used optics nobody holds are evicted, and
/// optics a session holds never are.
#[test]
fn the_optics_cache_is_bounded_by_memory() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("atmospheres/analytic-hg.toml");
    let (atm, _) = Atmosphere::load_bundle(&path).unwrap();
    let spectral = |nm: f64| Settings::directions(vec![], 40.0, vec![nm], 8, 3, false).spectral;
    let (a, b, c) = (spectral(450.0), spectral(550.0), spectral(650.0));
    let mie = MieCache::shared_by_tests();
    // A budget smaller than any optics: only what is held stays.
    let cache = OpticsCache::with_budget(1);
    let held_a = cache.get(&atm, &a, &mie, &|| {});
    let held_b = cache.get(&atm, &b, &mie, &|| {});
    // Both held: both kept, over the budget.
    assert!(cache.contains(&atm, &a) && cache.contains(&atm, &b));
    assert_eq!(cache.bytes(), held_a.encoded_bytes() + held_b.encoded_bytes());
    // Let a go: the next optics evict it, not the held b.
    drop(held_a);
    let _c = cache.get(&atm, &c, &mie, &|| {});
    assert!(!cache.contains(&atm, &a) && cache.contains(&atm, &b) && cache.contains(&atm, &c));
    assert_eq!(cache.prepared(), 3);
    // b is still the very same optics.
    assert!(Arc::ptr_eq(&held_b, &cache.get(&atm, &b, &mie, &|| {})));
    assert_eq!(cache.prepared(), 3);
}
