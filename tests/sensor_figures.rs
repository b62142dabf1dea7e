//! The paper's sensor figures as experiments (issue 15): Fig. 11 / Appendix III
//! (`measure "conversion-gain"`), Table I (`measure "sensor-calibration"`),
//! Fig. 8 / Appendix IV (`measure "noise"` with the noise model), and the pieces
//! they rest on: Eq. 12 on the caption's numbers, the noise model against
//! simulated flat frames, the render's channel-weighted standard error, the
//! dead-pixel rejection of Appendix IV. Reference values are typed from the
//! paper (Table I, Fig. 11's caption), not read from the code under test.

use camsim::measure::conversion_gain::{ConversionGainOptions, measure as conversion_gain};
use camsim::measure::noise::{NoiseOptions, Verdict, classify};
use camsim::measure::noise_model::sensor_variance_dv2;
use camsim::measure::plane::Plane;
use camsim::measure::stats::SplitMix64;
use camsim::optical_image::Rect;
use camsim::sensor::calibrate::alpha_eq12;
use camsim::sensor::config::SensorConfig;
use camsim::sensor::pipeline::{flat_rate_e_per_s, simulate_flat};
use camsim::sensor::{Exposure, SensorFrame};
use camsim::spectrum::{Spectrum, WavelengthGrid};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn imx363() -> SensorConfig {
    SensorConfig::load(&Path::new(ROOT).join("sensors/imx363.kdl")).unwrap()
}

/// Run one shipped experiment (optionally with --max-spp) into a temp dir and
/// return its (measurement/quantity → (value, stderr, render_s)) rows.
fn run_experiment(
    file: &str,
    max_spp: Option<&str>,
) -> (tempfile::TempDir, BTreeMap<String, (f64, f64, f64)>) {
    let tmp = tempfile::tempdir().unwrap();
    let mut c = Command::new(env!("CARGO_BIN_EXE_camsim"));
    c.current_dir(ROOT)
        .args(["run", "--threads", "2", "--out"])
        .arg(tmp.path());
    if let Some(n) = max_spp {
        c.args(["--max-spp", n]);
    }
    let o = c.arg(file).output().unwrap();
    assert!(
        o.status.success(),
        "{file}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let name = Path::new(file).file_stem().unwrap().to_str().unwrap();
    let rows =
        camsim::report::results::read_results(&tmp.path().join(name).join("results.csv")).unwrap();
    let m = rows
        .iter()
        .map(|r| {
            (
                format!("{}/{}", r.measurement, r.quantity),
                (r.value, r.stderr, r.render_s),
            )
        })
        .collect();
    (tmp, m)
}

/// Fig. 11's caption: mean 320.7 DV, variance 57.8 DV², PRNU 0.544 % (the
/// calibration script's 0.544447 %). Eq. 12 by hand: E²σ_p² = 320.7² ×
/// 0.00544² = 3.0436; (57.8 − 3.0436) / (320.7 × 1.0000296) = 0.17073 DV/e⁻
/// — the manufacturer's 0.1707, not the 0.1677 the paper's text reports (1.8 %
/// lower). With Table I's rounded 0.54 % it is 0.17087, still not 0.1677.
#[test]
fn fig11_caption_numbers_give_0_1707_by_eq12_not_0_1677() {
    for (prnu, tol) in [(0.00544, 0.0001), (0.00544447, 0.0001), (0.0054, 0.0003)] {
        let by_hand = (57.8 - 320.7f64.powi(2) * prnu * prnu) / (320.7 * (1.0 + prnu * prnu));
        let a = alpha_eq12(320.7, 57.8, prnu);
        eprintln!("Eq. 12 on the caption, PRNU {prnu}: {a:.5} DV/e-");
        assert!((a - by_hand).abs() < 1e-15, "{a} vs {by_hand}");
        assert!((a - 0.1707).abs() < tol, "Eq. 12 on the caption: {a}");
        assert!((a - 0.1677).abs() > 0.0029, "{a}");
    }
}

/// `fig11-conversion-gain` end to end: α within 2 % of 0.1707 with its
/// standard error, and within 3 of its standard errors; no render.
///
/// With 1500 values the relative SE of a variance is √(2/1500) = 3.7 %, so α
/// carries ≈ 3.9 % (1σ); the 2 % holds for the shipped seed (2020,
/// chosen before the run) but is tighter than the estimator's own precision —
/// the unbiasedness over many seeds is tested below.
#[test]
fn fig11_experiment_recovers_the_conversion_gain() {
    let (tmp, m) = run_experiment("experiments/fig11-conversion-gain.kdl", None);
    let (a, se, render_s) = m["conversion-gain/conversion_gain"];
    eprintln!(
        "fig11: alpha = {a:.5} ± {se:.5} DV/e- ({:+.2} %)",
        (a / 0.1707 - 1.0) * 100.0
    );
    assert!((a / 0.1707 - 1.0).abs() < 0.02, "alpha {a}");
    assert!((a - 0.1707).abs() < 3.0 * se, "alpha {a} ± {se}");
    assert!(se > 0.0 && se < 0.01, "stderr {se}");
    assert_eq!(m["conversion-gain/values"].0, 1500.0);
    // Eq. 12 on the caption's numbers, in the results: 0.1707, not 0.1677
    let r = m["conversion-gain/reference_conversion_gain"].0;
    assert!(
        (r - 0.1707).abs() < 0.0001 && (r - 0.1677).abs() > 0.0029,
        "{r}"
    );
    assert!((m["conversion-gain/mean"].0 - 320.0).abs() < 3.0);
    assert_eq!(render_s, 0.0, "a sensor-only measurement renders nothing");
    // no optical image was made: no preview of one
    let prev = tmp.path().join("fig11-conversion-gain/previews");
    assert!(!prev.join("default/optical-image.png").exists());
    // the report holds both histograms with their Poisson curves
    let html =
        std::fs::read_to_string(tmp.path().join("fig11-conversion-gain/report.html")).unwrap();
    for t in ["dv_histogram", "electrons_histogram", "poisson"] {
        assert!(html.contains(t), "report lacks {t}");
    }
}

/// The Appendix III estimator through the measurement is unbiased up to the
/// terms Eq. 12 neglects (as in tests/sensor_calibration.rs): read noise,
/// DSNU, dark current and quantisation add (σ²_read + σ²_DSNU + μ_dark) K² +
/// 1/12 DV² to the variance, so E[α]/K − 1 = (σ²_read,e + σ²_DSNU,e + μ_dark +
/// 1/(12K²)) / (μ(1 + σ_p²)) ≈ +0.6 %. Over 40 seeds the mean of α has SE
/// ≈ 3.9 %/√40 = 0.62 %; the crop's fixed PRNU field is the same in every seed,
/// and its 100-pixel sample variance departs from σ_p²μ² by ≈ √(2/100) of
/// 3 DV², i.e. up to ≈ 0.7 % of the variance: bound 3 SE + 0.7 %.
#[test]
fn conversion_gain_is_unbiased_over_seeds() {
    let cfg = imx363();
    let o = ConversionGainOptions::default();
    let k = cfg.conversion_gain_dv_per_e();
    let vals: Vec<f64> = (0..40u64)
        .map(|s| {
            let m = conversion_gain(&cfg, &o, 7000 + s, "cg").unwrap();
            m.figures
                .iter()
                .find(|f| f.quantity == "conversion_gain")
                .unwrap()
                .value
        })
        .collect();
    let n = vals.len() as f64;
    let mean = vals.iter().sum::<f64>() / n;
    let sd = (vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let cg = cfg.conversion_gain_v_per_e();
    let mu_dark = cfg.dark_voltage_v_per_s * o.exposure_s / cg;
    let mu = o.mean_dv / k;
    let extra =
        (cfg.read_noise_e().powi(2) + (cfg.dsnu_v / cg).powi(2) + mu_dark + 1.0 / (12.0 * k * k))
            / (mu * (1.0 + cfg.prnu.powi(2)));
    let predicted = k * (1.0 + extra);
    let bound = 3.0 * sd / n.sqrt() + 0.007 * k;
    eprintln!(
        "mean alpha over 40 seeds {mean:.5} (sd {sd:.5}), predicted {predicted:.5}, bound {bound:.5}"
    );
    assert!((mean - predicted).abs() < bound);
    // the reported SE is the real spread: sd/SE within [0.6, 1.5] (39 dof: ±25 % at 3σ)
    let se = conversion_gain(&cfg, &o, 7000, "cg").unwrap().figures[0].stderr;
    assert!(
        (0.6..1.5).contains(&(sd / se)),
        "sd {sd} vs reported SE {se}"
    );
}

/// Bad input to the sensor-only measurements is a clear error, never a panic.
#[test]
fn conversion_gain_refuses_bad_input() {
    let cfg = imx363();
    let e = |o: ConversionGainOptions, c: &SensorConfig| {
        conversion_gain(c, &o, 1, "cg").unwrap_err().to_string()
    };
    let clip = e(
        ConversionGainOptions {
            mean_dv: 1000.0,
            ..Default::default()
        },
        &cfg,
    );
    assert!(clip.contains("clip"), "{clip}");
    let outside = e(
        ConversionGainOptions {
            roi_px: Some(Rect::new(4030, 10, 20, 10)),
            ..Default::default()
        },
        &cfg,
    );
    assert!(
        outside.contains("not inside the 4032×3024 sensor"),
        "{outside}"
    );
    let mut sizeless = cfg.clone();
    sizeless.rows = None;
    sizeless.cols = None;
    let m = e(ConversionGainOptions::default(), &sizeless);
    assert!(m.contains("rows and cols"), "{m}");
}

/// `table1-sensor` end to end: each parameter within 3 standard errors or
/// 5 % of Table I, whichever is larger. Table I (typed here): conversion gain
/// 0.1707 DV/e⁻, read noise 0.226 mV, DSNU 0.038 mV, PRNU 0.54 %, dark voltage
/// 0.02 mV/s. Table I gives no saturation; its well (6000 e⁻) is not visible
/// through a 10-bit ADC with black level 64, which clips at (1023 − 64)/0.1707
/// = 5618 e⁻: that is the saturation compared (EMVA's variance maximum sits a
/// few noise σ below it).
#[test]
fn table1_experiment_recovers_table_i() {
    let (_tmp, m) = run_experiment("experiments/table1-sensor.kdl", None);
    let table = [
        ("conversion_gain", 0.1707),
        ("read_noise", 0.226),
        ("dsnu", 0.038),
        ("prnu", 0.54),
        ("dark_voltage", 0.02),
        ("saturation", (1023.0 - 64.0) / 0.1707),
    ];
    for (q, t) in table {
        let (v, se, render_s) = m[&format!("sensor-calibration/{q}")];
        let s = m[&format!("sensor-calibration/{q}/sensor")].0;
        eprintln!(
            "{q}: {v:.5} ± {se:.5} (Table I {t}; {:+.2} %)",
            (v / t - 1.0) * 100.0
        );
        assert!(
            (s / t - 1.0).abs() < 1e-9,
            "{q}: the sensor file holds {s}, Table I {t}"
        );
        assert!(
            (v - t).abs() <= (3.0 * se).max(0.05 * t),
            "{q}: {v} ± {se} vs Table I {t}"
        );
        assert!(se > 0.0, "{q} has no standard error");
        assert_eq!(render_s, 0.0);
    }
    assert_eq!(m["sensor-calibration/within_tolerance"].0, 7.0);
}

/// Green pixels of a frame.
fn green(f: &SensorFrame) -> Vec<f64> {
    let im = &f.image;
    let mut v = vec![];
    for y in 0..im.height() {
        for x in 0..im.width() {
            if im.cfa.channels[im.channel_at(x, y)] == "g" {
                v.push(im.dv_at(x, y) as f64 - im.black_level_dv);
            }
        }
    }
    v
}

/// The noise model's σ(mean) against the sensor pipeline itself: one
/// simulated flat frame (a 200×200 window, 20 000 green pixels: shot noise,
/// PRNU and DSNU fields, dark current, read noise, ADC) per level; the
/// spatial variance of its green pixels is what a region's spread estimates.
/// Its sampling SE is σ²·√(2/n) = 1 % (n = 20 000); bound 4 SE + 1 % for the
/// quantisation approximation (1/12 DV² is exact only for σ ≫ 1 DV).
#[test]
fn noise_model_matches_simulated_flat_frames() {
    let mut cfg = imx363();
    let g = WavelengthGrid::new(400.0, 700.0, 10.0).unwrap();
    let unit = Spectrum::constant("flat", 1.0);
    let rate = flat_rate_e_per_s(&cfg, &unit, &g)[1];
    cfg.exposure = Exposure::Seconds(0.05);
    for mu_e in [20.0, 200.0, 1000.0, 4000.0] {
        let spec = unit.clone().scaled(mu_e / (rate * 0.05));
        let f = simulate_flat(&cfg, &spec, &g, Rect::new(1900, 1400, 200, 200), 31).unwrap();
        let v = green(&f);
        let n = v.len() as f64;
        let m = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
        let model = sensor_variance_dv2(&cfg, m);
        let tol = 4.0 * model * (2.0 / n).sqrt() + 0.01 * model;
        eprintln!("mu {mu_e} e-: mean {m:.2} DV, variance {var:.3} vs model {model:.3} DV²");
        assert!((var - model).abs() < tol, "{var} vs {model} ± {tol}");
    }
}

/// Appendix IV rejects a region holding a dead pixel: clean 10×10 regions of
/// a simulated IMX363 flat field (≈ 1000 e⁻) are classified, then the same
/// region with one green pixel dead (at the black level) or hot (at the white
/// level) must be rejected as an outlier — also when a rendering's Monte Carlo
/// variance (here 4 DV², ≈ 1/7 of the shot noise's K²·1000 = 29 DV²) widens
/// the test's σ, as on a simulated image.
#[test]
fn appendix_iv_rejects_an_injected_dead_pixel() {
    let mut cfg = imx363();
    let g = WavelengthGrid::new(400.0, 700.0, 10.0).unwrap();
    let unit = Spectrum::constant("flat", 1.0);
    let rate = flat_rate_e_per_s(&cfg, &unit, &g)[1];
    cfg.exposure = Exposure::Seconds(0.05);
    let spec = unit.scaled(1000.0 / (rate * 0.05));
    let f = simulate_flat(&cfg, &spec, &g, Rect::new(1900, 1400, 100, 100), 5).unwrap();
    let clean = Plane::from_sensor(&f.image).unwrap();
    let mc = Plane::new(100, 100, vec![4.0; 10_000]).unwrap();
    let opts = NoiseOptions {
        conversion_gain_dv_per_e: cfg.conversion_gain_dv_per_e(),
        read_noise_e: cfg.read_noise_e(),
        ..NoiseOptions::for_sensor(&f.image)
    };
    let mut accepted = 0;
    for (i, r) in (0..10)
        .flat_map(|a| (0..10).map(move |b| Rect::new(a * 10, b * 10, 10, 10)))
        .enumerate()
    {
        for extra in [None, Some(&mc)] {
            let mut rng = SplitMix64(i as u64);
            let c = classify(&clean, r, &opts, &mut rng, extra).unwrap();
            if c.verdict != Verdict::Accepted {
                continue;
            }
            accepted += 1;
            // a green pixel of the region (grbg: green at even x + even y)
            let (x, y) = (r.x as usize, r.y as usize);
            let (x, y) = if (1400 + y + 1900 + x) % 2 == 0 {
                (x, y)
            } else {
                (x + 1, y)
            };
            for bad in [0.0, cfg.white_level_dv() - cfg.black_level_dv] {
                let mut p = clean.clone();
                p.data[y * p.width + x] = bad;
                let mut rng = SplitMix64(i as u64);
                let c = classify(&p, r, &opts, &mut rng, extra).unwrap();
                assert_eq!(c.verdict, Verdict::Outlier, "region {r:?}, pixel {bad} DV");
            }
        }
    }
    assert!(
        accepted >= 100,
        "only {accepted} of 200 clean classifications accepted"
    );
}

/// The render's channel-weighted standard error: with one-hot weights it is
/// the per-band standard error (same batches), and with all-ones weights it
/// lies between the quadrature sum (independent bands) and the plain sum
/// (fully correlated bands) of the per-band errors, since Var(ΣX) = ΣΣ Cov.
#[test]
fn weighted_stderr_is_the_stderr_of_the_weighted_sum() {
    let sf = camsim::scene::kdl_scene::load_kdl_scene(
        &PathBuf::from(ROOT).join("scenes/cornell-box.kdl"),
    )
    .unwrap();
    let scene = sf.scene;
    let film = camsim::scene::FilmSpec {
        width_px: 24,
        height_px: 18,
        pixel_pitch_m: 1.4e-6 * 4032.0 / 24.0,
        crop_window: None,
    };
    let cam = camsim::optics::camera::build(&scene.camera.as_ref().unwrap().model, &film).unwrap();
    let grid = WavelengthGrid::new(400.0, 700.0, 50.0).unwrap();
    let nb = grid.len();
    let mut weights: Vec<Vec<f32>> = (0..nb)
        .map(|b| (0..nb).map(|j| (j == b) as u8 as f32).collect())
        .collect();
    weights.push(vec![1.0; nb]);
    let s = camsim::render::RenderSettings {
        spp: 16,
        max_bounces: 3,
        grid,
        seed: 3,
        stderr_weights: weights,
        ..Default::default()
    };
    let img = camsim::render::render(&scene, cam.as_ref(), &film, &s).unwrap();
    let k = nb + 1;
    assert_eq!(img.weighted_stderr.len(), 24 * 18 * k);
    let mut strictly_between = 0;
    for p in 0..24 * 18 {
        let se = &img.stderr[p * nb..(p + 1) * nb];
        let w = &img.weighted_stderr[p * k..(p + 1) * k];
        for b in 0..nb {
            assert!(
                (w[b] - se[b]).abs() <= 1e-5 * se[b].max(1e-12),
                "pixel {p} band {b}"
            );
        }
        let quad = se.iter().map(|x| x * x).sum::<f32>().sqrt();
        let lin = se.iter().sum::<f32>();
        assert!(
            w[nb] <= lin * 1.0001 + 1e-12,
            "pixel {p}: {} > {lin}",
            w[nb]
        );
        if w[nb] > quad * 1.001 && w[nb] < lin * 0.999 {
            strictly_between += 1;
        }
    }
    // bands of one path are positively correlated: above the quadrature sum
    assert!(strictly_between > 24 * 18 / 2, "{strictly_between}");
}

/// `fig08-sensor-noise` at the baselines' quality (--max-spp 64): at least
/// 90 % of the accepted regions lie inside the model's 95 % band with the
/// render's Monte Carlo variance included; without it (the sensor model alone)
/// most regions lie above the band — rendering noise would be mistaken for
/// sensor noise.
#[test]
fn fig08_regions_lie_in_the_noise_models_band() {
    let (_tmp, m) = run_experiment("experiments/fig08-sensor-noise.kdl", Some("64"));
    let (frac, se, _) = m["noise/fraction_in_band"];
    let (frac0, _, _) = m["noise/fraction_in_band_sensor_only"];
    let used = m["noise/model_regions"].0;
    eprintln!(
        "fig08: {used} regions, {frac:.3} ± {se:.3} inside the 95 % band (sensor only: {frac0:.3}), std/model {:?}, MC share {:?}",
        m["noise/std_over_model"], m["noise/mc_variance_fraction"]
    );
    assert!(used >= 100.0, "{used} regions");
    assert!(frac >= 0.90, "{frac}");
    assert!(frac0 < 0.5, "{frac0}");
}

/// A sensor-only measurement in an experiment without a sensor is an error at
/// `check`, at the measurement, naming what to add.
#[test]
fn sensor_only_measurement_without_a_sensor_fails_check() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("x.kdl");
    std::fs::write(
        &f,
        "experiment \"x\" {\n    measure \"sensor-calibration\" level-count=8\n}\n",
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_camsim"))
        .arg("check")
        .arg(&f)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("x.kdl:2:13") && e.contains("add sensor"), "{e}");
}
