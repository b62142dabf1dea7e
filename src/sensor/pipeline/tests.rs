//! Unit tests of the pipeline's parts against values worked out by hand (the
//! whole chain is tested against a hand calculation and exact noise in
//! `tests/sensor_*.rs`).

use super::*;
use crate::sensor::Sources;
use std::path::Path;

fn mono(extra: &str) -> SensorConfig {
    let text = format!(
        "cfa \"mono\"\nqe w=\"one\"\nconversion-gain-uv-per-e 100\nvoltage-swing-v 1.0\n\
         well-capacity-e 1000\nbit-depth 12\nblack-level-dv 0\npixel-size-um 2\n{extra}\n"
    );
    let mut c = SensorConfig::parse(&text, Path::new("mono.kdl")).unwrap();
    c.sources = Sources::none();
    c
}

/// Weights of each sensor pixel on the optical-image pixels it covers.
fn weights(m: &AxisMap) -> Vec<Vec<(u32, f64)>> {
    m.weights.clone()
}

fn assert_weights(got: &[Vec<(u32, f64)>], want: &[&[(u32, f64)]]) {
    assert_eq!(got.len(), want.len(), "{got:?}");
    for (g, w) in got.iter().zip(want) {
        assert_eq!(g.len(), w.len(), "{got:?}");
        for (a, b) in g.iter().zip(w.iter()) {
            assert!(
                a.0 == b.0 && (a.1 - b.1).abs() < 1e-12,
                "{got:?} vs {want:?}"
            );
        }
    }
}

/// Same grids: pixel j reads optical pixel j. Sensor pixels of half the
/// pitch: each reads the one it lies in. Of twice the pitch: two halves.
/// Of 1.5×: [0, 1.5) and [1.5, 3) in optical pixels, split ⅔ + ⅓.
#[test]
fn axis_map_area_weights() {
    let m = axis_map(4, 4, 0, 4, 1.0);
    assert_eq!((m.start, m.centre.clone()), (0, vec![0, 1, 2, 3]));
    assert_weights(
        &weights(&m),
        &[&[(0, 1.0)], &[(1, 1.0)], &[(2, 1.0)], &[(3, 1.0)]],
    );
    let m = axis_map(8, 4, 0, 4, 0.5);
    assert_eq!(m.centre, vec![0, 0, 1, 1, 2, 2, 3, 3]);
    assert!(m.weights.iter().all(|w| w.len() == 1 && w[0].1 == 1.0));
    let m = axis_map(2, 4, 0, 4, 2.0);
    assert_weights(
        &weights(&m),
        &[&[(0, 0.5), (1, 0.5)], &[(2, 0.5), (3, 0.5)]],
    );
    assert_eq!(m.centre, vec![1, 3]);
    let m = axis_map(2, 3, 0, 3, 1.5);
    let (a, b) = (1.0 / 1.5, 0.5 / 1.5);
    assert_weights(&weights(&m), &[&[(0, a), (1, b)], &[(1, b), (2, a)]]);
    // Both grids centred: 3 sensor pixels of 1 on 4 optical pixels start
    // half a pixel in, [0.5, 1.5) …
    let m = axis_map(3, 4, 0, 4, 1.0);
    assert_weights(
        &weights(&m),
        &[
            &[(0, 0.5), (1, 0.5)],
            &[(1, 0.5), (2, 0.5)],
            &[(2, 0.5), (3, 0.5)],
        ],
    );
    assert_eq!(m.centre, vec![1, 2, 3]);
}

/// A window of optical pixels [1, 3) on a 4-pixel axis covers sensor
/// pixels 1 and 2 (same grids); indices are local to the window.
#[test]
fn axis_map_of_a_window() {
    let m = axis_map(4, 4, 1, 2, 1.0);
    assert_eq!(m.start, 1);
    assert_weights(&weights(&m), &[&[(0, 1.0)], &[(1, 1.0)]]);
    assert_eq!(m.centre, vec![0, 1]);
    // Twice the pitch: only sensor pixels wholly inside the window.
    let m = axis_map(4, 8, 2, 4, 2.0);
    assert_eq!(m.start, 1);
    assert_weights(
        &weights(&m),
        &[&[(0, 0.5), (1, 0.5)], &[(2, 0.5), (3, 0.5)]],
    );
}

#[test]
fn sensor_size_follows_the_field_of_view_unless_given() {
    let c = mono("");
    // 1 µm optical pixels on 2 µm sensor pixels: half as many.
    assert_eq!(sensor_size(&c, (100, 51), 1e-6), (50, 26));
    assert_eq!(sensor_size(&c, (1, 1), 1e-6), (1, 1));
    let c = mono("cols 7\nrows 5");
    assert_eq!(sensor_size(&c, (100, 51), 1e-6), (7, 5));
}

#[test]
fn percentile_is_the_nearest_rank() {
    let v = [5.0, 1.0, 4.0, 2.0, 3.0];
    assert_eq!(percentile_nearest_rank(&v, 100.0), 5.0);
    assert_eq!(percentile_nearest_rank(&v, 20.0), 1.0);
    assert_eq!(percentile_nearest_rank(&v, 20.1), 2.0);
    assert_eq!(percentile_nearest_rank(&v, 60.0), 3.0);
    assert_eq!(percentile_nearest_rank(&v, 1e-6), 1.0);
    assert_eq!(
        percentile_nearest_rank(&[f32::NAN, 1.0, f32::INFINITY, 2.0], 100.0),
        2.0
    );
    assert_eq!(percentile_nearest_rank(&[f32::NAN], 50.0), 0.0);
}

/// Auto exposure puts the percentile's rate at `level` of the full well.
#[test]
fn auto_exposure_time_from_the_rates() {
    let c = mono("exposure-s 0.25");
    assert_eq!(resolve_exposure_s(&c, &[1.0]).unwrap(), 0.25);
    let mut c = mono("");
    c.exposure = Exposure::Auto {
        level: 0.8,
        percentile: 100.0,
    };
    // Full well min(1000 e⁻, 1 V / 100 µV/e⁻ = 10⁴ e⁻) = 1000 e⁻; 0.8 · 1000 / 400.
    assert_eq!(resolve_exposure_s(&c, &[100.0, 400.0, 200.0]).unwrap(), 2.0);
    assert!(resolve_exposure_s(&c, &[0.0, 0.0]).is_err());
    assert!(resolve_exposure_s(&c, &[]).is_err());
}

/// The dot product over 8 lanes and a remainder, and the validity check:
/// a negative or non-finite value anywhere makes the spectrum invalid.
#[test]
fn dot_check_sums_and_validates() {
    let w: Vec<f32> = (1..=19).map(|i| i as f32).collect();
    let p = vec![1.0f32; 19];
    assert_eq!(dot_check(&w, &p), (190.0, true));
    let p2: Vec<f32> = (0..19)
        .map(|i| if i % 2 == 0 { 2.0 } else { 0.0 })
        .collect();
    // 2·(1 + 3 + … + 19) = 2·100.
    assert_eq!(dot_check(&w, &p2).0, 200.0);
    for (i, bad) in [(3, -1.0), (17, -1.0), (5, f32::NAN), (18, f32::INFINITY)] {
        let mut q = p.clone();
        q[i] = bad;
        assert!(!dot_check(&w, &q).1, "{i} {bad}");
    }
    // −0 and 0 are not negative, in the 8-lane blocks and in the remainder.
    let mut q = p.clone();
    q[2] = -0.0;
    q[17] = 0.0;
    q[18] = -0.0;
    assert!(dot_check(&w, &q).1);
    // A sum that overflows f32 is not finite: two values in one lane, or in
    // the remainder after blocks of zeros.
    let mut q = vec![0.0f32; 19];
    q[0] = 3e38;
    q[8] = 3e38;
    assert!(!dot_check(&w, &q).1);
    let mut q = vec![0.0f32; 19];
    q[16] = 3e38;
    q[17] = 3e38;
    assert!(!dot_check(&w, &q).1);
    // Under 16 bands (one pass in order): the same rules. Zeros of either
    // sign are valid, a negative value is not, an overflowing sum is not.
    let w3 = [1.0f32, 2.0, 3.0];
    assert_eq!(dot_check(&w3, &[1.0, 0.0, -0.0]), (1.0, true));
    assert!(!dot_check(&w3, &[1.0, -1.0, 0.0]).1);
    assert!(!dot_check(&w3, &[3e38, 3e38, 0.0]).1);
}

#[test]
fn channel_rows_follow_the_cfa_from_the_window() {
    let mut c = mono("");
    c.cfa = crate::image::CfaPattern::bayer("rggb").unwrap();
    let rows = channel_rows(&c, Rect::new(1, 0, 3, 2));
    let r = c.cfa.channel_at(0, 0) as u8;
    let g = c.cfa.channel_at(1, 0) as u8;
    let b = c.cfa.channel_at(1, 1) as u8;
    assert_eq!(rows, vec![vec![g, r, g], vec![b, g, b]]);
}

/// Relative illumination is 1 unless the sensor has a map and pixel
/// vignetting is on; the radius is measured from the sensor centre.
#[test]
fn relative_illumination_needs_a_map_and_the_source() {
    let mut c = mono("cols 4\nrows 4");
    assert_eq!(relative_illumination_at(&c, (4, 4), 0, 0), 1.0);
    // Linear from 1 on axis to 0.5 at 10 µm.
    c.relative_illumination = RelativeIllumination::Table {
        field_height_mm: vec![0.0, 0.01],
        value: vec![1.0, 0.5],
    };
    assert_eq!(relative_illumination_at(&c, (4, 4), 0, 0), 1.0);
    c.sources.pixel_vignetting = true;
    // Pixel (0, 0) of 4×4 at 2 µm: 1.5 px from the centre in x and y.
    let h_mm = (2.0f64 * 3e-3 * 3e-3).sqrt();
    let want = 1.0 - 0.5 * h_mm / 0.01;
    for (x, y) in [(0, 0), (3, 3), (0, 3)] {
        let got = relative_illumination_at(&c, (4, 4), x, y);
        assert!((got - want).abs() < 1e-12, "({x}, {y}): {got} vs {want}");
    }
    // Pixel (1, 2): ½ px from the centre in x and y.
    let h_mm = (2.0f64 * 1e-3 * 1e-3).sqrt();
    let got = relative_illumination_at(&c, (4, 4), 1, 2);
    assert!((got - (1.0 - 0.5 * h_mm / 0.01)).abs() < 1e-12, "{got}");
}

/// w[c][b] = k·QE_c(λ)·Δλ·A·FF·λ/(hc), written out with CODATA's h and c:
/// three channels of different constant QE, a fill factor and a calibration
/// factor other than 1, so each factor and each operation shows.
#[test]
fn channel_weights_are_electrons_per_second_per_irradiance() {
    let text = "cfa \"rggb\"\nqe r=\"constant:0.5\" g=\"constant:0.25\" b=\"constant:0.125\"\n\
                conversion-gain-uv-per-e 100\nvoltage-swing-v 1.0\nwell-capacity-e 1000\n\
                bit-depth 12\nblack-level-dv 0\npixel-size-um 2\nfill-factor 0.5\n\
                illuminance-scale-factor 3\n";
    let c = SensorConfig::parse(text, Path::new("rgb.kdl")).unwrap();
    let grid = WavelengthGrid::new(400.0, 700.0, 10.0).unwrap();
    let w = channel_weights(&c, &grid);
    assert_eq!(w.len(), 3);
    let (h, cl) = (6.626_070_15e-34, 299_792_458.0);
    for (ch, row) in w.iter().enumerate() {
        assert_eq!(row.len(), 31);
        let qe = match c.cfa.channels[ch].as_str() {
            "r" => 0.5,
            "g" => 0.25,
            "b" => 0.125,
            other => panic!("channel {other}"),
        };
        for (b, &got) in row.iter().enumerate() {
            let lambda_m = (400.0 + 10.0 * b as f64) * 1e-9;
            let want = 3.0 * qe * 10.0 * (2e-6 * 2e-6 * 0.5) * lambda_m / (h * cl);
            assert!(
                (got / want - 1.0).abs() < 1e-12,
                "{ch} {b}: {got} vs {want}"
            );
        }
    }
}

/// Sensor pixels of 0.7 optical pixels: the overlaps' sums miss 1 by round-off
/// (1 ± 2·10⁻¹⁶, worked out in IEEE doubles), and the renormalisation makes
/// every pixel's weights sum to exactly 1, so a flat field stays exactly flat.
#[test]
fn axis_map_weights_sum_to_exactly_one() {
    for (ns, of) in [(5, 7), (3, 4), (7, 13)] {
        let m = axis_map(ns, of, 0, of, 0.7);
        assert_eq!(m.weights.len(), ns as usize);
        for (j, v) in m.weights.iter().enumerate() {
            let sum: f64 = v.iter().map(|x| x.1).sum();
            assert_eq!(sum, 1.0, "{ns} on {of}, pixel {j}: {v:?}");
        }
    }
}

/// An RGB sensor of 2 µm pixels, exposure 0.5 s, analog gain 2, black level
/// 10 DV, no noise, no clipping, no quantisation (so every step is linear).
fn rgb_linear() -> SensorConfig {
    let text = "cfa \"rggb\"\nqe r=\"constant:0.5\" g=\"constant:0.25\" b=\"constant:0.125\"\n\
                conversion-gain-uv-per-e 100\nvoltage-swing-v 1.0\nwell-capacity-e 1000\n\
                bit-depth 12\nblack-level-dv 10\npixel-size-um 2\nexposure-s 0.5\n\
                analog-gain 2\n";
    let mut c = SensorConfig::parse(text, Path::new("rgb.kdl")).unwrap();
    c.sources = Sources::none();
    c
}

/// Nine bands (one 8-lane block and a remainder in the same-grid dot product).
fn nine_bands() -> WavelengthGrid {
    WavelengthGrid::new(400.0, 480.0, 10.0).unwrap()
}

/// Mean electrons over 0.5 s of a pixel of channel `ch` ("r", "g", "b") under
/// the spectral irradiance `e` (W/(m²·nm), on [`nine_bands`]), by hand.
fn hand_electrons(ch: &str, e: &[f64]) -> f64 {
    let qe = match ch {
        "r" => 0.5,
        "g" => 0.25,
        _ => 0.125,
    };
    let (h, c) = (6.626_070_15e-34, 299_792_458.0);
    let rate: f64 = e
        .iter()
        .enumerate()
        .map(|(b, eb)| qe * 10.0 * 4e-12 * (400.0 + 10.0 * b as f64) * 1e-9 / (h * c) * eb)
        .sum();
    0.5 * rate
}

/// Irradiance of optical pixel (x, y) in band b: distinct everywhere.
fn irradiance_at(x: u32, y: u32, b: usize) -> f64 {
    1e-3 * (1.0 + x as f64 + 7.0 * y as f64) * (1.0 + 0.1 * b as f64)
}

fn optical_image(full: (u32, u32), window: Rect, pitch_m: f64) -> OpticalImage {
    let mut oi = OpticalImage::new(full.0, full.1, window, pitch_m, nine_bands());
    let mut k = 0;
    for y in window.y..window.y + window.h {
        for x in window.x..window.x + window.w {
            for b in 0..9 {
                oi.irradiance[k] = irradiance_at(x, y, b) as f32;
                k += 1;
            }
        }
    }
    oi.labels = (0..window.area() as u32).map(|i| 100 + i).collect();
    oi
}

/// The linear chain of a pixel: electrons → volts (100 µV/e⁻) → DV (gain 2,
/// 2¹² steps per volt, black 10).
fn assert_linear_chain(f: &SensorFrame, i: usize, want_e: f64, what: &str) {
    let close = |a: f64, b: f64| (a / b - 1.0).abs() < 2e-6;
    let e = f.mean_electrons[i] as f64;
    assert!(close(e, want_e), "{what}: mean electrons {e} vs {want_e}");
    assert_eq!(f.image.electrons[i], f.mean_electrons[i], "{what}");
    assert!(close(f.volts[i] as f64, want_e * 1e-4), "{what}: volts");
    let dv = want_e * 1e-4 * 2.0 * 4096.0 + 10.0;
    assert!(
        close(f.image.dv[i] as f64, dv),
        "{what}: DV {} vs {dv}",
        f.image.dv[i]
    );
}

/// Same grids (2 µm optical pixels on 2 µm sensor pixels), a window of the
/// frame: each sensor pixel reads exactly its optical pixel, every CFA channel
/// with its own QE, labels carried over.
#[test]
fn run_on_the_same_grid_reads_each_optical_pixel() {
    let c = rgb_linear();
    let window = Rect::new(1, 2, 3, 2);
    let oi = optical_image((6, 5), window, 2e-6);
    let f = simulate_frame(&c, &oi, 1).unwrap();
    assert_eq!((f.image.full_width, f.image.full_height), (6, 5));
    assert_eq!(f.image.window, window);
    assert_eq!(f.image.exposure_s, 0.5);
    for (i, (x, y)) in (2..4).flat_map(|y| (1..4).map(move |x| (x, y))).enumerate() {
        let ch = &c.cfa.channels[c.cfa.channel_at(x, y)];
        let e: Vec<f64> = (0..9).map(|b| irradiance_at(x, y, b)).collect();
        assert_linear_chain(&f, i, hand_electrons(ch, &e), &format!("({x}, {y})"));
    }
    assert_eq!(f.image.labels, oi.labels);
    // `simulate` keeps DV and electrons only.
    let s = simulate(&c, &oi, 1).unwrap();
    assert_eq!(
        (s.dv, s.electrons),
        (f.image.dv.clone(), f.image.electrons.clone())
    );
}

/// 1 µm optical pixels under 2 µm sensor pixels: each sensor pixel averages
/// the 2×2 optical pixels it covers; its label is the one under its centre.
#[test]
fn run_on_a_finer_optical_grid_averages_the_covered_pixels() {
    let c = rgb_linear();
    let oi = optical_image((4, 4), Rect::new(0, 0, 4, 4), 1e-6);
    let f = simulate_frame(&c, &oi, 1).unwrap();
    assert_eq!((f.image.full_width, f.image.full_height), (2, 2));
    for (i, (x, y)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
        let ch = &c.cfa.channels[c.cfa.channel_at(x, y)];
        let e: Vec<f64> = (0..9)
            .map(|b| {
                let mut s = 0.0;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    s += irradiance_at(2 * x + dx, 2 * y + dy, b) as f32 as f64;
                }
                s / 4.0
            })
            .collect();
        assert_linear_chain(&f, i, hand_electrons(ch, &e), &format!("({x}, {y})"));
        let centre = (2 * y + 1) * 4 + 2 * x + 1;
        assert_eq!(f.image.labels[i], 100 + centre, "({x}, {y})");
    }
}

/// 4 µm optical pixels under 2 µm sensor pixels: every sensor pixel lies in
/// one optical pixel (weight 1, but two sensor pixels per optical pixel, so not
/// the same grid).
#[test]
fn run_on_a_coarser_optical_grid_repeats_each_pixel() {
    let c = rgb_linear();
    let oi = optical_image((2, 2), Rect::new(0, 0, 2, 2), 4e-6);
    let f = simulate_frame(&c, &oi, 1).unwrap();
    assert_eq!((f.image.full_width, f.image.full_height), (4, 4));
    for y in 0..4u32 {
        for x in 0..4u32 {
            let ch = &c.cfa.channels[c.cfa.channel_at(x, y)];
            let e: Vec<f64> = (0..9).map(|b| irradiance_at(x / 2, y / 2, b)).collect();
            let i = (y * 4 + x) as usize;
            assert_linear_chain(&f, i, hand_electrons(ch, &e), &format!("({x}, {y})"));
            assert_eq!(f.image.labels[i], 100 + (y / 2) * 2 + x / 2);
        }
    }
}

/// Relative illumination falling linearly from 1 on axis to 0.5 at 10 µm,
/// with pixel vignetting on.
fn vignette(c: &mut SensorConfig) {
    c.relative_illumination = RelativeIllumination::Table {
        field_height_mm: vec![0.0, 0.01],
        value: vec![1.0, 0.5],
    };
    c.sources.pixel_vignetting = true;
}

/// [`vignette`]'s factor at pixel (x, y) of a `full`×`full` sensor of 2 µm
/// pixels, by hand: 1 − 0.5·h/10 µm, h from the sensor centre.
fn hand_ri(x: u32, y: u32, full: u32) -> f64 {
    let dx = (x as f64 + 0.5 - full as f64 / 2.0) * 2e-3;
    let dy = (y as f64 + 0.5 - full as f64 / 2.0) * 2e-3;
    1.0 - 0.5 * (dx * dx + dy * dy).sqrt() / 0.01
}

/// Relative illumination scales the signal on the same-grid path and the
/// resampling path alike.
#[test]
fn run_applies_relative_illumination_on_both_paths() {
    let mut c = rgb_linear();
    vignette(&mut c);
    for (oi, full) in [
        (optical_image((4, 4), Rect::new(0, 0, 4, 4), 2e-6), 4u32),
        (optical_image((2, 2), Rect::new(0, 0, 2, 2), 4e-6), 4),
    ] {
        let f = simulate_frame(&c, &oi, 1).unwrap();
        let oi_px = |x: u32, y: u32| {
            if oi.full_width == 4 {
                (x, y)
            } else {
                (x / 2, y / 2)
            }
        };
        for (x, y) in [(0u32, 0u32), (1, 2), (3, 1)] {
            let ch = &c.cfa.channels[c.cfa.channel_at(x, y)];
            let (ox, oy) = oi_px(x, y);
            let e: Vec<f64> = (0..9).map(|b| irradiance_at(ox, oy, b)).collect();
            let ri = hand_ri(x, y, full);
            let i = (y * full + x) as usize;
            assert_linear_chain(&f, i, hand_electrons(ch, &e) * ri, &format!("({x}, {y})"));
        }
    }
}

/// Every refusal of `run`, each alone.
#[test]
fn run_refuses_bad_optical_images() {
    let c = rgb_linear();
    let good = optical_image((4, 4), Rect::new(0, 0, 4, 4), 2e-6);
    assert!(simulate(&c, &good, 1).is_ok());
    for pitch in [0.0, -2e-6, f64::NAN, f64::INFINITY] {
        let mut oi = good.clone();
        oi.pixel_pitch_m = pitch;
        let e = simulate(&c, &oi, 1).unwrap_err().to_string();
        assert!(e.contains("pixel pitch"), "{pitch}: {e}");
    }
    let mut oi = good.clone();
    oi.irradiance.pop();
    let e = simulate(&c, &oi, 1).unwrap_err().to_string();
    assert!(e.contains("wrong length"), "{e}");
    // A 1 µm-wide window under 2 µm pixels covers no whole sensor pixel.
    let oi = optical_image((4, 4), Rect::new(1, 0, 1, 4), 1e-6);
    let e = simulate(&c, &oi, 1).unwrap_err().to_string();
    assert!(e.contains("covers no whole pixel"), "{e}");
    let oi = optical_image((4, 4), Rect::new(0, 1, 4, 1), 1e-6);
    assert!(simulate(&c, &oi, 1).is_err());
    // Negative or non-finite irradiance, on both paths.
    for pitch in [2e-6, 1e-6] {
        for bad in [-1e-3, f32::NAN, f32::INFINITY] {
            let mut oi = optical_image((4, 4), Rect::new(0, 0, 4, 4), pitch);
            oi.irradiance[5 * 9 + 8] = bad;
            let e = simulate(&c, &oi, 1).unwrap_err().to_string();
            assert!(e.contains("negative or non-finite"), "{pitch} {bad}: {e}");
        }
    }
    // An invalid sensor: three channels, one QE curve.
    let mut bad = c.clone();
    bad.qe.truncate(1);
    let e = simulate(&bad, &good, 1).unwrap_err().to_string();
    assert!(e.contains("QE"), "{e}");
}

/// A flat field: every pixel of the window sees the same irradiance; the
/// window must lie inside the sensor (each edge alone), the sensor needs rows
/// and cols, and the irradiance must be finite and ≥ 0.
#[test]
fn simulate_flat_exposes_a_uniform_field_inside_the_sensor() {
    let mut c = rgb_linear();
    c.cols = Some(6);
    c.rows = Some(4);
    let grid = nine_bands();
    let spectrum = Spectrum::constant("flat", 2e-3);
    let window = Rect::new(1, 1, 5, 3);
    let f = simulate_flat(&c, &spectrum, &grid, window, 1).unwrap();
    assert_eq!(f.image.window, window);
    for y in 1..4u32 {
        for x in 1..6u32 {
            let ch = &c.cfa.channels[c.cfa.channel_at(x, y)];
            let i = ((y - 1) * 5 + (x - 1)) as usize;
            assert_linear_chain(
                &f,
                i,
                hand_electrons(ch, &[2e-3; 9]),
                &format!("({x}, {y})"),
            );
        }
    }
    // The whole sensor is a window; one more column or row is not.
    assert!(simulate_flat(&c, &spectrum, &grid, Rect::new(0, 0, 6, 4), 1).is_ok());
    for w in [
        Rect::new(0, 0, 0, 4),
        Rect::new(0, 0, 6, 0),
        Rect::new(1, 0, 6, 4),
        Rect::new(0, 1, 6, 4),
    ] {
        let e = simulate_flat(&c, &spectrum, &grid, w, 1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not inside"), "{w:?}: {e}");
    }
    for bad in [-1e-3, f64::NAN, f64::INFINITY] {
        let e = simulate_flat(&c, &Spectrum::constant("bad", bad), &grid, window, 1);
        assert!(e.is_err(), "{bad}");
    }
    let mut no_size = c.clone();
    no_size.rows = None;
    let e = simulate_flat(&no_size, &spectrum, &grid, window, 1)
        .unwrap_err()
        .to_string();
    assert!(e.contains("rows and cols"), "{e}");
    let mut no_size = c.clone();
    no_size.cols = None;
    assert!(simulate_flat(&no_size, &spectrum, &grid, window, 1).is_err());
    // The flat rate per channel is the same sum.
    let rates = flat_rate_e_per_s(&c, &spectrum, &grid);
    assert_eq!(rates.len(), 3);
    for (ch, r) in c.cfa.channels.iter().zip(&rates) {
        let want = 2.0 * hand_electrons(ch, &[2e-3; 9]);
        assert!((r / want - 1.0).abs() < 1e-12, "{ch}: {r} vs {want}");
    }
}

/// A sensor smaller than the optical image on the same grid (4×4 pixels
/// centred on 6×4 optical pixels): the same-grid path starts one optical pixel
/// in, and the labels are those under each sensor pixel, not the optical
/// image's own.
#[test]
fn run_of_a_smaller_sensor_on_the_same_grid_starts_inside_the_image() {
    let mut c = rgb_linear();
    c.cols = Some(4);
    c.rows = Some(4);
    let oi = optical_image((6, 4), Rect::new(0, 0, 6, 4), 2e-6);
    let f = simulate_frame(&c, &oi, 1).unwrap();
    assert_eq!(f.image.window, Rect::new(0, 0, 4, 4));
    assert_eq!(f.image.labels.len(), 16);
    for y in 0..4u32 {
        for x in 0..4u32 {
            let i = (y * 4 + x) as usize;
            let ch = &c.cfa.channels[c.cfa.channel_at(x, y)];
            let e: Vec<f64> = (0..9).map(|b| irradiance_at(x + 1, y, b)).collect();
            assert_linear_chain(&f, i, hand_electrons(ch, &e), &format!("({x}, {y})"));
            assert_eq!(f.image.labels[i], 100 + y * 6 + x + 1, "({x}, {y})");
        }
    }
}

/// Auto exposure through the whole chain: the brightest pixel (100th
/// percentile) collects `level` of the full well, on both paths; invalid
/// irradiance in one row is refused; a fixed exposure time that is not finite
/// and ≥ 0 is refused.
#[test]
fn run_with_auto_exposure_fills_the_well_to_the_level() {
    let mut c = rgb_linear();
    c.exposure = Exposure::Auto {
        level: 0.8,
        percentile: 100.0,
    };
    // Full well min(1000 e⁻, 1 V / 100 µV/e⁻) = 1000 e⁻.
    for pitch in [2e-6, 1e-6] {
        let oi = optical_image((4, 4), Rect::new(0, 0, 4, 4), pitch);
        let f = simulate_frame(&c, &oi, 1).unwrap();
        let max = f.mean_electrons.iter().fold(0f32, |a, &b| a.max(b));
        assert!((max as f64 / 800.0 - 1.0).abs() < 1e-6, "{pitch}: {max}");
        assert!(f.image.exposure_s > 0.0 && f.image.exposure_s.is_finite());
        // One bad band of one pixel in the last row.
        let mut bad = oi.clone();
        let last = bad.irradiance.len() - 1;
        bad.irradiance[last] = f32::NAN;
        let e = simulate(&c, &bad, 1).unwrap_err().to_string();
        assert!(e.contains("negative or non-finite"), "{pitch}: {e}");
    }
    let oi = optical_image((4, 4), Rect::new(0, 0, 4, 4), 2e-6);
    for t in [f64::NAN, f64::INFINITY, -1.0] {
        c.exposure = Exposure::Seconds(t);
        assert!(simulate(&c, &oi, 1).is_err(), "{t}");
    }
    c.exposure = Exposure::Seconds(0.0);
    let f = simulate_frame(&c, &oi, 1).unwrap();
    assert!(f.mean_electrons.iter().all(|&e| e == 0.0));
}

/// A dark flat field (zero irradiance) is valid; relative illumination
/// scales a flat field too.
#[test]
fn simulate_flat_of_zero_light_and_with_relative_illumination() {
    let mut c = rgb_linear();
    c.cols = Some(4);
    c.rows = Some(4);
    let grid = nine_bands();
    let window = Rect::new(0, 0, 4, 4);
    let f = simulate_flat(&c, &Spectrum::constant("dark", 0.0), &grid, window, 1).unwrap();
    assert!(f.mean_electrons.iter().all(|&e| e == 0.0));
    vignette(&mut c);
    let f = simulate_flat(&c, &Spectrum::constant("flat", 2e-3), &grid, window, 1).unwrap();
    for (x, y) in [(0u32, 0u32), (1, 2), (3, 1)] {
        let ch = &c.cfa.channels[c.cfa.channel_at(x, y)];
        let want = hand_electrons(ch, &[2e-3; 9]) * hand_ri(x, y, 4);
        assert_linear_chain(&f, (y * 4 + x) as usize, want, &format!("({x}, {y})"));
    }
}

/// Spectra of `nb` bands from a small LCG (values in [0, 2)), `n` pixels.
fn lcg_spectra(n: usize, nb: usize, seed: u64) -> Vec<f32> {
    let mut x = seed;
    (0..n * nb)
        .map(|_| {
            x = x
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (x >> 40) as f32 / (1u64 << 23) as f32
        })
        .collect()
}

/// The 16-lane dot product against the same sum in f64, for band counts
/// below, at and around the lane count (3, 15, 16, 17, 31, 32, 61): each
/// f32 product and sum rounds by ≤ 2⁻²⁴ relative, and with non-negative terms
/// the accumulated error is at most (n + 4)·2⁻²⁴ of the sum (n terms in at
/// most n additions down a lane and four tree levels); the bound used is that.
#[test]
fn dot_check_is_the_dot_product_within_f32_rounding() {
    for nb in [3usize, 15, 16, 17, 31, 32, 61] {
        let w = lcg_spectra(1, nb, 7 + nb as u64);
        let p = lcg_spectra(1, nb, 99 + nb as u64);
        let want: f64 = w.iter().zip(&p).map(|(&a, &b)| a as f64 * b as f64).sum();
        let (d, ok) = dot_check(&w, &p);
        assert!(ok, "{nb}");
        let tol = (nb as f64 + 4.0) * f64::from(f32::EPSILON) / 2.0 * want;
        assert!(
            (d as f64 - want).abs() <= tol,
            "{nb} bands: {d} vs {want} (tolerance {tol})"
        );
        // Every band counts once: one band set to 1000 (weights 1) raises the
        // sum by 1000 − its value, whichever lane or overlap it falls in.
        let ones = vec![1.0f32; nb];
        let base = dot_check(&ones, &p).0 as f64;
        for k in 0..nb {
            let mut q = p.clone();
            q[k] = 1000.0;
            let got = dot_check(&ones, &q).0 as f64;
            let want = base + 1000.0 - p[k] as f64;
            assert!(
                (got - want).abs() <= 1e-3,
                "{nb} bands, band {k}: {got} vs {want}"
            );
        }
    }
}

/// `dot_row` gives the same bits at every instruction set level this machine
/// has (the same IEEE operations in the same order), for two channels
/// alternating along the row as in a Bayer row, and reports an invalid
/// spectrum wherever it is.
#[test]
fn dot_row_gives_the_same_bits_at_every_level() {
    use crate::sensor::readout::Isa;
    let levels: Vec<Isa> = [Isa::Baseline, Isa::Avx2, Isa::Avx512]
        .into_iter()
        .filter(|&l| l as u8 <= Isa::detect() as u8)
        .collect();
    for nb in [3usize, 15, 16, 17, 20, 31, 32, 33] {
        let n = 37;
        let w = vec![lcg_spectra(1, nb, 1), lcg_spectra(1, nb, 2)];
        let chans: Vec<u8> = (0..n).map(|c| (c % 2) as u8).collect();
        let irr = lcg_spectra(n, nb, 3);
        let mut first: Option<Vec<u32>> = None;
        for &l in &levels {
            let mut out = vec![0f32; n];
            assert!(!dot_row(l, &w, &chans, &irr, nb, &mut out), "{l:?}");
            for c in [0, 1, n - 1] {
                assert_eq!(
                    out[c].to_bits(),
                    dot_check(&w[c % 2], &irr[c * nb..(c + 1) * nb]).0.to_bits()
                );
            }
            let bits: Vec<u32> = out.iter().map(|x| x.to_bits()).collect();
            match &first {
                None => first = Some(bits),
                Some(f) => assert_eq!(&bits, f, "{l:?}, {nb} bands"),
            }
            // An invalid spectrum anywhere (inside a block of 16 pixels or in
            // the row's remainder, in its first or last bands) is reported: a
            // negative band, NaN, infinity, or bands whose sum overflows.
            for c in [0, 5, 15, 16, 31, 32, n - 1] {
                for (k, x) in [
                    (0, -1.0),
                    (nb - 1, -1e-30),
                    (nb / 2, f32::NAN),
                    (nb - 1, f32::INFINITY),
                ] {
                    let mut bad = irr.clone();
                    bad[c * nb + k] = x;
                    assert!(
                        dot_row(l, &w, &chans, &bad, nb, &mut out),
                        "{l:?} {c} {k} {x}"
                    );
                }
                let mut big = irr.clone();
                big[c * nb..(c + 1) * nb].fill(3e38);
                assert!(
                    dot_row(l, &w, &chans, &big, nb, &mut out),
                    "{l:?} {c} overflow"
                );
            }
        }
    }
}

/// Every element of a frame's outputs is written: with buffers full of NaN
/// handed back to the pool (which `expose` takes its outputs from) a frame
/// with every noise source on has no NaN in DV, electrons, volts or mean
/// electrons. The frame is large enough for the pool (≥ 4 MiB a buffer).
#[test]
fn every_output_element_is_written() {
    let mut c = rgb_linear();
    c.sources = Sources::all();
    c.sources.pixel_vignetting = false;
    c.prnu = 0.01;
    c.dsnu_v = 1e-3;
    c.read_noise_v = 1e-3;
    c.reset_noise_v = 1e-3;
    c.column_fpn_gain = 0.01;
    c.column_fpn_offset_v = 1e-3;
    let (w, h) = (1100u32, 1000u32);
    let oi = optical_image((w, h), Rect::new(0, 0, w, h), 2e-6);
    let n = (w * h) as usize;
    for _ in 0..4 {
        crate::frame_buffer::recycle(vec![f32::NAN; n]);
    }
    let f = simulate_frame(&c, &oi, 3).unwrap();
    for (name, v) in [
        ("dv", &f.image.dv),
        ("electrons", &f.image.electrons),
        ("volts", &f.volts),
        ("mean electrons", &f.mean_electrons),
    ] {
        assert_eq!(v.len(), n, "{name}");
        let unwritten = v.iter().filter(|x| x.is_nan()).count();
        assert_eq!(unwritten, 0, "{name}: {unwritten} elements not written");
    }
}
