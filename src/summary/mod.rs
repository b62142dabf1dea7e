//! Cross-variant summaries: `summary "<kind>" of="<measurement>" …` inside an
//! `experiment`. A summary runs once every variant of the plan has results;
//! it reads the rows of one measurement across all variants (variant, swept
//! values, quantity, value, standard error) and returns its own figures and
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
use crate::measure::Measured;
use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Params, Schema};
use crate::report::results::ResultRow;
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

/// Run summary `name` on the rows of measurement `of` (every variant's rows
/// of that measurement, in plan order; `axes` are the results' swept columns).
pub fn run(
    name: &str,
    of: &str,
    opts: &SummaryOptions,
    axes: &[String],
    rows: &[ResultRow],
) -> Result<Measured> {
    let rows: Vec<&ResultRow> = rows.iter().filter(|r| r.measurement == of).collect();
    if rows.is_empty() {
        return Err(crate::Error::invalid(format!(
            "summary '{name}': no rows of measurement '{of}' in the results"
        )));
    }
    match opts {
        SummaryOptions::QeCorrection(o) => qe_correction::run(name, o, axes, &rows),
        SummaryOptions::Steps(o) => steps::run(name, o, axes, &rows),
    }
}
