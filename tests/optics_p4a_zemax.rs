//! Pixel 4a RTF blur against the lens maker's Zemax geometric LSF/MTF
//! (issue 5). `lenses/README.md` does not exist, so the findings live here.
//!
//! # What is compared
//! The paper's RTF (`pixel4a-rearcamera-ellipse-raytransfer.json`, one
//! wavelength: 550 nm, so no polychromatic mean is possible) goes through
//! `analysis::edge_spread`, the code behind `camsim lens esf`: on-axis
//! geometric ESF of an edge 1000 m in front of the front vertex (vergence
//! 0.001 1/m ≈ 0.02 µm of focus shift: infinity), on Zemax's own grid
//! (−5…5 µm, 0.1 µm), 64×64 pupil samples per film point. Zemax:
//! `zemax_p4a_geometric_lsf_onaxis.csv` (polychromatic 470–650 nm, LSF and
//! its integral ERF) and `zemax_p4a_geometric_mtf.csv` (field 0; tangential
//! = sagittal on axis). Both sides use the same operators: RMS width and
//! FWHM of the forward differences of the ESF; MTF = |Fourier transform| of
//! those differences divided by the difference operator's sinc(π f h).
//! Checked on Zemax alone: its ERF through this MTF gives 0.9794 / 0.9235 /
//! 0.7573 at 50/100/200 cy/mm and MTF50 342.5 cy/mm against its MTF table's
//! 0.9794 / 0.9242 / 0.7611 and 347 cy/mm (0.1 µm sampling, ±5 µm window).
//!
//! # Findings (measured 2026-11-23, 550 nm, object at 1000 m)
//! Zemax on-axis: RMS width 0.656 µm, FWHM 0.58 µm (0.39 µm from its LSF
//! column; the cusp is under-resolved at 0.1 µm, so FWHM is reported, not
//! tested), MTF50 347 cy/mm (table; 342.5 through our operator).
//!
//! | film mm  | what                    | RMS µm | FWHM µm | MTF 50/100/200        | MTF50 | ESF RMSE |
//! |----------|-------------------------|--------|---------|-----------------------|-------|----------|
//! | 0.465136 | paper (fig. 5 "infinity") | 1.198 | 1.62  | 0.930 / 0.736 / 0.139 | 142   | 0.125    |
//! | 0.4809   | RTF sharpest (min RMS)  | 0.209  | 0.31    | 0.998 / 0.992 / 0.967 | 897   | 0.059    |
//! | 0.4881   | RTF best match to Zemax | 0.567  | 0.58    | 0.984 / 0.939 / 0.776 | 332   | 0.0057   |
//! | Zemax    |                         | 0.656  | 0.58    | 0.979 / 0.924 / 0.761 | 347   | —        |
//!
//! (MTF50 in cy/mm; ESF RMSE between peak-1 curves on Zemax's grid. Printed
//! again by `cargo test --release --test optics_p4a_zemax -- --nocapture`.)
//!
//! - The RTF is sharpest at film distance 0.4809 mm (RMS-width minimum,
//!   golden section; a 0.5 µm scan puts it at 0.4805–0.4810; `camsim lens info` finds 0.48060 by the spread of output
//!   directions). There its geometric LSF is ~3× narrower than Zemax's
//!   (RMS 0.21 vs 0.66 µm, MTF50 ~900 vs ~345 cy/mm). Tangential and
//!   sagittal are the same on axis (Zemax's table; our edge is along y).
//! - Zemax's curve is reproduced almost exactly (ESF RMSE 0.0057, peak-
//!   normalised LSF RMSE 0.038, MTF within 0.015, MTF50 −4 %) by the RTF
//!   defocused ~7.2 µm *behind* its best focus (film 0.4881 mm). On the other
//!   side of focus (0.473 mm, RMS 0.60 µm) the shape does not match (ESF
//!   RMSE 0.046). We cannot tell from the files whether Zemax's image plane
//!   sits there or whether the difference is Zemax's polychromatic blur
//!   (axial colour, 470–650 nm) against our 550 nm-only RTF; note also that
//!   the RTF's on-axis pass ellipse (radius 0.38 mm at 2.589 mm) gives a
//!   working f-number of 3.46 in `lens info`, while the set-up file quotes
//!   an effective F/1.83 from Zemax: aberration and defocus blur both grow
//!   with the aperture, so a half-size pupil alone would make the RTF far
//!   sharper than Zemax at best focus. (Diagnostic only, not in the repo:
//!   doubling the file's ellipse radii gives working F/1.78 but a
//!   non-monotone ESF near focus — the polynomials are then used outside
//!   the cone they were fitted on — so the files alone do not settle it.)
//! - The paper's 0.465136 mm is 15.7 µm of film travel in front of the
//!   RTF's sharpest focus (15.5 µm from `lens info`'s 0.48060; beam vergence
//!   −0.82 1/m): blur-circle diameter ≈ 15.7 µm / 3.46 ≈ 4.5 µm, RMS width
//!   1.2 µm, 1.8× Zemax's; MTF50 142 cy/mm, 0.41× Zemax's.
//! - Fig. 7's film distances do not focus this RTF at fig. 7's object
//!   distances (on axis; objects 0.5 / 0.3 m from the front vertex; window
//!   ±10 µm):
//!   0.5 m at 0.49234 mm → RMS 1.95 µm, MTF50 89 cy/mm (the RTF is sharpest
//!   there at ≈ 0.520 mm in a 5 µm scan: RMS 0.22 µm, MTF50 ~870); 0.3 m at 0.57624 mm →
//!   RMS 2.18 µm, MTF50 82 cy/mm (sharpest ≈ 0.545 mm: RMS 0.22 µm). So the
//!   "in focus" edges of fig. 7 rendered with the paper's film distances are
//!   defocused by ≈ −28 µm and +31 µm of film travel and cannot be expected
//!   to show the absolute LSF widths of the paper or of Zemax; with the
//!   RTF's own focus they are ~3× sharper than Zemax's geometric LSF.

mod common;

use camsim::optics::analysis::{self, LensCamera};
use std::path::Path;

const P4A: &str = "lenses/rtf/pixel4a-rearcamera-ellipse-raytransfer.json";
const WAVELENGTH_NM: f64 = 550.0;

/// Zemax on-axis LSF table: (position_um, lsf_x, erf_x).
fn zemax_lsf() -> Vec<(f64, f64, f64)> {
    common::numeric_rows("lenses/zemax-reference/zemax_p4a_geometric_lsf_onaxis.csv")
        .into_iter()
        .map(|v| (v[0], v[1], v[2]))
        .collect()
}

/// Zemax on-axis MTF: (freq_cy_per_mm, tangential, sagittal).
fn zemax_mtf_on_axis() -> Vec<(f64, f64, f64)> {
    common::numeric_rows("lenses/zemax-reference/zemax_p4a_geometric_mtf.csv")
        .into_iter()
        .filter(|v| v[0] == 0.0)
        .map(|v| (v[1], v[2], v[3]))
        .collect()
}

fn camera(film_distance_mm: f64) -> LensCamera {
    let lens = analysis::load_lens(Path::new(P4A)).unwrap();
    analysis::lens_camera(lens, Some(film_distance_mm), None, WAVELENGTH_NM).unwrap()
}

/// ESF and (CLI-style, peak-normalised) LSF of the RTF on axis.
fn rtf_esf(film_distance_mm: f64, object_m: f64, pos_um: &[f64], n: usize) -> Vec<(f64, f64)> {
    let cam = camera(film_distance_mm);
    let z_obj = cam.front_vertex_z_mm() + object_m * 1e3;
    analysis::edge_spread(cam.camera(), z_obj, 0.0, pos_um, WAVELENGTH_NM, n).unwrap()
}

/// Widths of an LSF given by its ESF on a uniform grid: forward differences
/// at the midpoints. Returns (rms_um, fwhm_um).
fn widths(pos_um: &[f64], esf: &[f64]) -> (f64, f64) {
    let mid: Vec<(f64, f64)> = pos_um
        .windows(2)
        .zip(esf.windows(2))
        .map(|(p, e)| (0.5 * (p[0] + p[1]), e[1] - e[0]))
        .collect();
    let s: f64 = mid.iter().map(|m| m.1).sum();
    let mean = mid.iter().map(|m| m.0 * m.1).sum::<f64>() / s;
    let rms = (mid.iter().map(|m| (m.0 - mean).powi(2) * m.1).sum::<f64>() / s).sqrt();
    // FWHM: outermost half-maximum crossings walking out from the peak.
    let (kp, peak) = mid
        .iter()
        .enumerate()
        .fold((0, 0.0), |a, (k, m)| if m.1 > a.1 { (k, m.1) } else { a });
    let half = 0.5 * peak;
    let mut r = kp;
    while r + 1 < mid.len() && mid[r + 1].1 >= half {
        r += 1;
    }
    let mut l = kp;
    while l > 0 && mid[l - 1].1 >= half {
        l -= 1;
    }
    let cross = |a: (f64, f64), b: (f64, f64)| a.0 + (b.0 - a.0) * (a.1 - half) / (a.1 - b.1);
    let xr = if r + 1 < mid.len() {
        cross(mid[r], mid[r + 1])
    } else {
        mid[r].0
    };
    let xl = if l > 0 {
        cross(mid[l], mid[l - 1])
    } else {
        mid[l].0
    };
    (rms, xr - xl)
}

/// MTF at `freq_cy_per_mm` from an ESF sampled on a uniform grid (step h):
/// Fourier transform of the forward differences, divided by the difference
/// operator's own transfer sinc(π f h).
fn mtf(pos_um: &[f64], esf: &[f64], f: f64) -> f64 {
    let h_mm = (pos_um[1] - pos_um[0]) * 1e-3;
    let (mut re, mut im, mut s) = (0.0, 0.0, 0.0);
    for (p, e) in pos_um.windows(2).zip(esf.windows(2)) {
        let x_mm = 0.5 * (p[0] + p[1]) * 1e-3;
        let l = e[1] - e[0];
        let ph = 2.0 * std::f64::consts::PI * f * x_mm;
        re += l * ph.cos();
        im += l * ph.sin();
        s += l;
    }
    let a = std::f64::consts::PI * f * h_mm;
    let sinc = if a > 0.0 { a.sin() / a } else { 1.0 };
    (re * re + im * im).sqrt() / s / sinc
}

fn mtf50(pos_um: &[f64], esf: &[f64]) -> f64 {
    let (mut lo, mut hi) = (0.0, 5000.0);
    if mtf(pos_um, esf, hi) > 0.5 {
        return hi;
    }
    // First crossing: step up to bracket, then bisect.
    let mut f = 0.0;
    while f < hi {
        if mtf(pos_um, esf, f + 5.0) < 0.5 {
            lo = f;
            hi = f + 5.0;
            break;
        }
        f += 5.0;
    }
    for _ in 0..40 {
        let m = 0.5 * (lo + hi);
        if mtf(pos_um, esf, m) > 0.5 {
            lo = m
        } else {
            hi = m
        }
    }
    0.5 * (lo + hi)
}

fn rmse(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

#[derive(Clone, Copy)]
struct Row {
    rms_um: f64,
    fwhm_um: f64,
    mtf: [f64; 3],
    mtf50: f64,
    esf_rmse: f64,
    lsf_rmse: f64,
}

const FREQS: [f64; 3] = [50.0, 100.0, 200.0];

fn measure(pos: &[f64], esf: &[f64], lsf: &[f64], z: &[(f64, f64, f64)]) -> Row {
    let (rms_um, fwhm_um) = widths(pos, esf);
    let zesf: Vec<f64> = z.iter().map(|r| r.2).collect();
    let zlsf: Vec<f64> = z.iter().map(|r| r.1).collect();
    Row {
        rms_um,
        fwhm_um,
        mtf: FREQS.map(|f| mtf(pos, esf, f)),
        mtf50: mtf50(pos, esf),
        esf_rmse: if esf.len() == zesf.len() {
            rmse(esf, &zesf)
        } else {
            f64::NAN
        },
        lsf_rmse: if lsf.len() == zlsf.len() {
            rmse(lsf, &zlsf)
        } else {
            f64::NAN
        },
    }
}

fn rtf_row(film_mm: f64, object_m: f64, pos: &[f64], z: &[(f64, f64, f64)]) -> Row {
    let r = rtf_esf(film_mm, object_m, pos, 64);
    let esf: Vec<f64> = r.iter().map(|v| v.0).collect();
    let lsf: Vec<f64> = r.iter().map(|v| v.1).collect();
    measure(pos, &esf, &lsf, z)
}

/// Golden-section minimum of `f` on [a, b] to `tol`.
fn golden(mut a: f64, mut b: f64, tol: f64, f: impl Fn(f64) -> f64) -> f64 {
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    while b - a > tol {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}

fn print_row(name: &str, film: &str, r: &Row) {
    println!(
        "{name:<26} {film:>9} {:>7.3} {:>7.3} {:>6.4} {:>6.4} {:>6.4} {:>7.1} {:>8.4} {:>8.4}",
        r.rms_um, r.fwhm_um, r.mtf[0], r.mtf[1], r.mtf[2], r.mtf50, r.esf_rmse, r.lsf_rmse
    );
}

/// Everything the tests below compare, computed once (the golden sections
/// trace tens of thousands of rays).
struct Computed {
    zemax: Row,
    /// Zemax's MTF table at `FREQS`, and its MTF50 (linear interpolation).
    table_mtf: [f64; 3],
    t50: f64,
    d_best: f64,
    d_inf: f64,
    d_match: f64,
    best: Row,
    matched: Row,
    paper: Row,
    near05: Row,
    near03: Row,
}

fn computed() -> &'static Computed {
    static C: std::sync::OnceLock<Computed> = std::sync::OnceLock::new();
    C.get_or_init(|| {
        let z = zemax_lsf();
        let pos: Vec<f64> = z.iter().map(|r| r.0).collect();
        let zesf: Vec<f64> = z.iter().map(|r| r.2).collect();
        let zlsf: Vec<f64> = z.iter().map(|r| r.1).collect();
        let zemax = measure(&pos, &zesf, &zlsf, &z);
        let table = zemax_mtf_on_axis();
        let at = |f: f64| {
            let k = table.iter().position(|r| r.0 == f).unwrap();
            assert_eq!(table[k].1, table[k].2, "on axis tangential = sagittal");
            table[k].1
        };
        let t50 = {
            let k = table.iter().position(|r| r.1 < 0.5).unwrap();
            let (a, b) = (table[k - 1], table[k]);
            a.0 + (b.0 - a.0) * (a.1 - 0.5) / (a.1 - b.1)
        };
        // Sharpest RTF focus for an object at 1000 m: minimum RMS width.
        let far = 1000.0;
        let d_best = golden(0.470, 0.492, 2e-4, |d| rtf_row(d, far, &pos, &z).rms_um);
        let cam = camera(0.465136);
        let LensCamera::Rtf(c) = &cam else {
            unreachable!()
        };
        let d_inf = analysis::rtf_infinity_film_distance_mm(&c.rtf, WAVELENGTH_NM).unwrap();
        // Film distance that reproduces Zemax: minimum ESF RMSE, searched behind focus.
        let d_match = golden(d_best, d_best + 0.015, 2e-4, |d| {
            rtf_row(d, far, &pos, &z).esf_rmse
        });
        let wide: Vec<f64> = (0..=200).map(|i| -10.0 + 0.1 * i as f64).collect();
        let c = Computed {
            table_mtf: FREQS.map(at),
            t50,
            d_best,
            d_inf,
            d_match,
            best: rtf_row(d_best, far, &pos, &z),
            matched: rtf_row(d_match, far, &pos, &z),
            paper: rtf_row(0.465136, far, &pos, &z),
            near05: rtf_row(0.49234, 0.5, &wide, &z),
            near03: rtf_row(0.57624, 0.3, &wide, &z),
            zemax,
        };
        print_table(&c);
        c
    })
}

fn print_table(c: &Computed) {
    println!("RTF (550 nm) vs Zemax (470–650 nm) on-axis geometric LSF/MTF");
    println!(
        "{:<26} {:>9} {:>7} {:>7} {:>6} {:>6} {:>6} {:>7} {:>8} {:>8}",
        "case",
        "film_mm",
        "rms_um",
        "fwhm_um",
        "m50",
        "m100",
        "m200",
        "mtf50",
        "esf_rmse",
        "lsf_rmse"
    );
    let zt = Row {
        mtf: c.table_mtf,
        mtf50: c.t50,
        esf_rmse: 0.0,
        lsf_rmse: 0.0,
        ..c.zemax
    };
    print_row("zemax (MTF from table)", "-", &zt);
    print_row("zemax (MTF from ERF)", "-", &c.zemax);
    print_row("rtf sharpest, 1000 m", &format!("{:.5}", c.d_best), &c.best);
    print_row(
        "rtf matching zemax, 1000 m",
        &format!("{:.5}", c.d_match),
        &c.matched,
    );
    print_row("rtf paper film, 1000 m", "0.465136", &c.paper);
    print_row("rtf paper 0.5 m focus", "0.49234", &c.near05);
    print_row("rtf paper 0.3 m focus", "0.57624", &c.near03);
    println!(
        "infinity focus by direction spread {:.5} mm; paper film is {:.1} µm in front of the sharpest; Zemax match {:.1} µm behind it",
        c.d_inf,
        (c.d_best - 0.465136) * 1e3,
        (c.d_match - c.d_best) * 1e3
    );
}

/// Independent truth: the LSF→MTF operator applied to Zemax's own ERF
/// reproduces Zemax's own MTF table (measured |ΔMTF| ≤ 0.0038, MTF50
/// −1.4 % at 0.1 µm sampling in a ±5 µm window: truncation of the ERF's
/// tails and the 0.1 µm difference step; bounds 0.01 and 3 %).
#[test]
fn lsf_to_mtf_operator_reproduces_the_zemax_mtf_table() {
    let c = computed();
    for (k, f) in FREQS.iter().enumerate() {
        assert!(
            (c.zemax.mtf[k] - c.table_mtf[k]).abs() < 0.01,
            "Zemax ERF→MTF at {f}: {} vs {}",
            c.zemax.mtf[k],
            c.table_mtf[k]
        );
    }
    assert!(
        (c.zemax.mtf50 / c.t50 - 1.0).abs() < 0.03,
        "Zemax MTF50 {} vs table {}",
        c.zemax.mtf50,
        c.t50
    );
}

/// Two independent focus criteria agree: the film distance of minimum RMS
/// width of the traced ESF (golden section to 0.2 µm) and
/// `rtf_infinity_film_distance_mm` (minimum spread of the RTF's output
/// directions). Measured 0.48088 vs 0.48060 mm; the RMS minimum is flat over
/// ±0.5 µm (a 0.5 µm scan puts it at 0.4805–0.4810), bound 1.5 µm.
#[test]
fn sharpest_focus_agrees_with_the_direction_spread_focus() {
    let c = computed();
    assert!(
        (c.d_best - c.d_inf).abs() < 1.5e-3,
        "sharpest {} vs infinity focus {}",
        c.d_best,
        c.d_inf
    );
}

/// REGRESSION GUARD, not a physics check: the numbers below were measured on
/// 2026-11-23 (table in the module docs) and have no independent truth —
/// the RTF (550 nm) and Zemax (470–650 nm polychromatic, unknown image
/// plane) are not the same system. The bounds keep a margin of several times
/// the quadrature noise (64² vs 128² pupil samples: < 0.003 µm RMS, < 1.5 %
/// MTF50; golden sections stop at 0.2 µm) around the measured value, quoted
/// in each assertion, and fail on any change of the RTF camera's blur
/// (film-distance convention, pass test, polynomial use) that moves focus by
/// more than 1.5 µm or widths by > 15–20 %. If one fails after an intended change,
/// re-measure (`cargo test --release --test optics_p4a_zemax -- --nocapture`)
/// and update the table and these bounds together.
#[test]
fn regression_guard_p4a_rtf_blur_as_measured_on_2026_11_23() {
    let c = computed();
    let (zemax, best, matched, paper) = (&c.zemax, &c.best, &c.matched, &c.paper);
    let t50 = c.t50;
    // The paper's film distance is defocused: measured 15.7 µm in front.
    let defocus_um = (c.d_best - 0.465136) * 1e3;
    assert!(
        (12.0..19.0).contains(&defocus_um),
        "paper defocus {defocus_um} µm"
    );
    // At best focus the 550 nm RTF is ~3× sharper than Zemax: RMS 0.210 vs
    // 0.656 µm (ratio 0.32), MTF50 897 vs 347 cy/mm.
    assert!(
        best.rms_um < 0.45 * zemax.rms_um,
        "best-focus RMS {} vs Zemax {}",
        best.rms_um,
        zemax.rms_um
    );
    assert!(best.mtf50 > 2.0 * t50, "best-focus MTF50 {}", best.mtf50);
    // Zemax is reproduced 7.2 µm behind best focus: ESF RMSE 0.0057, LSF
    // RMSE 0.038, RMS width −14 %, MTF within 0.015, MTF50 −4.4 %.
    let behind_um = (c.d_match - c.d_best) * 1e3;
    assert!(
        (5.0..10.0).contains(&behind_um),
        "Zemax match {behind_um} µm behind focus"
    );
    assert!(matched.esf_rmse < 0.012, "ESF RMSE {}", matched.esf_rmse);
    assert!(matched.lsf_rmse < 0.06, "LSF RMSE {}", matched.lsf_rmse);
    assert!(
        (matched.rms_um / zemax.rms_um - 1.0).abs() < 0.2,
        "RMS {} vs {}",
        matched.rms_um,
        zemax.rms_um
    );
    for (k, f) in FREQS.iter().enumerate() {
        assert!(
            (matched.mtf[k] - c.table_mtf[k]).abs() < 0.03,
            "matched MTF at {f}: {}",
            matched.mtf[k]
        );
    }
    assert!(
        (matched.mtf50 / t50 - 1.0).abs() < 0.08,
        "matched MTF50 {}",
        matched.mtf50
    );
    // Paper film distances blur: 0.465136 mm RMS 1.20 µm (1.8× Zemax),
    // MTF50 142; fig. 7's in-focus pairs RMS 1.95 / 2.18 µm, MTF50 89 / 82.
    assert!(
        paper.rms_um > 1.5 * zemax.rms_um && paper.mtf50 < 0.5 * t50,
        "paper focus RMS {} MTF50 {}",
        paper.rms_um,
        paper.mtf50
    );
    for (name, r) in [("0.5 m", &c.near05), ("0.3 m", &c.near03)] {
        assert!(
            r.rms_um > 1.5 && r.mtf50 < 120.0,
            "{name}: RMS {} MTF50 {}",
            r.rms_um,
            r.mtf50
        );
    }
}
