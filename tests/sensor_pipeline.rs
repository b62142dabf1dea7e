//! The optical-image path of the sensor model: absolute photon → electron
//! conversion against a hand calculation, spatial integration between different
//! pixel grids, windows, labels, relative-illumination maps, auto-exposure, bad input.

use camsim::optical_image::{OpticalImage, Rect};
use camsim::sensor::config::{RelativeIllumination, SensorConfig};
use camsim::sensor::{Exposure, Sources, simulate, simulate_frame};
use camsim::spectrum::{WavelengthGrid, library};
use std::path::Path;

fn imx363() -> SensorConfig {
    SensorConfig::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("sensors/imx363.kdl")).unwrap()
}

/// A noiseless monochrome sensor with QE 1 (mono CFA) and the IMX363 electronics.
fn ideal_mono() -> SensorConfig {
    let text = "cfa \"mono\"\nqe w=\"one\"\nconversion-gain-uv-per-e 100\nvoltage-swing-v 1.0\nwell-capacity-e 1e9\n\
                bit-depth 16\nblack-level-dv 0\npixel-size-um 1.4\nexposure-s 0.01\n";
    let mut c = SensorConfig::parse(text, Path::new("ideal.kdl")).unwrap();
    c.sources = Sources::none();
    c
}

const H: f64 = 6.626_070_15e-34;
const C: f64 = 299_792_458.0;

/// Monochromatic 550 nm irradiance on a same-grid optical image: electrons =
/// E·Δλ · λ/(hc) · QE_g(550) · (1.4 µm)² · FF · T, written out by hand.
#[test]
fn photons_to_electrons_matches_a_hand_calculation() {
    let mut cfg = imx363();
    cfg.sources = Sources::none();
    cfg.exposure = Exposure::Seconds(0.02);
    let grid = WavelengthGrid::new(400.0, 700.0, 10.0).unwrap();
    let (w, h) = (4032, 3024);
    let win = Rect::new(2000, 1500, 8, 8);
    let mut oi = OpticalImage::new(w, h, win, 1.4e-6, grid.clone());
    let band = 15; // 550 nm
    assert_eq!(grid.wavelength(band), 550.0);
    for y in 0..8 {
        for x in 0..8 {
            oi.pixel_mut(x, y)[band] = 0.01;
        }
    }
    let f = simulate_frame(&cfg, &oi, 1).unwrap();
    assert_eq!(f.image.window, win);
    let qe_g = library::named("p4a-qe-g").unwrap().eval(550.0);
    let expect_g = 0.01 * 10.0 * (550e-9 / (H * C)) * qe_g * 1.4e-6 * 1.4e-6 * 1.0 * 0.02;
    let k = cfg.conversion_gain_dv_per_e();
    for y in 0..8 {
        for x in 0..8 {
            if f.image.channel_at(x, y) == 1 {
                let e = f.mean_electrons[(y * 8 + x) as usize] as f64;
                assert!((e / expect_g - 1.0).abs() < 1e-5, "{e} vs {expect_g}");
                let dv = f.image.dv_at(x, y) as f64;
                assert!((dv - (64.0 + k * expect_g)).abs() < 1e-3 * dv);
            }
        }
    }
    assert!(expect_g > 100.0);
}

/// Optical image at 0.7 µm (2× finer) and at 1.0 µm (non-integer 1.4 ratio): each
/// sensor pixel is the area-weighted mean of the irradiance it covers. Truth by
/// dense point sampling of the piecewise-constant irradiance (4000² points per
/// pixel ⇒ relative error < 1e-3).
#[test]
fn spatial_integration_between_different_pixel_grids() {
    let grid = WavelengthGrid::new(550.0, 550.0, 10.0).unwrap();
    for &(pitch_um, n_oi, n_s) in &[(0.7, 8u32, 4u32), (1.0, 7, 5)] {
        let mut cfg = ideal_mono();
        cfg.cols = Some(n_s);
        cfg.rows = Some(n_s);
        let mut oi = OpticalImage::new(
            n_oi,
            n_oi,
            Rect::new(0, 0, n_oi, n_oi),
            pitch_um * 1e-6,
            grid.clone(),
        );
        let e_at = |i: u32, j: u32| 1.0 + i as f64 + 3.0 * j as f64;
        for j in 0..n_oi {
            for i in 0..n_oi {
                oi.pixel_mut(i, j)[0] = e_at(i, j) as f32;
            }
        }
        let f = simulate_frame(&cfg, &oi, 1).unwrap();
        assert_eq!((f.image.width(), f.image.height()), (n_s, n_s));
        // electrons per (W/m²/nm) of mean irradiance
        let per = 10.0 * 550e-9 / (H * C) * 1.4e-6 * 1.4e-6 * 0.01;
        let s = 1.4 / pitch_um;
        let off = n_oi as f64 / 2.0 - n_s as f64 / 2.0 * s;
        for y in 0..n_s {
            for x in 0..n_s {
                let m = 400;
                let mut acc = 0.0;
                for b in 0..m {
                    for a in 0..m {
                        let u = off + (x as f64 + (a as f64 + 0.5) / m as f64) * s;
                        let v = off + (y as f64 + (b as f64 + 0.5) / m as f64) * s;
                        acc += e_at(u.floor() as u32, v.floor() as u32);
                    }
                }
                let expect = acc / (m * m) as f64 * per;
                let got = f.mean_electrons[(y * n_s + x) as usize] as f64;
                assert!(
                    (got / expect - 1.0).abs() < 2e-3,
                    "pitch {pitch_um}: ({x},{y}) {got} vs {expect}"
                );
            }
        }
    }
}

/// Windows: an ROI-rendered optical image maps to the matching sensor window, at the
/// same pitch and at half the pitch; labels come from the pixel centre.
#[test]
fn windows_and_labels_follow_the_optical_image() {
    let grid = WavelengthGrid::new(550.0, 550.0, 10.0).unwrap();
    let mut cfg = ideal_mono();
    cfg.cols = Some(400);
    cfg.rows = Some(300);
    let mut oi = OpticalImage::new(400, 300, Rect::new(100, 200, 50, 40), 1.4e-6, grid.clone());
    oi.label_names = vec!["a".into(), "b".into()];
    for (i, l) in oi.labels.iter_mut().enumerate() {
        *l = ((i % 50) >= 25) as u32;
    }
    let im = simulate(&cfg, &oi, 1).unwrap();
    assert_eq!(im.window, Rect::new(100, 200, 50, 40));
    assert_eq!(im.labels, oi.labels);
    assert_eq!(im.label_names, oi.label_names);
    let oi2 = OpticalImage::new(800, 600, Rect::new(200, 400, 100, 80), 0.7e-6, grid);
    let mut oi2 = oi2;
    for (i, l) in oi2.labels.iter_mut().enumerate() {
        *l = ((i % 100) >= 50) as u32;
    }
    let im = simulate(&cfg, &oi2, 1).unwrap();
    assert_eq!(im.window, Rect::new(100, 200, 50, 40));
    for y in 0..40 {
        for x in 0..50 {
            assert_eq!(im.labels[(y * 50 + x) as usize], (x >= 25) as u32);
        }
    }
}

/// The relative-illumination map multiplies the signal by RI(field height) at each
/// pixel: cos⁴ at the frame corner and a measured table, both exact in a noiseless run.
#[test]
fn relative_illumination_map_is_applied_per_pixel() {
    let grid = WavelengthGrid::new(550.0, 550.0, 10.0).unwrap();
    let mut cfg = ideal_mono();
    cfg.cols = Some(4032);
    cfg.rows = Some(3024);
    let corner = Rect::new(0, 0, 4, 4);
    let centre = Rect::new(2014, 1510, 4, 4);
    let flat = |w: Rect| {
        let mut oi = OpticalImage::new(4032, 3024, w, 1.4e-6, grid.clone());
        oi.irradiance.iter_mut().for_each(|v| *v = 1.0);
        oi
    };
    let base = simulate_frame(&cfg, &flat(centre), 1)
        .unwrap()
        .mean_electrons[0] as f64;
    for ri in [
        RelativeIllumination::CosN {
            n: 4.0,
            distance_mm: 4.0,
        },
        RelativeIllumination::Table {
            field_height_mm: vec![0.0, 2.0, 4.0],
            value: vec![1.0, 0.8, 0.4],
        },
    ] {
        cfg.relative_illumination = ri.clone();
        cfg.sources.pixel_vignetting = true;
        let f = simulate_frame(&cfg, &flat(corner), 1).unwrap();
        // pixel (1, 2): centre offset (1.5 − 2016, 2.5 − 1512) px × 1.4 µm
        let (dx, dy): (f64, f64) = ((1.5 - 2016.0) * 1.4e-3, (2.5 - 1512.0) * 1.4e-3);
        let h = (dx * dx + dy * dy).sqrt();
        let expect = match &ri {
            RelativeIllumination::CosN { .. } => (4.0f64 / (16.0 + h * h).sqrt()).powi(4),
            _ => 0.8 + (h - 2.0) / 2.0 * (0.4 - 0.8),
        };
        let got = f.mean_electrons[2 * 4 + 1] as f64 / base;
        assert!(
            (got - expect).abs() < 1e-5,
            "{ri:?}: {got} vs {expect} at h = {h} mm"
        );
        cfg.sources.pixel_vignetting = false;
        let off = simulate_frame(&cfg, &flat(corner), 1)
            .unwrap()
            .mean_electrons[2 * 4 + 1] as f64;
        assert!((off / base - 1.0).abs() < 1e-6);
    }
}

/// An ideal n×n mono sensor with a 6000 e⁻ well, the given exposure, and a
/// matching black 550 nm optical image.
fn auto_setup(n: u32, exposure: Exposure) -> (SensorConfig, OpticalImage) {
    let grid = WavelengthGrid::new(550.0, 550.0, 10.0).unwrap();
    let mut cfg = ideal_mono();
    cfg.well_capacity_e = 6000.0;
    cfg.cols = Some(n);
    cfg.rows = Some(n);
    cfg.exposure = exposure;
    let oi = OpticalImage::new(n, n, Rect::new(0, 0, n, n), 1.4e-6, grid);
    (cfg, oi)
}

/// Auto-exposure at percentile 100 (ISETCam's rule) sets the brightest pixel's
/// mean signal to the level × full well.
#[test]
fn auto_exposure_targets_the_level() {
    let isetcam = Exposure::Auto {
        level: 0.95,
        percentile: 100.0,
    };
    let (cfg, mut oi) = auto_setup(16, isetcam);
    for (i, v) in oi.irradiance.iter_mut().enumerate() {
        *v = 0.001 * (1 + i % 7) as f32;
    }
    let f = simulate_frame(&cfg, &oi, 1).unwrap();
    let max = f.mean_electrons.iter().cloned().fold(0.0f32, f32::max) as f64;
    assert!((max / (0.95 * 6000.0) - 1.0).abs() < 1e-5, "{max}");
    assert!(f.image.exposure_s > 0.0);
    let (_, black) = auto_setup(16, isetcam);
    assert!(
        simulate(&cfg, &black, 1)
            .unwrap_err()
            .to_string()
            .contains("black")
    );
}

/// The default auto-exposure (99.9th percentile) is not set by a few Monte Carlo
/// fireflies: 4 of 10 000 pixels 1000× brighter than the rest leave the uniform
/// pixels at level × full well (nearest rank 9990 of 10 000 is a uniform pixel),
/// whereas percentile 100 exposes for the fireflies and leaves the scene at
/// 1/1000 of that.
#[test]
fn auto_exposure_ignores_fireflies() {
    let (mut cfg, mut oi) = auto_setup(100, Exposure::auto_default());
    oi.irradiance.iter_mut().for_each(|v| *v = 0.001);
    for i in [17, 2024, 5555, 9876] {
        oi.irradiance[i] = 1.0;
    }
    let f = simulate_frame(&cfg, &oi, 1).unwrap();
    let bulk = f.mean_electrons[0] as f64;
    assert!((bulk / (0.95 * 6000.0) - 1.0).abs() < 1e-5, "{bulk}");
    cfg.exposure = Exposure::Auto {
        level: 0.95,
        percentile: 100.0,
    };
    let f = simulate_frame(&cfg, &oi, 1).unwrap();
    let bulk = f.mean_electrons[0] as f64;
    assert!((bulk / (0.95 * 6.0) - 1.0).abs() < 1e-4, "{bulk}");
}

#[test]
fn bad_optical_images_are_errors_not_panics() {
    let grid = WavelengthGrid::new(550.0, 560.0, 10.0).unwrap();
    let cfg = ideal_mono();
    let mut oi = OpticalImage::new(8, 8, Rect::new(0, 0, 8, 8), 1.4e-6, grid.clone());
    oi.irradiance[5] = f32::NAN;
    assert!(
        simulate(&cfg, &oi, 1)
            .unwrap_err()
            .to_string()
            .contains("non-finite")
    );
    oi.irradiance[5] = -1.0;
    assert!(simulate(&cfg, &oi, 1).is_err());
    oi.irradiance[5] = f32::INFINITY;
    assert!(simulate(&cfg, &oi, 1).is_err());
    let mut z = OpticalImage::new(8, 8, Rect::new(0, 0, 8, 8), 0.0, grid.clone());
    z.irradiance.clear();
    assert!(simulate(&cfg, &z, 1).is_err());
    // a 1-pixel window at 0.7 µm covers no whole 1.4 µm pixel
    let tiny = OpticalImage::new(8, 8, Rect::new(3, 3, 1, 1), 0.7e-6, grid.clone());
    assert!(
        simulate(&cfg, &tiny, 1)
            .unwrap_err()
            .to_string()
            .contains("covers no whole pixel")
    );
    // same-grid NaN is also caught on the non-identity path
    let mut oi = OpticalImage::new(8, 8, Rect::new(0, 0, 8, 8), 0.7e-6, grid);
    oi.irradiance[0] = f32::NAN;
    assert!(simulate(&cfg, &oi, 1).is_err());
}

/// Extreme brightness (1e30 W/(m²·nm), overflowing f32 electron rates) saturates
/// cleanly at the white level; zero light gives the black level ± noise.
#[test]
fn extreme_irradiance_saturates_cleanly() {
    let cfg = imx363();
    let grid = WavelengthGrid::new(400.0, 700.0, 10.0).unwrap();
    let mut oi = OpticalImage::new(4032, 3024, Rect::new(0, 0, 8, 8), 1.4e-6, grid.clone());
    oi.irradiance.iter_mut().for_each(|v| *v = 1e30);
    let im = simulate(&cfg, &oi, 1).unwrap();
    assert!(im.dv.iter().all(|&v| v == 1023.0));
    assert!(
        im.electrons
            .iter()
            .all(|&e| e.is_finite() && (e as f64) <= cfg.full_well_e() + 1e-3)
    );
    let dark = OpticalImage::new(4032, 3024, Rect::new(0, 0, 64, 64), 1.4e-6, grid);
    let im = simulate(&cfg, &dark, 1).unwrap();
    assert!(im.dv.iter().all(|&v| (60.0..=68.0).contains(&v)));
}

/// `simulate` (electrons written over the rate buffer) and `simulate_frame` (keeps
/// volts and means) are the same model: identical DV and electrons.
#[test]
fn simulate_and_simulate_frame_agree() {
    let cfg = imx363();
    let grid = WavelengthGrid::new(400.0, 700.0, 10.0).unwrap();
    let mut oi = OpticalImage::new(4032, 3024, Rect::new(1000, 1000, 37, 23), 1.4e-6, grid);
    for (i, v) in oi.irradiance.iter_mut().enumerate() {
        *v = 1e-4 * (i % 13) as f32;
    }
    let a = simulate(&cfg, &oi, 5).unwrap();
    let b = simulate_frame(&cfg, &oi, 5).unwrap();
    assert_eq!(a.dv, b.image.dv);
    assert_eq!(a.electrons, b.image.electrons);
    assert_eq!(b.volts.len(), a.dv.len());
    assert!(a.dv.iter().any(|&v| v > 70.0));
}
