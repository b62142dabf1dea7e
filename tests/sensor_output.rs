//! Sensor outputs: 16-bit PNG round trip, DNG structure (and dcraw, required in CI,
//! decodes it to the same numbers), bilinear demosaic, preview.

use camsim::optical_image::Rect;
use camsim::sensor::config::SensorConfig;
use camsim::sensor::output::{
    demosaic_bilinear, dng_bytes, dng_color, read_png16, write_dng, write_preview_png,
    write_raw_png,
};
use camsim::sensor::pipeline::simulate_flat;
use camsim::sensor::{Exposure, Sources};
use camsim::spectrum::{Spectrum, WavelengthGrid};
use std::path::Path;

fn imx363() -> SensorConfig {
    SensorConfig::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("sensors/imx363.kdl")).unwrap()
}

fn frame(cfg: &SensorConfig, w: Rect) -> camsim::image::SensorImage {
    let g = WavelengthGrid::new(400.0, 700.0, 10.0).unwrap();
    simulate_flat(cfg, &Spectrum::constant("flat", 0.01), &g, w, 3)
        .unwrap()
        .image
}

/// Minimal TIFF IFD reader (independent of the writer): tag → (type, count, value bytes).
fn ifd(b: &[u8]) -> std::collections::BTreeMap<u16, (u16, u32, Vec<u8>)> {
    assert_eq!(&b[..4], b"II*\0");
    let off = u32::from_le_bytes(b[4..8].try_into().unwrap()) as usize;
    let n = u16::from_le_bytes(b[off..off + 2].try_into().unwrap()) as usize;
    let mut m = std::collections::BTreeMap::new();
    let mut last = 0u16;
    for i in 0..n {
        let e = &b[off + 2 + 12 * i..][..12];
        let tag = u16::from_le_bytes([e[0], e[1]]);
        assert!(tag > last, "tags must be sorted ascending");
        last = tag;
        let ty = u16::from_le_bytes([e[2], e[3]]);
        let count = u32::from_le_bytes(e[4..8].try_into().unwrap());
        let size = [0, 1, 1, 2, 4, 8, 1, 1, 2, 4, 8][ty as usize] * count as usize;
        let data = if size <= 4 {
            e[8..8 + size].to_vec()
        } else {
            let o = u32::from_le_bytes(e[8..12].try_into().unwrap()) as usize;
            b[o..o + size].to_vec()
        };
        m.insert(tag, (ty, count, data));
    }
    m
}

#[test]
fn raw_png_round_trips_and_dng_has_cfa_black_white_and_pixels() {
    let cfg = imx363();
    // odd window origin: the DNG CFA pattern must follow the window phase
    let w = Rect::new(2001, 1500, 40, 30);
    let im = frame(&cfg, w);
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("raw.png");
    write_raw_png(&p, &im).unwrap();
    let (pw, ph, v) = read_png16(&p).unwrap();
    assert_eq!((pw, ph), (40, 30));
    assert!(v.iter().zip(&im.dv).all(|(a, b)| *a as f32 == *b));

    let b = dng_bytes(&im, &cfg).unwrap();
    let t = ifd(&b);
    let long = |tag: u16| u32::from_le_bytes(t[&tag].2[..4].try_into().unwrap());
    assert_eq!(long(256), 40);
    assert_eq!(long(257), 30);
    assert_eq!(u16::from_le_bytes([t[&262].2[0], t[&262].2[1]]), 32803);
    assert_eq!(long(50717), 1023);
    let bl = &t[&50714].2;
    let (num, den) = (
        u32::from_le_bytes(bl[..4].try_into().unwrap()),
        u32::from_le_bytes(bl[4..8].try_into().unwrap()),
    );
    assert_eq!(num as f64 / den as f64, 64.0);
    // grbg anchored at (0,0); window origin (2001, 1500) → row 0 starts at x odd: R G / G B.
    assert_eq!(t[&33422].2, vec![0, 1, 1, 2]);
    assert_eq!(t[&33421].2, vec![2, 0, 2, 0]);
    let so = long(273) as usize;
    let px: Vec<u16> = b[so..so + 40 * 30 * 2]
        .chunks(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    assert!(px.iter().zip(&im.dv).all(|(a, b)| *a as f32 == *b));
    assert_eq!(b.len(), so + 40 * 30 * 2);
}

/// dcraw (an independent DNG reader) must identify the DNG and decode the raw
/// values unchanged: `dcraw -D -4 -t 0 -c` writes the undemosaiced values as
/// 16-bit PGM. `.ci/run` installs dcraw; without it the test fails when `CI`
/// is set and skips with a note otherwise.
#[test]
fn dcraw_reads_the_dng() {
    if std::process::Command::new("dcraw").output().is_err() {
        assert!(
            std::env::var_os("CI").is_none(),
            "dcraw must be installed in CI (.ci/run installs the Debian package 'dcraw')"
        );
        eprintln!("note: dcraw not installed; skipping the external DNG check (CI would fail)");
        return;
    }
    let cfg = imx363();
    let im = frame(&cfg, Rect::new(2000, 1500, 64, 48));
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("f.dng");
    write_dng(&p, &im, &cfg).unwrap();
    let id = std::process::Command::new("dcraw")
        .arg("-i")
        .arg("-v")
        .arg(&p)
        .output()
        .unwrap();
    let s = String::from_utf8_lossy(&id.stdout);
    assert!(
        id.status.success(),
        "dcraw -i failed: {s} {}",
        String::from_utf8_lossy(&id.stderr)
    );
    assert!(
        s.contains("Image size:  64 x 48") || s.contains("64 x 48"),
        "{s}"
    );
    assert!(
        s.contains("Filter pattern: GRBG") || s.contains("GR/BG"),
        "{s}"
    );
    let out = std::process::Command::new("dcraw")
        .args(["-D", "-4", "-t", "0", "-c"])
        .arg(&p)
        .output()
        .unwrap();
    assert!(out.status.success());
    let pgm = out.stdout;
    // header "P5\n64 48\n65535\n"
    let hdr = b"P5\n64 48\n65535\n";
    assert_eq!(&pgm[..hdr.len()], hdr);
    let v: Vec<u16> = pgm[hdr.len()..]
        .chunks(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect();
    assert_eq!(v.len(), 64 * 48);
    assert!(
        v.iter().zip(&im.dv).all(|(a, b)| *a as f32 == *b),
        "dcraw values differ from the DV"
    );
}

#[test]
fn bilinear_demosaic_recovers_a_constant_per_channel_field() {
    let mut cfg = imx363();
    cfg.sources = Sources::none();
    cfg.exposure = Exposure::Seconds(0.01);
    let im = frame(&cfg, Rect::new(100, 101, 16, 12));
    let d = demosaic_bilinear(&im);
    // the noiseless field is constant per channel: every reconstructed value equals it
    let mut truth = [f32::NAN; 3];
    for y in 0..12 {
        for x in 0..16 {
            truth[im.channel_at(x, y)] = im.dv_at(x, y) - 64.0;
        }
    }
    assert!(truth.iter().all(|t| t.is_finite() && *t > 1.0));
    for (i, v) in d.iter().enumerate() {
        assert!(
            (v - truth[i % 3]).abs() < 1e-3 * truth[i % 3],
            "{i}: {v} vs {}",
            truth[i % 3]
        );
    }
    let dir = tempfile::tempdir().unwrap();
    write_preview_png(&dir.path().join("p.png"), &im, &cfg).unwrap();
    assert!(dir.path().join("p.png").metadata().unwrap().len() > 50);
}

/// The fitted colour matrix sends D65 white to the as-shot neutral, max component 1.
#[test]
fn dng_colour_matrix_maps_d65_white_to_the_neutral() {
    let cfg = imx363();
    let (m, n) = dng_color(&cfg).unwrap();
    assert!(n.iter().all(|&v| v > 0.0 && v <= 1.0) && n.contains(&1.0));
    // D65 XYZ with Y = 1 (CIE 1931 2°): (0.9505, 1, 1.0888)
    let xyz = [0.9505, 1.0, 1.0888];
    let cam: Vec<f64> = (0..3)
        .map(|r| (0..3).map(|c| m[r * 3 + c] * xyz[c]).sum())
        .collect();
    let mx = cam.iter().cloned().fold(0.0, f64::max);
    assert!((mx - 1.0).abs() < 0.01, "{cam:?}");
    // the least-squares matrix is close to, not exactly, the direct white response
    for c in 0..3 {
        assert!((cam[c] - n[c]).abs() < 0.05, "{cam:?} vs {n:?}");
    }
}
