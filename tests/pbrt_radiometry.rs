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

/// A spectral film's `nbuckets`/`lambdamin`/`lambdamax` are honoured: the EXR
/// has one channel per bucket, named (pbrt-v4's way) by the bucket centre,
/// and in the white furnace every bucket reads 1/∫ȳ (the emitter and the
/// reflectance are constant over 300–900 nm, so even buckets outside camsim's
/// default 400–700 nm must). Tolerance as in the furnace test above.
#[test]
fn pbrt_spectral_film_buckets_honoured() {
    let base = std::fs::read_to_string("tests/pbrt/radiometry/white_furnace.pbrt").unwrap();
    let dir = tempfile::tempdir().unwrap();
    for (params, want_nm) in [
        (
            "\"integer nbuckets\" 31 \"float lambdamin\" 395 \"float lambdamax\" 705",
            (0..31).map(|k| 400.0 + 10.0 * k as f64).collect::<Vec<_>>(),
        ),
        (
            // pbrt-v4 defaults for the range: 360–830 nm.
            "\"integer nbuckets\" 4",
            vec![418.75, 536.25, 653.75, 771.25],
        ),
    ] {
        let text = base.replace("Film \"spectral\"", &format!("Film \"spectral\" {params}"));
        assert_ne!(text, base);
        let scene = dir.path().join("f.pbrt");
        std::fs::write(&scene, text).unwrap();
        let bands = render(
            &scene,
            &[
                "--film",
                "radiance",
                "--spp",
                "256",
                "--seed",
                "2",
                "--max-bounces",
                "30",
            ],
        );
        let got: Vec<f64> = bands.iter().map(|b| b.0).collect();
        assert_eq!(got, want_nm, "{params}");
        for (nm, v) in &bands {
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            assert!(
                (mean * CIE_Y_INTEGRAL - 1.0).abs() < 0.01,
                "{params}: {nm} nm reads {mean}"
            );
        }
    }
}

/// Buckets that cannot be rendered are a located error, not a silent default.
#[test]
fn pbrt_spectral_film_bad_buckets_are_located_errors() {
    let base = std::fs::read_to_string("tests/pbrt/radiometry/white_furnace.pbrt").unwrap();
    let dir = tempfile::tempdir().unwrap();
    for (params, needle) in [
        ("\"integer nbuckets\" 0", "nbuckets must be 1..10000"),
        ("\"float lambdamin\" 900", "0 < lambdamin < lambdamax"),
    ] {
        let scene = dir.path().join("bad.pbrt");
        std::fs::write(
            &scene,
            base.replace("Film \"spectral\"", &format!("Film \"spectral\" {params}")),
        )
        .unwrap();
        let o = Command::new(env!("CARGO_BIN_EXE_camsim"))
            .args(["render", scene.to_str().unwrap(), "--out"])
            .arg(dir.path().join("bad.exr"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success());
        assert!(err.contains("bad.pbrt:4:") && err.contains(needle), "{err}");
        assert!(!dir.path().join("bad.exr").exists());
    }
}

/// Why camsim's irradiance band means are not pbrt's radiance band means
/// times the image's mean cos⁴θ (the ≈3.5 % "residual" of issue 18): a band
/// mean of irradiance is Σ cos⁴θ·L / N, so the factor is the cos⁴θ weighted
/// by that band's radiance, not the plain mean — higher when the light sits
/// near the image centre, lower in bands whose radiance is at the edges.
/// On the ISET Cornell box (paper spectra, 48.2° across the shorter side of
/// 1280×720): plain mean cos⁴ 0.655, band factors 0.754 (700 nm, red wall at
/// the edge) to 0.766 (450 nm). The pinhole is f/(√π/2), so its weight is
/// exactly cos⁴θ and both films trace the same rays (same seed): the
/// per-band ratio must equal the radiance-weighted cos⁴ at the pixel centres
/// up to the cos⁴ variation inside a pixel (< 1e-3 relative here).
#[test]
fn irradiance_over_radiance_is_the_radiance_weighted_cos4() {
    let scene = Path::new("scenes/CornellBoxReference/CornellBoxReference.pbrt");
    let args = |film: &'static str| {
        [
            "--paper-spectra",
            "--spp",
            "1",
            "--seed",
            "4",
            "--film",
            film,
        ]
    };
    let irr = render(scene, &args("irradiance"));
    let rad = render(scene, &args("radiance"));
    let (w, h) = (1280.0f64, 720.0f64);
    let d = 0.5 * h / (0.5 * 48.2106066326f64.to_radians()).tan();
    let cos4: Vec<f64> = (0..720)
        .flat_map(|y| {
            (0..1280).map(move |x| {
                let (px, py) = (x as f64 + 0.5 - 0.5 * w, y as f64 + 0.5 - 0.5 * h);
                (d * d / (px * px + py * py + d * d)).powi(2)
            })
        })
        .collect();
    let plain = cos4.iter().sum::<f64>() / cos4.len() as f64;
    assert!((plain - 0.655).abs() < 1e-3, "{plain}");
    let mut lo: f64 = 1.0;
    for ((nm, e), (_, l)) in irr.iter().zip(&rad) {
        let ratio = e.iter().sum::<f64>() / l.iter().sum::<f64>();
        let weighted = l.iter().zip(&cos4).map(|(l, c)| l * c).sum::<f64>() / l.iter().sum::<f64>();
        assert!(
            (ratio / weighted - 1.0).abs() < 1e-3,
            "{nm}: {ratio} vs {weighted}"
        );
        lo = lo.min(ratio);
    }
    // Every band's factor is ≥ 15 % above the plain mean cos⁴.
    assert!(lo > 1.15 * plain, "{lo} vs {plain}");
}

/// pbrt-v4's own render of a Cornell box with measured spectra
/// (`tests/pbrt/radiometry/cornell_spectral.pbrt`: the ISET box's wall
/// reflectances and lamp SPD with `scale 40`, pbrt-v4 syntax, 31 spectral
/// film buckets of 10 nm over 395–705 nm) against camsim's
/// `--film radiance` render of the same file. The reference,
/// `data/pbrt-v4/cornell-spectral-band-means.csv`, holds pbrt-v4's per-bucket
/// image means (radiance × ∫ȳ, as its spectral film stores them) and their
/// standard errors over 8 independent renders (provenance in the file and
/// data/README.md); camsim's means are compared after pbrt's film factor.
///
/// Tolerance: 4 combined standard errors per band, √(s_p² + s_c²)·4, with
/// s_p the reference's standard error pooled over the 31 bands (RMS of the
/// relative errors: each band's own 7-degree-of-freedom estimate is itself
/// ±27 % uncertain) and s_c camsim's at 256 spp, 0.1 % (measured: the 4
/// renders at 1024 spp scatter by 0.05 % (sd), ×2 for 4× fewer samples).
/// That is ≈ 0.64 %, three times tighter than the 2 % acceptance,
/// which is asserted too. Sampling each 10 nm bucket at its centre instead of averaging over
/// it (camsim before this comparison) misses by up to 8 % (400 nm) and 7 %
/// (450 nm, the lamp's blue peak), so the test fails on that error.
#[test]
fn pbrt_v4_spectral_cornell_box_matches_pbrt_v4_per_band() {
    let text = std::fs::read_to_string("data/pbrt-v4/cornell-spectral-band-means.csv").unwrap();
    let reference: Vec<(f64, f64, f64)> = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("wavelength"))
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.trim().parse().unwrap()).collect();
            (v[0], v[1], v[2])
        })
        .collect();
    assert_eq!(reference.len(), 31);
    let pooled = (reference
        .iter()
        .map(|(_, m, s)| (s / m).powi(2))
        .sum::<f64>()
        / reference.len() as f64)
        .sqrt();
    let camsim_se = 1e-3;
    let tol = 4.0 * pooled.hypot(camsim_se);
    println!(
        "pbrt s.e. pooled {:.4} %, tolerance {:.3} %",
        pooled * 100.0,
        tol * 100.0
    );
    assert!(tol < 0.01, "reference too noisy for the test: {tol}");
    let bands = render(
        Path::new("tests/pbrt/radiometry/cornell_spectral.pbrt"),
        &[
            "--film",
            "radiance",
            "--spp",
            "256",
            "--seed",
            "5",
            "--max-bounces",
            "200",
        ],
    );
    assert_eq!(bands.len(), reference.len());
    for ((nm, v), (ref_nm, pbrt, _)) in bands.iter().zip(&reference) {
        assert_eq!(nm, ref_nm);
        let ours = v.iter().sum::<f64>() / v.len() as f64;
        let want = pbrt / CIE_Y_INTEGRAL;
        let rel = ours / want - 1.0;
        println!(
            "{nm} nm: camsim {ours:.6e}, pbrt-v4 / ∫ȳ {want:.6e}, {:+.3} %",
            rel * 100.0
        );
        assert!(rel.abs() < 0.02, "{nm} nm: outside the issue's 2 %: {rel}");
        assert!(rel.abs() < tol, "{nm} nm: {rel} beyond {tol}");
    }
}
