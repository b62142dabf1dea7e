//! Convergence: a figure's standard error against the wall time of each run,
//! and its error against a reference run.
//!
//! For an unbiased Monte Carlo estimator the standard error falls as N^(−½)
//! in the sample count N. Two log–log slopes are fitted, each with its
//! regression standard error (≥ 3 runs): against N (`stderr_samples_slope`,
//! the estimator's own rate, reproducible from the seed) and against the
//! runs' wall time (`stderr_time_slope`, what a user waits for; steeper than
//! the first while a fixed cost per run — label pass, sensor, measurement —
//! is not small beside the render, and it varies with the machine's load).
//! The flag `slope_off_minus_half` tests the sample slope, so the same seed
//! gives the same flag ([`slope_off`]): with independent samples (the
//! `independent` sampler, sensor frames) |b + ½| > t₉₅(n − 2)·se; with the
//! default Sobol sampler, whose scrambled nets converge at least as fast as
//! N^(−½) and often faster, only a slope significantly shallower than −½
//! (b + ½ > t₉₅(n − 2)·se) is flagged. Figures of clipped pixels are always
//! flagged. [`flag_notes`] writes the report's note
//! for a flagged figure with its likely reason. The efficiency 1/(se²·t) (the
//! usual figure of merit, 1/(unit²·s)) compares methods at equal time.

use super::stats::line_fit;
use super::{Curve, Measured};
use crate::figure::Figure;
use crate::params::{Kind, ParamError, ParamSpec};
use crate::{Error, Result};

/// `measure "convergence" of="<measurement>" spp=(…)`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ConvergenceOptions {
    /// Sample counts, strictly increasing, at least two (required).
    pub spp: Vec<u64>,
    /// A reference run's sample count (rendered with the variant's seed).
    pub reference_spp: Option<u64>,
    /// Follow only quantities whose name contains this text.
    pub quantity: Option<String>,
}

/// The properties of `measure "convergence"`.
pub static SCHEMA: crate::params::Schema = crate::params::Schema {
    node: "measure \"convergence\"",
    params: &[
        super::shared_params::name_param(),
        super::shared_params::of_param(
            "the measurement whose figures are followed (required; one): a rendered one (sfr, mcc, profile, noise, ri), a compare-curve of one (re-measured and compared per run), or the sensor-only conversion-gain (spp then counts frames)",
            "\"sfr-near\"",
        ),
        ParamSpec {
            name: "spp",
            kind: Kind::Numbers,
            default: "",
            doc: "samples per pixel of the runs (frames for conversion-gain), at least two, strictly increasing (required; ≥ 3 for a slope uncertainty); run k uses seed render.seed + 1 + k",
            example: "(8 32)",
        },
        ParamSpec {
            name: "reference-spp",
            kind: Kind::Integer,
            default: "none",
            doc: "samples per pixel (frames) of a reference run (the variant's seed), run first; adds each figure's error against it, and the other runs take its exposure time",
            example: "512",
        },
        ParamSpec {
            name: "quantity",
            kind: Kind::Text,
            default: "all",
            doc: "follow only quantities whose name contains this text (e.g. \"mtf50\")",
            example: "\"mtf50\"",
        },
    ],
};

/// Read `measure "convergence"` (see [`SCHEMA`]).
pub fn from_params(
    d: &crate::params::ParamDict,
) -> std::result::Result<ConvergenceOptions, ParamError> {
    let help = "e.g. spp=(16 64 256): at least two increasing sample counts";
    let spp = match d.f64s("spp")? {
        None => vec![],
        Some(v) => {
            if v.iter().any(|x| x.fract() != 0.0 || *x < 1.0 || *x > 1e9) {
                return Err(ParamError::value(
                    "spp",
                    "'spp': expected whole sample counts 1 … 1000000000",
                )
                .with_help(help));
            }
            let s: Vec<u64> = v.iter().map(|x| *x as u64).collect();
            if s.len() < 2 || s.windows(2).any(|w| w[1] <= w[0]) {
                return Err(ParamError::value(
                    "spp",
                    "'spp': expected at least two strictly increasing sample counts",
                )
                .with_help(help));
            }
            s
        }
    };
    Ok(ConvergenceOptions {
        spp,
        reference_spp: d.int("reference-spp", 1, 1_000_000_000)?,
        quantity: super::shared_params::nonempty(d, "quantity")?,
    })
}

/// One run of the same figure at some sample count.
#[derive(Clone, Debug, PartialEq)]
pub struct Run {
    /// Wall time of the whole run (render with its label pass, sensor,
    /// measurement; or the frames' synthesis and measurement), s.
    pub wall_s: f64,
    /// Its sample count: samples per pixel of a render, or frames of a
    /// sensor-only measurement (`conversion-gain`).
    pub samples: f64,
    pub value: f64,
    pub stderr: f64,
}

/// Two-sided 95 % quantile of Student's t with `dof` degrees of freedom
/// (standard tables; 1.96 beyond 30). A slope fitted through n points has
/// n − 2: with 3 runs its regression standard error rests on one residual,
/// and a 2·se test would flag about 30 % of unbiased estimators.
pub fn t95(dof: usize) -> f64 {
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match dof {
        0 => f64::INFINITY,
        d if d <= 30 => T[d - 1],
        _ => 1.96,
    }
}

/// How a figure's standard error should fall with the sample count N.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorLaw {
    /// Independent samples (the independent sampler, sensor frames):
    /// exactly ∝ N^(−½).
    InverseSqrt,
    /// Scrambled nets (the Sobol sampler, `render::sampler`): at least as
    /// fast as N^(−½) — Owen (1997) — and faster for smooth integrands; a
    /// figure that also carries independent noise (the sensor's) falls
    /// between the two rates.
    AtLeastInverseSqrt,
}

/// Whether a fitted slope `b ± se` from `n` runs is off the law: no
/// uncertainty (fewer than 3 runs, or an exact fit) always is; otherwise
/// |b + ½| > t₉₅(n − 2)·se for `InverseSqrt`, and b + ½ > t₉₅(n − 2)·se
/// (falling significantly slower than N^(−½)) for `AtLeastInverseSqrt`.
pub fn slope_off(b: f64, se: f64, n: usize, law: ErrorLaw) -> bool {
    if !(b.is_finite() && se.is_finite() && se > 0.0 && n >= 3) {
        return true;
    }
    let excess = match law {
        ErrorLaw::InverseSqrt => (b + 0.5).abs(),
        ErrorLaw::AtLeastInverseSqrt => b + 0.5,
    };
    excess > t95(n - 2) * se
}

/// Figures a run's wall time enters (not reproducible from the seed: they
/// vary with the machine's load). Everything else convergence reports is
/// bit-identical for the same inputs and seed.
pub fn depends_on_wall_time(quantity: &str) -> bool {
    [
        "/wall_s",
        "/stderr_time_slope",
        "/efficiency",
        "fixed_cost_s",
    ]
    .iter()
    .any(|s| quantity.ends_with(s))
}

/// The convergence figures and curves of one quantity. `clipped`: the largest
/// fraction of clipped pixels over the runs (an MCC patch channel at the
/// white level or the ADC floor); such a figure is fitted and flagged, but
/// gets no efficiency. `reference`: (value, standard error) of a reference run.
pub fn convergence(
    runs: &[Run],
    reference: Option<(f64, f64)>,
    quantity: &str,
    unit: &str,
    measurement: &str,
    clipped: f64,
    law: ErrorLaw,
) -> Result<Measured> {
    let mut ok: Vec<&Run> = runs
        .iter()
        .filter(|r| r.wall_s > 0.0 && r.samples > 0.0 && r.stderr > 0.0 && r.value.is_finite())
        .collect();
    // The curves run along the time axis (a small run can take longer than a
    // larger one when the fixed cost per run dominates).
    ok.sort_by(|a, b| a.wall_s.total_cmp(&b.wall_s));
    if ok.len() < 2 {
        return Err(Error::invalid(format!(
            "convergence of '{quantity}' needs ≥ 2 runs with positive time and standard error"
        )));
    }
    let fig = |q: &str, u: &str, v: f64, se: f64| {
        Figure::new(measurement, format!("{quantity}/{q}"), u, v, se)
    };
    let ls: Vec<f64> = ok.iter().map(|r| r.stderr.ln()).collect();
    let fit = |x: Vec<f64>| line_fit(&x, &ls).map(|(_, b, _, sb)| (b, sb));
    let by_time = fit(ok.iter().map(|r| r.wall_s.ln()).collect());
    let by_samples = fit(ok.iter().map(|r| r.samples.ln()).collect());
    let mut figures = vec![];
    if let Some((b, sb)) = by_time {
        figures.push(fig("stderr_time_slope", "1", b, sb));
    }
    let (b, sb) = by_samples.unwrap_or((f64::NAN, f64::NAN));
    if by_samples.is_some() {
        figures.push(fig("stderr_samples_slope", "1", b, sb));
    }
    // Clipped pixels make the standard error a measure of the clipping, not
    // of the Monte Carlo noise: always flagged, whatever the slope.
    let off = clipped > 0.0 || slope_off(b, sb, ok.len(), law);
    figures.push(fig(
        "slope_off_minus_half",
        "1",
        f64::from(u8::from(off)),
        0.0,
    ));
    let longest = ok
        .iter()
        .max_by(|a, b| a.samples.total_cmp(&b.samples))
        .copied()
        .unwrap_or(ok[0]);
    if clipped > 0.0 {
        figures.push(fig("clipped_fraction", "1", clipped, 0.0));
    } else {
        figures.push(fig(
            "efficiency",
            &format!("1/({unit}^2*s)"),
            1.0 / (longest.stderr.powi(2) * longest.wall_s),
            0.0,
        ));
    }
    let legend = match (by_samples, by_time) {
        (Some((b, sb)), Some((bt, sbt))) => format!(
            "{quantity}: slope {} ± {} per sample, {} ± {} per s{}",
            round2(b),
            round2(sb),
            round2(bt),
            round2(sbt),
            match (off, law) {
                (false, _) => "",
                (true, ErrorLaw::InverseSqrt) => " (not −½)",
                (true, ErrorLaw::AtLeastInverseSqrt) => " (slower than −½)",
            }
        ),
        _ => format!("{quantity}: too few runs for a slope"),
    };
    let t: Vec<f64> = ok.iter().map(|r| r.wall_s).collect();
    let mut curves = vec![Curve::new(
        &format!("stderr_vs_time#{legend}"),
        ("wall time", "s"),
        ("standard error", unit),
        t.clone(),
        ok.iter().map(|r| r.stderr).collect(),
        vec![],
    )];
    if let Some((rv, rse)) = reference {
        let err: Vec<f64> = ok.iter().map(|r| (r.value - rv).abs()).collect();
        let d = (longest.value - rv).abs();
        figures.push(fig("error_at_longest", unit, d, longest.stderr));
        // The longest run against the reference in their combined standard
        // errors: > 3 says the figure converges to something else (bias).
        // A z-score: its own spread between seeds is 1 (its standard error).
        let se = longest.stderr.hypot(rse);
        figures.push(fig(
            "error_z",
            "1",
            if se > 0.0 { d / se } else { f64::INFINITY },
            1.0,
        ));
        curves.push(Curve::new(
            &format!("error_vs_time#{quantity}"),
            ("wall time", "s"),
            ("|error| against the reference", unit),
            t,
            err,
            ok.iter().map(|r| r.stderr).collect(),
        ));
    }
    Ok(Measured {
        figures,
        curves,
        pixels_read: vec![],
    })
}

fn round2(x: f64) -> String {
    format!("{:.2}", x).replace('-', "−")
}

/// The report's convergence notes of one variant from its rows (quantity,
/// value, standard error): one line per quantity whose slope is flagged
/// (`<q>/slope_off_minus_half` = 1), naming the slope and the likely reason.
pub fn flag_notes(rows: &[(String, f64, f64)]) -> Vec<String> {
    let get = |q: &str, f: &str| {
        let name = format!("{q}/{f}");
        rows.iter().find(|r| r.0 == name).map(|r| (r.1, r.2))
    };
    let mut out = vec![];
    let s = |x: Option<(f64, f64)>| {
        x.map_or("—".to_string(), |(b, se)| {
            format!("{} ± {}", round2(b), round2(se))
        })
    };
    for (name, v, _) in rows {
        let Some(q) = name.strip_suffix("/slope_off_minus_half") else {
            continue;
        };
        if *v != 1.0 {
            // a slope of −½ that converges to something else than the reference
            if let Some((z, _)) = get(q, "error_z").filter(|z| z.0 > 3.0) {
                out.push(format!(
                    "Convergence: {q} — standard error ∝ N^({}), consistent with −½, but the longest run differs from the reference by {z:.1} combined standard errors (biased).",
                    s(get(q, "stderr_samples_slope"))
                ));
            }
            continue;
        }
        let slope = get(q, "stderr_samples_slope");
        let time = get(q, "stderr_time_slope");
        let clipped = get(q, "clipped_fraction").map_or(0.0, |c| c.0);
        let z = get(q, "error_z").map(|c| c.0);
        let mut why = match slope {
            None => "too few runs: a slope and its uncertainty need ≥ 3 sample counts".to_string(),
            Some(_) if clipped > 0.0 => format!(
                "clipped pixels (up to {:.1} % of the region in a run): their spread shrinks with the noise, not as N^−½",
                clipped * 100.0
            ),
            Some((b, _)) if b > -0.5 => "the standard error falls slower than N^−½: part of it does not fall with samples (the sensor's own noise, drawn afresh each run; a statistic limited by a region or frame count; or a bias)".to_string(),
            Some(_) => "the standard error falls faster than N^−½ (clipping or quantisation, or an error estimate that is not a Monte Carlo one)".to_string(),
        };
        if let Some(z) = z.filter(|z| *z > 3.0) {
            why.push_str(&format!(
                "; the longest run differs from the reference by {:.1} combined standard errors (biased)",
                z
            ));
        }
        out.push(format!(
            "Convergence: {q} — standard error ∝ N^({}) per sample, t^({}) per wall-clock second{}: {why}.",
            s(slope),
            s(time),
            if clipped > 0.0 && !slope.is_some_and(|(b, se)| (b + 0.5).abs() > 2.0 * se) {
                ""
            } else {
                ", not −½"
            }
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn inverse_sqrt_time_gives_slope_minus_half() {
        let runs: Vec<Run> = [1.0, 4.0, 16.0, 64.0]
            .iter()
            .map(|&t| Run {
                wall_s: t,
                samples: 8.0 * t,
                value: 1.0,
                stderr: 0.1 / f64::sqrt(t),
            })
            .collect();
        let m = convergence(
            &runs,
            Some((1.0, 0.0)),
            "mtf50",
            "cy/px",
            "conv",
            0.0,
            ErrorLaw::InverseSqrt,
        )
        .unwrap();
        let get = |q: &str| m.figures.iter().find(|f| f.quantity == q).unwrap().value;
        assert!((get("mtf50/stderr_time_slope") + 0.5).abs() < 1e-12);
        assert!((get("mtf50/stderr_samples_slope") + 0.5).abs() < 1e-12);
        // exactly −½ (a regression se at rounding level): not flagged
        assert_eq!(get("mtf50/slope_off_minus_half"), 0.0);
        // efficiency at the longest run: 1/(se²·t) = 1/(0.1²/64 · 64)
        assert!((get("mtf50/efficiency") - 100.0).abs() < 1e-9);
    }

    #[test]
    fn t_test_flags_only_a_slope_off_minus_half() {
        // −0.45 ± 0.02 from 5 runs: |0.05| < 3.182·0.02 = 0.064, not flagged;
        // −0.9 ± 0.05 from 4 runs: 0.4 > 4.303·0.05 = 0.215, flagged.
        let law = ErrorLaw::InverseSqrt;
        assert!(!slope_off(-0.45, 0.02, 5, law));
        assert!(slope_off(-0.9, 0.05, 4, law));
        // 3 runs: t = 12.706, so −0.9 ± 0.05 (0.4 < 0.635) is not flagged
        assert!(!slope_off(-0.9, 0.05, 3, law));
        assert!(slope_off(-0.5, 0.0, 4, law) && slope_off(-0.5, 0.1, 2, law));
        assert_eq!(t95(40), 1.96);
        // Scrambled nets: only a slope significantly shallower than −½ is off.
        let nets = ErrorLaw::AtLeastInverseSqrt;
        assert!(!slope_off(-0.9, 0.05, 4, nets));
        assert!(!slope_off(-0.45, 0.02, 5, nets));
        assert!(slope_off(-0.2, 0.05, 4, nets)); // 0.3 > 4.303·0.05
        assert!(slope_off(-0.9, 0.0, 4, nets) && slope_off(-0.9, 0.1, 2, nets));
    }

    #[test]
    fn flag_notes_name_the_reason() {
        let rows = |b: f64, clipped: Option<f64>| {
            let mut r = vec![
                ("p/stderr_samples_slope".to_string(), b, 0.02),
                ("p/stderr_time_slope".to_string(), b, 0.03),
                ("p/slope_off_minus_half".to_string(), 1.0, 0.0),
                ("p/error_z".to_string(), 5.0, 0.0),
            ];
            if let Some(c) = clipped {
                r.push(("p/clipped_fraction".to_string(), c, 0.0));
            }
            r
        };
        let n = flag_notes(&rows(-1.0, Some(0.25)));
        assert_eq!(n.len(), 1);
        assert!(
            n[0].contains("clipped pixels (up to 25.0 %") && n[0].contains("biased"),
            "{n:?}"
        );
        assert!(flag_notes(&rows(-0.1, None))[0].contains("slower than N^−½"));
        assert!(flag_notes(&rows(-0.9, None))[0].contains("faster than N^−½"));
        let mut ok = rows(-0.5, None);
        ok[2].1 = 0.0;
        assert!(
            flag_notes(&ok)[0].contains("consistent with −½, but")
                && flag_notes(&ok)[0].contains("5.0 combined")
        );
        ok[3].1 = 1.0;
        assert!(flag_notes(&ok).is_empty());
    }
}
