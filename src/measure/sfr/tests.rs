//! Unit tests of the e-SFR's parts, each against values worked out by hand
//! from its definition (the whole measurement is tested against analytic
//! MTFs in `tests/measure_sfr.rs`).

use super::*;

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// An `Sfr` holding the given MTF table and ESF/LSF, other fields plain.
fn sfr_with(freq: &[f64], mtf: &[f64], se: &[f64], pitch: Option<f64>) -> Sfr {
    Sfr {
        freq_cy_per_px: freq.to_vec(),
        mtf: mtf.to_vec(),
        mtf_stderr: se.to_vec(),
        esf_x_px: vec![],
        esf: vec![],
        lsf: vec![],
        mtf50_cy_per_px: Some(0.2),
        mtf50_stderr: 0.01,
        edge_angle_deg: 5.0,
        edge_angle_stderr_deg: 0.1,
        lsf_fwhm_stderr_px: 0.05,
        rows_used: 64,
        noise_floor_nyquist: 0.03,
        noise_floor: vec![0.0, 0.01, 0.02, 0.03, 0.04],
        noise_floor_stderr: 0.004,
        transposed: false,
        pixel_pitch_m: pitch,
    }
}

#[test]
fn hamming_window_peaks_at_mid() {
    let w = ahamming(11, 5.0);
    assert!(
        (w[5] - 1.0).abs() < 1e-12 && (w[0] - 0.08).abs() < 1e-12 && (w[10] - 0.08).abs() < 1e-12
    );
}

#[test]
fn rejects_flat_and_axis_aligned_edges() {
    let flat = Plane::new(32, 32, vec![1.0; 1024]).unwrap();
    assert!(sfr(&flat, &SfrOptions::default()).is_err());
    let d: Vec<f64> = (0..32 * 32)
        .map(|i| if i % 32 < 16 { 0.1 } else { 0.9 })
        .collect();
    let e = sfr(&Plane::new(32, 32, d).unwrap(), &SfrOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("too close to the pixel grid"), "{e}");
}

#[test]
fn channel_names_parse() {
    for s in ["lum", "Y", "luminance"] {
        assert_eq!(SfrChannel::parse(s).unwrap(), SfrChannel::Lum);
    }
    for s in ["r", "G", "b", "w"] {
        assert_eq!(
            SfrChannel::parse(s).unwrap(),
            SfrChannel::Named(s.to_ascii_lowercase())
        );
    }
    assert!(
        SfrChannel::parse("x")
            .unwrap_err()
            .to_string()
            .contains("'x'")
    );
}

#[test]
fn mtf_is_interpolated_linearly_between_frequencies() {
    let s = sfr_with(&[0.0, 0.1, 0.3], &[1.0, 0.8, 0.4], &[0.0, 0.01, 0.03], None);
    let (m, se) = s.mtf_at(0.2).unwrap();
    assert!(close(m, 0.6, 1e-15) && close(se, 0.02, 1e-15), "{m} {se}");
    let (m, se) = s.mtf_at(0.125).unwrap();
    assert!(
        close(m, 0.75, 1e-15) && close(se, 0.0125, 1e-15),
        "{m} {se}"
    );
    assert_eq!(s.mtf_at(0.0).unwrap(), (1.0, 0.0));
    assert_eq!(s.mtf_at(-0.1).unwrap(), (1.0, 0.0));
    assert_eq!(s.mtf_at(0.3).unwrap(), (0.8 + (0.4 - 0.8), 0.03));
    assert!(s.mtf_at(0.3 + 1e-12).is_none());
    assert_eq!(s.freq_cy_per_mm(), None);
    let s = sfr_with(
        &[0.0, 0.1, 0.3],
        &[1.0, 0.8, 0.4],
        &[0.0, 0.01, 0.03],
        Some(2e-6),
    );
    // 2 µm pixels: 1 cy/px = 500 cy/mm.
    let f = s.freq_cy_per_mm().unwrap();
    for (g, w) in f.iter().zip([0.0, 50.0, 150.0]) {
        assert!(close(*g, w, 1e-9), "{f:?}");
    }
}

/// The figures of one edge: MTF50 in cy/px and (with a pitch) cy/mm, the MTF
/// at ⅛, ¼ and ½ cy/px, the noise floor, the edge angle and the LSF width,
/// each with its standard error; the curves up to Nyquist in cy/mm and the
/// LSF in µm.
#[test]
fn figures_and_curves_carry_values_units_and_errors() {
    let freq = [0.0, 0.125, 0.25, 0.5, 0.75];
    let mut s = sfr_with(
        &freq,
        &[1.0, 0.9, 0.7, 0.3, 0.1],
        &[0.0, 0.01, 0.02, 0.03, 0.04],
        Some(2e-6),
    );
    // A triangular LSF of FWHM 1.5 px on a ¼-px grid.
    s.esf_x_px = (0..41).map(|i| (i as f64 - 20.0) * 0.25).collect();
    s.lsf = s
        .esf_x_px
        .iter()
        .map(|x| (1.0 - x.abs() / 1.5).max(0.0))
        .collect();
    s.esf = s
        .esf_x_px
        .iter()
        .map(|x| if *x < 0.0 { 0.0 } else { 1.0 })
        .collect();
    let m = s.measured("sfr", Rect::new(1, 2, 3, 4));
    let fig = |q: &str| {
        m.figures
            .iter()
            .find(|f| f.quantity == q)
            .unwrap_or_else(|| panic!("no {q}"))
            .clone()
    };
    let f = fig("mtf50");
    assert_eq!((f.value, f.stderr, f.unit.as_str()), (0.2, 0.01, "cy/px"));
    let f = fig("mtf50_mm");
    assert!(close(f.value, 100.0, 1e-9) && close(f.stderr, 5.0, 1e-9));
    assert_eq!(f.unit, "cy/mm");
    for (q, v, se) in [
        ("mtf@0.125cy/px", 0.9, 0.01),
        ("mtf@0.25cy/px", 0.7, 0.02),
        ("mtf@0.5cy/px", 0.3, 0.03),
    ] {
        let f = fig(q);
        assert_eq!((f.value, f.stderr), (v, se), "{q}");
    }
    let f = fig("mtf_noise@0.5cy/px");
    assert_eq!((f.value, f.stderr), (0.03, 0.004));
    let f = fig("edge_angle");
    assert_eq!((f.value, f.stderr, f.unit.as_str()), (5.0, 0.1, "deg"));
    let f = fig("lsf_fwhm");
    assert!(close(f.value, 1.5, 1e-12) && f.stderr == 0.05, "{f:?}");
    assert_eq!(m.figures.len(), 8);
    assert_eq!(m.pixels_read, vec![Rect::new(1, 2, 3, 4)]);

    let curve = |n: &str| m.curves.iter().find(|c| c.name == n).unwrap().clone();
    let mtf = curve("mtf");
    assert_eq!(mtf.x_unit, "cy/mm");
    assert_eq!(mtf.x, vec![0.0, 62.5, 125.0, 250.0]);
    assert_eq!(mtf.y, vec![1.0, 0.9, 0.7, 0.3]);
    assert_eq!(mtf.stderr, vec![0.0, 0.01, 0.02, 0.03]);
    assert_eq!(curve("mtf#noise floor").y, vec![0.0, 0.01, 0.02, 0.03]);
    let lsf = curve("lsf");
    assert_eq!((lsf.x_unit.as_str(), lsf.y_unit.as_str()), ("µm", "1/µm"));
    // The peak: 1/px = 0.5/µm at x = 0.
    let k = lsf.x.iter().position(|x| *x == 0.0).unwrap();
    assert!(close(lsf.y[k], 0.5, 1e-12));
    // ¼ px apart = 0.5 µm at a 2 µm pitch.
    assert!(close(lsf.x[k + 1], 0.5, 1e-12), "{:?}", lsf.x);
    assert_eq!(curve("esf").x, s.esf_x_px);

    // Without a pitch: no cy/mm figure, curves in px.
    s.pixel_pitch_m = None;
    let m = s.measured("sfr", Rect::new(1, 2, 3, 4));
    assert!(m.figures.iter().all(|f| f.quantity != "mtf50_mm"));
    let mtf = m.curves.iter().find(|c| c.name == "mtf").unwrap();
    assert_eq!((mtf.x_unit.as_str(), mtf.x[3]), ("cy/px", 0.5));
    let lsf = m.curves.iter().find(|c| c.name == "lsf").unwrap();
    assert_eq!(lsf.x_unit, "px");
    // No MTF50: neither MTF50 figure.
    s.mtf50_cy_per_px = None;
    let m = s.measured("sfr", Rect::new(1, 2, 3, 4));
    assert!(m.figures.iter().all(|f| !f.quantity.starts_with("mtf50")));
}

/// A sharp step at x = 0 on a ¼-px grid from −20 to +20 px: smoothed over
/// 17 bins, the normalised ESF rises linearly from bin 72 to bin 88, so it
/// passes ½ at bin 80, is ≤ 10 % at bin 72 (1/17) and ≥ 90 % at bin 87
/// (16/17): rise 15 bins = 3.75 px, pad 2·3.75 + 4 = 11.5 px, span
/// (x₇₂ − 11.5, x₈₇ + 11.5) = (−13.5, 13.25) px — for a falling edge too.
#[test]
fn lsf_span_brackets_the_rise_with_its_padding() {
    let mut s = sfr_with(&[0.0], &[1.0], &[0.0], None);
    s.esf_x_px = (0..161).map(|i| (i as f64 - 80.0) * 0.25).collect();
    s.esf = (0..161).map(|i| if i < 80 { 0.0 } else { 1.0 }).collect();
    assert_eq!(s.lsf_span(), (-13.5, 13.25));
    s.esf = s.esf.iter().map(|v| 2.0 - 3.0 * v).collect();
    assert_eq!(s.lsf_span(), (-13.5, 13.25));
    // The LSF curve (px without a pitch) holds exactly the bins of the span:
    // x[26] = −13.5 px … x[133] = 13.25 px, 108 of the 161.
    s.lsf = vec![0.0; 161];
    let lsf = s.curves().into_iter().find(|c| c.name == "lsf").unwrap();
    assert_eq!(lsf.x.len(), 108);
    assert_eq!((lsf.x[0], lsf.x[107]), (-13.5, 13.25));
    // The span stops at the data's ends.
    s.esf_x_px = (0..161).map(|i| (i as f64 - 80.0) * 0.05).collect();
    s.esf = (0..161).map(|i| if i < 80 { 0.0 } else { 1.0 }).collect();
    assert_eq!(s.lsf_span(), (-4.0, 4.0));
    // Flat: all of it; fewer than 8 samples: all of it.
    s.esf = vec![1.0; 161];
    assert_eq!(s.lsf_span(), (-4.0, 4.0));
    s.esf_x_px = vec![-1.0, 0.0, 2.0];
    s.esf = vec![0.0, 1.0, 1.0];
    assert_eq!(s.lsf_span(), (-1.0, 2.0));
    s.esf_x_px = vec![-10.0, -5.0, 0.0, 5.0, 10.0];
    s.esf = vec![0.0, 0.0, 1.0, 1.0, 1.0];
    assert_eq!(s.lsf_span(), (-10.0, 10.0));
}

/// The rise ends where the smoothed ESF reaches 90 %, at it included: a
/// step 9 bins before the end of 40 (plateaus of 5 bins: 0 and 1) reaches
/// exactly 9/10 at bin 38, whose window is cut to 10 bins by the end. From
/// the ½ crossing at bin 31 down to bin 23 (1/17 ≤ 10 %): rise 38 − 23 =
/// 15 px on a 1-px grid, pad 34 px, span (23 − 34, 39) — the right end
/// held at the last sample, the first sample placed far out of the way.
#[test]
fn lsf_span_rise_ends_at_ninety_percent_inclusive() {
    let mut s = sfr_with(&[0.0], &[1.0], &[0.0], None);
    s.esf_x_px = (0..40)
        .map(|i| if i == 0 { -1000.0 } else { i as f64 })
        .collect();
    s.esf = (0..40).map(|i| if i < 31 { 0.0 } else { 1.0 }).collect();
    assert_eq!(s.lsf_span(), (-11.0, 39.0));
}

/// And it starts where the smoothed ESF falls to 10 %, at it included: a
/// step at bin 9 of 40 (plateaus 0 and 1) is smoothed to exactly 1/10 at
/// bin 1, whose window is cut to 10 bins by the start; the ½ crossing is at
/// bin 9 (9/17) and the rise ends at bin 16 (16/17 ≥ 90 %): rise 15 px,
/// pad 34 px, span (1 − 34, 39), the first sample placed far out of the way.
#[test]
fn lsf_span_rise_starts_at_ten_percent_inclusive() {
    let mut s = sfr_with(&[0.0], &[1.0], &[0.0], None);
    s.esf_x_px = (0..40)
        .map(|i| if i == 0 { -1000.0 } else { i as f64 })
        .collect();
    s.esf = (0..40).map(|i| if i < 9 { 0.0 } else { 1.0 }).collect();
    assert_eq!(s.lsf_span(), (-33.0, 39.0));
}

/// Eight samples are enough to search for the rise: all eight smoothing
/// windows cover the whole ESF, whose normalised mean here is 0 (a dip below
/// the dark plateau), so no bin reaches ½; the rise starts at the middle
/// bin 4 and runs to the end: rise 7 − 4 = 3 px, pad 10 px, span (−6, 7),
/// not the whole range from the first sample, placed at −1000.
#[test]
fn lsf_span_of_eight_samples_is_searched() {
    let mut s = sfr_with(&[0.0], &[1.0], &[0.0], None);
    s.esf_x_px = vec![-1000.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
    s.esf = vec![0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    assert_eq!(s.lsf_span(), (-6.0, 7.0));
}

/// Piecewise-linear peaks are measured exactly: a triangle of half-widths
/// 1 and 2 px at half height has FWHM 0.5 + 1 = 1.5 px; a peak at the first
/// sample has its left edge there.
#[test]
fn fwhm_of_triangles() {
    let x: Vec<f64> = (0..41).map(|i| (i as f64 - 16.0) * 0.25).collect();
    let tri = |l: f64, r: f64| -> Vec<f64> {
        x.iter()
            .map(|&x| {
                if x < 0.0 {
                    (1.0 + x / l).max(0.0)
                } else {
                    (1.0 - x / r).max(0.0)
                }
            })
            .collect()
    };
    assert!(close(fwhm(&x, &tri(1.0, 2.0)), 1.5, 1e-12));
    assert!(close(fwhm(&x, &tri(1.3, 1.3)), 1.3, 1e-12));
    let y: Vec<f64> = tri(1.0, 2.0).iter().map(|v| 3.0 * v).collect();
    assert!(close(fwhm(&x, &y), 1.5, 1e-12));
    let edge: Vec<f64> = x
        .iter()
        .map(|&v| (1.0 - (v + 4.0) / 2.0).max(0.0))
        .collect();
    assert!(close(fwhm(&x, &edge), 1.0, 1e-12), "{}", fwhm(&x, &edge));
    // Kinks just past half height on both sides: the crossing is interpolated
    // in the segment that crosses (2.5 and 5.5), not extrapolated from the
    // flat one after it.
    let xk: Vec<f64> = (0..9).map(|i| i as f64).collect();
    let yk = [0.38, 0.39, 0.4, 0.6, 1.0, 0.6, 0.4, 0.39, 0.38];
    assert!(close(fwhm(&xk, &yk), 3.0, 1e-12), "{}", fwhm(&xk, &yk));
    // Shoulders at exactly half height belong to the peak: the width runs to
    // where the curve falls below half, 1 to 5, not from the inner shoulder
    // samples.
    let xs: Vec<f64> = (0..7).map(|i| i as f64).collect();
    let ys = [0.0, 0.5, 0.5, 1.0, 0.5, 0.5, 0.0];
    assert!(close(fwhm(&xs, &ys), 4.0, 1e-12), "{}", fwhm(&xs, &ys));
    // Never falling to half on the right: the right edge is the last sample.
    let ramp: Vec<f64> = x.iter().map(|&v| (v + 4.0).min(2.0)).collect();
    assert!(
        close(fwhm(&x, &ramp), 6.0 - (-3.0), 1e-12),
        "{}",
        fwhm(&x, &ramp)
    );
}

/// sfrmat's asymmetric window: 0.54 + 0.46·cos(π(i − mid)/wid), wid the
/// longer side, so it reaches 0.08 only at the far end.
#[test]
fn asymmetric_hamming_window() {
    let w = ahamming(11, 3.0);
    for (i, v) in w.iter().enumerate() {
        let want = 0.54 + 0.46 * (std::f64::consts::PI * (i as f64 - 3.0) / 7.0).cos();
        assert!(close(*v, want, 1e-15), "{i}");
    }
    assert!(close(w[10], 0.08, 1e-15) && w[0] > 0.4);
    assert_eq!(ahamming(1, 0.0), vec![1.0]);
}

/// The edge polynomial reproduces a cubic exactly, with its slope, however
/// far the rows are from zero (the fit is in a scaled variable).
#[test]
fn edge_fit_reproduces_a_cubic_and_its_slope() {
    let x = |y: f64| 2.0 + 0.1 * y + 0.01 * y * y - 0.001 * y * y * y;
    let dx = |y: f64| 0.1 + 0.02 * y - 0.003 * y * y;
    for off in [0.0, 100.0] {
        let ys: Vec<f64> = (0..21).map(|i| off + i as f64).collect();
        let xs: Vec<f64> = ys.iter().map(|&y| x(y - off)).collect();
        let f = EdgeFit::fit(&ys, &xs, 3).unwrap();
        for y in [3.3, 7.0, 18.9] {
            assert!(close(f.x(off + y), x(y), 1e-9), "{off} {y}");
            assert!(close(f.slope(off + y), dx(y), 1e-9), "{off} {y}");
        }
        assert!(close(f.y0, off + 10.0, 1e-12) && close(f.ys, 10.0, 1e-12));
    }
    // A straight edge needs 3 rows; 2 are refused.
    assert!(EdgeFit::fit(&[0.0, 1.0], &[0.0, 1.0], 1).is_none());
    let f = EdgeFit::fit(&[0.0, 1.0, 2.0], &[1.0, 1.5, 2.0], 1).unwrap();
    assert!(close(f.x(4.0), 3.0, 1e-12) && close(f.slope(9.0), 0.5, 1e-12));
    // A single row's scale is 1, not 0.
    assert_eq!(EdgeFit::fit(&[5.0; 4], &[1.0; 4], 0).unwrap().ys, 1.0);
}

/// A single-channel plane is located as is; a mosaic by its 2×2 means,
/// whose samples sit half a pixel in.
#[test]
fn locate_plane_of_a_mosaic_is_its_2x2_mean() {
    let data: Vec<f64> = (0..12).map(|i| i as f64).collect();
    let p = Plane::new(4, 3, data.clone()).unwrap();
    assert_eq!(locate_plane(&p), (4, 3, data.clone(), 0.0));
    let mut m = p.clone();
    m.channel = vec![0, 1, 0, 1, 1, 2, 1, 2, 0, 1, 0, 1];
    m.channel_names = vec!["r".into(), "g".into(), "b".into()];
    let (w, h, d, off) = locate_plane(&m);
    assert_eq!((w, h, off), (3, 2, 0.5));
    // Mean of (x, y), (x+1, y), (x, y+1), (x+1, y+1) = 4y + x + 2.5.
    assert_eq!(d, vec![2.5, 3.5, 4.5, 6.5, 7.5, 8.5]);
}

#[test]
fn gradient_energy_is_the_mean_absolute_difference() {
    // d = 2x − 3y on 4×3: |Δx| = 2, |Δy| = 3 everywhere.
    let d: Vec<f64> = (0..12)
        .map(|i| 2.0 * (i % 4) as f64 - 3.0 * (i / 4) as f64)
        .collect();
    assert_eq!(gradient_energy(4, 3, &d), (2.0, 3.0));
    // One jump of 6 in x among 3·3 differences, none in y among 4·2.
    let d: Vec<f64> = (0..12).map(|i| if i % 4 < 2 { 0.0 } else { 6.0 }).collect();
    assert_eq!(gradient_energy(4, 3, &d), (2.0, 0.0));
}

/// A step between samples k and k+1 has its derivative at k + ½ (+ offset);
/// two equal steps under a window centred between them, midway; the wrong
/// sign or no edge gives none.
#[test]
fn row_centroid_finds_the_step() {
    let row = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
    assert!(close(
        row_centroid(&row, 1.0, None, 0.0).unwrap(),
        3.5,
        1e-12
    ));
    assert!(close(
        row_centroid(&row, 1.0, Some(3.0), 0.25).unwrap(),
        3.75,
        1e-12
    ));
    let falling: Vec<f64> = row.iter().map(|v| 1.0 - v).collect();
    assert!(close(
        row_centroid(&falling, -1.0, None, 0.0).unwrap(),
        3.5,
        1e-12
    ));
    assert!(row_centroid(&row, -1.0, None, 0.0).is_none());
    assert!(row_centroid(&[1.0; 8], 1.0, None, 0.0).is_none());
    // By default the window centres on the middle derivative sample (3 of
    // 0…6): two equal steps at 2 and 4 balance at 3.5.
    let even = [0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 2.0];
    assert!(close(
        row_centroid(&even, 1.0, None, 0.0).unwrap(),
        3.5,
        1e-12
    ));
    let two = [0.0, 0.0, 0.0, 1.0, 2.0, 2.0, 2.0];
    assert!(close(
        row_centroid(&two, 1.0, Some(2.5), 0.0).unwrap(),
        3.0,
        1e-12
    ));
    // An off-centre window weights the nearer step more: centroid moves toward it.
    assert!(row_centroid(&two, 1.0, Some(1.0), 0.0).unwrap() < 3.0);
}

#[test]
fn bin_variances_are_unbiased_sample_variances() {
    // Bin 2 holds {1, 2, 3} (variance 1), bin 3 {5, 5} (0), bin 1 one sample.
    let v = bin_variances(
        &[0.0, 4.0, 6.0, 10.0],
        &[0.0, 16.0, 14.0, 50.0],
        &[0, 1, 3, 2],
    );
    assert_eq!(v, vec![0.0, 0.0, 1.0, 0.0]);
    // Two samples {1, 3}: variance 2.
    assert_eq!(bin_variances(&[4.0], &[10.0], &[2]), vec![2.0]);
    // Rounding below zero is clamped.
    let v = bin_variances(&[0.3], &[0.045 - 1e-17], &[2]);
    assert_eq!(v, vec![0.0]);
}

#[test]
fn edge_contrast_is_the_plateaus_difference() {
    let mut esf = vec![1.0, 3.0];
    esf.extend([2.0; 12]);
    esf.extend([5.0, 7.0]);
    assert_eq!(edge_contrast(&esf), 4.0);
    esf.reverse();
    assert_eq!(edge_contrast(&esf), 4.0);
    assert_eq!(edge_contrast(&[1.0, 4.0]), 3.0);
}

#[test]
fn crossing_is_interpolated_where_the_curve_first_falls_below() {
    assert!(close(
        crossing(&[1.0, 0.8, 0.4, 0.2], 0.5).unwrap(),
        1.75,
        1e-15
    ));
    assert_eq!(crossing(&[1.0, 0.5, 0.4], 0.5), Some(1.0)); // at the level itself
    assert_eq!(crossing(&[1.0, 0.6, 0.55], 0.5), None);
    assert_eq!(crossing(&[0.4, 0.3], 0.5), None);
    // The first fall counts, not a later one.
    assert!(close(
        crossing(&[1.0, 0.0, 1.0, 0.0], 0.5).unwrap(),
        0.5,
        1e-15
    ));
}

/// Bin means sit at their samples' mean position and are interpolated back
/// to the bin centres; empty bins are filled, the ends held.
#[test]
fn bins_are_moved_to_their_centres() {
    // Bin 0: one sample at +½ bin (value 2); bin 2: two at −½ (mean 3);
    // bin 3: two at 0 (mean 4); bin 1 empty. Points (0.5, 2), (1.5, 3), (3, 4).
    let e = fill_bins(&[2.0, 0.0, 6.0, 8.0], &[0.5, 0.0, -1.0, 0.0], &[1, 0, 2, 2]).unwrap();
    let want = [2.0, 2.5, 3.0 + 0.5 / 1.5, 4.0];
    for (g, w) in e.iter().zip(want) {
        assert!(close(*g, w, 1e-15), "{e:?}");
    }
    let e = fill_bins(&[0.0, 2.0, 0.0, 4.0, 0.0], &[0.0; 5], &[0, 1, 0, 1, 0]).unwrap();
    assert_eq!(e, vec![2.0, 2.0, 3.0, 4.0, 4.0]);
    assert!(fill_bins(&[1.0, 0.0], &[0.0; 2], &[1, 0]).is_none());
}

/// White noise of variance σ² per bin (one sample each, unit window): the
/// LSF's noise is Σ aⱼ eⱼ with |aⱼ|² = 4·|z⁻¹ − z|² = 16 sin²ω inside and
/// 4 at the two bins at each end that enter one difference only, so
/// E|N|² = σ²·(16 (n − 4) sin²ω + 16), and the floor is its root times the
/// derivative correction ω/sin ω over the DC sum.
#[test]
fn noise_floor_of_white_noise() {
    let n = 64;
    let (sigma2, dc) = (0.01, 10.0);
    let f = noise_floor(&vec![1.0; n], &vec![1; n], &vec![sigma2; n], dc, 6);
    assert_eq!(f[0], 0.0);
    for (m, got) in f.iter().enumerate().skip(1) {
        let w = 2.0 * std::f64::consts::PI * m as f64 / n as f64;
        let var = sigma2 * (16.0 * (n - 4) as f64 * w.sin().powi(2) + 16.0);
        let want = var.sqrt() * (w / w.sin()) / dc;
        assert!(close(*got, want, 1e-12 * want), "m {m}: {got} vs {want}");
    }
    // Four samples per bin quarter the variance; no DC, no floor.
    let g = noise_floor(&vec![1.0; n], &vec![4; n], &vec![sigma2; n], dc, 6);
    assert!(close(g[3], f[3] / 2.0, 1e-15));
    assert_eq!(
        noise_floor(&vec![1.0; n], &vec![1; n], &vec![sigma2; n], 0.0, 6),
        vec![0.0; 6]
    );
}

/// The strip of a plate's box: its central half in width and up to 128 of
/// its central rows; small boxes keep at least 8 px (or all they have).
#[test]
fn edge_strip_is_the_central_half() {
    assert_eq!(
        edge_strip(Rect::new(10, 20, 100, 400)),
        Rect::new(35, 156, 50, 128)
    );
    assert_eq!(
        edge_strip(Rect::new(10, 20, 100, 60)),
        Rect::new(35, 35, 50, 30)
    );
    assert_eq!(edge_strip(Rect::new(0, 0, 20, 12)), Rect::new(5, 2, 10, 8));
    assert_eq!(edge_strip(Rect::new(0, 0, 10, 6)), Rect::new(2, 0, 8, 6));
}

fn request(props: &[(&str, crate::params::Value)]) -> std::result::Result<SfrRequest, ParamError> {
    let mut p = crate::params::Params::new();
    for (k, v) in props {
        p.set(*k, v.clone());
    }
    from_params(&crate::params::ParamDict::new(&p, &SCHEMA))
}

/// Each property's range, at its boundary: the first value allowed arrives,
/// the last refused is refused.
#[test]
fn properties_arrive_within_their_ranges() {
    use crate::params::Value::{Number as N, String as S};
    let o = request(&[]).unwrap().options;
    assert_eq!(o.fit_degree, 1);
    assert_eq!(o.jackknife_groups, 8);
    assert_eq!(o.max_freq_cy_per_px, 1.0);
    assert_eq!(o.max_noise_floor, MAX_NOISE_FLOOR);
    assert_eq!(o.channel, SfrChannel::Lum);
    let o = |k: &str, v: crate::params::Value| request(&[(k, v)]).map(|r| r.options);
    assert_eq!(
        o("channel", S("g".into())).unwrap().channel,
        SfrChannel::Named("g".into())
    );
    assert_eq!(o("fit-degree", N(5.0)).unwrap().fit_degree, 5);
    assert!(o("fit-degree", N(6.0)).is_err());
    assert!(o("fit-degree", N(0.0)).is_err());
    assert_eq!(o("jackknife-count", N(4.0)).unwrap().jackknife_groups, 4);
    assert_eq!(o("jackknife-count", N(64.0)).unwrap().jackknife_groups, 64);
    assert!(o("jackknife-count", N(3.0)).is_err());
    assert!(o("jackknife-count", N(65.0)).is_err());
    assert_eq!(o("max-freq-cy-px", N(2.0)).unwrap().max_freq_cy_per_px, 2.0);
    assert_eq!(o("max-freq-cy-px", N(0.3)).unwrap().max_freq_cy_per_px, 0.3);
    assert!(o("max-freq-cy-px", N(2.001)).is_err());
    assert!(o("max-freq-cy-px", N(0.0)).is_err());
    assert_eq!(
        o("max-noise-fraction", N(1.0)).unwrap().max_noise_floor,
        1.0
    );
    assert_eq!(
        o("max-noise-fraction", N(0.2)).unwrap().max_noise_floor,
        0.2
    );
    assert!(o("max-noise-fraction", N(1.001)).is_err());
}

/// The object's bounding box inset 15 % a side when that is solid label;
/// further in (5 % steps) when the outline is ragged; refused when no
/// solid 8×8 interior is left, and when the label is missing.
#[test]
fn object_region_is_the_solid_interior() {
    let names: Vec<String> = vec!["bg".into(), "edge".into()];
    let (w, h) = (60, 50);
    // The object fills x 10..=49, y 5..=44 (40 × 40).
    let mut labels: Vec<u32> = (0..w * h)
        .map(|i| ((10..50).contains(&(i % w)) && (5..45).contains(&(i / w))) as u32)
        .collect();
    // 15 % of 40 = 6: x 16..=43, y 11..=38.
    assert_eq!(
        object_roi(&labels, &names, w, h, "edge").unwrap(),
        Rect::new(16, 11, 28, 28)
    );
    // A background hole at (16, 11) and one at (42, 37): the 20 % inset
    // (x 18..=41, y 13..=36) avoids both.
    labels[11 * w + 16] = 0;
    labels[37 * w + 42] = 0;
    assert_eq!(
        object_roi(&labels, &names, w, h, "edge").unwrap(),
        Rect::new(18, 13, 24, 24)
    );
    // A hole in the centre: no inset is solid.
    labels[25 * w + 30] = 0;
    let e = object_roi(&labels, &names, w, h, "edge")
        .unwrap_err()
        .to_string();
    assert!(e.contains("no solid interior"), "{e}");
    // Too small for 8×8 after the inset: 12 × 12 → 14 % … stops at once.
    let small: Vec<u32> = (0..w * h)
        .map(|i| ((10..22).contains(&(i % w)) && (5..17).contains(&(i / w))) as u32)
        .collect();
    assert!(object_roi(&small, &names, w, h, "edge").is_err());
    // Narrow in one direction only (12 × 40 and 40 × 12): refused too.
    for (xs, ys) in [(10..22, 5..45), (10..50, 5..17)] {
        let thin: Vec<u32> = (0..w * h)
            .map(|i| (xs.contains(&(i % w)) && ys.contains(&(i / w))) as u32)
            .collect();
        let e = object_roi(&thin, &names, w, h, "edge")
            .unwrap_err()
            .to_string();
        assert!(e.contains("no solid interior"), "{xs:?} {ys:?}: {e}");
    }
    let e = object_roi(&vec![0; w * h], &names, w, h, "edge")
        .unwrap_err()
        .to_string();
    assert!(e.contains("not visible"), "{e}");
    assert!(object_roi(&labels, &names, w, h, "egde").is_err());
    assert!(object_roi(&labels[1..], &names, w, h, "edge").is_err());
    // 30 px wide and tall (x 10..=39, y 5..=34): 15 % is 4.5, rounded to 5
    // (29 or 28 px would give 4): x 15..=34, y 10..=29.
    let square: Vec<u32> = (0..w * h)
        .map(|i| ((10..40).contains(&(i % w)) && (5..35).contains(&(i / w))) as u32)
        .collect();
    assert_eq!(
        object_roi(&square, &names, w, h, "edge").unwrap(),
        Rect::new(15, 10, 20, 20)
    );
}

/// A sharp edge 5° from the columns (or, `horizontal`, from the rows) through
/// the centre of a `w` × `h` plane, dark 0.1 → bright 0.9, each pixel its area
/// average (16 × 16 subsamples).
fn slanted(w: usize, h: usize, horizontal: bool) -> Plane {
    let t = 5f64.to_radians().tan();
    let v = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let (a, b) = if horizontal { (y, x) } else { (x, y) };
            let (ca, cb) = if horizontal {
                (h as f64 / 2.0, w as f64 / 2.0)
            } else {
                (w as f64 / 2.0, h as f64 / 2.0)
            };
            // Area fraction of the pixel beyond the edge a = ca + t·(b − cb).
            let mut f = 0.0;
            for sy in 0..16 {
                for sx in 0..16 {
                    let aa = a - 0.5 + (sx as f64 + 0.5) / 16.0;
                    let bb = b - 0.5 + (sy as f64 + 0.5) / 16.0;
                    if aa > ca + t * (bb - cb) {
                        f += 1.0 / 256.0;
                    }
                }
            }
            0.1 + 0.8 * f
        })
        .collect();
    Plane::new(w, h, v).unwrap()
}

/// A horizontal edge is measured transposed, with the same MTF as the
/// vertical one; the options' checks hold.
#[test]
fn horizontal_edges_are_transposed_and_options_checked() {
    let v = sfr(&slanted(64, 64, false), &SfrOptions::default()).unwrap();
    let h = sfr(&slanted(64, 64, true), &SfrOptions::default()).unwrap();
    assert!(!v.transposed && h.transposed);
    assert!(
        (v.edge_angle_deg.abs() - 5.0).abs() < 0.1,
        "{}",
        v.edge_angle_deg
    );
    for (a, b) in v.mtf.iter().zip(&h.mtf) {
        assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    }
    // A sharp edge sampled by square pixels: MTF(0.25) = sinc(0.25) = 0.900.
    let (m, _) = v.mtf_at(0.25).unwrap();
    assert!((m - 0.9003).abs() < 0.02, "{m}");
    let small = Plane::new(7, 64, vec![0.5; 7 * 64]).unwrap();
    assert!(
        sfr(&small, &SfrOptions::default())
            .unwrap_err()
            .to_string()
            .contains("too small")
    );
    let small = Plane::new(64, 7, vec![0.5; 7 * 64]).unwrap();
    let e = sfr(&small, &SfrOptions::default()).unwrap_err().to_string();
    assert!(e.contains("too small"), "{e}");
    // 8 px is enough in either direction (a flat 8×8 region fails later, for
    // having no edge).
    for (w, h) in [(8, 64), (64, 8)] {
        let flat = Plane::new(w, h, vec![0.5; w * h]).unwrap();
        let e = sfr(&flat, &SfrOptions::default()).unwrap_err().to_string();
        assert!(!e.contains("too small"), "{w}×{h}: {e}");
    }
    for degree in [0, 6] {
        let o = SfrOptions {
            fit_degree: degree,
            ..Default::default()
        };
        let e = sfr(&slanted(64, 64, false), &o).unwrap_err().to_string();
        assert!(e.contains("fit degree"), "{e}");
    }
    let o = SfrOptions {
        channel: SfrChannel::Named("r".into()),
        ..Default::default()
    };
    let e = sfr(&slanted(64, 64, false), &o).unwrap_err().to_string();
    assert!(e.contains("single-channel"), "{e}");
    let o = SfrOptions {
        channel: SfrChannel::Named("g".into()),
        ..Default::default()
    };
    assert!(sfr(&slanted(64, 64, false), &o).is_ok());
}

/// A 96 × 96 mono capture of the edge (64 DV black level, 1000 DV step),
/// at (10, 5) in a 200 × 150 frame, with the object "edge" labelled over
/// window pixels x 16..80, y 8..88.
fn edge_capture() -> crate::image::SensorImage {
    let p = slanted(96, 96, false);
    let dv: Vec<u16> = p
        .data
        .iter()
        .map(|v| (64.0 + 1000.0 * (v - 0.1) / 0.8).round() as u16)
        .collect();
    let cfa = crate::image::CfaPattern::bayer("mono").unwrap();
    let mut si = crate::image::SensorImage::from_raw_dv(96, 96, &cfa, &dv, 64.0, 4095.0);
    (si.full_width, si.full_height) = (200, 150);
    si.window = Rect::new(10, 5, 96, 96);
    si.label_names = vec!["bg".into(), "edge".into()];
    si.labels = (0..96 * 96)
        .map(|i| ((16..80).contains(&(i % 96)) && (8..88).contains(&(i / 96))) as u32)
        .collect();
    si
}

fn run(of: &[&str], roi: Option<Rect>, rects: &[(&str, Rect)]) -> Result<Measured> {
    let si = edge_capture();
    let of: Vec<String> = of.iter().map(|s| s.to_string()).collect();
    let object_rects = rects.iter().map(|(k, r)| (k.to_string(), *r)).collect();
    let grid = crate::spectrum::WavelengthGrid::new(400.0, 700.0, 10.0).unwrap();
    let inp = crate::measure::inputs::Inputs {
        oi: None,
        si: Some(&si),
        sensor: None,
        object_rects: &object_rects,
        seed: 1,
        grid: &grid,
    };
    let r = SfrRequest {
        roi_px: roi,
        ..Default::default()
    };
    run_on_sensor("sfr", &of, &r, &si, &inp)
}

/// Where the region comes from: the render stage's strip for the object
/// (full-frame → window pixels), else the central strip of its label box,
/// else `roi-px`; figures prefixed by the object (or `roi`), the pixel
/// pitch giving cy/mm.
#[test]
fn on_a_sensor_image_the_region_follows_the_object() {
    let m = run(&["edge"], None, &[]).unwrap();
    // Label box (16, 8, 64, 80) → its strip (32, 28, 32, 40).
    assert_eq!(m.pixels_read, vec![Rect::new(32, 28, 32, 40)]);
    let q: Vec<&str> = m.figures.iter().map(|f| f.quantity.as_str()).collect();
    assert!(
        q.contains(&"edge/mtf50") && q.contains(&"edge/mtf50_mm"),
        "{q:?}"
    );
    let m50 = m
        .figures
        .iter()
        .find(|f| f.quantity == "edge/mtf50")
        .unwrap()
        .value;
    let mm = m
        .figures
        .iter()
        .find(|f| f.quantity == "edge/mtf50_mm")
        .unwrap()
        .value;
    // 1 µm pixels: 1 cy/px = 1000 cy/mm.
    assert!((mm / m50 - 1000.0).abs() < 1e-9);
    assert!(m.curves.iter().all(|c| c.name.starts_with("edge/")));
    let m = run(&["edge"], None, &[("edge", Rect::new(40, 25, 36, 50))]).unwrap();
    assert_eq!(m.pixels_read, vec![Rect::new(30, 20, 36, 50)]);
    let m = run(&[], Some(Rect::new(40, 25, 36, 50)), &[]).unwrap();
    assert_eq!(m.pixels_read, vec![Rect::new(30, 20, 36, 50)]);
    assert!(m.figures.iter().all(|f| f.quantity.starts_with("roi/")));
    let m = run(&["edge"], Some(Rect::new(40, 25, 36, 50)), &[]).unwrap();
    assert!(m.figures.iter().all(|f| f.quantity.starts_with("edge/")));
}

#[test]
fn on_a_sensor_image_a_missing_region_is_an_error() {
    let e = |r: Result<Measured>| r.map(|_| ()).unwrap_err().to_string();
    let msg = e(run(&["a", "b"], Some(Rect::new(40, 25, 36, 50)), &[]));
    assert!(
        msg.contains("roi-px names one region but of= names 2"),
        "{msg}"
    );
    let msg = e(run(&[], None, &[]));
    assert!(msg.contains("sfr needs of="), "{msg}");
    let msg = e(run(&["plate"], None, &[]));
    assert!(
        msg.contains("object 'plate' is not in the measured image"),
        "{msg}"
    );
    let msg = e(run(
        &["edge"],
        None,
        &[("edge", Rect::new(150, 120, 10, 10))],
    ));
    assert!(msg.contains("outside the rendered window"), "{msg}");
    // A flat region: the error names the measurement and the edge.
    let msg = e(run(&[], Some(Rect::new(12, 60, 20, 20)), &[]));
    assert!(msg.contains("measurement 'sfr', edge 'roi'"), "{msg}");
}

/// The LSF is a density across the edge: on ¼-px bins it integrates to 1
/// (the normalisation is exact, so only float rounding is allowed), and a
/// sharp edge on unit pixels spreads it over about one pixel (peak ≈ 1/px).
#[test]
fn lsf_has_unit_area_per_pixel() {
    let s = sfr(&slanted(64, 64, false), &SfrOptions::default()).unwrap();
    let dx = s.esf_x_px[1] - s.esf_x_px[0];
    assert!(close(dx, 0.25, 1e-12), "{dx}");
    let area: f64 = s.lsf.iter().sum::<f64>() * dx;
    assert!(close(area, 1.0, 1e-9), "{area}");
    let peak = s.lsf.iter().cloned().fold(f64::MIN, f64::max);
    assert!(peak > 0.7 && peak < 1.3, "{peak}");
}

/// Φ, the standard normal CDF (Abramowitz & Stegun 7.1.26: |error| < 1.5·10⁻⁷).
fn phi(z: f64) -> f64 {
    let x = z.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erfc = poly * (-x * x).exp();
    if z >= 0.0 {
        1.0 - 0.5 * erfc
    } else {
        0.5 * erfc
    }
}

/// A 64×64 edge at 12° from the columns through the centre, Gaussian blur σ
/// (px), each pixel the mean of 16×16 sub-samples: 0.1 dark, 0.9 bright.
fn blurred_edge(sigma: f64) -> Vec<f64> {
    let th = 12f64.to_radians();
    let (c, s) = (th.cos(), th.sin());
    let mut v = Vec::with_capacity(64 * 64);
    for j in 0..64 {
        for i in 0..64 {
            let mut acc = 0.0;
            for a in 0..16 {
                let y = j as f64 - 0.5 + (a as f64 + 0.5) / 16.0;
                for b in 0..16 {
                    let x = i as f64 - 0.5 + (b as f64 + 0.5) / 16.0;
                    acc += phi(((x - 32.0) * c - (y - 32.0) * s) / sigma);
                }
            }
            v.push(0.1 + 0.8 * acc / 256.0);
        }
    }
    v
}

/// The MTF of a Gaussian blur σ seen through square pixels of an edge at θ
/// and ¼-px bins: exp(−2π²σ²f²)·sinc(f cos θ)·sinc(f sin θ)·sinc(f/4).
fn gaussian_edge_mtf(sigma: f64, f: f64) -> f64 {
    let sinc = |x: f64| {
        if x == 0.0 {
            1.0
        } else {
            (std::f64::consts::PI * x).sin() / (std::f64::consts::PI * x)
        }
    };
    let th = 12f64.to_radians();
    (-2.0 * std::f64::consts::PI.powi(2) * sigma * sigma * f * f).exp()
        * sinc(f * th.cos())
        * sinc(f * th.sin())
        * sinc(f / 4.0)
}

/// Where the ESF first reaches ½, px (linear interpolation between bins).
fn esf_half_crossing_px(r: &Sfr) -> f64 {
    let k = r.esf.iter().position(|&v| v >= 0.5).unwrap();
    r.esf_x_px[k - 1]
        + (0.5 - r.esf[k - 1]) / (r.esf[k] - r.esf[k - 1]) * (r.esf_x_px[k] - r.esf_x_px[k - 1])
}

/// On a steeper edge (12°: distances along the rows are 2 % longer than
/// across the edge, so a wrong projection shows) the whole estimate against
/// the analytic MTF, and the ESF and LSF where the edge is: ESF in the
/// input's units from 0.1 to 0.9 crossing ½ at x = 0, the LSF centred there.
#[test]
fn steep_blurred_edge_matches_the_analytic_mtf_and_sits_at_zero() {
    let sigma = 0.7;
    let p = Plane::new(64, 64, blurred_edge(sigma)).unwrap();
    let r = sfr(&p, &SfrOptions::default()).unwrap();
    assert!(
        (r.edge_angle_deg.abs() - 12.0).abs() < 0.05,
        "{}",
        r.edge_angle_deg
    );
    let (mut lo, mut hi) = (0.0, 0.5);
    for _ in 0..60 {
        let m = 0.5 * (lo + hi);
        if gaussian_edge_mtf(sigma, m) > 0.5 {
            lo = m
        } else {
            hi = m
        }
    }
    let m50 = r.mtf50_cy_per_px.unwrap();
    // Noise-free; the 1 % the integration tests hold at 5° on 128 px, widened
    // for the 61 rows and 250 bins of this region.
    assert!((m50 / lo - 1.0).abs() < 0.015, "MTF50 {m50} vs {lo}");
    for (f, m) in r.freq_cy_per_px.iter().zip(&r.mtf) {
        if *f <= 0.5 {
            assert!(
                (m - gaussian_edge_mtf(sigma, *f)).abs() < 0.015,
                "MTF({f}) {m}"
            );
        }
    }
    // ¼-px bins over the region's width across the edge: 64·cos 12°·4 = 250.4
    // → 250 (even) bins centred on the edge; frequencies up to 1 cy/px in steps
    // of 4/250 cy/px: 63 of them.
    let n = r.esf.len();
    assert_eq!((n, r.lsf.len(), r.esf_x_px.len()), (250, 250, 250));
    assert_eq!((r.esf_x_px[0], r.esf_x_px[249]), (-31.125, 31.125));
    assert_eq!(r.mtf.len(), 63);
    // Up to 2 cy/px: every frequency of the 250 bins' DFT, 0 … 125.
    let o = SfrOptions {
        max_freq_cy_per_px: 2.0,
        ..Default::default()
    };
    assert_eq!(sfr(&p, &o).unwrap().mtf.len(), 126);
    // Up to 0.3 cy/px: 0 … 18 (18.75 steps), and the noise check at 0.3 cy/px
    // reads the last of them (0.3·62.5 rounds to 19, one past the table).
    let o = SfrOptions {
        max_freq_cy_per_px: 0.3,
        ..Default::default()
    };
    assert_eq!(sfr(&p, &o).unwrap().mtf.len(), 19);
    assert_eq!(
        (r.freq_cy_per_px[1], r.freq_cy_per_px[62]),
        (4.0 / 250.0, 62.0 * 4.0 / 250.0)
    );
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    assert!(
        (mean(&r.esf[..20]) - 0.1).abs() < 0.01,
        "{:?}",
        &r.esf[..20]
    );
    assert!(
        (mean(&r.esf[n - 20..]) - 0.9).abs() < 0.01,
        "{:?}",
        &r.esf[n - 20..]
    );
    let x_half = esf_half_crossing_px(&r);
    assert!(x_half.abs() < 0.15, "ESF crosses ½ at {x_half} px");
    let area: f64 = r.lsf.iter().sum::<f64>() * 0.25;
    let centroid = r
        .lsf
        .iter()
        .zip(&r.esf_x_px)
        .map(|(l, x)| l * x)
        .sum::<f64>()
        * 0.25
        / area;
    assert!(centroid.abs() < 0.15, "LSF centroid {centroid} px");
}

/// A Bayer mosaic of channels seeing `e` with the given offsets and gains.
fn mosaic_of(e: &[f64], offset: [f64; 3], gain: [f64; 3]) -> Plane {
    let ch = |x: usize, y: usize| match (x % 2, y % 2) {
        (0, 0) => 0u8,
        (1, 1) => 2,
        _ => 1,
    };
    let mut p = Plane::new(
        64,
        64,
        (0..64 * 64)
            .map(|i| {
                let c = ch(i % 64, i / 64) as usize;
                offset[c] + gain[c] * e[i]
            })
            .collect(),
    )
    .unwrap();
    p.channel = (0..64 * 64).map(|i| ch(i % 64, i / 64)).collect();
    p.channel_names = vec!["r".into(), "g".into(), "b".into()];
    p
}

/// A channel that does not see the edge (blue flat at 5) has no plateaus to
/// normalise by: `lum` leaves it out and measures the edge in red and green.
#[test]
fn lum_leaves_out_a_channel_without_the_edge() {
    let e = blurred_edge(0.7);
    let mono = sfr(
        &Plane::new(64, 64, e.clone()).unwrap(),
        &SfrOptions::default(),
    )
    .unwrap();
    let lum = sfr(
        &mosaic_of(&e, [5.0, 20.0, 5.0], [50.0, 100.0, 0.0]),
        &SfrOptions::default(),
    )
    .unwrap();
    assert!(lum.mtf.iter().all(|m| m.is_finite()));
    let (a, b) = (mono.mtf50_cy_per_px.unwrap(), lum.mtf50_cy_per_px.unwrap());
    assert!((a / b - 1.0).abs() < 0.02, "MTF50 mono {a}, lum {b}");
}

/// A Bayer mosaic whose channels see the same edge with their own offset and
/// gain (r 5 + 50·e, g 20 + 100·e, b 2 + 30·e): the `lum` estimate normalises
/// each channel by its plateaus, so it measures the mono edge's MTF.
#[test]
fn lum_of_a_mosaic_with_unequal_channels_is_the_edge_mtf() {
    let sigma = 0.7;
    let e = blurred_edge(sigma);
    let mono = sfr(
        &Plane::new(64, 64, e.clone()).unwrap(),
        &SfrOptions::default(),
    )
    .unwrap();
    let p = mosaic_of(&e, [5.0, 20.0, 2.0], [50.0, 100.0, 30.0]);
    let lum = sfr(&p, &SfrOptions::default()).unwrap();
    // Each channel's dark plateau is 0 and bright plateau 1 after normalising.
    let n = lum.esf.len();
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    assert!(mean(&lum.esf[..20]).abs() < 0.01, "{:?}", &lum.esf[..20]);
    assert!(
        (mean(&lum.esf[n - 20..]) - 1.0).abs() < 0.01,
        "{:?}",
        &lum.esf[n - 20..]
    );
    // The mosaic's edge is located on 2×2 block means, whose centres lie half
    // a pixel in: it still crosses ½ at x = 0 (a row off would move it tan 12°
    // = 0.21 px).
    let x_half = esf_half_crossing_px(&lum);
    println!("mosaic ESF crosses ½ at {x_half} px");
    assert!(x_half.abs() < 0.08, "ESF crosses ½ at {x_half} px");
    let (a, b) = (mono.mtf50_cy_per_px.unwrap(), lum.mtf50_cy_per_px.unwrap());
    assert!((a / b - 1.0).abs() < 0.01, "MTF50 mono {a}, lum {b}");
    for f in [0.1, 0.2, 0.3, 0.4] {
        let (m, _) = mono.mtf_at(f).unwrap();
        let (l, _) = lum.mtf_at(f).unwrap();
        assert!((m - l).abs() < 0.01, "MTF({f}) mono {m}, lum {l}");
    }
}

/// Finite values whose ESF sums overflow (an edge at 10³⁰⁷): refused with an
/// error, never measured as NaN.
#[test]
fn an_edge_whose_sums_overflow_is_refused_not_nan() {
    let v: Vec<f64> = blurred_edge(0.7).iter().map(|x| x * 1e307).collect();
    match sfr(&Plane::new(64, 64, v).unwrap(), &SfrOptions::default()) {
        Err(e) => assert!(e.to_string().contains("edge"), "{e}"),
        Ok(r) => panic!("measured: MTF {:?}", &r.mtf[..4]),
    }
}

/// The noise floor of one noisy ESF bin j₀ (variance 2 over 4 samples, all
/// other bins noise-free), worked out from its definition: the 3-tap LSF
/// takes 2·ESF_{j₀} into LSF_{j₀−1} (when 1 ≤ j₀ − 1) and −2·ESF_{j₀} into
/// LSF_{j₀+1} (when j₀ + 1 ≤ n − 2; the end copies are left out), so the
/// windowed DFT at ω = 2πm/n moves by 2·(w_{j₀−1}e^{−iω(j₀−1)} −
/// w_{j₀+1}e^{−iω(j₀+1)}) per unit of ESF; its rms over the bin's variance,
/// times the derivative correction |ω/sin ω| (≤ 10), over the DC term.
#[test]
fn noise_floor_of_one_noisy_bin_follows_its_definition() {
    let win = [0.1, 0.3, 0.5, 0.7, 0.9, 1.0, 0.8, 0.6, 0.4, 0.2];
    let n = win.len();
    let dc = 2.0;
    for j0 in [1, 2, 5, 8, 9] {
        let mut var = vec![0.0; n];
        var[j0] = 2.0;
        let mut cnt = vec![1u32; n];
        cnt[j0] = 4;
        let got = noise_floor(&win, &cnt, &var, dc, 4);
        assert_eq!(got.len(), 4);
        assert_eq!(got[0], 0.0);
        for (m, &g) in got.iter().enumerate().skip(1) {
            let w = 2.0 * std::f64::consts::PI * m as f64 / n as f64;
            let (mut re, mut im) = (0.0, 0.0);
            if j0 >= 2 {
                let a = w * (j0 - 1) as f64;
                re += win[j0 - 1] * a.cos();
                im -= win[j0 - 1] * a.sin();
            }
            if j0 < n - 2 {
                let a = w * (j0 + 1) as f64;
                re -= win[j0 + 1] * a.cos();
                im += win[j0 + 1] * a.sin();
            }
            let want =
                (4.0 * (re * re + im * im) * 2.0 / 4.0).sqrt() * (w / w.sin()).abs().min(10.0) / dc;
            assert!((g - want).abs() < 1e-12, "j₀ {j0}, m {m}: {g} vs {want}");
        }
    }
    // No DC, no floor.
    assert!(
        noise_floor(&win, &[1; 10], &[1.0; 10], 0.0, 4)
            .iter()
            .all(|&v| v == 0.0)
    );
}
