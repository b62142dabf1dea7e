//! Convergence: a figure's Monte Carlo standard error against render time,
//! and its error against a high-spp reference.
//!
//! For a Monte Carlo estimator the standard error falls as t^(−½); the fitted
//! log–log slope (with its regression standard error) checks that, and the
//! efficiency 1/(se²·t) (the usual figure of merit, 1/(unit²·s)) compares
//! methods at equal time. The slope needs ≥ 3 runs (its standard error comes
//! from the regression residuals); the efficiency is reported without one.

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
            "the rendered measurement (sfr, mcc, profile, noise or ri) whose figures are followed (required; one)",
            "\"sfr-near\"",
        ),
        ParamSpec {
            name: "spp",
            kind: Kind::Numbers,
            default: "",
            doc: "samples per pixel of the runs, at least two, strictly increasing (required); run k uses seed render.seed + 1 + k",
            example: "(8 32)",
        },
        ParamSpec {
            name: "reference-spp",
            kind: Kind::Integer,
            default: "none",
            doc: "samples per pixel of a reference run (the variant's seed); adds each figure's error against it",
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
    pub render_s: f64,
    pub value: f64,
    pub stderr: f64,
}

pub fn convergence(
    runs: &[Run],
    reference: Option<f64>,
    quantity: &str,
    unit: &str,
    measurement: &str,
) -> Result<Measured> {
    let ok: Vec<&Run> = runs
        .iter()
        .filter(|r| r.render_s > 0.0 && r.stderr > 0.0 && r.value.is_finite())
        .collect();
    if ok.len() < 2 {
        return Err(Error::invalid(format!(
            "convergence of '{quantity}' needs ≥ 2 runs with positive time and standard error"
        )));
    }
    let lt: Vec<f64> = ok.iter().map(|r| r.render_s.ln()).collect();
    let ls: Vec<f64> = ok.iter().map(|r| r.stderr.ln()).collect();
    let mut figures = vec![];
    if let Some((_, b, _, sb)) = line_fit(&lt, &ls) {
        figures.push(Figure::new(
            measurement,
            format!("{quantity}/stderr_time_slope"),
            "1",
            b,
            sb,
        ));
    }
    let longest = ok
        .iter()
        .max_by(|a, b| a.render_s.total_cmp(&b.render_s))
        .copied()
        .unwrap_or(ok[0]);
    figures.push(Figure::new(
        measurement,
        format!("{quantity}/efficiency"),
        &format!("1/({unit}^2*s)"),
        1.0 / (longest.stderr.powi(2) * longest.render_s),
        0.0,
    ));
    let t: Vec<f64> = ok.iter().map(|r| r.render_s).collect();
    let mut curves = vec![Curve::new(
        "stderr_vs_time",
        ("render time", "s"),
        ("standard error", unit),
        t.clone(),
        ok.iter().map(|r| r.stderr).collect(),
        vec![],
    )];
    if let Some(rv) = reference {
        let err: Vec<f64> = ok.iter().map(|r| (r.value - rv).abs()).collect();
        // Within-error agreement of the longest run with the reference, in its standard errors.
        figures.push(Figure::new(
            measurement,
            format!("{quantity}/error_at_longest"),
            unit,
            (longest.value - rv).abs(),
            longest.stderr,
        ));
        curves.push(Curve::new(
            "error_vs_time",
            ("render time", "s"),
            ("|error|", unit),
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

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn inverse_sqrt_time_gives_slope_minus_half() {
        let runs: Vec<Run> = [1.0, 4.0, 16.0, 64.0]
            .iter()
            .map(|&t| Run {
                render_s: t,
                value: 1.0,
                stderr: 0.1 / f64::sqrt(t),
            })
            .collect();
        let m = convergence(&runs, Some(1.0), "mtf50", "cy/px", "conv").unwrap();
        assert!((m.figures[0].value + 0.5).abs() < 1e-12);
        assert!((m.figures[1].value - 100.0).abs() < 1e-9);
    }
}
