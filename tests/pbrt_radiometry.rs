//! pbrt-v4 scene radiometry: what a pbrt-v4 file means, rendered with
//! `--film radiance` (pbrt's film quantity).

use std::path::Path;
use std::process::Command;

/// ∫ȳ(λ)dλ over pbrt-v4's CIE table (360–830 nm, 1 nm): pbrt-v4 divides an
/// emission spectrum by ∫ȳ·S, so a constant spectrum 1 becomes 1/106.856895.
const CIE_Y_INTEGRAL: f64 = 106.856895;

/// Render a pbrt file with camsim and return (wavelength nm, per-band pixel
/// values) from the spectral EXR.
fn render(scene: &Path, extra: &[&str]) -> Vec<(f64, Vec<f64>)> {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r.exr");
    let o = Command::new(env!("CARGO_BIN_EXE_camsim"))
        .arg("render")
        .arg(scene)
        .arg("--out")
        .arg(&out)
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = exr::prelude::read_first_flat_layer_from_file(&out).unwrap();
    let mut bands = vec![];
    for ch in &img.layer_data.channel_data.list {
        let name = ch.name.to_string();
        // pbrt-v4 spectral channel names: S0.<nm with a decimal comma>nm
        if let Some(nm) = name.strip_prefix("S0.").and_then(|s| s.strip_suffix("nm")) {
            let nm: f64 = nm.replace(',', ".").parse().unwrap();
            bands.push((nm, ch.sample_data.values_as_f32().map(f64::from).collect()));
        }
    }
    assert!(!bands.is_empty(), "no spectral channels");
    bands
}

/// Camera inside a `ReverseOrientation` sphere (radius 1) that is both a
/// diffuse reflector ρ = 0.5 and an emitter Le = 0.5/∫ȳ: radiance everywhere
/// is Le·Σρᵏ = Le/(1 − ρ) = 1/∫ȳ W/(sr·m²·nm), for every band and direction.
/// Rendered with `--max-bounces 30` (camsim does not read the file's
/// maxdepth; its default 6 would sum k = 0…6, 0.78 % low): the truncation
/// is ρ³¹ ≈ 5e-10. Tolerance: the 1 % on the per-band mean; the
/// standard error of that mean (over 256 px × 1024 spp, printed) must stay
/// below 0.2 % so that 1 % is ≥ 5 standard errors — the test can fail only
/// through a real radiometric error (a sphere facing outwards renders 0).
#[test]
fn pbrt_white_furnace_reverse_orientation_radiance_film() {
    let bands = render(
        Path::new("tests/pbrt/radiometry/white_furnace.pbrt"),
        &[
            "--film",
            "radiance",
            "--spp",
            "1024",
            "--seed",
            "1",
            "--max-bounces",
            "30",
        ],
    );
    let want = 0.5 / (1.0 - 0.5) / CIE_Y_INTEGRAL;
    for (nm, v) in &bands {
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let se = (var / n).sqrt();
        println!(
            "{nm} nm: {mean:.6e} (want {want:.6e}), rel {:+.4} %, s.e. {:.4} %",
            (mean / want - 1.0) * 100.0,
            se / mean * 100.0
        );
        assert!(se / mean < 2e-3, "{nm} nm: noisy, s.e. {se}");
        assert!(
            (mean / want - 1.0).abs() < 0.01,
            "{nm} nm: {mean} vs {want}"
        );
    }
}
