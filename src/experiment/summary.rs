//! The cross-variant stage: once every variant of a plan has results (a full
//! run, the shard run that completes the plan, or `camsim merge`), each
//! `summary` node of the experiment reads the assembled rows of its
//! measurement and that measurement's curves (`curves/<variant>/<of>.csv`)
//! and adds its own: `variant` = `summary`, empty swept columns,
//! `render_s` 0 and `total_s` the summary's own time, so `camsim diff` and
//! the baselines treat them like any row. Its curves go to
//! `curves/summary/<name>.csv`. Summaries are always recomputed (they are
//! cheap) and never hashed as variant inputs. A summary that fails is
//! reported and leaves no rows (the variants' rows are still written).

use crate::figure::Figure;
use crate::params::Params;
use crate::report::results::{parse_results, read_curves, write_curves};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// The `variant` column of summary rows (defined with the results files the
/// report reads, a layer below).
pub use crate::report::results::SUMMARY_VARIANT as VARIANT;

/// A `summary` node as the plan and the manifest keep it (so `camsim merge`
/// can recompute it without the experiment file's parse).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SummaryRecord {
    pub name: String,
    pub kind: String,
    pub of: String,
    #[serde(default)]
    pub params: Params,
}

impl SummaryRecord {
    pub fn from_node(m: &super::spec::Measure) -> Self {
        Self {
            name: m.name.clone(),
            kind: m.kind.clone(),
            of: m.of.first().cloned().unwrap_or_default(),
            params: m.params.clone(),
        }
    }
}

fn csv_line(fields: &[String]) -> String {
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .from_writer(vec![]);
    let _ = w.write_record(fields);
    let _ = w.flush();
    String::from_utf8(w.into_inner().unwrap_or_default()).unwrap_or_default()
}

fn num(x: f64) -> String {
    if x == 0.0 { "0".into() } else { format!("{x}") }
}

/// Rows of summary figures, in `results.csv`'s column order (empty axes).
fn rows_text(experiment: &str, n_axes: usize, figures: &[Figure], total_s: f64) -> String {
    let mut s = String::new();
    for f in figures {
        let mut row = vec![experiment.to_string(), VARIANT.to_string()];
        row.extend(std::iter::repeat_n(String::new(), n_axes));
        row.extend([
            f.measurement.clone(),
            f.quantity.clone(),
            f.unit.clone(),
            num(f.value),
            num(f.stderr),
            "0".into(),
            num(total_s),
        ]);
        s.push_str(&csv_line(&row));
    }
    s
}

/// Run every summary on the assembled `results.csv` text `csv` of the
/// experiment in `root` (defined in `file`, for relative paths) and return
/// the text with the summaries' rows appended, plus one message per failed
/// summary. Curves are written to `root/curves/summary/<name>.csv`
/// (atomically, before the results that name them).
pub fn append(
    root: &Path,
    experiment: &str,
    file: &Path,
    axes: &[String],
    csv: &str,
    summaries: &[SummaryRecord],
) -> Result<(String, Vec<String>)> {
    if summaries.is_empty() {
        return Ok((csv.to_string(), vec![]));
    }
    let rows = parse_results(csv, &root.join("results.csv").display().to_string())?;
    let dir = file.parent().unwrap_or(Path::new(""));
    let mut text = csv.to_string();
    let mut failed = vec![];
    for s in summaries {
        let t = Instant::now();
        let r = crate::summary::checked(&s.kind, &s.params, dir)
            .map_err(|e| Error::invalid(format!("summary '{}': {}", s.name, e.message)))
            .and_then(|o| {
                let curves_of = |variant: &str| -> Result<Option<Vec<crate::measure::Curve>>> {
                    let p = root
                        .join("curves")
                        .join(variant)
                        .join(format!("{}.csv", s.of));
                    if p.exists() {
                        read_curves(&p).map(Some)
                    } else {
                        Ok(None)
                    }
                };
                let input = crate::summary::SummaryInput::new(&s.of, axes, &rows, curves_of)?;
                crate::summary::run(&s.name, &s.of, &o, &input)
            });
        match r {
            Ok(m) => {
                if let Some(f) = m
                    .figures
                    .iter()
                    .find(|f| !f.value.is_finite() || !f.stderr.is_finite())
                {
                    failed.push(format!(
                        "summary '{}' produced a non-finite {} ({} ± {}); not written",
                        s.name, f.quantity, f.value, f.stderr
                    ));
                    continue;
                }
                if !m.curves.is_empty() {
                    write_curves(root, VARIANT, &s.name, &m.curves)?;
                }
                text.push_str(&rows_text(
                    experiment,
                    axes.len(),
                    &m.figures,
                    t.elapsed().as_secs_f64(),
                ));
            }
            Err(e) => failed.push(e.to_string()),
        }
    }
    Ok((text, failed))
}
