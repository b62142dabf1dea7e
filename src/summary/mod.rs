//! Cross-variant summaries: `summary "<kind>" of="<measurement>" …` inside an
//! `experiment`. A summary runs once every variant of the plan has results;
//! it reads the rows of one measurement across all variants (variant, swept
//! values, quantity, value, standard error) and that measurement's curves
//! ([`SummaryInput`]), and returns its own figures and
//! curves, which the experiment layer writes with `variant` = `summary`
//! (`experiment::summary`).
//!
//! Each kind's properties are listed once, in the `SCHEMA` beside it
//! ([`qe_correction::SCHEMA`], [`steps::SCHEMA`]), and read through a
//! [`ParamDict`] by [`options`] — the same call for `camsim check` and the run.

pub mod pairing;
pub mod qe_correction;
pub mod steps;

use crate::Result;
use crate::measure::{Curve, Measured};
use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Params, Schema};
use crate::report::results::ResultRow;
use std::collections::BTreeMap;
use std::path::Path;

/// The kinds of `summary "<kind>"`, in the order of the language reference.
pub const KINDS: &[&str] = &["qe-correction", "steps"];

/// The schema of `summary "<kind>"`.
pub fn schema(kind: &str) -> Option<&'static Schema> {
    Some(match kind {
        "qe-correction" => &qe_correction::SCHEMA,
        "steps" => &steps::SCHEMA,
        _ => return None,
    })
}

/// Every summary kind's schema, in [`KINDS`] order.
pub fn schemas() -> Vec<&'static Schema> {
    KINDS.iter().filter_map(|k| schema(k)).collect()
}

/// `name=` of a summary (read by the experiment layer).
pub const fn name_param() -> ParamSpec {
    ParamSpec::new(
        "name",
        Kind::Text,
        "the kind",
        "the summary's name: the `measurement` column of its rows (variant `summary`) and `curves/summary/<name>.csv`; unique among the experiment's measure and summary names (no '.', ',' or '/')",
        "\"s-probe\"",
    )
}

/// `of=` of a summary (read by the experiment layer).
pub const fn of_param() -> ParamSpec {
    ParamSpec::new(
        "of",
        Kind::Text,
        "",
        "the measurement whose rows are read across the variants (required; a `measure` of the experiment)",
        "\"mcc\"",
    )
}

/// `note=`: a sentence shown with the summary in the report.
pub const fn note_param() -> ParamSpec {
    ParamSpec::new(
        "note",
        Kind::Text,
        "none",
        "a sentence shown with the summary in the report (e.g. what stands in for the measurement)",
        "\"n-probe note\"",
    )
}

/// `axis=`: the swept path that tells the compared variants apart.
pub const fn axis_param(doc: &'static str) -> ParamSpec {
    ParamSpec::new("axis", Kind::Text, "", doc, "\"tag.probe\"")
}

/// The typed options of one summary.
#[derive(Clone, Debug)]
pub enum SummaryOptions {
    QeCorrection(qe_correction::QeCorrectionOptions),
    Steps(steps::StepsOptions),
}

/// Read the properties of `summary "<kind>"` (without `name`/`of`, which the
/// experiment layer reads). Every written property must be in the kind's
/// schema and valid; required ones must be present.
pub fn options(
    kind: &str,
    params: &Params,
    base_dir: &Path,
) -> std::result::Result<SummaryOptions, ParamError> {
    let schema = schema(kind).ok_or_else(|| {
        ParamError::section(format!(
            "unknown summary '{kind}'; expected one of: {}",
            KINDS.join(", ")
        ))
    })?;
    let d = ParamDict::new(params, schema);
    let o = match kind {
        "qe-correction" => SummaryOptions::QeCorrection(qe_correction::from_params(&d, base_dir)?),
        "steps" => SummaryOptions::Steps(steps::from_params(&d)?),
        _ => unreachable!("schema() knows the kind"),
    };
    d.finish()?;
    Ok(o)
}

/// [`options`] and the properties a run cannot do without: what `check` and
/// the run call on every `summary` node.
pub fn checked(
    kind: &str,
    params: &Params,
    base_dir: &Path,
) -> std::result::Result<SummaryOptions, ParamError> {
    let o = options(kind, params, base_dir)?;
    match &o {
        SummaryOptions::QeCorrection(q) => q.require_complete()?,
        SummaryOptions::Steps(s) => s.require_complete()?,
    }
    Ok(o)
}

/// What a summary reads: the rows of its measurement `of` across every
/// variant (plan order) and that measurement's curves per variant.
pub struct SummaryInput<'a> {
    /// The results' swept columns.
    pub axes: &'a [String],
    /// Every variant's rows of `of`.
    pub rows: Vec<&'a ResultRow>,
    /// Curves of `of` by variant id (variants that wrote none are absent).
    pub curves: BTreeMap<String, Vec<Curve>>,
}

impl<'a> SummaryInput<'a> {
    /// The rows of `of` among `all`, and the curves `curves_of(variant)` finds.
    pub fn new(
        of: &str,
        axes: &'a [String],
        all: &'a [ResultRow],
        curves_of: impl Fn(&str) -> Result<Option<Vec<Curve>>>,
    ) -> Result<Self> {
        let rows: Vec<&ResultRow> = all.iter().filter(|r| r.measurement == of).collect();
        let mut curves = BTreeMap::new();
        for r in &rows {
            if !curves.contains_key(&r.variant)
                && let Some(c) = curves_of(&r.variant)?
            {
                curves.insert(r.variant.clone(), c);
            }
        }
        Ok(Self { axes, rows, curves })
    }
}

/// Run summary `name` on its input (the rows and curves of measurement `of`).
pub fn run(name: &str, of: &str, opts: &SummaryOptions, input: &SummaryInput) -> Result<Measured> {
    if input.rows.is_empty() {
        return Err(crate::Error::invalid(format!(
            "summary '{name}': no rows of measurement '{of}' in the results"
        )));
    }
    let (axes, rows) = (input.axes, &input.rows);
    match opts {
        SummaryOptions::QeCorrection(o) => qe_correction::run(name, o, axes, rows),
        SummaryOptions::Steps(o) => steps::run(name, o, axes, rows),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(variant: &str, measurement: &str) -> ResultRow {
        ResultRow {
            experiment: "e".into(),
            variant: variant.into(),
            params: vec![("tag.a".into(), variant.into())],
            measurement: measurement.into(),
            quantity: "q".into(),
            unit: "1".into(),
            value: 1.0,
            stderr: 0.0,
            render_s: 0.0,
            total_s: 0.0,
        }
    }

    #[test]
    fn input_holds_the_rows_and_curves_of_its_measurement() {
        let all = vec![row("a=1", "m"), row("a=1", "other"), row("a=2", "m")];
        let axes = vec!["tag.a".to_string()];
        let input = SummaryInput::new("m", &axes, &all, |v| {
            Ok((v == "a=2").then(|| {
                vec![Curve::new(
                    "c",
                    ("x", "1"),
                    ("y", "1"),
                    vec![0.0],
                    vec![1.0],
                    vec![],
                )]
            }))
        })
        .unwrap();
        assert_eq!(input.rows.len(), 2);
        assert!(input.rows.iter().all(|r| r.measurement == "m"));
        assert_eq!(input.curves.keys().collect::<Vec<_>>(), vec!["a=2"]);
    }
}
