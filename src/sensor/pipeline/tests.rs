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
    // −0 is not negative.
    let mut q = p.clone();
    q[2] = -0.0;
    assert!(dot_check(&w, &q).1);
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
