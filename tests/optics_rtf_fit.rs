//! RTF fitting acceptance: the Zemax sample double Gauss (28°) and Tessar
//! prescriptions are traced directly and through RTFs fitted at degrees 3–7.
//! Relative illumination and geometric ESF of prescription vs RTF are
//! compared (RI within 0.01; ESF RMSE ≤ 1 % of the mean of the 10 largest
//! values), and both against the Zemax references. The per-degree table is
//! written to `target/optics-report.csv` and printed (`--nocapture`).
//!
//! Models per lens: `rtf-degreeN` is the default fit (film-point bundles on
//! the film planes of objects at ∞, 20, 10 and 5 focal lengths,
//! aberration-relative least-squares weights, area-matched pass ellipses),
//! `-unweighted` the unweighted least squares on the same traced data,
//! `-inputplane` the input-plane sampling of sessions 1–3,
//! `rtf-degree3-axisweightW` degree 3 with the on-axis rays weighted ×W,
//! and at degree 5 the other pass/no-pass representations (the paper's
//! enclosing ellipses; vignetting circles). ESF positions: every Zemax
//! position; on axis (the acceptance line) and, tabulated, at 25/50/75 % of
//! the RI film range (columns `esf_rmse_vs_prescription_fieldNN`).
//! `rtf-degreeN-onaxis-only` fits the same monomials (same planes and
//! ellipses) to only the rays the on-axis ESF traces: the reach of the
//! polynomial form on axis, evidence for which lines are feasible at all.
//!
//! Film-plane residuals (columns `film_residual_rms_um`,
//! `film_residual_max_um`; `analysis::film_residuals`): film at infinity
//! focus, the RI film heights, a 24×24 pupil grid; every ray the model's
//! camera emits into the scene is traced back through the prescription to
//! the film plane, and its distance from the film point that emitted it is
//! the residual (rays the prescription blocks on the way back are left
//! out). The prescription row is its own reverse trace (0 to rounding).
//!
//! Set-up: RI at infinity focus (paraxial back focal distance), 0–95 % of the
//! largest film radius that receives light. ESF on axis, object at the first
//! Zemax distance (dgauss 1 m, Tessar 1.3 m from the front vertex), film at
//! its paraxial focus, positions from the Zemax table. Quadrature: 96×96
//! (RI) and 40×40 (ESF) midpoint grids over the pupil sample square; their
//! error (< 0.3 % of a value) is well inside the tolerances.

mod common;

use camsim::optics::Camera;
use camsim::optics::analysis::{edge_spread, esf_rmse, film_residuals, relative_illumination};
use camsim::optics::fit::{
    DataSampling, FitOptions, PassMethod, Sample, Weighting, film_bundle_samples, fit_polys,
    fit_rtf, fit_rtf_degrees,
};
use camsim::optics::prescription::{Prescription, PrescriptionCamera};
use camsim::optics::rtf::{Rtf, RtfCamera};
use std::fmt::Write as _;
use std::path::Path;

const DEGREES: [usize; 5] = [3, 4, 5, 6, 7];

struct Case {
    name: &'static str,
    file: &'static str,
    ri_ref: &'static str,
    esf_ref: &'static str,
    object_mm: f64,
}

fn read_pairs(path: &str) -> Vec<(f64, f64)> {
    common::numeric_rows(path)
        .into_iter()
        .map(|v| (v[0], v[1]))
        .collect()
}

/// Zemax ESF (x edge) of condition 0: (position µm, esf).
fn read_esf(path: &str) -> Vec<(f64, f64)> {
    common::numeric_rows(path)
        .into_iter()
        .filter(|v| v[0] == 0.0)
        .map(|v| (v[1], v[3]))
        .collect()
}

fn interp(t: &[(f64, f64)], x: f64) -> f64 {
    let k = t.partition_point(|p| p.0 <= x).clamp(1, t.len() - 1);
    let (a, b) = (t[k - 1], t[k]);
    a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0)
}

struct Row {
    lens: &'static str,
    model: String,
    ri_err_vs_prescription: f64,
    esf_rmse_vs_prescription: f64,
    /// ESF RMSE vs the prescription at 25/50/75 % of the RI film range.
    esf_off_axis: [f64; 3],
    ri_err_vs_zemax: f64,
    esf_rmse_vs_zemax: f64,
    cond: f64,
    film_rms_um: f64,
    film_max_um: f64,
}

/// The rays the on-axis ESF traces through `rtf` (film at `film_mm`): every
/// ESF position's film point × a 20×20 grid over the RTF camera's pupil
/// sampling box, traced through the prescription (`fit::film_bundle_samples`).
fn on_axis_esf_samples(
    lens: &Prescription,
    rtf: &Rtf,
    film_mm: f64,
    pos_um: &[f64],
) -> Vec<Sample> {
    pos_um
        .iter()
        .flat_map(|x_um| {
            film_bundle_samples(lens, rtf, film_mm, (x_um * 1e-3).abs(), 20, 550.0).unwrap()
        })
        .collect()
}

fn evaluate(case: &Case, rows: &mut Vec<Row>) {
    let lens = Prescription::load(Path::new(case.file)).unwrap();
    let bfd = lens.paraxial(550.0).unwrap().back_focal_distance_mm;
    let film_esf = lens.image_distance_mm(case.object_mm, 550.0).unwrap();
    let track = lens.total_track_mm();
    let presc_inf = PrescriptionCamera::new(lens.clone(), bfd, 550.0).unwrap();
    let presc_esf = PrescriptionCamera::new(lens.clone(), film_esf, 550.0).unwrap();
    let r_hi = 0.95 * presc_inf.max_film_radius_mm;
    let heights: Vec<f64> = (0..=12).map(|k| r_hi * k as f64 / 12.0).collect();
    let zemax_ri = read_pairs(case.ri_ref);
    // Every Zemax position (Tessar 10 µm, double Gauss 2 µm apart).
    let zemax_esf: Vec<(f64, f64)> = read_esf(case.esf_ref);
    let pos: Vec<f64> = zemax_esf.iter().map(|p| p.0).collect();
    let z_obj = film_esf + track + case.object_mm;
    let ri_of = |cam: &dyn Camera| relative_illumination(cam, &heights, 550.0, 96).unwrap();
    // An off-axis ESF of a model that sends no light there (the on-axis-only
    // fits) is NaN in the table.
    let esf_at = |cam: &dyn Camera, field_mm: f64| match edge_spread(
        cam, z_obj, field_mm, &pos, 550.0, 40,
    ) {
        Ok(e) => e.into_iter().map(|e| e.0).collect::<Vec<_>>(),
        Err(_) if field_mm > 0.0 => vec![f64::NAN; pos.len()],
        Err(e) => panic!("{}: on-axis ESF: {e}", case.name),
    };
    let esf_of = |cam: &dyn Camera| esf_at(cam, 0.0);
    let off_fields = [0.25 * r_hi, 0.5 * r_hi, 0.75 * r_hi];
    let esf_off_p: Vec<Vec<f64>> = off_fields.iter().map(|&h| esf_at(&presc_esf, h)).collect();
    let ri_p = ri_of(&presc_inf);
    // Film-plane residuals: infinity focus, the RI film heights, 24×24 pupil
    // grid (analysis::film_residuals). The prescription against itself
    // checks the reverse trace (rounding only).
    let film_of = |cam: &dyn Camera| film_residuals(cam, &lens, bfd, &heights, 550.0, 24).unwrap();
    let film_p = film_of(&presc_inf);
    assert!(film_p.max_um < 1e-3, "reverse trace: {film_p:?}");
    let esf_p = esf_of(&presc_esf);
    let zemax_esf_v: Vec<f64> = zemax_esf.iter().map(|p| p.1).collect();
    let ri_vs_zemax = |ri: &[f64]| {
        heights
            .iter()
            .zip(ri)
            .filter(|(h, _)| **h <= zemax_ri.last().unwrap().0)
            .map(|(h, v)| (v - interp(&zemax_ri, *h)).abs())
            .fold(0.0, f64::max)
    };
    rows.push(Row {
        lens: case.name,
        model: "prescription".into(),
        ri_err_vs_prescription: 0.0,
        esf_rmse_vs_prescription: 0.0,
        esf_off_axis: [0.0; 3],
        ri_err_vs_zemax: ri_vs_zemax(&ri_p),
        esf_rmse_vs_zemax: esf_rmse(&esf_p, &zemax_esf_v),
        cond: f64::NAN,
        film_rms_um: film_p.rms_um,
        film_max_um: film_p.max_um,
    });
    let mut push_rtf = |model: String, rtf: &Rtf, cond: f64| {
        let ri_r = ri_of(&RtfCamera::new(rtf.clone(), bfd).unwrap());
        let cam_esf = RtfCamera::new(rtf.clone(), film_esf).unwrap();
        let esf_r = esf_of(&cam_esf);
        let esf_off_axis: [f64; 3] =
            std::array::from_fn(|k| esf_rmse(&esf_at(&cam_esf, off_fields[k]), &esf_off_p[k]));
        let film = film_of(&RtfCamera::new(rtf.clone(), bfd).unwrap());
        let ri_err = ri_r
            .iter()
            .zip(&ri_p)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        rows.push(Row {
            lens: case.name,
            model,
            ri_err_vs_prescription: ri_err,
            esf_rmse_vs_prescription: esf_rmse(&esf_r, &esf_p),
            esf_off_axis,
            ri_err_vs_zemax: ri_vs_zemax(&ri_r),
            esf_rmse_vs_zemax: esf_rmse(&esf_r, &zemax_esf_v),
            cond,
            film_rms_um: film.rms_um,
            film_max_um: film.max_um,
        });
    };
    // Default fit: aberration-relative weights, area-matched ellipses.
    let opts = FitOptions::default();
    let mut degree6 = None;
    let default_fits = fit_rtf_degrees(&lens, &[550.0], &DEGREES, &opts).unwrap();
    // Reach of the polynomial form on axis: the same monomials fitted (same
    // planes and pass ellipses) to ONLY the rays the on-axis ESF traces. If
    // this exceeded 1 %, no polynomial of that degree could pass the line.
    let onaxis = on_axis_esf_samples(&lens, &default_fits[0].0, film_esf, &pos);
    let onaxis_w = vec![1.0; onaxis.len()];
    let mut onaxis_rows = Vec::new();
    for (&d, (base, _)) in DEGREES.iter().zip(&default_fits) {
        let (mut outputs, rep) = fit_polys(&onaxis, &onaxis_w, d, 550.0, &lens.name).unwrap();
        let mut rtf = base.clone();
        outputs[2] = rtf.waves[0].outputs[2].take();
        rtf.waves[0].outputs = outputs;
        onaxis_rows.push((
            format!("rtf-degree{d}-onaxis-only"),
            rtf,
            rep[0].condition_number,
        ));
    }
    for (d, (rtf, rep)) in DEGREES.iter().zip(default_fits) {
        // The JSON round trip is what renders: write and read back.
        let back = Rtf::from_value(&rtf.to_json(), Path::new("fit.json")).unwrap();
        assert_eq!(back, rtf);
        push_rtf(format!("rtf-degree{d}"), &back, rep[0].condition_number);
        if *d == 6 {
            degree6 = Some(back);
        }
    }
    for (model, rtf, cond) in onaxis_rows {
        push_rtf(model, &rtf, cond);
    }
    // The other choices, same degrees: unweighted least squares (session 1)
    // and the input-plane sampling of sessions 1–3 (aberration-relative
    // weights), for comparison.
    let variants = [
        (
            "unweighted",
            FitOptions {
                weighting: Weighting::Uniform,
                ..Default::default()
            },
        ),
        (
            "inputplane",
            FitOptions {
                sampling: DataSampling::InputPlane,
                ..Default::default()
            },
        ),
    ];
    for (name, opts) in variants {
        for (d, (rtf, rep)) in DEGREES
            .iter()
            .zip(fit_rtf_degrees(&lens, &[550.0], &DEGREES, &opts).unwrap())
        {
            push_rtf(
                format!("rtf-degree{d}-{name}"),
                &rtf,
                rep[0].condition_number,
            );
        }
    }
    // Degree 3 with the on-axis rays weighted up (`--axis-weight`): what the
    // axis gains and the field loses.
    for w in [16.0, 64.0] {
        let opts = FitOptions {
            degree: 3,
            axis_weight: w,
            ..Default::default()
        };
        let (rtf, rep) = fit_rtf(&lens, &[550.0], &opts).unwrap();
        push_rtf(
            format!("rtf-degree3-axisweight{w}"),
            &rtf,
            rep[0].condition_number,
        );
    }
    // Output-plane z convention (rtf.rs): moving the output plane by
    // planeoffsetinput (the "measured from the rear vertex" reading) must
    // visibly defocus the near object — so agreement above tests the convention.
    if case.name == "dgauss28deg" {
        let mut rtf = degree6.unwrap();
        let shift = rtf.plane_offset_input_mm;
        let outz = rtf.waves[0].outputs[2].as_mut().unwrap();
        outz.coeff[0] -= shift;
        let esf_shifted = esf_of(&RtfCamera::new(rtf, film_esf).unwrap());
        let err = esf_rmse(&esf_shifted, &esf_p);
        println!(
            "{}: ESF RMSE with the output plane moved by planeoffsetinput ({shift:.2} mm): {err:.4}",
            case.name
        );
        assert!(
            err > 0.02,
            "a displaced output plane should change the ESF (RMSE {err})"
        );
    }
    // The other pass/no-pass representations, degree 5 (same polynomials):
    // the paper's minimum-area enclosing ellipses, and area-matched ellipses.
    for (name, pass_method) in [
        ("enclosing-ellipses", PassMethod::Ellipses),
        ("circles", PassMethod::Circles),
    ] {
        let opts = FitOptions {
            degree: 5,
            pass_method,
            ..Default::default()
        };
        let (rtf, rep) = fit_rtf(&lens, &[550.0], &opts).unwrap();
        push_rtf(format!("rtf-degree5-{name}"), &rtf, rep[0].condition_number);
    }
}

/// The per-model table of both lenses, computed once (≈ 80 s on 2 cores) and
/// shared by the tests below; written to `target/optics-report.csv`.
fn rows() -> &'static Vec<Row> {
    static ROWS: std::sync::OnceLock<Vec<Row>> = std::sync::OnceLock::new();
    ROWS.get_or_init(compute_rows)
}

fn compute_rows() -> Vec<Row> {
    let cases = [
        Case {
            name: "dgauss28deg",
            file: "lenses/prescriptions/dgauss.28deg-zemax.json",
            ri_ref: "lenses/zemax-reference/dgauss28deg-relativeillum-zemax.csv",
            esf_ref: "lenses/zemax-reference/esf-dgauss28deg.csv",
            object_mm: 1000.0,
        },
        Case {
            name: "tessar",
            file: "lenses/prescriptions/tessar-zemax.json",
            ri_ref: "lenses/zemax-reference/tessar-relativeillum-zemax.csv",
            esf_ref: "lenses/zemax-reference/esf-tessar.csv",
            object_mm: 1300.0,
        },
    ];
    let mut rows = Vec::new();
    for c in &cases {
        evaluate(c, &mut rows);
    }
    let mut csv = String::from(
        "lens,model,ri_max_abs_err_vs_prescription,esf_rmse_vs_prescription,esf_rmse_vs_prescription_field25,esf_rmse_vs_prescription_field50,esf_rmse_vs_prescription_field75,ri_max_abs_err_vs_zemax,esf_rmse_vs_zemax,condition_number,film_residual_rms_um,film_residual_max_um\n",
    );
    for r in &rows {
        writeln!(
            csv,
            "{},{},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.3e},{:.3},{:.3}",
            r.lens,
            r.model,
            r.ri_err_vs_prescription,
            r.esf_rmse_vs_prescription,
            r.esf_off_axis[0],
            r.esf_off_axis[1],
            r.esf_off_axis[2],
            r.ri_err_vs_zemax,
            r.esf_rmse_vs_zemax,
            r.cond,
            r.film_rms_um,
            r.film_max_um
        )
        .unwrap();
    }
    println!("{csv}");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("optics-report.csv"), &csv).unwrap();
    rows
}

/// Acceptance against an independent reference, the traced prescription:
/// the default fit (film-point bundles on four focus planes,
/// aberration-relative weights, area-matched ellipses) keeps RI within 0.01
/// at every degree 3–7 and the on-axis ESF within 1 % at degrees 4–7
/// (measured double Gauss 0.43/0.36/0.31/0.31 %, Tessar 0.40/0.15/0.04/0.03
/// %); the on-axis-only fits and the axis-weighted degree-3 fit reach the
/// 1 % line too. Quadrature error of both sides < 0.3 % of a value.
#[test]
fn fitted_rtfs_match_the_traced_prescriptions() {
    let rows = rows();
    for (r, d) in rows.iter().filter_map(|r| {
        let d = r.model.strip_prefix("rtf-degree")?;
        d.parse::<usize>().ok().map(|d| (r, d))
    }) {
        assert!(
            r.ri_err_vs_prescription <= 0.01,
            "{} {}: RI error {}",
            r.lens,
            r.model,
            r.ri_err_vs_prescription
        );
        if d >= 4 {
            assert!(
                r.esf_rmse_vs_prescription <= 0.01,
                "{} {}: ESF RMSE {}",
                r.lens,
                r.model,
                r.esf_rmse_vs_prescription
            );
        }
    }
    // Feasibility: fitted to only the rays the on-axis ESF traces, every
    // degree 3–7 of this polynomial form reaches the 1 % line (measured
    // 0.39/0.30/0.31/0.31/0.31 % double Gauss, 0.20/0.18/0.03/0.01/0.06 %
    // Tessar; the double Gauss floor is the quadrature's; limit 1 %, the
    // acceptance line). So the gap of the
    // default fit at low degree is the trade-off between the axis and the
    // rest of the field (fit.rs docs), not the reach of the form.
    for r in rows.iter().filter(|r| r.model.ends_with("-onaxis-only")) {
        assert!(
            r.esf_rmse_vs_prescription <= 0.01,
            "{} {}: ESF RMSE {}",
            r.lens,
            r.model,
            r.esf_rmse_vs_prescription
        );
    }
    // Degree 3 fitted with the on-axis rays weighted ×64 (`--axis-weight
    // 64`): the on-axis ESF line holds (measured 0.75 % / 0.41 %), RI too,
    // and the field pays (ESF at 25 % of the field 3.1 → 6.4 % double
    // Gauss, 2.3 → 2.8 % Tessar).
    for r in rows
        .iter()
        .filter(|r| r.model == "rtf-degree3-axisweight64")
    {
        assert!(
            r.esf_rmse_vs_prescription <= 0.01 && r.ri_err_vs_prescription <= 0.01,
            "{} {}: ESF RMSE {}, RI error {}",
            r.lens,
            r.model,
            r.esf_rmse_vs_prescription,
            r.ri_err_vs_prescription
        );
    }
}

/// Independent reference: the prescription's own geometric ESF against
/// Zemax's (measured RMSE 0.99 % double Gauss, 0.61 % Tessar; bound 1.5 %:
/// our 40×40 pupil quadrature < 0.3 %, the rest Zemax's own sampling).
/// (RI against Zemax is tabulated, not asserted: the traced prescription
/// differs from Zemax's RI tables by up to 0.033 / 0.065, unexplained.)
#[test]
fn prescriptions_reproduce_the_zemax_esf() {
    let rows = rows();
    for r in rows.iter().filter(|r| r.model == "prescription") {
        assert!(
            r.esf_rmse_vs_zemax <= 0.015,
            "{}: ESF vs Zemax {}",
            r.lens,
            r.esf_rmse_vs_zemax
        );
    }
}

/// REGRESSION GUARD, not a physics check: bounds set from the run of
/// 2026-11-23 (values quoted below) with no independent truth behind them.
/// They fail when the fitter's behaviour changes (film-plane residuals of the
/// default fit at 1.5× the measured RMS; degree 3, which cannot be accurate
/// on axis and over the field at once, at 3 % on-axis ESF where it measured
/// 1.8 % / 2.5 %; the paper's enclosing ellipses letting light through at
/// vignetted fields, RI +0.03…+0.08). After an intended change, re-measure
/// (`cargo test --release --test optics_rtf_fit -- --nocapture` prints the
/// table) and update these bounds with it.
#[test]
fn regression_guard_rtf_fit_residuals_as_measured_on_2026_11_23() {
    let rows = rows();
    for r in rows.iter().filter(|r| r.model == "rtf-degree3") {
        assert!(
            r.esf_rmse_vs_prescription <= 0.03,
            "{} {}: ESF RMSE {}",
            r.lens,
            r.model,
            r.esf_rmse_vs_prescription
        );
    }
    // Film-plane residuals of the default fit (regression guards at 1.5×
    // the measured RMS: double Gauss 14.1/3.5/0.99/0.32/0.09 µm, Tessar
    // 206/310/196/102/62 µm at degrees 3–7; the Tessar's outer field, 42°
    // and strongly vignetted, dominates).
    let film_limit = |lens: &str, d: usize| match (lens, d) {
        ("dgauss28deg", 3) => 21.0,
        ("dgauss28deg", 4) => 5.3,
        ("dgauss28deg", 5) => 1.5,
        ("dgauss28deg", _) => 0.5,
        ("tessar", 3) => 310.0,
        ("tessar", 4) => 465.0,
        ("tessar", 5) => 295.0,
        ("tessar", 6) => 155.0,
        _ => 95.0,
    };
    for (r, d) in rows.iter().filter_map(|r| {
        let d = r.model.strip_prefix("rtf-degree")?;
        d.parse::<usize>().ok().map(|d| (r, d))
    }) {
        assert!(
            r.film_rms_um.is_finite() && r.film_rms_um <= film_limit(r.lens, d),
            "{} {}: film residual RMS {} µm",
            r.lens,
            r.model,
            r.film_rms_um
        );
    }
    // The paper's enclosing ellipses let light through at vignetted fields
    // (RI +0.03…+0.08), which is why they are not the default.
    for r in rows
        .iter()
        .filter(|r| r.model.ends_with("enclosing-ellipses"))
    {
        assert!(r.ri_err_vs_prescription > 0.02, "{} {}", r.lens, r.model);
    }
}

/// Stiff case: a degree-16 fit (969 monomials) stays finite, reports its
/// condition number, and its RTF traces finite rays.
#[test]
fn optics_degree16_fit_is_finite() {
    let lens = Prescription::load(Path::new("lenses/prescriptions/tessar-zemax.json")).unwrap();
    let opts = FitOptions {
        degree: 16,
        n_field: 20,
        n_rho: 7,
        n_theta: 16,
        n_ellipses: 11,
        pass_method: PassMethod::AreaEllipses,
        ..Default::default()
    };
    let (rtf, reports) = fit_rtf(&lens, &[550.0], &opts).unwrap();
    for r in &reports {
        println!(
            "degree 16 {}: terms {}, samples {}, dropped {}, condition {:.3e}, rms {:.3e}, max {:.3e}",
            r.output,
            r.n_terms,
            r.n_samples,
            r.n_dropped,
            r.condition_number,
            r.rms_residual,
            r.max_residual
        );
        assert_eq!(r.n_terms, 969);
        assert!(r.condition_number.is_finite() && r.condition_number >= 1.0);
        assert!(r.rms_residual.is_finite() && r.max_residual.is_finite());
    }
    assert!(
        rtf.waves[0]
            .outputs
            .iter()
            .flatten()
            .all(|p| p.coeff.iter().all(|c| c.is_finite()))
    );
    let bfd = lens.paraxial(550.0).unwrap().back_focal_distance_mm;
    let cam = RtfCamera::new(rtf, bfd).unwrap();
    let mut n = 0;
    for i in 0..16 {
        for j in 0..16 {
            let u = glam::DVec2::new((i as f64 + 0.5) / 16.0, (j as f64 + 0.5) / 16.0);
            if let Some(r) = cam.sample_ray(glam::DVec2::new(0.0, 0.02), u, 550.0) {
                assert!(r.origin.is_finite() && r.direction.is_finite() && r.weight.is_finite());
                n += 1;
            }
        }
    }
    assert!(n > 0);
}
