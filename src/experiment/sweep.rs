//! Sweeps: named axes over parameter paths, expanded into variants.
//!
//! - Axes at the top of `sweep { … }` combine as a cartesian product, the
//!   first axis varying slowest (like nested loops written in file order).
//! - A `zip { … }` group moves its axes together; they must have equal lengths.
//! - An axis lists its values (`sensor.exposure-s 0.1 0.2 0.4`) or is a range
//!   (`render.spp start=64 stop=256 step=64`). A range's count is
//!   `round((stop − start)/step) + 1` when that ratio is within 1e-9 of an
//!   integer (so `0 1 0.1` gives 11 values despite binary floating point),
//!   otherwise `floor(…) + 1`; value *i* is `start + i·step` (never
//!   accumulated) rounded to 12 significant digits, which removes the binary
//!   artefacts (`0.30000000000000004` → `0.3`).
//! - A variant's id joins `name=value` over the axes in file order, where name
//!   is the last segment of the path (the full path when two axes share it) and
//!   value is the shortest text that reads back to the same number:
//!   `exposure-s=0.2,film-distance-mm=0.57624,focus-m=0.3`. Without a sweep the
//!   single variant is called `default`.

use super::apply::{self, fmt_value};
use super::source::Span;
use super::spec::ResolvedExperiment;
use crate::params::Value;
use serde::Serialize;
use std::collections::BTreeMap;

/// At most this many variants per experiment.
pub const MAX_VARIANTS: usize = 100_000;

/// One axis: a parameter path and its values.
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    pub path: String,
    pub values: Vec<(Value, Span)>,
    pub span: Span,
}

/// A top-level sweep item.
#[derive(Clone, Debug, PartialEq)]
pub enum SweepItem {
    Axis(Axis),
    Zip { axes: Vec<Axis>, span: Span },
}

impl SweepItem {
    pub fn len(&self) -> usize {
        match self {
            SweepItem::Axis(a) => a.values.len(),
            SweepItem::Zip { axes, .. } => axes.first().map(|a| a.values.len()).unwrap_or(0),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn axes(&self) -> Vec<&Axis> {
        match self {
            SweepItem::Axis(a) => vec![a],
            SweepItem::Zip { axes, .. } => axes.iter().collect(),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Default)]
pub struct Sweep {
    pub items: Vec<SweepItem>,
    pub span: Span,
}

impl Sweep {
    pub fn axes(&self) -> Vec<&Axis> {
        self.items.iter().flat_map(|i| i.axes()).collect()
    }
    /// Number of variants (saturating).
    pub fn count(&self) -> usize {
        self.items
            .iter()
            .fold(1usize, |n, i| n.saturating_mul(i.len()))
    }
    /// Column names of the swept parameters, in file order.
    pub fn paths(&self) -> Vec<String> {
        self.axes().iter().map(|a| a.path.clone()).collect()
    }
    /// Short names used in ids (last path segment, full path on collision).
    pub fn short_names(&self) -> Vec<String> {
        let paths = self.paths();
        let last = |p: &str| p.rsplit('.').next().unwrap_or(p).to_string();
        paths
            .iter()
            .map(|p| {
                let l = last(p);
                if paths.iter().filter(|q| last(q) == l).count() > 1 {
                    p.clone()
                } else {
                    l
                }
            })
            .collect()
    }
}

/// One expanded variant.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Variant {
    /// 0-based position in the plan.
    pub index: usize,
    pub id: String,
    /// Swept path → value for this variant.
    pub params: BTreeMap<String, Value>,
    pub spec: ResolvedExperiment,
}

/// Values of a range axis (see module docs).
pub fn range_values(start: f64, stop: f64, step: f64) -> Result<Vec<f64>, String> {
    if !(start.is_finite() && stop.is_finite() && step.is_finite()) {
        return Err("range start, stop and step must be finite".into());
    }
    if step == 0.0 {
        return Err("range step must not be 0".into());
    }
    let n = (stop - start) / step;
    if n < -1e-9 {
        return Err(format!(
            "range from {start} to {stop} never arrives with step {step} (wrong sign)"
        ));
    }
    let k = n.round();
    let count = if (n - k).abs() <= 1e-9 * k.abs().max(1.0) {
        k
    } else {
        n.floor()
    } + 1.0;
    if !count.is_finite() || count > MAX_VARIANTS as f64 {
        return Err(format!(
            "range has {count} values; at most {MAX_VARIANTS} allowed"
        ));
    }
    Ok((0..count.max(1.0) as usize)
        .map(|i| snap(start + i as f64 * step))
        .collect())
}

/// Round to 12 significant digits (removes float-step artefacts).
pub fn snap(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    format!("{x:.11e}").parse().unwrap_or(x)
}

/// Expand a sweep over a resolved spec. Errors carry the span of the value
/// (or axis) that made the variant invalid.
pub fn expand(
    base: &ResolvedExperiment,
    sweep: &Sweep,
    loader: super::source::Loader,
) -> Result<Vec<Variant>, (Span, apply::ApplyError)> {
    let n = sweep.count();
    if n > MAX_VARIANTS {
        return Err((
            sweep.span,
            apply::ApplyError::new(format!(
                "the sweep expands to {n} variants; at most {MAX_VARIANTS} allowed"
            )),
        ));
    }
    let shorts = sweep.short_names();
    let mut out = Vec::with_capacity(n);
    for index in 0..n {
        // Decompose index: the last item varies fastest.
        let mut rem = index;
        let mut picks = vec![0usize; sweep.items.len()];
        for (k, item) in sweep.items.iter().enumerate().rev() {
            let len = item.len().max(1);
            picks[k] = rem % len;
            rem /= len;
        }
        let mut spec = base.clone();
        let mut params = BTreeMap::new();
        let mut id_parts = Vec::new();
        let mut a_i = 0;
        for (item, &pick) in sweep.items.iter().zip(&picks) {
            for axis in item.axes() {
                let (v, span) = &axis.values[pick];
                apply::apply(&mut spec, &axis.path, v, loader).map_err(|e| (*span, e))?;
                id_parts.push(format!("{}={}", shorts[a_i], fmt_value(v)));
                params.insert(axis.path.clone(), v.clone());
                a_i += 1;
            }
        }
        let id = if id_parts.is_empty() {
            "default".to_string()
        } else {
            id_parts.join(",")
        };
        out.push(Variant {
            index,
            id,
            params,
            spec,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn ranges_handle_float_steps() {
        assert_eq!(range_values(0.0, 1.0, 0.1).unwrap().len(), 11);
        assert_eq!(range_values(0.0, 1.0, 0.1).unwrap()[3], 0.3);
        assert_eq!(range_values(0.1, 0.3, 0.1).unwrap(), vec![0.1, 0.2, 0.3]);
        assert_eq!(
            range_values(64.0, 256.0, 64.0).unwrap(),
            vec![64.0, 128.0, 192.0, 256.0]
        );
        assert_eq!(
            range_values(0.0, 1.0, 0.3).unwrap(),
            vec![0.0, 0.3, 0.6, 0.9]
        );
        assert_eq!(range_values(1.0, 0.0, -0.5).unwrap(), vec![1.0, 0.5, 0.0]);
        assert!(range_values(0.0, 1.0, -0.1).is_err());
        assert!(range_values(0.0, 1.0, 0.0).is_err());
        assert!(range_values(0.0, 1e9, 1e-3).is_err());
        assert_eq!(range_values(2.0, 2.0, 1.0).unwrap(), vec![2.0]);
    }
}
