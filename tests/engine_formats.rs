//! Issue 38's engine formats end to end: `sky bake-luts --texture-format
//! r11g11b10|rgba16f --container ktx2|dds` bakes the same slices four ways;
//! each file is read back by a reader that is not ours (npm's ktx-parse
//! for KTX2, the `ddsfile` crate for DDS), the same format's texels are
//! the same bytes in both containers, the two formats' texels agree within
//! R11G11B10's rounding, and `sky lut sample` gives the same answer from
//! both containers and answers within that rounding across the formats.

use crate::common::sky;
use crate::ktx_readers::ktx_parse;
use serde_json::Value;
use sky::lut::{r11g11b10, rgba16f};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

const FORMATS: [&str; 2] = ["r11g11b10", "rgba16f"];
const CONTAINERS: [&str; 2] = ["ktx2", "dds"];

/// A texture file as a reader other than ours sees it: its format number
/// (vkFormat, or the DXGI format mapped to it), sizes and level-0 bytes.
#[derive(Debug, PartialEq)]
struct Seen {
    vk_format: u64,
    size: (u64, u64, u64),
    data: Vec<u8>,
}

fn read_independently(path: &Path) -> Seen {
    if path.extension().is_some_and(|e| e == "dds") {
        let d = ddsfile::Dds::read(std::fs::File::open(path).unwrap()).unwrap();
        let vk_format = match d.get_dxgi_format() {
            Some(ddsfile::DxgiFormat::R11G11B10_Float) => 122,
            Some(ddsfile::DxgiFormat::R16G16B16A16_Float) => 97,
            other => panic!("{}: DXGI format {other:?}", path.display()),
        };
        assert_eq!(d.get_num_mipmap_levels(), 1, "{}", path.display());
        let size = (d.get_width().into(), d.get_height().into(), d.get_num_array_layers().into());
        Seen { vk_format, size, data: d.data }
    } else {
        let r = ktx_parse(path, true);
        let hex = r["level0Hex"].as_str().unwrap();
        let data = (0..hex.len() / 2).map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap()).collect();
        let n = |k: &str| r[k].as_u64().unwrap();
        Seen { vk_format: n("vkFormat"), size: (n("pixelWidth"), n("pixelHeight"), n("layerCount")), data }
    }
}

/// RGB of each texel of level-0 bytes in format `vk_format`.
fn texels(vk_format: u64, data: &[u8]) -> Vec<[f32; 3]> {
    match vk_format {
        122 => data.chunks_exact(4).map(|b| r11g11b10::unpack(u32::from_le_bytes(b.try_into().unwrap()))).collect(),
        97 => data
            .chunks_exact(8)
            .map(|b| {
                let v = rgba16f::unpack([0, 2, 4, 6].map(|i| u16::from_le_bytes([b[i], b[i + 1]])));
                [v[0], v[1], v[2]]
            })
            .collect(),
        other => panic!("vkFormat {other}"),
    }
}

/// R11G11B10's rounding of a value stored from `exact`: half a unit in the
/// last place of a 6-bit (R, G) or 5-bit (B) mantissa, relative, or half
/// the smallest denormal (2^-14 · 2^-mantissa / 2) near zero.
fn r11g11b10_rounding(channel: usize, exact: f64) -> f64 {
    let mantissa_bits = if channel == 2 { 5 } else { 6 };
    let half_ulp = 2f64.powi(-mantissa_bits - 1);
    (exact.abs() * half_ulp).max(2f64.powi(-14 - mantissa_bits - 1))
}

#[test]
fn both_texture_formats_in_both_containers_read_back_alike() {
    let tmp = tempfile::tempdir().unwrap();
    let bake = root().join("tests/bakes/tiny.toml");
    let cache = tmp.path().join("cache");
    let mut dirs = BTreeMap::new();
    // The first bake renders the slices; the others pack them from the cache.
    for format in FORMATS {
        for container in CONTAINERS {
            let out = tmp.path().join(format!("{format}-{container}"));
            let o = sky(&[
                "bake-luts",
                "--method",
                "monte-carlo",
                bake.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "--cache",
                cache.to_str().unwrap(),
                "--texture-format",
                format,
                "--container",
                container,
            ]);
            assert!(o.status.success(), "{format} {container}: {}", String::from_utf8_lossy(&o.stderr));
            dirs.insert((format, container), out);
        }
    }

    // Per bake: the manifest names the container and the format, every
    // file has the container's extension and reads back independently as
    // the manifest describes it.
    let mut seen = BTreeMap::new();
    for (&(format, container), dir) in &dirs {
        let m: Value = serde_json::from_slice(&std::fs::read(dir.join("manifest.json")).unwrap()).unwrap();
        assert_eq!(m["container"], container);
        let check = sky(&["lut", "check", dir.join("manifest.json").to_str().unwrap()]);
        assert!(check.status.success(), "{}", String::from_utf8_lossy(&check.stderr));
        let sky_format = if format == "rgba16f" { 97 } else { 122 };
        let mut entries: Vec<(&Value, u64, u64)> = Vec::new();
        for s in m["skies"].as_array().unwrap() {
            assert_eq!(s["vk_format"], sky_format);
            entries.push((s, s["layers"].as_u64().unwrap(), sky_format));
        }
        let fog = &m["fog"];
        entries.push((fog, fog["layers"].as_u64().unwrap(), 97));
        entries.push((&fog["attenuation"], fog["attenuation"]["layers"].as_array().unwrap().len() as u64, 97));
        entries.push((&m["transmittance"], m["transmittance"]["layers"].as_array().unwrap().len() as u64, 97));
        entries.push((&m["ambient_file"], m["ambient_file"]["layers"].as_array().unwrap().len() as u64, 97));
        for (e, layers, vk_format) in entries {
            let file = e["file"].as_str().unwrap();
            assert!(file.ends_with(&format!(".{container}")), "{file} in a {container} bake");
            let s = read_independently(&dir.join(file));
            let size = (e["width"].as_u64().unwrap(), e["height"].as_u64().unwrap(), layers);
            assert_eq!((s.vk_format, s.size), (vk_format, size), "{format} {container} {file}");
            assert_eq!(e["vk_format"], vk_format, "{file}");
            let stem = file.rsplit_once('.').unwrap().0.to_string();
            seen.insert((format, container, stem), s);
        }
    }

    // The same format holds the same bytes in both containers; across the
    // formats the sky texels agree within R11G11B10's rounding (RGBA16F's
    // own, 2^-11 relative, is 16 to 32 times finer), everything else is
    // RGBA16F in both and equal.
    let mut sky_texels = 0;
    for ((format, container, stem), s) in &seen {
        if *container == "dds" {
            assert_eq!(s.data, seen[&(*format, "ktx2", stem.clone())].data, "{format} {stem}: DDS and KTX2 differ");
        }
        if *format != "rgba16f" || *container != "ktx2" {
            continue;
        }
        let other = &seen[&("r11g11b10", "ktx2", stem.clone())];
        if other.vk_format == 97 {
            assert_eq!(s.data, other.data, "{stem}");
            continue;
        }
        let (fine, coarse) = (texels(97, &s.data), texels(122, &other.data));
        assert_eq!(fine.len(), coarse.len());
        for (i, (a, b)) in fine.iter().zip(&coarse).enumerate() {
            for c in 0..3 {
                let (a, b) = (f64::from(a[c]), f64::from(b[c]));
                // (a is itself rounded: the bound taken a little wider.)
                let bound = r11g11b10_rounding(c, a) * (1.0 + 2f64.powi(-10)) + a.abs() * 2f64.powi(-10);
                assert!((a - b).abs() <= bound, "{stem} texel {i} channel {c}: RGBA16F {a}, R11G11B10 {b}");
            }
        }
        sky_texels += fine.len();
    }
    assert_eq!(sky_texels, 2 * 4 * 16 * 64, "both skies compared");

    // `sky lut sample` through the decoder: identical from both containers;
    // across formats the sky's RGB within R11G11B10's rounding of the
    // value (interpolation weights are non-negative and sum to one, between
    // slices geometric: a relative bound carries through), and the rest
    // (fog, ambient, sun: RGBA16F or manifest numbers in both) equal.
    // (The tiny bake's plane-parallel skies are dark with the sun below the horizon.)
    let cases = [
        ("20", "0", "0", "60,90"),
        ("3.5", "0.4", "0", "85,10"),
        ("1.5", "1", "0", "40,180"),
        ("55", "0.7", "0", "5,300"),
    ];
    for (elevation, haziness, cloudiness, direction) in cases {
        let mut answers = BTreeMap::new();
        for (&(format, container), dir) in &dirs {
            let m = dir.join("manifest.json");
            let args = [
                "lut",
                "sample",
                m.to_str().unwrap(),
                "--sun-elevation-deg",
                elevation,
                "--haziness",
                haziness,
                "--cloudiness",
                cloudiness,
                "--direction",
                direction,
                "--depth-m",
                "3000",
                "--json",
            ];
            let o = sky(&args);
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            let v: Value = serde_json::from_slice(&o.stdout).unwrap();
            answers.insert((format, container), v);
        }
        for format in FORMATS {
            assert_eq!(
                answers[&(format, "ktx2")],
                answers[&(format, "dds")],
                "{format} at {elevation} deg {direction}"
            );
        }
        let (mut fine, mut coarse) = (answers[&("rgba16f", "ktx2")].clone(), answers[&("r11g11b10", "ktx2")].clone());
        let rgb =
            |v: &Value| -> Vec<f64> { v["rgb"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect() };
        let (a, b) = (rgb(&fine), rgb(&coarse));
        for c in 0..3 {
            let bound = r11g11b10_rounding(c, a[c]) * (1.0 + 2f64.powi(-10)) + a[c].abs() * 2f64.powi(-10);
            assert!((a[c] - b[c]).abs() <= bound, "{elevation} deg {direction} channel {c}: {} vs {}", a[c], b[c]);
        }
        assert!(a.iter().all(|&x| x > 0.0), "a lit sky: {a:?}");
        for v in [&mut fine, &mut coarse] {
            let o = v.as_object_mut().unwrap();
            o.remove("rgb");
            o.remove("xyz");
        }
        assert_eq!(fine, coarse, "fog, ambient and sun do not depend on the sky's texture format");
    }
}
