//! Stability cases of the ray-transfer function: an RTF evaluated beyond
//! the field it was fitted on, and fits of near-singular (degenerate,
//! collinear, non-finite, too few) samples. The RTF is fitted by the
//! project's own least squares ([`crate::optics::fit::fit_polys`]) to an
//! analytic lens — a slab of free space of thickness T followed by an ideal
//! thin lens of focal length f at the output plane:
//! position p' = p + T·d⊥/d_z, direction d'⊥ = d⊥ − p'/f — and evaluated by
//! [`crate::optics::rtf::Rtf::transfer`], the RTF camera's ray mapping.

use super::Check;
use crate::optics::fit::{Sample, fit_polys, monomials};
use crate::optics::rtf::{Circles, PassNoPass, Rtf, RtfWave};
use crate::{Error, Result};
use glam::DVec3;

const T_MM: f64 = 5.0;
const F_MM: f64 = 20.0;
/// The fitted field: input radii 0 … R_MAX mm, directions |d⊥| ≤ D_MAX.
const R_MAX: f64 = 2.0;
const D_MAX: f64 = 0.2;
const DEGREE: usize = 5;

/// The analytic lens in the RTF's rotated frame (input point (0, r)):
/// outx, outy, outdx, outdy, outdz.
fn exact(r: f64, dx: f64, dy: f64) -> [f64; 5] {
    let dz = (1.0 - dx * dx - dy * dy).sqrt();
    let (x, y) = (T_MM * dx / dz, r + T_MM * dy / dz);
    let (ax, ay) = (dx - x / F_MM, dy - y / F_MM);
    [x, y, ax, ay, (1.0 - ax * ax - ay * ay).sqrt()]
}

fn lin(n: usize, a: f64, b: f64) -> impl Iterator<Item = f64> {
    (0..n).map(move |i| a + (b - a) * i as f64 / (n - 1) as f64)
}

fn samples() -> Vec<Sample> {
    let mut v = vec![];
    for r in lin(9, 0.0, R_MAX) {
        for dx in lin(9, -D_MAX, D_MAX) {
            for dy in lin(9, -D_MAX, D_MAX) {
                v.push(([r, dx, dy], exact(r, dx, dy)));
            }
        }
    }
    v
}

/// The fitted RTF (one wavelength), its largest training residuals
/// (position mm, direction) and the pass region's input-radius limit.
fn fitted(limit: Option<f64>) -> Result<(Rtf, f64, f64)> {
    let data = samples();
    let (outputs, reports) = fit_polys(&data, &vec![1.0; data.len()], DEGREE, 550.0, "analytic")?;
    let res = |names: &[&str]| {
        reports
            .iter()
            .filter(|r| names.contains(&r.output.as_str()))
            .map(|r| r.max_residual)
            .fold(0.0, f64::max)
    };
    let wave = RtfWave {
        wavelength_nm: 550.0,
        outputs,
        pass: PassNoPass::Circles(Circles {
            // one huge circle: the limit on the input radius is the only stop
            radii_mm: vec![if limit.is_some() {
                1e6
            } else {
                f64::MAX.sqrt()
            }],
            sensitivities: vec![0.0],
            plane_distance_mm: 1.0,
            max_input_radius_mm: limit,
        }),
    };
    let rtf = Rtf {
        name: "analytic".into(),
        description: "slab + ideal thin lens".into(),
        thickness_mm: T_MM,
        plane_offset_input_mm: 0.0,
        plane_offset_output_mm: 0.0,
        waves: vec![wave],
    };
    Ok((rtf, res(&["outx", "outy"]), res(&["outdx", "outdy"])))
}

/// A ray given by input radius r, azimuth ψ and direction (dx, dy) in the
/// rotated frame, in the RTF's world frame.
fn ray(r: f64, psi: f64, dx: f64, dy: f64) -> (f64, f64, DVec3) {
    let (s, c) = psi.sin_cos();
    // rotated frame: input point on +y; world = rotate by ψ
    let (x, y) = (r * s, r * c);
    let (wx, wy) = (dx * c + dy * s, -dx * s + dy * c);
    let dz = (1.0 - dx * dx - dy * dy).sqrt();
    (x, y, DVec3::new(wx, wy, dz))
}

/// `rtf-beyond-field`: inside its fitted field (radii and directions between
/// the fit's samples, at eight azimuths) the RTF must pass every ray and
/// agree with the analytic lens; beyond it (1.01 … 10⁶ × the field radius,
/// and NaN/∞ inputs) it must refuse every ray (the pass region's input-
/// radius limit) — and with no limit, evaluating the polynomials far out
/// must give finite rays or a refusal, never a non-finite ray.
///
/// Tolerance inside: 10 × the fit's largest training residual. Between the
/// samples of a smooth map, a least-squares polynomial's error is of the
/// order of its residual at the samples (the map's next Taylor terms);
/// 10× leaves room for the interpolation, and an evaluation bug (a wrong
/// rotation, a swapped output) is of the order of the ray itself (≥ 10⁻²).
/// Refusals and non-finite rays are exact counts.
pub fn beyond_field() -> Result<Vec<Check>> {
    let (rtf, res_p, res_d) = fitted(Some(R_MAX))?;
    let w = &rtf.waves[0];
    let (mut refused, mut n_in, mut err_p, mut err_d) = (0usize, 0usize, 0.0f64, 0.0f64);
    let mut nonfinite = 0usize;
    for r in lin(8, 0.5 * R_MAX / 8.0, R_MAX * (1.0 - 0.5 / 8.0)) {
        for dx in lin(4, -0.75 * D_MAX, 0.75 * D_MAX) {
            for dy in lin(4, -0.65 * D_MAX, 0.85 * D_MAX) {
                for k in 0..8 {
                    let psi = k as f64 * std::f64::consts::FRAC_PI_4 + 0.1;
                    let (x, y, d) = ray(r, psi, dx, dy);
                    n_in += 1;
                    let Some((p, od)) = rtf.transfer(w, x, y, d) else {
                        refused += 1;
                        continue;
                    };
                    if !(p.is_finite() && od.is_finite()) {
                        nonfinite += 1;
                        continue;
                    }
                    let e = exact(r, dx, dy);
                    // rotate the exact rotated-frame answer to the world frame
                    let (s, c) = psi.sin_cos();
                    let (ex, ey) = (e[0] * c + e[1] * s, -e[0] * s + e[1] * c);
                    let (edx, edy) = (e[2] * c + e[3] * s, -e[2] * s + e[3] * c);
                    err_p = err_p.max((p.x - ex).abs()).max((p.y - ey).abs());
                    err_d = err_d.max((od.x - edx).abs()).max((od.y - edy).abs());
                }
            }
        }
    }
    let at_in = format!("{n_in} rays inside the fitted field (r < {R_MAX} mm, |d⊥| < {D_MAX})");
    let mut checks = vec![
        Check::count("inside/refused", refused, 0, &at_in),
        Check::count("inside/nonfinite", nonfinite, 0, &at_in),
        Check::new(
            "inside/position_error_over_field",
            err_p / R_MAX,
            0.0,
            10.0 * res_p / R_MAX,
            &at_in,
        ),
        Check::new("inside/direction_error", err_d, 0.0, 10.0 * res_d, &at_in),
    ];
    let far = [1.01, 1.5, 2.0, 10.0, 1e3, 1e6, 1e200];
    let mut passed = 0usize;
    let mut n_far = 0usize;
    for k in far {
        for (dx, dy) in [(0.0, 0.0), (0.1, -0.1), (-0.15, 0.05)] {
            let (x, y, d) = ray(k * R_MAX, 0.3, dx, dy);
            n_far += 1;
            if rtf.transfer(w, x, y, d).is_some() {
                passed += 1;
            }
        }
    }
    for (x, y) in [
        (f64::NAN, 0.0),
        (0.0, f64::INFINITY),
        (f64::NEG_INFINITY, f64::NAN),
    ] {
        n_far += 1;
        if rtf.transfer(w, x, y, DVec3::Z).is_some() {
            passed += 1;
        }
    }
    checks.push(Check::count(
        "beyond/not_refused",
        passed,
        0,
        &format!("{n_far} rays at 1.01 … 1e200 × the field radius and with NaN/∞ inputs"),
    ));
    // no input-radius limit: the polynomials extrapolate
    let (free, _, _) = fitted(None)?;
    let wf = &free.waves[0];
    let mut bad = 0usize;
    let mut n_free = 0usize;
    for k in far {
        for (dx, dy) in [(0.0, 0.0), (0.1, -0.1), (-0.15, 0.05), (0.5, 0.5)] {
            let (x, y, d) = ray(k * R_MAX, 1.1, dx, dy);
            n_free += 1;
            if let Some((p, od)) = free.transfer(wf, x, y, d)
                && !(p.is_finite() && od.is_finite() && (od.length() - 1.0).abs() < 1e-9)
            {
                bad += 1;
            }
        }
    }
    checks.push(Check::count(
        "unlimited/nonfinite_rays",
        bad,
        0,
        &format!("{n_free} rays far outside the field with no input-radius limit"),
    ));
    Ok(checks)
}

/// One near-singular fit: 1 when it ends cleanly (an error that says why,
/// or finite coefficients that report the dropped terms and give finite
/// rays at `probe` points), 0 otherwise; and the explanation.
fn clean_fit(data: &[Sample], probe: &[[f64; 3]], must_fail: bool) -> (usize, String) {
    match fit_polys(data, &vec![1.0; data.len()], DEGREE, 550.0, "degenerate") {
        Err(e) => {
            let msg = e.to_string();
            ((!msg.trim().is_empty()) as usize, format!("refused: {msg}"))
        }
        Ok(_) if must_fail => (0, "accepted samples it must refuse".into()),
        Ok((outputs, reports)) => {
            let polys: Vec<_> = outputs.iter().flatten().collect();
            let coeff_ok = polys.iter().all(|p| p.coeff.iter().all(|c| c.is_finite()));
            let dropped = reports.iter().map(|r| r.n_dropped).max().unwrap_or(0);
            let eval_ok = probe
                .iter()
                .all(|q| polys.iter().all(|p| p.eval(q[0], q[1], q[2]).is_finite()));
            let ok = coeff_ok && eval_ok && dropped > 0;
            (
                ok as usize,
                format!(
                    "fitted: {dropped} of {} terms dropped, coefficients {}, rays {}",
                    monomials(DEGREE).len(),
                    if coeff_ok { "finite" } else { "NOT finite" },
                    if eval_ok { "finite" } else { "NOT finite" }
                ),
            )
        }
    }
}

/// `rtf-singular-fit`: fits of samples that do not determine the
/// polynomials. Each must end cleanly — a clear error, or a regularised
/// (rank-reduced) finite fit that says how many terms it dropped — never a
/// NaN coefficient:
/// - degenerate: every sample the same ray (rank 1);
/// - collinear: samples on one line through (r, dx, dy) space;
/// - a NaN sample among good ones (must be refused);
/// - fewer samples than twice the terms (must be refused).
///
/// A degenerate fit must also reproduce its one sample: the kept column
/// fits it exactly, so the residual is f64 rounding (≈ 10⁻¹⁵ relative);
/// tolerance 10⁻⁹ relative.
pub fn singular_fit() -> Result<Vec<Check>> {
    let terms = monomials(DEGREE).len();
    let probe: Vec<[f64; 3]> = vec![[0.0, 0.0, 0.0], [1.0, 0.1, -0.1], [R_MAX, D_MAX, D_MAX]];
    let one = ([0.5, 0.1, 0.0], exact(0.5, 0.1, 0.0));
    let degenerate = vec![one; 2 * terms + 3];
    let collinear: Vec<Sample> = lin(4 * terms, 0.0, R_MAX)
        .map(|r| {
            let (dx, dy) = (0.05 * r, -0.02 * r);
            ([r, dx, dy], exact(r, dx, dy))
        })
        .collect();
    let mut with_nan = samples();
    with_nan[17].0[1] = f64::NAN;
    let few: Vec<Sample> = samples().into_iter().take(2 * terms - 1).collect();
    let mut checks = vec![];
    for (tag, data, must_fail) in [
        ("degenerate", &degenerate, false),
        ("collinear", &collinear, false),
        ("nan-sample", &with_nan, true),
        ("too-few-samples", &few, true),
    ] {
        let (ok, why) = clean_fit(data, &probe, must_fail);
        checks.push(Check::new(
            &format!("{tag}/ended_cleanly"),
            ok as f64,
            1.0,
            0.0,
            &format!("{} samples: {why}", data.len()),
        ));
    }
    // the degenerate fit reproduces its sample
    let (outputs, _) = fit_polys(
        &degenerate,
        &vec![1.0; degenerate.len()],
        DEGREE,
        550.0,
        "d",
    )
    .map_err(|e| Error::invalid(format!("rtf-singular-fit: degenerate fit: {e}")))?;
    let (q, want) = one;
    let mut worst = 0.0f64;
    for (k, p) in [0usize, 1, 3, 4, 5].iter().zip(0..5) {
        if let Some(poly) = &outputs[*k] {
            let got = poly.eval(q[0], q[1], q[2]);
            worst = worst.max((got - want[p]).abs() / want[p].abs().max(1e-3));
        } else {
            worst = f64::NAN;
        }
    }
    checks.push(Check::new(
        "degenerate/relative_residual",
        worst,
        0.0,
        1e-9,
        "the one sample the degenerate fit was given",
    ));
    Ok(checks)
}
