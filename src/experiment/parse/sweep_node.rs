//! The `sweep { … }` block: axes, `zip` groups and ranges.

use super::*;
use crate::diag::Located;
use crate::experiment::apply;
use crate::experiment::source::Span;
use crate::experiment::sweep::{Axis, Sweep, SweepItem, range_values};
use crate::params::Value;
use kdl::KdlNode;
use std::collections::BTreeMap;

impl P {
    pub(super) fn parse_axis(
        &self,
        file: usize,
        n: &KdlNode,
        spec: &ResolvedExperiment,
    ) -> Result<Axis, Located> {
        self.no_type(file, n)?;
        let sp = self.node_span(file, n);
        let path = n.name().value().to_string();
        if n.children().is_some() {
            return Err(self
                .e(sp, format!("sweep axis '{path}' takes no {{ … }} block"))
                .with_help("list values after the path, or give start= stop= step="));
        }
        let ents = self.entries(file, n)?;
        let mut values = Vec::new();
        let (mut start, mut stop, mut step) = (None, None, None);
        for e in &ents {
            match &e.name {
                None => values.push((e.value.clone(), e.vspan)),
                Some((k, ks)) => {
                    let slot = match k.as_str() {
                        "start" => &mut start,
                        "stop" => &mut stop,
                        "step" => &mut step,
                        _ => {
                            return Err(self.unknown_prop(
                                k,
                                *ks,
                                &["start", "stop", "step"],
                                "sweep axis",
                                &e.value,
                            ));
                        }
                    };
                    let x = apply::as_f64(&e.value, k).map_err(|x| self.ae(e.vspan, x))?;
                    *slot = Some(x);
                }
            }
        }
        let is_range = start.is_some() || stop.is_some() || step.is_some();
        if is_range && !values.is_empty() {
            return Err(self
                .e(
                    sp,
                    format!("axis '{path}' mixes a value list with start/stop/step"),
                )
                .with_help("use either a list or a range"));
        }
        if is_range {
            let (Some(a), Some(b), Some(c)) = (start, stop, step) else {
                return Err(self.e(
                    sp,
                    format!("range axis '{path}' needs start=, stop= and step="),
                ));
            };
            let vs =
                range_values(a, b, c).map_err(|m| self.e(sp, format!("axis '{path}': {m}")))?;
            values = vs.into_iter().map(|x| (Value::Number(x), sp)).collect();
        }
        if values.is_empty() {
            return Err(self.e(sp, format!("empty sweep axis '{path}'")).with_help(
                "list values (e.g. sensor.exposure-s 0.1 0.2) or give start= stop= step=",
            ));
        }
        // Check path and every value by applying it to the resolved spec.
        for (v, vs) in &values {
            let mut probe = spec.clone();
            apply::apply(&mut probe, &path, v, self.loader).map_err(|x| {
                let at = if x.on_path { sp } else { *vs };
                self.ae(at, x)
            })?;
        }
        Ok(Axis {
            path,
            values,
            span: sp,
        })
    }

    pub(super) fn parse_sweep(
        &self,
        file: usize,
        n: &KdlNode,
        spec: &ResolvedExperiment,
    ) -> Result<Sweep, Located> {
        let sp = self.node_span(file, n);
        if let Some(e) = self.entries(file, n)?.first() {
            return Err(self.e(
                e.vspan,
                "'sweep' takes no values; put axes inside its { … } block",
            ));
        }
        let Some(children) = n.children() else {
            return Err(self.e(sp, "'sweep' needs a { … } block of axes"));
        };
        let mut sweep = Sweep {
            items: Vec::new(),
            span: sp,
        };
        let mut seen: BTreeMap<String, Span> = BTreeMap::new();
        let mut note = |p: &P, a: &Axis| -> Result<(), Located> {
            if let Some(prev) = seen.get(&a.path) {
                return Err(p
                    .e(a.span, format!("duplicate sweep axis '{}'", a.path))
                    .with_help(format!("first at {}", p.where_(*prev))));
            }
            seen.insert(a.path.clone(), a.span);
            Ok(())
        };
        for c in children.nodes() {
            if c.name().value() == "zip" {
                self.no_type(file, c)?;
                let zs = self.node_span(file, c);
                if let Some(e) = self.entries(file, c)?.first() {
                    return Err(self.e(
                        e.vspan,
                        "'zip' takes no values; put axes inside its { … } block",
                    ));
                }
                let Some(zc) = c.children() else {
                    return Err(self.e(zs, "'zip' needs a { … } block of axes"));
                };
                let mut axes = Vec::new();
                for z in zc.nodes() {
                    if z.name().value() == "zip" {
                        return Err(self.e(self.node_span(file, z), "'zip' cannot be nested"));
                    }
                    let a = self.parse_axis(file, z, spec)?;
                    note(self, &a)?;
                    axes.push(a);
                }
                if axes.is_empty() {
                    return Err(self.e(zs, "empty 'zip' group"));
                }
                let n0 = axes[0].values.len();
                if let Some(bad) = axes.iter().find(|a| a.values.len() != n0) {
                    return Err(self
                        .e(bad.span, format!("zip axes must have equal lengths: '{}' has {n0} values, '{}' has {}", axes[0].path, bad.path, bad.values.len()))
                        .with_help("axes in a zip move together, value by value"));
                }
                sweep.items.push(SweepItem::Zip { axes, span: zs });
            } else {
                let a = self.parse_axis(file, c, spec)?;
                note(self, &a)?;
                sweep.items.push(SweepItem::Axis(a));
            }
        }
        // Repeated values would give two variants with the same id and inputs.
        for item in &sweep.items {
            let axes = item.axes();
            let mut seen_vals: BTreeMap<String, usize> = BTreeMap::new();
            for k in 0..item.len() {
                let key: Vec<String> = axes
                    .iter()
                    .map(|a| apply::fmt_value(&a.values[k].0))
                    .collect();
                let key = key.join("\u{1f}");
                if let Some(first) = seen_vals.insert(key, k) {
                    let (v, vs) = &axes[0].values[k];
                    let msg = if axes.len() > 1 {
                        let combo: Vec<String> = axes
                            .iter()
                            .map(|a| apply::fmt_value(&a.values[k].0))
                            .collect();
                        format!(
                            "repeated value combination ({}) in this zip (same as combination {})",
                            combo.join(", "),
                            first + 1
                        )
                    } else {
                        format!(
                            "repeated value {} in sweep axis '{}' (same as value {})",
                            apply::fmt_value(v),
                            axes[0].path,
                            first + 1
                        )
                    };
                    return Err(self
                        .e(*vs, msg)
                        .with_help("each value of an axis must differ; remove the repetition"));
                }
            }
        }
        if sweep.items.is_empty() {
            return Err(self
                .e(sp, "empty sweep")
                .with_help("add axes, e.g. sensor.exposure-s 0.1 0.2 0.4, or remove the sweep"));
        }
        let count = sweep.count();
        if count > crate::experiment::sweep::MAX_VARIANTS {
            return Err(self.e(
                sp,
                format!(
                    "the sweep expands to {count} variants; at most {} allowed",
                    crate::experiment::sweep::MAX_VARIANTS
                ),
            ));
        }
        Ok(sweep)
    }
}
