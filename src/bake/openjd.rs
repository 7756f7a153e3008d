//! A bake as an Open Job Description job (the open job format of AWS
//! Deadline Cloud; specification `jobtemplate-2023-09`,
//! <https://github.com/OpenJobDescription/openjd-specifications/wiki>), for
//! studios whose farm manager already runs their renders.
//!
//! The template has two steps:
//! - `Render`: one task per (basis sky, slice) and one per (basis sky, fog
//!   slice), a STRING task parameter `Slice` ranging over `NAME:INDEX` and
//!   `NAME:fog:INDEX`, each running `sky bake-luts BAKE --slice SLICE` into
//!   the shared content-addressed slice cache;
//! - `Pack`: depends on `Render` and runs `sky bake-luts BAKE
//!   --pack-only`, which packs the cached slices and fails, naming them, if
//!   any is missing (it renders no slice, so a lost task cannot hide in it;
//!   it does compute each sky's Fog from its Shadowed Fog by quadrature,
//!   and the fog falloff's fit, whose reference renders are seconds).
//!
//! The files a job packs are byte-identical to a direct `sky bake-luts` of
//! the same bake: a slice's cache key and its render do not depend on
//! which process rendered it.
//!
//! YAML is written by hand: every scalar is a JSON string (YAML 1.2 is a
//! superset of JSON), so no quoting rule of YAML can bite.

use super::file::{BakeFile, Quality};
use crate::colour::ColourSpace;
use crate::lut::container::{Container, TextureFormat};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The specification version the template follows.
pub const SPECIFICATION_VERSION: &str = "jobtemplate-2023-09";

/// The file name of the template in the bake's output folder.
pub const TEMPLATE_FILE: &str = "bake.openjd.yaml";

/// The file name of the job parameters of this machine, beside the
/// template (`openjd run ... -p file://bake.openjd.params.json`).
pub const PARAMS_FILE: &str = "bake.openjd.params.json";

/// What the template's job parameters default to. A PATH default must be
/// relative and inside the template's folder (`openjd` refuses an absolute
/// one or one that walks up); a path elsewhere gets no default, and its
/// value goes into the parameter file instead. A farm manager maps paths
/// with its own rules.
#[derive(Debug, Clone)]
pub struct PlanDefaults {
    /// The `sky` command the farm's hosts run (a STRING: a program on the
    /// hosts' PATH or an absolute path on them).
    pub sky_executable: String,
    pub bake_file: Option<PathBuf>,
    pub out_dir: PathBuf,
    pub cache_dir: Option<PathBuf>,
    pub quality: Quality,
    pub method: super::Method,
    pub colour_space: ColourSpace,
    /// The texture format and container of the pack step.
    pub encoding: crate::lut::container::Encoding,
}

/// A YAML scalar: a JSON string.
fn q(s: &str) -> String {
    serde_json::to_string(s).expect("a string always serialises")
}

/// A path as a template value, with `/` separators on every platform.
fn p(path: &Path) -> String {
    let parts: Vec<String> = path.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    let joined = if parts.is_empty() { ".".to_string() } else { parts.join("/") };
    q(joined.strip_prefix("//").map_or(joined.as_str(), |s| s))
}

/// ` default: VALUE` on its own line, or nothing.
fn default_path(path: &Option<PathBuf>) -> String {
    path.as_ref().map_or(String::new(), |d| format!("\n  default: {}", p(d)))
}

fn list(items: impl IntoIterator<Item = String>) -> String {
    format!("[{}]", items.into_iter().collect::<Vec<_>>().join(", "))
}

/// The render tasks of `bake`, as `--slice` values: every basis sky's
/// slices, then its fog slices (see [`SliceId`](super::SliceId)). By the
/// transport solver a basis sky's slices are one task (`NAME:0,NAME:1,...`):
/// they share one solution, which a task per slice would solve 64 times.
pub fn render_tasks(bake: &BakeFile, method: super::Method) -> Vec<String> {
    let per_slice = |s: &super::BasisSky| (0..s.slices).map(move |i| format!("{}:{i}", s.name)).collect::<Vec<_>>();
    let sky: Vec<String> = match method {
        super::Method::MonteCarlo => bake.skies.iter().flat_map(per_slice).collect(),
        super::Method::Deterministic => bake.skies.iter().map(|s| per_slice(s).join(",")).collect(),
    };
    let fog = bake.skies.iter().flat_map(|s| (0..s.slices).map(move |i| format!("{}:fog:{i}", s.name)));
    sky.into_iter().chain(fog).collect()
}

/// The job template of `bake` (see the module documentation).
pub fn job_template(bake: &BakeFile, job_name: &str, d: &PlanDefaults) -> String {
    let slices = render_tasks(bake, d.method).into_iter().map(|t| q(&t));
    let common = [
        "{{Param.BakeFile}}",
        "--out",
        "{{Param.OutDir}}",
        "--cache",
        "{{Param.CacheDir}}",
        "--quality",
        "{{Param.Quality}}",
        "--method",
        "{{Param.Method}}",
    ];
    let args = |extra: &[&str]| list(["bake-luts"].iter().chain(common.iter()).chain(extra.iter()).map(|a| q(a)));
    let mut t = String::new();
    let w = &mut t;
    // `write!` to a String cannot fail.
    let _ = writeln!(
        w,
        "# An Open Job Description job template written by `sky bake-luts --plan openjd` (sky {}).",
        env!("CARGO_PKG_VERSION")
    );
    let _ = writeln!(w, "# Render: one task per (basis sky, slice) and per fog slice into the shared slice cache; Pack: the LUT files and");
    let _ =
        writeln!(w, "# manifest.json from the cache, after every Render task. Check it with `openjd check`, run it");
    let _ = writeln!(
        w,
        "# locally with `openjd run {TEMPLATE_FILE} --step Pack --run-dependencies`, or submit it to a farm"
    );
    let _ =
        writeln!(w, "# manager that reads Open Job Description (AWS Deadline Cloud). Relative paths are relative to");
    let _ = writeln!(w, "# this file's folder; the hosts must all see the cache folder.");
    let _ = writeln!(w, "specificationVersion: {}", q(SPECIFICATION_VERSION));
    let _ = writeln!(w, "name: {}", q(job_name));
    let _ = writeln!(w, "parameterDefinitions:");
    let _ = writeln!(
        w,
        "- name: \"SkyExecutable\"\n  type: \"STRING\"\n  description: \"The sky command on the farm's hosts (on their PATH, or an absolute path there)\"\n  default: {}",
        q(&d.sky_executable)
    );
    // The PATH parameters: name, object type, data flow, description, default.
    let paths = [
        (
            "BakeFile",
            "FILE",
            "IN",
            "The bake file (its atmosphere files are found relative to it)",
            d.bake_file.clone(),
        ),
        ("OutDir", "DIRECTORY", "OUT", "Where Pack writes the LUT files and manifest.json", Some(d.out_dir.clone())),
        (
            "CacheDir",
            "DIRECTORY",
            "INOUT",
            "The content-addressed slice cache, shared by every task",
            d.cache_dir.clone(),
        ),
    ];
    for (name, object, flow, description, default) in &paths {
        let _ = writeln!(
            w,
            "- name: {}\n  type: \"PATH\"\n  objectType: {}\n  dataFlow: {}\n  description: {}{}",
            q(name),
            q(object),
            q(flow),
            q(description),
            default_path(default)
        );
    }
    let _ = writeln!(
        w,
        "- name: \"Quality\"\n  type: \"STRING\"\n  allowedValues: {}\n  default: {}",
        list([q("draft"), q("final")]),
        q(d.quality.name())
    );
    let _ = writeln!(
        w,
        "- name: \"Method\"\n  type: \"STRING\"\n  allowedValues: {}\n  default: {}",
        list([q("deterministic"), q("monte-carlo")]),
        q(d.method.name())
    );
    let _ = writeln!(
        w,
        "- name: \"ColourSpace\"\n  type: \"STRING\"\n  allowedValues: {}\n  default: {}",
        list(ColourSpace::ALL.iter().map(|c| q(c.name()))),
        q(d.colour_space.name())
    );
    let _ = writeln!(
        w,
        "- name: \"TextureFormat\"\n  type: \"STRING\"\n  allowedValues: {}\n  default: {}",
        list(TextureFormat::ALL.iter().map(|f| q(f.name()))),
        q(d.encoding.texture_format.name())
    );
    let _ = writeln!(
        w,
        "- name: \"Container\"\n  type: \"STRING\"\n  allowedValues: {}\n  default: {}",
        list(Container::ALL.iter().map(|c| q(c.name()))),
        q(d.encoding.container.name())
    );
    let _ = writeln!(w, "steps:");
    let _ = writeln!(w, "- name: \"Render\"\n  parameterSpace:\n    taskParameterDefinitions:\n    - name: \"Slice\"\n      type: \"STRING\"\n      range: {}", list(slices));
    let _ = writeln!(
        w,
        "  script:\n    actions:\n      onRun:\n        command: \"{{{{Param.SkyExecutable}}}}\"\n        args: {}",
        args(&["--slice", "{{Task.Param.Slice}}"])
    );
    let _ = writeln!(w, "- name: \"Pack\"\n  dependencies:\n  - dependsOn: \"Render\"");
    let _ = writeln!(
        w,
        "  script:\n    actions:\n      onRun:\n        command: \"{{{{Param.SkyExecutable}}}}\"\n        args: {}",
        args(&[
            "--colour-space",
            "{{Param.ColourSpace}}",
            "--texture-format",
            "{{Param.TextureFormat}}",
            "--container",
            "{{Param.Container}}",
            "--pack-only"
        ])
    );
    t
}

/// `target` as a PATH default of a template in the folder `from` (both
/// absolute, as `canonicalize` returns them): relative and inside `from`,
/// or None.
pub fn default_within(from: &Path, target: &Path) -> Option<PathBuf> {
    target.strip_prefix(from).ok().map(|r| if r.as_os_str().is_empty() { PathBuf::from(".") } else { r.to_path_buf() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lut::container::Encoding;

    #[test]
    fn path_defaults_stay_inside_the_template_folder() {
        let w = |a: &str, b: &str| default_within(Path::new(a), Path::new(b)).map(|p| p.to_string_lossy().into_owned());
        assert_eq!(w("/a/out", "/a/out/cache").as_deref(), Some("cache"));
        assert_eq!(w("/a/out", "/a/out").as_deref(), Some("."));
        assert_eq!(w("/a/out", "/a/outside/x").as_deref(), None);
        assert_eq!(w("/a/out", "/a/bake.toml").as_deref(), None);
    }

    #[test]
    fn the_template_has_a_task_per_slice_and_quotes_everything() {
        let bake = BakeFile::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bakes/tiny.toml")).unwrap();
        let d = PlanDefaults {
            sky_executable: "/opt/sky: {bin}/sky".into(),
            bake_file: None,
            out_dir: ".".into(),
            cache_dir: Some("cache".into()),
            quality: Quality::Final,
            method: crate::bake::Method::MonteCarlo,
            colour_space: ColourSpace::AcesCg,
            encoding: Encoding { texture_format: TextureFormat::Rgba16f, container: Container::Dds },
        };
        let t = job_template(&bake, "sky bake-luts bake", &d);
        assert!(t.contains("\"--method\", \"{{Param.Method}}\"") && t.contains("default: \"monte-carlo\""), "{t}");
        assert!(t.contains("specificationVersion: \"jobtemplate-2023-09\""), "{t}");
        assert!(t.contains("\"clear:0\", \"clear:1\""), "{t}");
        assert!(t.contains("\"clear:63\", \"hazed:0\"") && t.contains("\"hazed:63\", \"clear:fog:0\""), "{t}");
        assert!(t.contains("\"hazed:fog:62\", \"hazed:fog:63\"]"), "{t}");
        assert!(t.contains("default: \"/opt/sky: {bin}/sky\""), "{t}");
        assert!(t.contains("default: \"final\"") && t.contains("default: \"acescg\""), "{t}");
        assert!(t.contains("\"--slice\", \"{{Task.Param.Slice}}\""), "{t}");
        assert!(t.contains("\"--pack-only\""), "{t}");
        assert!(t.contains("\"--container\", \"{{Param.Container}}\"") && t.contains("default: \"dds\""), "{t}");
        assert!(
            t.contains("\"--texture-format\", \"{{Param.TextureFormat}}\"") && t.contains("default: \"rgba16f\""),
            "{t}"
        );
        assert_eq!(t.matches("dependsOn: \"Render\"").count(), 1);
        assert_eq!(t.matches("default: \"cache\"").count(), 1);
        let bake_param = &t[t.find("name: \"BakeFile\"").unwrap()..t.find("name: \"OutDir\"").unwrap()];
        assert!(!bake_param.contains("default"), "{bake_param}");
        // By the transport solver, a basis sky's slices are one task.
        let solver = job_template(
            &bake,
            "sky bake-luts bake",
            &PlanDefaults { method: crate::bake::Method::Deterministic, ..d },
        );
        let all: Vec<String> = (0..64).map(|i| format!("clear:{i}")).collect();
        assert!(solver.contains(&format!("[\"{}\", \"hazed:0,", all.join(","))), "{solver}");
        assert!(solver.contains("default: \"deterministic\""), "{solver}");
    }
}
