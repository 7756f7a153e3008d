//! The second independent KTX2 reader: npm's `ktx-parse` (2.0.0, pinned in
//! tests/ktx_parse/package-lock.json) reads files from `sky::lut::ktx2`
//! through `node tests/ktx_parse/check.mjs`. (The first, the `ktx2` crate,
//! is in the module's unit tests.)
//!
//! Needs `node` and `npm`: the test installs the pinned package itself
//! (`npm ci --prefix tests/ktx_parse`, once, if it is missing; `make test`
//! also runs it). Without node the test fails, on purpose: CI must not
//! skip it.

use serde_json::{json, Value};
use sky::colour::ColourSpace;
use sky::lut::ktx2::{self, ArrayTexture};
use sky::lut::texels::{texel_index, Texels};
use sky::lut::{r11g11b10, rgba16f};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Installs the pinned ktx-parse into `dir` if it is not there (once per
/// test process: the tests of this file share it).
fn install_ktx_parse(dir: &Path) {
    static INSTALLED: std::sync::OnceLock<()> = std::sync::OnceLock::new();
    INSTALLED.get_or_init(|| {
        if dir.join("node_modules/ktx-parse/package.json").exists() {
            return;
        }
        let out = Command::new("npm")
            .args(["ci", "--prefix"])
            .arg(dir)
            .args(["--no-audit", "--no-fund"])
            .output()
            .unwrap_or_else(|e| panic!("cannot run npm ({e}) to install ktx-parse: install Node.js and npm (e.g. apt-get install nodejs npm)"));
        assert!(out.status.success(), "npm ci --prefix {} failed: {}", dir.display(), String::from_utf8_lossy(&out.stderr));
    });
}

/// Runs check.mjs on `file` (with a time limit: ktx-parse loops forever on
/// some malformed input) and parses its JSON.
pub(crate) fn ktx_parse(file: &Path, data: bool) -> Value {
    let dir = root().join("tests/ktx_parse");
    install_ktx_parse(&dir);
    let mut cmd = Command::new("node");
    cmd.arg(dir.join("check.mjs")).arg(file);
    if data {
        cmd.arg("--data");
    }
    let mut child = cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap_or_else(|e| {
        panic!("cannot run node ({e}): install Node.js (and run `npm ci --prefix tests/ktx_parse`)")
    });
    let start = Instant::now();
    // Drain stdout on a thread so a large output cannot block the child.
    let mut stdout = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut stdout, &mut s).map(|_| s)
    });
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if start.elapsed() > Duration::from_secs(60) {
            child.kill().ok();
            panic!("ktx-parse did not finish within 60 s on {}", file.display());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let out = child.wait_with_output().unwrap();
    let stdout = reader.join().unwrap().unwrap();
    assert!(out.status.success(), "check.mjs failed on {}: {}", file.display(), String::from_utf8_lossy(&out.stderr));
    serde_json::from_str(&stdout).unwrap()
}

fn sample(bit_offset: u32, bits: u32, channel: u32, lower: u32) -> Value {
    json!({"bitOffset": bit_offset, "bitLength": bits - 1, "channelType": channel, "samplePosition": [0, 0, 0, 0], "sampleLower": lower, "sampleUpper": 0x3F80_0000u32})
}

/// A 32 × 128 × 64 R11G11B10 array (the talk's sunny size) and a small
/// RGBA16F one: header, level index, DFD, keys in file order and the texels.
#[test]
fn ktx_parse_reads_our_files() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = r#"{"basis":"hazed","colour_space":"rec2020","scale":0.001}"#;

    let (w, h, l) = (32u32, 128u32, 64u32);
    let rgb: Vec<[f64; 3]> =
        (0..w * h * l).map(|i| [f64::from(i % w), f64::from((i / w) % h), f64::from(i / (w * h))]).collect();
    let (words, _) = r11g11b10::pack_array(&rgb).unwrap();
    let path = dir.path().join("hazed.ktx2");
    let size = ktx2::write(
        &path,
        &ArrayTexture {
            width: w,
            height: h,
            layers: l,
            colour_space: ColourSpace::Rec2020,
            texels: Texels::B10G11R11(&words),
            sky_json: manifest,
        },
    )
    .unwrap();
    let r = ktx_parse(&path, true);
    assert_eq!(r["fileByteLength"], size);
    for (key, want) in [
        ("vkFormat", 122),
        ("typeSize", 4),
        ("pixelWidth", 32),
        ("pixelHeight", 128),
        ("pixelDepth", 0),
        ("layerCount", 64),
        ("faceCount", 1),
        ("levelCount", 1),
        ("supercompressionScheme", 0),
    ] {
        assert_eq!(r[key], want, "{key}");
    }
    let level = &r["levels"][0];
    assert_eq!(r["levels"].as_array().unwrap().len(), 1);
    assert_eq!(level["byteLength"], w * h * l * 4);
    assert_eq!(level["uncompressedByteLength"], w * h * l * 4);
    assert_eq!(level["byteOffset"].as_u64().unwrap() % 4, 0);
    assert_eq!(level["byteOffset"].as_u64().unwrap() + u64::from(w * h * l * 4), size);
    let dfd = &r["dataFormatDescriptor"][0];
    assert_eq!(
        *dfd,
        json!({
            "vendorId": 0, "descriptorType": 0, "versionNumber": 2,
            "colorModel": 1, "colorPrimaries": 4, "transferFunction": 1, "flags": 0,
            "texelBlockDimension": [0, 0, 0, 0], "bytesPlane": [4, 0, 0, 0, 0, 0, 0, 0],
            "samples": [sample(0, 11, 0x80, 0), sample(11, 11, 0x81, 0), sample(22, 10, 0x82, 0)],
        })
    );
    let writer = format!("sky {}", env!("CARGO_PKG_VERSION"));
    assert_eq!(
        r["keyValue"],
        json!([["KTXorientation", "rd"], ["KTXwriter", writer], ["sky", format!("{manifest}\0")]])
    );
    let hex = r["level0Hex"].as_str().unwrap();
    let back: Vec<u32> =
        (0..hex.len() / 8).map(|i| u32::from_str_radix(&hex[8 * i..8 * i + 8], 16).unwrap().swap_bytes()).collect();
    assert_eq!(back, words);
    // Texel (x, y) of layer 9 holds (x, y, 9) (row-major, layer after layer).
    assert_eq!(r11g11b10::unpack(back[texel_index(w, h, 9, 5, 100)]), [5.0, 100.0, 9.0]);

    let rgb: Vec<[f64; 3]> = (0..4 * 3 * 2).map(|i| [f64::from(i), 0.25, 7e4]).collect();
    let (halves, _) = rgba16f::pack_array(&rgb).unwrap();
    let path = dir.path().join("godot.ktx2");
    ktx2::write(
        &path,
        &ArrayTexture {
            width: 4,
            height: 3,
            layers: 2,
            colour_space: ColourSpace::Xyz,
            texels: Texels::Rgba16f(&halves),
            sky_json: "{}",
        },
    )
    .unwrap();
    let r = ktx_parse(&path, true);
    assert_eq!(
        (r["vkFormat"].as_u64(), r["typeSize"].as_u64(), r["layerCount"].as_u64()),
        (Some(97), Some(2), Some(2))
    );
    assert_eq!(r["levels"][0]["byteOffset"].as_u64().unwrap() % 8, 0);
    let dfd = &r["dataFormatDescriptor"][0];
    assert_eq!((dfd["colorPrimaries"].as_u64(), dfd["bytesPlane"][0].as_u64()), (Some(5), Some(8)));
    // Signed samples: ktx-parse reads the bounds as int32 (−1.0f = 0xBF800000).
    let signed = |ch: u32, off: u32| json!({"bitOffset": off, "bitLength": 15, "channelType": ch, "samplePosition": [0, 0, 0, 0], "sampleLower": 0xBF80_0000u32 as i32, "sampleUpper": 0x3F80_0000});
    assert_eq!(dfd["samples"], json!([signed(0xC0, 0), signed(0xC1, 16), signed(0xC2, 32), signed(0xCF, 48)]));
    let hex = r["level0Hex"].as_str().unwrap();
    let back: Vec<u16> =
        (0..hex.len() / 4).map(|i| u16::from_str_radix(&hex[4 * i..4 * i + 4], 16).unwrap().swap_bytes()).collect();
    assert_eq!(back, halves.concat());
}
