//! Calibration acceptance (issue 6): Appendix III conversion gain on simulated
//! IMX363 crops, NNLS recovery of the paper's QE matrix M, EMVA 1288 photon
//! transfer on simulated sequences, and the CLI end to end.

use camsim::optical_image::Rect;
use camsim::sensor::calibrate::{FlatSequence, conversion_gain_appendix3, photon_transfer};
use camsim::sensor::config::SensorConfig;
use camsim::sensor::nnls::qe_correction_matrix;
use camsim::sensor::pipeline::{flat_rate_e_per_s, simulate_flat};
use camsim::sensor::rng::PixelRng;
use camsim::sensor::{Exposure, SensorFrame};
use camsim::spectrum::{Spectrum, WavelengthGrid, library};
use std::path::Path;

fn imx363() -> SensorConfig {
    SensorConfig::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("sensors/imx363.kdl")).unwrap()
}
fn grid() -> WavelengthGrid {
    WavelengthGrid::new(400.0, 700.0, 10.0).unwrap()
}
/// Exposure for `mu_e` green electrons under a 1 W/(m²·nm) flat field.
fn exposure_for(cfg: &SensorConfig, mu_e: f64) -> (Spectrum, f64) {
    let s = Spectrum::constant("flat", 1.0);
    (s.clone(), mu_e / flat_rate_e_per_s(cfg, &s, &grid())[1])
}
/// Pixels of one CFA sub-plane (phase px, py) of a frame.
fn plane(f: &SensorFrame, px: u32, py: u32) -> Vec<f64> {
    let im = &f.image;
    let mut v = vec![];
    for y in (0..im.height()).filter(|y| (im.window.y + y) % 2 == py) {
        for x in (0..im.width()).filter(|x| (im.window.x + x) % 2 == px) {
            v.push(im.dv_at(x, y) as f64);
        }
    }
    v
}

/// Paper Appendix III: 15 frames, a 10×10 crop of the G1 plane near the centre, mean
/// ≈ 320 DV above black (the paper's Fig. 11: 320.7 DV, variance 57.8), exposure
/// 1/10 s, PRNU 0.54 % (Table I). Fixed seed 2020 (not tuned).
///
/// Bound: with 1500 values the relative SE of a variance is √(2/1500) = 3.7 %, so α
/// itself carries ≈ 3.9 % (1σ) of sampling error; the issue's 2 % is therefore a
/// property of the seed as much as of the model. We assert the 2 % of the issue and,
/// independently, the estimator's own 3-SE interval, and print the value.
#[test]
fn appendix3_recovers_the_conversion_gain_from_15_green_crops() {
    let mut cfg = imx363();
    let target_e = 320.0 / cfg.conversion_gain_dv_per_e();
    let (spec, t) = exposure_for(&cfg, target_e);
    // paper: 1/10 s; scale the irradiance instead of the exposure
    let spec = spec.scaled(t / 0.1);
    cfg.exposure = Exposure::Seconds(0.1);
    // 20×20 sensor window at the centre → 10×10 G1 crop (grbg: G1 at even x, even y)
    let w = Rect::new(2016, 1512, 20, 20);
    let mut vals = vec![];
    for i in 0..15u64 {
        let f = simulate_flat(&cfg, &spec, &grid(), w, 2020 * 1000 + i).unwrap();
        let p = plane(&f, 0, 0);
        assert_eq!(p.len(), 100);
        vals.extend(p.iter().map(|v| v - cfg.black_level_dv));
    }
    let mean = vals.iter().sum::<f64>() / 1500.0;
    let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 1499.0;
    let e = conversion_gain_appendix3(&vals, cfg.prnu).unwrap();
    let k = cfg.conversion_gain_dv_per_e();
    let err = e.value / k - 1.0;
    eprintln!(
        "Appendix III: mean {mean:.1} DV, var {var:.1} DV², alpha {:.4} ± {:.4} DV/e- vs {k} ({:+.2} %)",
        e.value,
        e.stderr,
        err * 100.0
    );
    assert!((mean - 320.0).abs() < 3.0, "mean {mean}");
    assert!((e.value - k).abs() < 3.0 * e.stderr, "{e:?}");
    assert!(
        err.abs() < 0.02,
        "Appendix III error {:.2} % exceeds 2 %",
        err * 100.0
    );
}

/// The estimator is unbiased up to the terms Eq. 12 neglects: read noise (2.95 e⁻),
/// DSNU, dark current and quantisation add (σ²_read,e + σ²_dsnu,e + dark) K² + 1/12 DV²
/// to the variance, i.e. α_est/K − 1 = (σ²_read,e + σ²_dsnu,e + μ_dark + 1/(12K²)) /
/// (μ (1 + σ_p²)) ≈ +0.62 % at μ = 1875 e⁻. With 160 000 values the SE is 0.37 %;
/// we require agreement with this predicted bias within 4 SE.
#[test]
fn appendix3_bias_matches_the_neglected_terms() {
    let mut cfg = imx363();
    let target_e = 320.0 / cfg.conversion_gain_dv_per_e();
    let (spec, t) = exposure_for(&cfg, target_e);
    cfg.exposure = Exposure::Seconds(t);
    let mut vals = vec![];
    for i in 0..10u64 {
        let f = simulate_flat(
            &cfg,
            &spec,
            &grid(),
            Rect::new(1800, 1400, 400, 400),
            50 + i,
        )
        .unwrap();
        vals.extend(plane(&f, 0, 0).iter().map(|v| v - cfg.black_level_dv));
    }
    let e = conversion_gain_appendix3(&vals, cfg.prnu).unwrap();
    let k = cfg.conversion_gain_dv_per_e();
    let cg = cfg.conversion_gain_v_per_e();
    let mu_dark = cfg.dark_voltage_v_per_s * t / cg;
    let mu = target_e + mu_dark;
    let extra =
        (cfg.read_noise_e().powi(2) + (cfg.dsnu_v / cg).powi(2) + mu_dark + 1.0 / (12.0 * k * k))
            / (mu * (1.0 + cfg.prnu.powi(2)));
    let predicted = k * (1.0 + extra);
    eprintln!(
        "Appendix III (160k values): {:.5} ± {:.5}, predicted {predicted:.5} (bias {:+.3} %)",
        e.value,
        e.stderr,
        extra * 100.0
    );
    assert!(
        (e.value - predicted).abs() < 4.0 * e.stderr,
        "{e:?} vs {predicted}"
    );
}

/// NNLS recovers the paper's M from synthetic 72×3 data: nominal IMX363 QE × IR cut
/// predicts RGB for the 24 mini-MCC patches under the three Gretag illuminants; the
/// "measurement" is prediction · M with 1 % multiplicative Gaussian noise (seeded).
#[test]
fn nnls_recovers_the_paper_qe_matrix() {
    let m_true = [
        [0.5636, 0.0807, 0.0069],
        [0.0, 0.5917, 0.0],
        [0.0, 0.2470, 0.7098],
    ];
    let qe: Vec<Spectrum> = ["imx363-qe-r", "imx363-qe-g", "imx363-qe-b"]
        .iter()
        .map(|n| library::named(n).unwrap())
        .collect();
    let ir = library::named("ircf-largan").unwrap();
    let g = WavelengthGrid::new(400.0, 700.0, 5.0).unwrap();
    let mut pred = vec![];
    for ill in ["gretag-a", "gretag-cwf", "gretag-day"] {
        let l = library::named(ill).unwrap();
        for p in 1..=24 {
            let r = library::named(&format!("mcc-mini-{p:02}")).unwrap();
            let rgb: Vec<f64> = qe
                .iter()
                .map(|q| {
                    (0..g.len())
                        .map(|i| {
                            let w = g.wavelength(i);
                            l.eval(w) * r.eval(w) * q.eval(w) * ir.eval(w) * w
                        })
                        .sum()
                })
                .collect();
            pred.push(rgb);
        }
    }
    assert_eq!(pred.len(), 72);
    let scale = pred.iter().flatten().cloned().fold(0.0, f64::max);
    for r in &mut pred {
        r.iter_mut().for_each(|v| *v /= scale);
    }
    let mut rng = PixelRng::new(72, 3, 0);
    let meas: Vec<Vec<f64>> = pred
        .iter()
        .map(|r| {
            (0..3)
                .map(|c| {
                    (0..3).map(|n| r[n] * m_true[n][c]).sum::<f64>() * (1.0 + 0.01 * rng.normal())
                })
                .collect()
        })
        .collect();
    let (m, res) = qe_correction_matrix(&pred, &meas).unwrap();
    eprintln!("NNLS M = {m:?}, residuals {res:?}");
    for r in 0..3 {
        for c in 0..3 {
            assert!(m[r][c] >= 0.0 && m[r][c].is_finite());
            assert!(
                (m[r][c] - m_true[r][c]).abs() < 0.01,
                "M[{r}][{c}] = {} vs {}",
                m[r][c],
                m_true[r][c]
            );
        }
    }
    // degenerate: a duplicated channel and an all-zero channel still give finite M
    let deg: Vec<Vec<f64>> = pred.iter().map(|r| vec![r[1], r[1], 0.0]).collect();
    let (m, _) = qe_correction_matrix(&deg, &meas).unwrap();
    assert!(m.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
}

/// EMVA 1288 on simulated IMX363 sequences: 4 frames per level, 24 light levels from
/// 100 e⁻ to beyond saturation (step ≈ 250 e⁻ near the clip), dark frames at each
/// exposure. Truths and bounds:
/// - K = 0.1707 DV/e⁻ · (1 + σ_p²) (the temporal variance carries the pixel's PRNU
///   gain squared): within 4 SE;
/// - dark noise = read noise 2.953 e⁻: EMVA subtracts 1/12 DV² for quantisation, exact
///   only for σ ≫ 1 DV; at σ = 0.50 DV the rounded variance is lower than σ² + 1/12 by
///   up to 0.007 DV² (exact rounded-normal moments), i.e. up to −1.4 % on σ; bound 3 %;
/// - PRNU 0.54 % within 4 SE; DSNU 0.038 mV = 0.497 e⁻ within 4 SE;
/// - saturation: EMVA takes the temporal-variance maximum, which lies a few noise σ
///   below the ADC clip at (1023 − 64)/K = 5618 e⁻ (σ ≈ 80 e⁻ there; the variance
///   falls as soon as the upper tail of a pixel's distribution reaches the clip, and
///   PRNU spreads the pixel means by ≈ 29 e⁻): clip − 4σ < saturation < clip.
#[test]
fn emva1288_photon_transfer_recovers_the_model() {
    let mut cfg = imx363();
    let k_true = cfg.conversion_gain_dv_per_e();
    let w = Rect::new(1952, 1448, 128, 128);
    let mut seqs = vec![];
    let mut levels: Vec<f64> = (1..=20)
        .map(|i| 100.0 * 1.2f64.powi(i))
        .filter(|&e| e < 5000.0)
        .collect();
    levels.extend((0..12).map(|i| 5000.0 + 100.0 * i as f64));
    levels.push(9000.0);
    for (i, &mu) in levels.iter().enumerate() {
        let (spec, t) = exposure_for(&cfg, mu);
        cfg.exposure = Exposure::Seconds(t);
        let mut light = vec![];
        let mut dark = vec![];
        for f in 0..4u64 {
            light.push(simulate_flat(&cfg, &spec, &grid(), w, 1000 * i as u64 + f).unwrap());
            dark.push(
                simulate_flat(
                    &cfg,
                    &Spectrum::constant("zero", 0.0),
                    &grid(),
                    w,
                    500_000 + 1000 * i as u64 + f,
                )
                .unwrap(),
            );
        }
        let g = |fs: &Vec<SensorFrame>| {
            fs.iter()
                .map(|f| {
                    let mut v = plane(f, 0, 0);
                    v.extend(plane(f, 1, 1));
                    v
                })
                .collect::<Vec<_>>()
        };
        seqs.push(FlatSequence {
            exposure_s: t,
            dark: false,
            frames: g(&light),
            white_level_dv: 1023.0,
        });
        seqs.push(FlatSequence {
            exposure_s: t,
            dark: true,
            frames: g(&dark),
            white_level_dv: 1023.0,
        });
    }
    let pt = photon_transfer(&seqs).unwrap();
    for f in pt.figures() {
        eprintln!("{},{},{:.5},{:.5}", f.quantity, f.unit, f.value, f.stderr);
    }
    let k = pt.k_dv_per_e;
    let k_expect = k_true * (1.0 + cfg.prnu.powi(2));
    assert!(
        (k.value - k_expect).abs() < 4.0 * k.stderr,
        "K {k:?} vs {k_expect}"
    );
    assert!((k.value / k_true - 1.0).abs() < 0.02);
    let rn = cfg.read_noise_e();
    assert!(
        (pt.dark_noise_e.value / rn - 1.0).abs() < 0.03,
        "dark noise {:?} vs {rn}",
        pt.dark_noise_e
    );
    assert!(
        (pt.prnu.value - cfg.prnu).abs() < 4.0 * pt.prnu.stderr,
        "PRNU {:?}",
        pt.prnu
    );
    let dsnu_e = cfg.dsnu_v / cfg.conversion_gain_v_per_e();
    assert!(
        (pt.dsnu_e.value - dsnu_e).abs() < 4.0 * pt.dsnu_e.stderr,
        "DSNU {:?} vs {dsnu_e}",
        pt.dsnu_e
    );
    let sat = pt.saturation_e.expect("saturation reached");
    let clip = (1023.0 - 64.0) / k_true;
    assert!(
        sat.value < clip && sat.value > clip - 4.0 * 80.0,
        "saturation {sat:?} vs clip {clip}"
    );
}

/// Simulate one calibration set with the CLI (3 exposures × 4 light and 4 dark
/// frames, 96×96, seeds from `seed0`) into `dir` and return `sensor calibrate`'s CSV.
/// 0.0022 W/(m²·nm) of D65 puts the green levels at ≈ 1140, 2280, 3410 e⁻, all
/// within EMVA's fit range (≤ 70 % of the 5618 e⁻ ADC clip). (At 0.01, the
/// earlier setting, the levels are 5170 e⁻ and two clipped ones: the fit falls
/// back to the single level at 92 % of the clip and K comes out 1.4 % low,
/// 4.6 real standard errors over 10 sets.)
fn cli_calibration_set(dir: &Path, seed0: u64) -> String {
    let bin = env!("CARGO_BIN_EXE_camsim");
    let run = |args: &[&str]| std::process::Command::new(bin).args(args).output().unwrap();
    for (i, t) in ["0.002", "0.004", "0.006"].iter().enumerate() {
        let o = run(&[
            "sensor",
            "simulate",
            "imx363",
            "--flat-irradiance-w-m2-nm",
            "0.0022",
            "--spectrum",
            "cie-d65",
            "--exposure-s",
            t,
            "--frames",
            "4",
            "--size",
            "96x96",
            "--seed",
            &format!("{}", seed0 + i as u64),
            "--dng",
            "--out",
            dir.join(format!("light{i}")).to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let o = run(&[
            "sensor",
            "simulate",
            "imx363",
            "--flat-irradiance-w-m2-nm",
            "0.0022",
            "--exposure-s",
            t,
            "--frames",
            "4",
            "--size",
            "96x96",
            "--dark",
            "--seed",
            &format!("{}", seed0 + 10 + i as u64),
            "--out",
            dir.join(format!("dark{i}")).to_str().unwrap(),
        ]);
        assert!(o.status.success());
    }
    let o = run(&["sensor", "calibrate", dir.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout).unwrap()
}

/// (value, stderr) of a `quantity,unit` row of `sensor calibrate`'s CSV.
fn row(out: &str, key: &str) -> (f64, f64) {
    let l = out
        .lines()
        .find(|l| l.starts_with(key))
        .unwrap_or_else(|| panic!("missing {key} in {out}"));
    let f: Vec<f64> = l.split(',').skip(2).map(|v| v.parse().unwrap()).collect();
    (f[0], f[1])
}

/// `camsim sensor simulate` + `camsim sensor calibrate` end to end, and bad input.
///
/// The true values are the sensor file's: K = 0.1707 DV/e⁻ (× (1 + PRNU²) =
/// 1 + 3e-5, see the photon-transfer test), read noise 2.953 e⁻, DSNU
/// 0.038 mV / 76.53 µV/e⁻ = 0.497 e⁻, PRNU 0.54 %. The real standard error of
/// each estimate is measured: 10 independent sets (different seeds) give its
/// spread s. The reported stderr must agree with s (with 9 degrees of
/// freedom s/σ lies in [0.4, 2.5] with probability > 0.997), the first
/// set lies within 3 s of the truth, and the mean of the 10 within 3 s/√10.
/// Read noise carries a known bias from the EMVA 1/12 DV² quantisation term
/// at σ = 0.5 DV (up to ±1.4 %, see the photon-transfer test), added to its
/// tolerance. The PRNU and DSNU fields are fixed per sensor, so all sets see
/// the same 4608-pixel realisation; its departure from the specified std
/// (≈ 1/√(2·4608) = 1 % relative) is < 0.1 of the measured spread.
#[test]
fn cli_simulate_then_calibrate() {
    let bin = env!("CARGO_BIN_EXE_camsim");
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| std::process::Command::new(bin).args(args).output().unwrap();
    let out = cli_calibration_set(dir.path(), 0);
    eprintln!("{out}");
    assert!(dir.path().join("light0/frame_0003.png").exists());
    assert!(dir.path().join("light0/frame_0003.dng").exists());
    let s = std::fs::read_to_string(dir.path().join("light0/settings.csv")).unwrap();
    assert!(
        s.starts_with("key,value\n")
            && s.contains("exposure_s,0.002")
            && s.contains("spectrum,cie-d65")
    );
    let mut lines = out.lines();
    assert_eq!(lines.next(), Some("quantity,unit,value,stderr"));
    let cfg = imx363();
    let truth = [
        (
            "system_gain_k,DV/e-,",
            cfg.conversion_gain_dv_per_e() * (1.0 + cfg.prnu.powi(2)),
            0.0,
        ),
        (
            "read_noise,e-,",
            cfg.read_noise_e(),
            0.014 * cfg.read_noise_e(),
        ),
        ("dsnu,e-,", cfg.dsnu_v / cfg.conversion_gain_v_per_e(), 0.0),
        ("prnu,%,", cfg.prnu * 100.0, 0.0),
    ];
    let repeats: Vec<String> = (1..10u64)
        .map(|r| {
            let d = tempfile::tempdir().unwrap();
            cli_calibration_set(d.path(), 100 * r)
        })
        .chain(std::iter::once(out.clone()))
        .collect();
    for (key, want, bias) in truth {
        let (v0, se0) = row(&out, key);
        let vals: Vec<f64> = repeats.iter().map(|o| row(o, key).0).collect();
        let n = vals.len() as f64;
        let mean = vals.iter().sum::<f64>() / n;
        let sd = (vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        eprintln!(
            "{key} truth {want:.5}: first {v0:.5} ± {se0:.5} (reported), \
             10 sets: mean {mean:.5}, spread {sd:.5}"
        );
        assert!(
            se0 > 0.4 * sd && se0 < 2.5 * sd,
            "{key}: reported stderr {se0} vs measured spread {sd}"
        );
        assert!(
            (v0 - want).abs() < 3.0 * sd + bias,
            "{key}: {v0} vs true {want} (real SE {sd})"
        );
        assert!(
            (mean - want).abs() < 3.0 * sd / n.sqrt() + bias,
            "{key}: mean of 10 sets {mean} vs true {want} (SE {})",
            sd / n.sqrt()
        );
    }
    // bad input: exit 3, message names the path
    let o = run(&[
        "sensor",
        "calibrate",
        dir.path().join("nope").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&o.stderr).contains("nope"));
    let o = run(&[
        "sensor",
        "simulate",
        "imx636",
        "--flat-irradiance-w-m2-nm",
        "1",
        "--exposure-s",
        "0.1",
        "--frames",
        "2",
        "--out",
        "x",
    ]);
    assert_eq!(o.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&o.stderr).contains("did you mean 'imx363'"));
}

/// `CAMSIM_SENSOR_ISA` lowers the readout's instruction set: a value it does
/// not know is reported on stderr (and ignored), a known one is not, and the
/// frames are the same bits either way.
#[test]
fn an_unknown_sensor_isa_cap_is_reported() {
    let bin = env!("CARGO_BIN_EXE_camsim");
    let dir = tempfile::tempdir().unwrap();
    let run = |cap: &str, out: &str| {
        let o = std::process::Command::new(bin)
            .env("CAMSIM_SENSOR_ISA", cap)
            .args([
                "sensor",
                "simulate",
                "imx363",
                "--flat-irradiance-w-m2-nm",
                "0.0022",
                "--exposure-s",
                "0.002",
                "--frames",
                "1",
                "--size",
                "16x16",
                "--out",
                dir.path().join(out).to_str().unwrap(),
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let warned = run("bogus", "a");
    assert!(
        warned.contains("CAMSIM_SENSOR_ISA=\"bogus\" ignored"),
        "{warned}"
    );
    for cap in ["avx2", "baseline"] {
        let quiet = run(cap, cap);
        assert!(!quiet.contains("CAMSIM_SENSOR_ISA"), "{cap}: {quiet}");
    }
    let frame = |d: &str| std::fs::read(dir.path().join(d).join("frame_0000.png")).unwrap();
    assert_eq!(frame("a"), frame("baseline"));
    assert_eq!(frame("a"), frame("avx2"));
}
