//! The `render` node (its properties and its `target` children) and the
//! `quality "NAME"` presets, which hold `render` properties.

use super::*;
use crate::experiment::apply;
use crate::experiment::language::{RENDER_SCHEMA, TARGET_SCHEMA};
use crate::experiment::source::Span;
use crate::params::Params;
use kdl::{KdlNode, KdlValue};

impl P {
    /// `render spp=… … [{ target "MEASUREMENT" stderr=… [quantity=…] … }]`,
    /// applied onto `spec` (a base's render node is overridden property by
    /// property; a child target replaces the base's target of the same
    /// measurement and quantity).
    pub(super) fn parse_render(
        &self,
        file: usize,
        n: &KdlNode,
        spec: &mut ResolvedExperiment,
    ) -> Result<(), Located> {
        spec.render.span = self.node_span(file, n);
        for e in self.entries(file, n)? {
            let (k, ks) = self.prop(&e, "render")?;
            self.render_prop(spec, &k, ks, &e, "render")?;
        }
        for t in self.parse_targets(file, n, "render")? {
            spec.render.set_target(t);
        }
        Ok(())
    }

    /// The `target` children of a `render` or `quality` node.
    fn parse_targets(
        &self,
        file: usize,
        n: &KdlNode,
        node: &str,
    ) -> Result<Vec<FigureTarget>, Located> {
        let mut out = vec![];
        if let Some(children) = n.children() {
            for c in children.nodes() {
                self.no_type(file, c)?;
                let cs = self.node_span(file, c);
                let name = c.name().value();
                if name != "target" {
                    let help = if RENDER_SCHEMA.get(name).is_some() {
                        format!(
                            "write '{name}' as a property on the {node} line, e.g. {node} {name}=…; the block holds only `target \"MEASUREMENT\" stderr=…` nodes"
                        )
                    } else {
                        format!("{node}'s block holds `target \"MEASUREMENT\" stderr=…` nodes")
                    };
                    return Err(self
                        .e(cs, format!("unknown node '{name}' inside {node}"))
                        .with_help(help));
                }
                self.no_children(file, c)?;
                out.push(self.parse_target(file, c)?);
            }
        }
        Ok(out)
    }

    /// One `render` property (also a `quality` preset's), checked as it is read.
    fn render_prop(
        &self,
        spec: &mut ResolvedExperiment,
        k: &str,
        ks: Span,
        e: &Ent,
        node: &str,
    ) -> Result<(), Located> {
        let known = RENDER_SCHEMA.names();
        if !known.contains(&k) {
            return Err(self.unknown_prop(k, ks, &known, node, &e.value));
        }
        if k == "seed"
            && let KdlValue::Integer(i) = e.raw
            && (i < 0 || i > u64::MAX as i128)
        {
            return Err(self.e(
                e.vspan,
                format!("'seed' = {i} is out of range; expected 0…{}", 1u64 << 53),
            ));
        }
        apply::apply(spec, &format!("render.{k}"), &e.value, self.loader)
            .map_err(|x| self.ae(e.vspan, x))
    }

    /// `target "MEASUREMENT" stderr=… [quantity="Q"]`.
    fn parse_target(&self, file: usize, n: &KdlNode) -> Result<FigureTarget, Located> {
        let sp = self.node_span(file, n);
        let mut measurement = None;
        let mut quantity = None;
        let mut stderr = None;
        let help = "write target \"sfr-near\" stderr=\"2%\" [quantity=\"mtf50\"]";
        for e in self.entries(file, n)? {
            match &e.name {
                None => match &e.value {
                    Value::String(s) if measurement.is_none() && !s.is_empty() => {
                        measurement = Some(s.clone())
                    }
                    v => {
                        return Err(self
                            .e(
                                e.vspan,
                                format!(
                                    "target: expected one measurement name, found {}",
                                    apply::describe(v)
                                ),
                            )
                            .with_help(help));
                    }
                },
                Some((k, ks)) => match k.as_str() {
                    "stderr" => {
                        stderr = Some(
                            apply::as_stderr_target(&e.value, "stderr")
                                .map_err(|x| self.ae(e.vspan, x))?,
                        )
                    }
                    "quantity" => match &e.value {
                        Value::String(q) if !q.is_empty() => quantity = Some(q.clone()),
                        v => {
                            return Err(self.e(
                                e.vspan,
                                format!(
                                    "'quantity': expected a figure's name, found {}",
                                    apply::describe(v)
                                ),
                            ));
                        }
                    },
                    _ => {
                        let known = TARGET_SCHEMA.names();
                        return Err(self.unknown_prop(k, *ks, &known, "target", &e.value));
                    }
                },
            }
        }
        let Some(measurement) = measurement else {
            return Err(self
                .e(sp, "target needs the measurement's name")
                .with_help(help));
        };
        let Some(stderr) = stderr else {
            return Err(self
                .e(sp, format!("target \"{measurement}\" needs stderr=…"))
                .with_help(help));
        };
        Ok(FigureTarget {
            measurement,
            quantity,
            stderr,
            span: sp,
        })
    }

    /// `quality "NAME" spp=… target-stderr=… … [{ target … }]`: the properties are checked
    /// as `render` properties now (on a scratch copy of `spec`) and kept for
    /// `camsim run --quality NAME`.
    pub(super) fn parse_quality(
        &self,
        file: usize,
        n: &KdlNode,
        spec: &ResolvedExperiment,
    ) -> Result<QualityPreset, Located> {
        let sp = self.node_span(file, n);
        let mut name = None;
        let mut params = Params::new();
        let mut spans = PropSpans::default();
        let mut scratch = spec.clone();
        for e in self.entries(file, n)? {
            match &e.name {
                None => match &e.value {
                    Value::String(s) if name.is_none() && !s.is_empty() => name = Some(s.clone()),
                    v => {
                        return Err(self
                            .e(
                                e.vspan,
                                format!(
                                    "quality: expected one preset name, found {}",
                                    apply::describe(v)
                                ),
                            )
                            .with_help(
                                "write quality \"paper\" spp=256 target-stderr=\"1%\" max-s=300",
                            ));
                    }
                },
                Some((k, ks)) => {
                    self.render_prop(&mut scratch, k, *ks, &e, "quality")?;
                    params.set(k.clone(), e.value.clone());
                    spans.insert(k, *ks, e.vspan);
                }
            }
        }
        if name.as_deref() == Some("quick") {
            return Err(self
                .e(sp, "'quick' is the render node's own settings; it cannot be redefined")
                .with_help("put the quick settings on `render`, and name other presets, e.g. quality \"paper\""));
        }
        let Some(name) = name else {
            return Err(self
                .e(sp, "quality needs the preset's name")
                .with_help("write quality \"paper\" spp=256 target-stderr=\"1%\" max-s=300"));
        };
        let targets = self.parse_targets(file, n, "quality")?;
        Ok(QualityPreset {
            name,
            params,
            targets,
            span: sp,
            spans,
        })
    }
}
