//! Simulated against reference (measured) values, e.g. MCC RGB means:
//! scatter, RMSE, mean absolute percentage error and the least-squares slope through the
//! origin (1 when simulation and reference agree up to noise).
//!
//! Standard errors: the RMSE's from the per-pair squared errors
//! (√ of the standard error of their mean, by the delta method); the mean
//! absolute % error's as std/√n; the slope's from the residuals.

use super::stats::{mean, std_dev};
use super::{Curve, Measured};
use crate::figure::Figure;
use crate::params::{Kind, ParamError, ParamSpec};
use crate::{Error, Result};

/// `measure "compare" of="<simulated>" reference="<measured>"`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CompareOptions {
    /// The measurement compared against (required).
    pub reference: Option<String>,
    /// Keep only quantities containing this text.
    pub quantity: Option<String>,
    /// Divide each side by its mean over the pairs first (compare shapes).
    pub normalize_mean: bool,
}

/// The properties of `measure "compare"`.
pub static SCHEMA: crate::params::Schema = crate::params::Schema {
    node: "measure \"compare\"",
    params: &[
        super::shared_params::name_param(),
        super::shared_params::of_param(
            "the (simulated) measurement whose figures are compared (required; one)",
            "\"mcc-far\"",
        ),
        ParamSpec {
            name: "reference",
            kind: Kind::Text,
            default: "",
            doc: "the measurement compared against, e.g. one of a captured image (required); figures pair by quantity name and unit",
            example: "\"mcc-measured\"",
        },
        ParamSpec {
            name: "quantity",
            kind: Kind::Text,
            default: "all",
            doc: "keep only quantities whose name contains this text (e.g. \"_mean\")",
            example: "\"/g_mean\"",
        },
        ParamSpec {
            name: "normalize",
            kind: Kind::Choice(&["none", "mean"]),
            default: "none",
            doc: "\"mean\" divides each side by its mean over the pairs first (compares shapes, not exposure)",
            example: "\"mean\"",
        },
    ],
};

/// Read `measure "compare"` (see [`SCHEMA`]).
pub fn from_params(
    d: &crate::params::ParamDict,
) -> std::result::Result<CompareOptions, ParamError> {
    Ok(CompareOptions {
        reference: super::shared_params::nonempty(d, "reference")?,
        quantity: super::shared_params::nonempty(d, "quantity")?,
        normalize_mean: d.choice("normalize")? == Some("mean"),
    })
}

/// One compared value: name (e.g. "patch04/g"), simulated, reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Pair {
    pub name: String,
    pub simulated: f64,
    pub reference: f64,
}

/// Match simulated and reference values by name (names missing on either side are an error).
pub fn pair_by_name(sim: &[(String, f64)], reference: &[(String, f64)]) -> Result<Vec<Pair>> {
    sim.iter()
        .map(|(n, s)| {
            reference
                .iter()
                .find(|r| &r.0 == n)
                .map(|r| Pair {
                    name: n.clone(),
                    simulated: *s,
                    reference: r.1,
                })
                .ok_or_else(|| {
                    Error::invalid(format!(
                        "'{n}' has a simulated value but no reference value"
                    ))
                })
        })
        .collect()
}

pub fn compare(pairs: &[Pair], unit: &str, measurement: &str) -> Result<Measured> {
    let n = pairs.len();
    if n < 2 {
        return Err(Error::invalid(
            "comparison needs at least 2 simulated/reference pairs",
        ));
    }
    if pairs
        .iter()
        .any(|p| !p.simulated.is_finite() || !p.reference.is_finite())
    {
        return Err(Error::invalid("comparison: non-finite value"));
    }
    let sq: Vec<f64> = pairs
        .iter()
        .map(|p| (p.simulated - p.reference).powi(2))
        .collect();
    let mse = mean(&sq);
    let rmse = mse.sqrt();
    let se_mse = std_dev(&sq) / (n as f64).sqrt();
    let se_rmse = if rmse > 0.0 {
        se_mse / (2.0 * rmse)
    } else {
        0.0
    };
    let pct: Vec<f64> = pairs
        .iter()
        .filter(|p| p.reference != 0.0)
        .map(|p| 100.0 * (p.simulated - p.reference).abs() / p.reference.abs())
        .collect();
    let sxx: f64 = pairs.iter().map(|p| p.reference * p.reference).sum();
    let ref_mean = mean(&pairs.iter().map(|p| p.reference).collect::<Vec<_>>()).abs();
    let mut figures = vec![
        Figure::new(measurement, "rmse", unit, rmse, se_rmse),
        Figure::new(
            measurement,
            "rmse_pct_of_mean",
            "%",
            100.0 * rmse / ref_mean,
            100.0 * se_rmse / ref_mean,
        ),
    ];
    if !pct.is_empty() {
        figures.push(Figure::new(
            measurement,
            "mean_abs_pct_error",
            "%",
            mean(&pct),
            std_dev(&pct) / (pct.len() as f64).sqrt(),
        ));
    }
    if sxx > 0.0 {
        let b = pairs.iter().map(|p| p.reference * p.simulated).sum::<f64>() / sxx;
        let s2 = pairs
            .iter()
            .map(|p| (p.simulated - b * p.reference).powi(2))
            .sum::<f64>()
            / (n - 1) as f64;
        figures.push(Figure::new(measurement, "slope", "1", b, (s2 / sxx).sqrt()));
    }
    let curves = vec![Curve::new(
        "scatter",
        ("reference", unit),
        ("simulated", unit),
        pairs.iter().map(|p| p.reference).collect(),
        pairs.iter().map(|p| p.simulated).collect(),
        vec![],
    )];
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
    fn rmse_pct_and_slope() {
        let pairs: Vec<Pair> = [(100.0, 110.0), (200.0, 220.0), (300.0, 330.0)]
            .iter()
            .enumerate()
            .map(|(i, &(r, s))| Pair {
                name: format!("{i}"),
                simulated: s,
                reference: r,
            })
            .collect();
        let m = compare(&pairs, "DV", "cmp").unwrap();
        let get = |q: &str| m.figures.iter().find(|f| f.quantity == q).unwrap().value;
        assert!((get("rmse") - (1400.0f64 / 3.0).sqrt() * 1.0).abs() < 1e-9);
        assert!((get("mean_abs_pct_error") - 10.0).abs() < 1e-9);
        assert!((get("slope") - 1.1).abs() < 1e-12);
        assert!(pair_by_name(&[("a".into(), 1.0)], &[("b".into(), 1.0)]).is_err());
    }
}
