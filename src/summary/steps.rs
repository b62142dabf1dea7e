//! `summary "steps"`: successive simulation steps against a reference, as in
//! the paper's Fig. 10 (nominal QE without relative illumination; + relative
//! illumination; + corrected QE, each against the measured patch means). The
//! variants are split by the values of `axis`; the value `reference` is the
//! measurement (a capture, or the full model standing in for one) and every
//! other value is a step, in the order the sweep lists them. Rows pair when
//! every other swept value and the quantity agree (a step must have a value
//! for every reference row).
//!
//! Figures per step `<step>` (unit: the measurement's): `<step>/rms_error`
//! = √(mean (step − reference)²) with its standard error by the delta method
//! (se(mean sq)/(2·rms), se(mean sq) = std/√n), `<step>/rms_error_percent`
//! = 100·rms / mean(reference) (same relative standard error) and
//! `<step>/pairs`. Curves: `scatter-<step>/<channel>` (reference on x, step on
//! y; channel from quantities `…/<ch>_mean`, else "all") and
//! `histogram/<value>` for the reference and every step (count of values per
//! `histogram-bin-dv` bin, x = bin centre), Fig. 10 d.

use super::pairing::{points_of, series_of, split_by_axis};
use crate::figure::Figure;
use crate::measure::{Curve, Measured};
use crate::params::{Kind, ParamDict, ParamError, ParamSpec};
use crate::report::results::ResultRow;
use crate::{Error, Result};
use std::collections::BTreeMap;

/// Options of `summary "steps"`.
#[derive(Clone, Debug, PartialEq)]
pub struct StepsOptions {
    pub axis: Option<String>,
    pub reference: Option<String>,
    /// Keep only quantities containing this text.
    pub quantity: String,
    pub bin: f64,
    /// Shown with the summary in the report.
    pub note: Option<String>,
}

impl Default for StepsOptions {
    fn default() -> Self {
        Self {
            axis: None,
            reference: None,
            quantity: "_mean".into(),
            bin: 25.0,
            note: None,
        }
    }
}

/// The properties of `summary "steps"`.
pub static SCHEMA: crate::params::Schema = crate::params::Schema {
    node: "summary \"steps\"",
    params: &[
        super::name_param(),
        super::of_param(),
        super::note_param(),
        super::axis_param(
            "the swept path whose values are the steps and the reference, e.g. \"tag.step\" (required); rows pair when every other swept value agrees",
        ),
        ParamSpec::new(
            "reference",
            Kind::Text,
            "",
            "the axis value standing for the measurement (required); every other value is a step",
            "\"r-probe\"",
        ),
        ParamSpec::new(
            "quantity",
            Kind::Text,
            "_mean",
            "keep only quantities whose name contains this text",
            "\"/g_mean\"",
        ),
        ParamSpec::new(
            "histogram-bin-dv",
            Kind::Number,
            "25",
            "bin width of the histograms of values (in the measurement's unit, > 0)",
            "12.5",
        ),
    ],
};

/// Read `summary "steps"` (see [`SCHEMA`]).
pub fn from_params(d: &ParamDict) -> std::result::Result<StepsOptions, ParamError> {
    let nonempty = |k: &str| -> std::result::Result<Option<String>, ParamError> {
        match d.str(k)? {
            Some("") => Err(ParamError::value(k, format!("'{k}' must not be empty"))),
            o => Ok(o.map(str::to_string)),
        }
    };
    let mut o = StepsOptions {
        axis: nonempty("axis")?,
        reference: nonempty("reference")?,
        ..Default::default()
    };
    o.note = d.str("note")?.map(str::to_string);
    if let Some(q) = d.str("quantity")? {
        o.quantity = q.to_string();
    }
    if let Some(b) = d.positive("histogram-bin-dv")? {
        o.bin = b;
    }
    Ok(o)
}

impl StepsOptions {
    /// The properties a run cannot do without.
    pub fn require_complete(&self) -> std::result::Result<(), ParamError> {
        if self.axis.is_none() || self.reference.is_none() {
            return Err(
                ParamError::section("steps needs axis=\"…\" and reference=\"…\"")
                    .with_help("e.g. axis=\"tag.step\" reference=\"measured\""),
            );
        }
        Ok(())
    }
}

/// Counts of `values` in bins of width `bin` (bin k covers [k·bin, (k+1)·bin)),
/// from the lowest to the highest occupied bin: (centres, counts).
pub fn histogram(values: &[f64], bin: f64) -> (Vec<f64>, Vec<f64>) {
    let mut counts: BTreeMap<i64, usize> = BTreeMap::new();
    for v in values {
        *counts.entry((v / bin).floor() as i64).or_default() += 1;
    }
    let (Some(&lo), Some(&hi)) = (counts.keys().next(), counts.keys().next_back()) else {
        return (vec![], vec![]);
    };
    (lo..=hi)
        .map(|k| {
            (
                (k as f64 + 0.5) * bin,
                counts.get(&k).copied().unwrap_or(0) as f64,
            )
        })
        .unzip()
}

/// Compare every step with the reference (see the module docs).
pub fn run(name: &str, o: &StepsOptions, axes: &[String], rows: &[&ResultRow]) -> Result<Measured> {
    o.require_complete()
        .map_err(|e| Error::invalid(format!("summary '{name}': {}", e.message)))?;
    let axis = o.axis.as_deref().unwrap_or_default();
    let rv = o.reference.as_deref().unwrap_or_default();
    let split = split_by_axis(name, axis, axes, rows)?;
    let reference = points_of(name, axis, &split, rv)?;
    let keep = |q: &str| q.contains(&o.quantity);
    let refs: Vec<_> = reference.iter().filter(|(k, _)| keep(&k.1)).collect();
    if refs.len() < 2 {
        return Err(Error::invalid(format!(
            "summary '{name}': {} reference rows with a quantity containing \"{}\"; need at least 2",
            refs.len(),
            o.quantity
        )));
    }
    let unit = refs[0].1.unit.clone();
    let mut out = Measured::default();
    let ref_vals: Vec<f64> = refs.iter().map(|(_, p)| p.value).collect();
    let ref_mean = ref_vals.iter().sum::<f64>() / ref_vals.len() as f64;
    let (hx, hy) = histogram(&ref_vals, o.bin);
    out.curves.push(Curve::new(
        &format!("histogram/{rv}"),
        ("value", &unit),
        ("count", "1"),
        hx,
        hy,
        vec![],
    ));
    let steps: Vec<&(String, super::pairing::Points)> =
        split.iter().filter(|(v, _)| v != rv).collect();
    if steps.is_empty() {
        return Err(Error::invalid(format!(
            "summary '{name}': {axis} has only the reference value \"{rv}\"; no step to compare"
        )));
    }
    for (sv, pts) in steps {
        let mut series: BTreeMap<String, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
        let mut sq = vec![];
        let mut vals = vec![];
        for (k, r) in &refs {
            let s = pts.get(k).ok_or_else(|| {
                Error::invalid(format!(
                    "summary '{name}': {axis}={sv} has no '{}' for {}",
                    k.1, k.0
                ))
            })?;
            sq.push((s.value - r.value).powi(2));
            vals.push(s.value);
            let e = series.entry(series_of(&k.1)).or_default();
            e.0.push(r.value);
            e.1.push(s.value);
        }
        let n = sq.len() as f64;
        let mse = sq.iter().sum::<f64>() / n;
        let sd = (sq.iter().map(|x| (x - mse).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let rms = mse.sqrt();
        let se = if rms > 0.0 {
            sd / n.sqrt() / (2.0 * rms)
        } else {
            0.0
        };
        out.figures
            .push(Figure::new(name, format!("{sv}/rms_error"), &unit, rms, se));
        out.figures.push(Figure::new(
            name,
            format!("{sv}/rms_error_percent"),
            "%",
            100.0 * rms / ref_mean,
            100.0 * se / ref_mean,
        ));
        out.figures
            .push(Figure::new(name, format!("{sv}/pairs"), "1", n, 0.0));
        let order = super::qe_correction::channel_order(series.keys().cloned().collect());
        for ch in order {
            let (x, y) = series.remove(&ch).unwrap_or_default();
            out.curves.push(Curve::new(
                &format!("scatter-{sv}/{ch}"),
                (rv, &unit),
                (sv, &unit),
                x,
                y,
                vec![],
            ));
        }
        let (hx, hy) = histogram(&vals, o.bin);
        out.curves.push(Curve::new(
            &format!("histogram/{sv}"),
            ("value", &unit),
            ("count", "1"),
            hx,
            hy,
            vec![],
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_counts_every_value_once() {
        let (x, y) = histogram(&[0.0, 10.0, 24.9, 25.0, 80.0], 25.0);
        assert_eq!(x, vec![12.5, 37.5, 62.5, 87.5]);
        assert_eq!(y, vec![3.0, 1.0, 0.0, 1.0]);
    }
}
