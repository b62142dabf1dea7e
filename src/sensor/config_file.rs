//! Sensor definition files (`sensors/*.kdl`, KDL v2) → [`SensorConfig`].
//!
//! A sensor file is a flat list of nodes. Scalar nodes take one argument and
//! carry their unit in the name (`pixel-size-um 1.4`, `exposure-s 0.01`): the
//! properties of [`super::sensor_params::SCHEMA`], read by the same code as an
//! experiment's inline `sensor` properties. Block nodes are `qe` (one property
//! per CFA channel naming a spectrum), `qe-matrix` (three `row` children) and
//! `relative-illumination` ([`super::relative_illumination`]).
//! Validation is strict: an unknown name, a wrong type, a number without its
//! unit or an out-of-range value is an error at `file:line:col`, with the
//! nearest valid name suggested.

use super::config::SensorConfig;
use super::relative_illumination::parse_ri;
use super::sensor_params::{BLOCK_NAMES, SCHEMA, set_property};
use crate::diag::{Error, Located, did_you_mean};
use crate::params::{ParamDict, Params, Value};
use crate::spectrum::library;
use kdl::{KdlDocument, KdlNode, KdlValue};
use std::path::Path;

/// Suggestion text for an unknown name: a missing unit is called out explicitly.
fn suggestion(word: &str, names: &[&str]) -> Option<String> {
    if let Some(n) = names
        .iter()
        .find(|n| n.starts_with(word) && n.as_bytes().get(word.len()) == Some(&b'-'))
    {
        return Some(format!(
            "numbers carry their unit in the name: did you mean '{n}'?"
        ));
    }
    did_you_mean(word, names.iter().copied()).map(|s| format!("did you mean '{s}'?"))
}

impl SensorConfig {
    /// Read and validate a sensor file.
    pub fn load(path: &Path) -> crate::Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::parse(&text, path)
    }

    /// Parse a sensor file's text; `path` names it in diagnostics and anchors spectra.
    pub fn parse(text: &str, path: &Path) -> crate::Result<Self> {
        let doc = KdlDocument::parse(text).map_err(|e| {
            let d = e.diagnostics.first();
            let (off, len) = d.map(|d| (d.span.offset(), d.span.len())).unwrap_or((0, 1));
            let msg = d
                .and_then(|d| d.message.clone())
                .unwrap_or_else(|| "invalid KDL".into());
            let help = d.and_then(|d| d.help.clone());
            Located::at_offset(path, text, off, len, format!("KDL syntax: {msg}"))
                .with_help_opt(help)
        })?;
        let mut c = Self::generic();
        c.name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        c.source = path.to_path_buf();
        let base = c.base_dir();
        let at = |span: miette::SourceSpan, msg: String| -> Error {
            Located::at_offset(path, text, span.offset(), span.len(), msg).into()
        };
        let mut seen: Vec<String> = vec![];
        let mut cfa_span = None;
        let mut qe_span = None;
        for node in doc.nodes() {
            let name = node.name().value().to_string();
            let span = node.name().span();
            if seen.contains(&name) {
                return Err(at(span, format!("'{name}' is given twice")));
            }
            seen.push(name.clone());
            match name.as_str() {
                "qe" => {
                    qe_span = Some(node.span());
                    parse_qe(node, &mut c, &base, path, text)?;
                }
                "qe-matrix" => c.qe_matrix = Some(parse_matrix(node, path, text)?),
                "relative-illumination" => {
                    c.relative_illumination = parse_ri(node, &base, path, text)?
                }
                _ => {
                    if SCHEMA.get(&name).is_none() {
                        let mut all: Vec<&str> = SCHEMA.names();
                        all.extend_from_slice(BLOCK_NAMES);
                        let hint = suggestion(&name, &all);
                        return Err(Error::from(
                            Located::at_offset(
                                path,
                                text,
                                span.offset(),
                                span.len(),
                                format!("unknown sensor property '{name}'"),
                            )
                            .with_help_opt(hint),
                        ));
                    }
                    if name == "cfa" {
                        cfa_span = Some(node.span());
                    }
                    if node.children().is_some() {
                        return Err(at(
                            node.span(),
                            format!("'{name}' takes one value, not a block"),
                        ));
                    }
                    let entries = node.entries();
                    if let Some(p) = entries.iter().find(|e| e.name().is_some()) {
                        return Err(at(
                            p.span(),
                            format!("'{name}' takes one value, not properties"),
                        ));
                    }
                    if entries.len() != 1 {
                        return Err(at(
                            node.span(),
                            format!("'{name}' takes exactly one value, found {}", entries.len()),
                        ));
                    }
                    let e = &entries[0];
                    let v =
                        kdl_value(e.value()).map_err(|m| at(e.span(), format!("'{name}': {m}")))?;
                    // The same setter as an experiment's inline property.
                    let mut one = Params::new();
                    one.set(name.as_str(), v);
                    let d = ParamDict::new(&one, &SCHEMA);
                    set_property(&mut c, &d, &name).map_err(|m| at(e.span(), m.to_string()))?;
                }
            }
        }
        if let Err(m) = c.validate() {
            let span = qe_span.or(cfa_span).unwrap_or_else(|| (0, 1).into());
            return Err(at(span, m));
        }
        Ok(c)
    }
}

/// KDL value → parameter value.
pub fn kdl_value(v: &KdlValue) -> Result<Value, String> {
    Ok(match v {
        KdlValue::String(s) => Value::String(s.clone()),
        KdlValue::Integer(i) => Value::Number(*i as f64),
        KdlValue::Float(x) => Value::Number(*x),
        KdlValue::Bool(b) => Value::Bool(*b),
        KdlValue::Null => return Err("#null is not a value here".into()),
    })
}

pub(super) fn loc(path: &Path, text: &str, span: miette::SourceSpan, msg: String) -> Error {
    Located::at_offset(path, text, span.offset(), span.len(), msg).into()
}

fn parse_qe(
    node: &KdlNode,
    c: &mut SensorConfig,
    base: &Path,
    path: &Path,
    text: &str,
) -> crate::Result<()> {
    if node.children().is_some() {
        return Err(loc(
            path,
            text,
            node.span(),
            "'qe' takes properties, one per CFA channel (r=\"p4a-qe-r\" …)".into(),
        ));
    }
    let mut refs: Vec<(String, String, miette::SourceSpan)> = vec![];
    for e in node.entries() {
        let Some(ch) = e.name() else {
            return Err(loc(
                path,
                text,
                e.span(),
                "'qe' takes properties named by CFA channel, e.g. r=\"p4a-qe-r\"".into(),
            ));
        };
        let Some(s) = e.value().as_string() else {
            return Err(loc(
                path,
                text,
                e.span(),
                format!(
                    "qe channel '{}' expects a spectrum name or PATH.csv#column",
                    ch.value()
                ),
            ));
        };
        refs.push((ch.value().to_string(), s.to_string(), e.span()));
    }
    c.qe_refs.clear();
    c.qe.clear();
    // Order by the CFA's channels; the cfa node may come later, so keep file order and
    // reorder in `validate_qe_order` below.
    let channels = ["r", "g", "b", "w"];
    for (ch, r, span) in &refs {
        if !channels.contains(&ch.as_str()) {
            let hint = did_you_mean(ch, channels).map(|s| format!("did you mean '{s}'?"));
            return Err(Error::from(
                Located::at_offset(
                    path,
                    text,
                    span.offset(),
                    span.len(),
                    format!("unknown CFA channel '{ch}' (r, g, b, or w for mono)"),
                )
                .with_help_opt(hint),
            ));
        }
        let s = library::resolve(r, base).map_err(|m| loc(path, text, *span, m))?;
        c.qe_refs.push(format!("{ch}={r}"));
        c.qe.push(s);
    }
    // Canonical order r, g, b (CfaPattern::bayer uses channel indices 0=r, 1=g, 2=b).
    let mut order: Vec<usize> = (0..refs.len()).collect();
    order.sort_by_key(|&i| channels.iter().position(|c| *c == refs[i].0).unwrap_or(9));
    c.qe = order.iter().map(|&i| c.qe[i].clone()).collect();
    c.qe_refs = order.iter().map(|&i| c.qe_refs[i].clone()).collect();
    let names: Vec<&str> = order.iter().map(|&i| refs[i].0.as_str()).collect();
    if !(names == ["r", "g", "b"] || names == ["w"]) {
        return Err(loc(
            path,
            text,
            node.span(),
            format!("'qe' needs r, g and b (or w for a mono sensor), found {names:?}"),
        ));
    }
    Ok(())
}

fn parse_matrix(node: &KdlNode, path: &Path, text: &str) -> crate::Result<Vec<Vec<f64>>> {
    let Some(ch) = node.children() else {
        return Err(loc(
            path,
            text,
            node.span(),
            "'qe-matrix' takes a block of rows: qe-matrix { row 1 0 0; … }".into(),
        ));
    };
    if !node.entries().is_empty() {
        return Err(loc(
            path,
            text,
            node.span(),
            "'qe-matrix' takes only a block of rows".into(),
        ));
    }
    let mut m = vec![];
    for r in ch.nodes() {
        if r.name().value() != "row" {
            return Err(loc(
                path,
                text,
                r.name().span(),
                format!("expected 'row', found '{}'", r.name().value()),
            ));
        }
        let mut row = vec![];
        for e in r.entries() {
            let x = match (e.name(), e.value()) {
                (None, KdlValue::Integer(i)) => *i as f64,
                (None, KdlValue::Float(x)) if x.is_finite() => *x,
                _ => {
                    return Err(loc(
                        path,
                        text,
                        e.span(),
                        "matrix entries are plain numbers".into(),
                    ));
                }
            };
            row.push(x);
        }
        m.push(row);
    }
    let n = m.len();
    if n == 0 || m.iter().any(|r| r.len() != n) {
        return Err(loc(
            path,
            text,
            node.span(),
            format!(
                "'qe-matrix' must be square; found {n} rows of lengths {:?}",
                m.iter().map(|r| r.len()).collect::<Vec<_>>()
            ),
        ));
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::Exposure;

    fn parse(s: &str) -> crate::Result<SensorConfig> {
        SensorConfig::parse(s, Path::new("t.kdl"))
    }

    #[test]
    fn unknown_and_unitless_names_are_located_with_help() {
        let e = parse("bit-depth 10\npixel-size 1.4\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("t.kdl:2:1:"), "{e}");
        assert!(e.contains("pixel-size-um"), "{e}");
        let e = parse("exposure-ms 10\n").unwrap_err().to_string();
        assert!(e.contains("did you mean 'exposure-s'"), "{e}");
    }

    #[test]
    fn wrong_types_and_ranges() {
        let e = parse("bit-depth \"ten\"\n").unwrap_err().to_string();
        assert!(
            e.contains("t.kdl:1:11") && e.contains("expected a whole number"),
            "{e}"
        );
        assert!(
            parse("fill-factor 100\n")
                .unwrap_err()
                .to_string()
                .contains("fraction")
        );
        assert!(parse("bit-depth 10.5\n").is_err());
        assert!(
            parse("photon-noise 1\n")
                .unwrap_err()
                .to_string()
                .contains("#true")
        );
        assert!(parse("black-level-dv 2000\n").is_err());
        assert!(parse("read-noise-mv -1\n").is_err());
        assert!(
            parse("rows 10\nrows 12\n")
                .unwrap_err()
                .to_string()
                .contains("twice")
        );
        assert!(parse("qe r=\"p4a-qe-r\" g=\"p4a-qe-g\"\n").is_err());
        assert!(
            parse("qe r=\"p4a-qe-r\" g=\"p4a-qe-g\" b=\"p4a-qe-bb\"\n")
                .unwrap_err()
                .to_string()
                .contains("did you mean")
        );
        assert!(parse("exposure-s \"later\"\n").is_err());
        let e = parse("exposure-s \"auto\"\nauto-exposure-percentile 150\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("(0, 100]"), "{e}");
        let c = parse("exposure-s \"auto\"\nauto-exposure-percentile 100\n").unwrap();
        assert_eq!(
            c.exposure,
            Exposure::Auto {
                level: 0.95,
                percentile: 100.0
            }
        );
        assert!(
            parse("garbage {{{")
                .unwrap_err()
                .to_string()
                .starts_with("t.kdl:")
        );
    }
}
