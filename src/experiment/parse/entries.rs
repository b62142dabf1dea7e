//! Reading a KDL node's entries: spans, values (the `(x y z)` lists), the
//! checks every node shares (no block, no type annotation, properties only),
//! and the located errors the parser reports.

use super::*;
use crate::diag::{Located, did_you_mean};
use crate::experiment::apply::{self, ApplyError};
use crate::experiment::source::{Span, skip_trivia};
use crate::params::Value;
use kdl::{KdlEntry, KdlNode, KdlValue};

impl P {
    pub(super) fn e(&self, span: Span, msg: impl Into<String>) -> Located {
        err_at(&self.map, span, msg)
    }

    pub(super) fn ae(&self, span: Span, e: ApplyError) -> Located {
        self.e(span, e.message).with_help_opt(e.help)
    }

    pub(super) fn node_span(&self, file: usize, node: &KdlNode) -> Span {
        let s = node.name().span();
        Span {
            file,
            offset: s.offset(),
            len: s.len().max(1),
        }
    }

    pub(super) fn where_(&self, span: Span) -> String {
        let l = self.map.error(span, "");
        format!("{}:{}:{}", l.file.display(), l.line, l.col)
    }

    /// Entries of a node with spans and converted values.
    pub(super) fn entries(&self, file: usize, node: &KdlNode) -> Result<Vec<Ent>, Located> {
        let text = &self.map.file(file).text;
        let mut out: Vec<Ent> = Vec::new();
        for entry in node.entries() {
            let (name, voff) = match entry.name() {
                Some(id) => {
                    let ns = id.span();
                    let nspan = Span {
                        file,
                        offset: ns.offset(),
                        len: ns.len().max(1),
                    };
                    let mut o = ns.offset() + ns.len();
                    o = skip_trivia(text, o);
                    if text.as_bytes().get(o) == Some(&b'=') {
                        o = skip_trivia(text, o + 1);
                    }
                    (Some((id.value().to_string(), nspan)), o)
                }
                None => (None, skip_trivia(text, entry.span().offset())),
            };
            let vlen = value_len(entry);
            let vspan = Span {
                file,
                offset: voff,
                len: vlen,
            };
            if let Some(ty) = entry.ty() {
                let s = ty.span();
                return Err(self
                    .e(Span { file, offset: s.offset(), len: s.len().max(1) }, format!("type annotation '({})' is not used by camsim", ty.value()))
                    .with_help("remove the annotation; units belong in the property name, e.g. exposure-s=0.2"));
            }
            if let Some((n, s)) = &name
                && let Some(prev) = out
                    .iter()
                    .find(|e| e.name.as_ref().is_some_and(|(m, _)| m == n))
            {
                let first = self.where_(prev.name.as_ref().map(|x| x.1).unwrap_or(*s));
                return Err(self
                    .e(*s, format!("duplicate property '{n}'"))
                    .with_help(format!("first given at {first}")));
            }
            let value = self.convert(file, entry, voff, name.as_ref().map(|n| n.0.as_str()))?;
            out.push(Ent {
                name,
                value,
                vspan,
                raw: entry.value().clone(),
            });
        }
        Ok(out)
    }

    pub(super) fn convert(
        &self,
        file: usize,
        entry: &KdlEntry,
        voff: usize,
        name: Option<&str>,
    ) -> Result<Value, Located> {
        let what = name.unwrap_or("value");
        let span = Span {
            file,
            offset: voff,
            len: value_len(entry),
        };
        Ok(match entry.value() {
            KdlValue::String(s) => {
                if self.map.file(file).tuples.contains(&voff) {
                    let mut items = Vec::new();
                    let mut pos = voff + 1;
                    for tok in s.split([' ', '\t']) {
                        if tok.is_empty() {
                            pos += 1;
                            continue;
                        }
                        let t = tok.replace('_', "");
                        match t.parse::<f64>() {
                            Ok(x) if x.is_finite() && !t.contains("inf") && !t.contains("nan") => {
                                items.push(Value::Number(x))
                            }
                            _ => {
                                return Err(self
                                    .e(Span { file, offset: pos, len: tok.len() }, format!("'{tok}' in the list '{what}' is not a number"))
                                    .with_help("a list is written (x y z) with numbers separated by spaces"));
                            }
                        }
                        pos += tok.len() + 1;
                    }
                    Value::List(items)
                } else {
                    Value::String(s.clone())
                }
            }
            KdlValue::Integer(i) => {
                if i.unsigned_abs() > (1u128 << 53) {
                    return Err(self.e(
                        span,
                        format!("'{what}': integer {i} is too large (at most 2^53)"),
                    ));
                }
                Value::Number(*i as f64)
            }
            KdlValue::Float(x) => {
                if !x.is_finite() {
                    return Err(
                        self.e(span, format!("'{what}' must be a finite number, found {x}"))
                    );
                }
                Value::Number(*x)
            }
            KdlValue::Bool(b) => Value::Bool(*b),
            KdlValue::Null => {
                return Err(self.e(span, format!("'{what}': #null is not a value camsim uses")));
            }
        })
    }

    pub(super) fn no_children(&self, file: usize, node: &KdlNode) -> Result<(), Located> {
        if node.children().is_some() {
            return Err(self
                .e(
                    self.node_span(file, node),
                    format!("'{}' takes no {{ … }} block", node.name().value()),
                )
                .with_help(
                    "write its settings as properties on the same line, e.g. render spp=256",
                ));
        }
        Ok(())
    }

    pub(super) fn no_type(&self, file: usize, node: &KdlNode) -> Result<(), Located> {
        if let Some(ty) = node.ty() {
            let s = ty.span();
            return Err(self.e(
                Span {
                    file,
                    offset: s.offset(),
                    len: s.len().max(1),
                },
                format!("type annotation '({})' is not used by camsim", ty.value()),
            ));
        }
        Ok(())
    }

    pub(super) fn prop(&self, e: &Ent, node: &str) -> Result<(String, Span), Located> {
        match &e.name {
            Some((k, s)) => Ok((k.clone(), *s)),
            None => Err(self
                .e(
                    e.vspan,
                    format!("unexpected argument on '{node}'; expected name=value properties"),
                )
                .with_help(format!(
                    "e.g. {node} {}",
                    match node {
                        "camera" => "position-m=(0 0.1 -0.4) look-at-m=(0 0.1 0.6)",
                        "render" => "spp=256 max-bounces=5",
                        _ => "name=value",
                    }
                ))),
        }
    }

    pub(super) fn unknown_prop(
        &self,
        k: &str,
        ks: Span,
        known: &[&str],
        node: &str,
        v: &Value,
    ) -> Located {
        let mut help =
            did_you_mean(k, known.iter().copied()).map(|s| format!("did you mean '{s}'?"));
        if matches!(v, Value::Number(_)) && !crate::experiment::units::has_unit(k) {
            let with = crate::experiment::units::suggest_unit(k);
            if known.contains(&with.as_str()) || help.is_none() {
                help = Some(crate::experiment::units::unit_help(k));
            }
        }
        self.e(
            ks,
            format!(
                "unknown property '{k}' on '{node}'; expected one of: {}",
                known.join(", ")
            ),
        )
        .with_help_opt(help)
    }

    pub(super) fn single_string(
        &self,
        file: usize,
        n: &KdlNode,
        what: &str,
    ) -> Result<(String, Span), Located> {
        let ents = self.entries(file, n)?;
        let sp = self.node_span(file, n);
        let nm = n.name().value();
        if let Some(e) = ents.iter().find(|e| e.name.is_some()) {
            let (k, s) = e.name.clone().unwrap_or_default();
            return Err(self
                .e(s, format!("unexpected property '{k}' on '{nm}'"))
                .with_help(format!("write {nm} \"…\"")));
        }
        match ents.as_slice() {
            [e] => match &e.value {
                Value::String(s) => Ok((s.clone(), e.vspan)),
                v => Err(self.e(
                    e.vspan,
                    format!("{what}: expected a string, found {}", apply::describe(v)),
                )),
            },
            [] => Err(self
                .e(sp, format!("'{nm}' needs the {what}"))
                .with_help(format!("write {nm} \"…\""))),
            [_, e, ..] => Err(self.e(e.vspan, format!("'{nm}' takes one value"))),
        }
    }
}

/// Byte length of an entry's value as written (≥ 1).
fn value_len(entry: &KdlEntry) -> usize {
    entry
        .format()
        .map(|f| f.value_repr.len())
        .filter(|&l| l > 0)
        .unwrap_or(1)
}
