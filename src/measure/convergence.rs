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
use crate::{Error, Result};

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
