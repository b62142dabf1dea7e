//! Pixel/microlens relative illumination applied at the sensor (issue 5 item 4):
//! the models, the `relative-illumination` block of a sensor file, and the
//! `field_height_mm,relative_illumination` CSV that `camsim lens ri` writes.

use crate::diag::{Error, Located, did_you_mean};
use kdl::{KdlNode, KdlValue};
use std::path::Path;

/// Pixel/microlens relative illumination applied at the sensor (issue 5 item 4),
/// as a function of image-side field height from the sensor centre.
#[derive(Clone, Debug, PartialEq)]
pub enum RelativeIllumination {
    None,
    /// cos^n of the chief-ray angle atan(h / distance).
    CosN {
        n: f64,
        distance_mm: f64,
    },
    /// Measured table, linear in field height; beyond the last point the last value holds.
    Table {
        field_height_mm: Vec<f64>,
        value: Vec<f64>,
    },
}

impl RelativeIllumination {
    /// Relative illumination at field height `h_mm` (1 on axis for the models above).
    pub fn at(&self, h_mm: f64) -> f64 {
        match self {
            RelativeIllumination::None => 1.0,
            RelativeIllumination::CosN { n, distance_mm } => {
                let c = distance_mm / (distance_mm * distance_mm + h_mm * h_mm).sqrt();
                c.powf(*n)
            }
            RelativeIllumination::Table {
                field_height_mm: h,
                value: v,
            } => {
                if h_mm <= h[0] {
                    return v[0];
                }
                let i = h.partition_point(|&x| x < h_mm);
                if i >= h.len() {
                    return v[v.len() - 1];
                }
                let t = (h_mm - h[i - 1]) / (h[i] - h[i - 1]);
                v[i - 1] + t * (v[i] - v[i - 1])
            }
        }
    }
}

/// Parse the `relative-illumination` node of a sensor file (`base`: the file's directory).
pub(super) fn parse_ri(
    node: &KdlNode,
    base: &Path,
    path: &Path,
    text: &str,
) -> crate::Result<RelativeIllumination> {
    let args: Vec<_> = node
        .entries()
        .iter()
        .filter(|e| e.name().is_none())
        .collect();
    let model = match args.as_slice() {
        [a] => a.value().as_string().map(str::to_string).ok_or_else(|| {
            loc(
                path,
                text,
                a.span(),
                "relative-illumination model is a string: \"none\", \"cos-n\" or \"table\"".into(),
            )
        })?,
        _ => {
            return Err(loc(
                path,
                text,
                node.span(),
                "relative-illumination takes one model name: \"none\", \"cos-n\" or \"table\""
                    .into(),
            ));
        }
    };
    let prop = |n: &str| {
        node.entries()
            .iter()
            .find(|e| e.name().map(|i| i.value()) == Some(n))
    };
    let allowed: &[&str] = match model.as_str() {
        "none" => &[],
        "cos-n" => &["n", "distance-mm"],
        "table" => &["file"],
        m => {
            let hint =
                did_you_mean(m, ["none", "cos-n", "table"]).map(|s| format!("did you mean '{s}'?"));
            return Err(Error::from(
                Located::at_offset(
                    path,
                    text,
                    args[0].span().offset(),
                    args[0].span().len(),
                    format!("unknown relative-illumination model '{m}'"),
                )
                .with_help_opt(hint),
            ));
        }
    };
    for e in node.entries() {
        if let Some(n) = e.name()
            && !allowed.contains(&n.value())
        {
            let hint = did_you_mean(n.value(), allowed.iter().copied())
                .map(|s| format!("did you mean '{s}'?"));
            return Err(Error::from(
                Located::at_offset(
                    path,
                    text,
                    e.span().offset(),
                    e.span().len(),
                    format!(
                        "'{}' is not a property of model '{model}' (allowed: {allowed:?})",
                        n.value()
                    ),
                )
                .with_help_opt(hint),
            ));
        }
    }
    let number = |n: &str| -> crate::Result<f64> {
        let e = prop(n).ok_or_else(|| {
            loc(
                path,
                text,
                node.span(),
                format!("model '{model}' needs {n}=…"),
            )
        })?;
        match e.value() {
            KdlValue::Integer(i) => Ok(*i as f64),
            KdlValue::Float(x) if x.is_finite() => Ok(*x),
            _ => Err(loc(path, text, e.span(), format!("'{n}' expects a number"))),
        }
    };
    match model.as_str() {
        "none" => Ok(RelativeIllumination::None),
        "cos-n" => {
            let n = number("n")?;
            let d = number("distance-mm")?;
            if n < 0.0 || d <= 0.0 {
                return Err(loc(
                    path,
                    text,
                    node.span(),
                    format!("cos-n needs n ≥ 0 and distance-mm > 0, found n={n}, distance-mm={d}"),
                ));
            }
            Ok(RelativeIllumination::CosN { n, distance_mm: d })
        }
        _ => {
            if let Some(ch) = node.children() {
                if prop("file").is_some() {
                    return Err(loc(
                        path,
                        text,
                        node.span(),
                        "give the table as file=… or as point children, not both".into(),
                    ));
                }
                let mut h = vec![];
                let mut v = vec![];
                for p in ch.nodes() {
                    if p.name().value() != "point" {
                        return Err(loc(
                            path,
                            text,
                            p.name().span(),
                            format!(
                                "expected 'point field-height-mm=… value=…', found '{}'",
                                p.name().value()
                            ),
                        ));
                    }
                    let get = |n: &str| -> crate::Result<f64> {
                        let e = p
                            .entries()
                            .iter()
                            .find(|e| e.name().map(|i| i.value()) == Some(n))
                            .ok_or_else(|| {
                                loc(path, text, p.span(), format!("'point' needs {n}=…"))
                            })?;
                        match e.value() {
                            KdlValue::Integer(i) => Ok(*i as f64),
                            KdlValue::Float(x) if x.is_finite() => Ok(*x),
                            _ => Err(loc(path, text, e.span(), format!("'{n}' expects a number"))),
                        }
                    };
                    for e in p.entries() {
                        let ok = e.name().is_some_and(|n| {
                            n.value() == "field-height-mm" || n.value() == "value"
                        });
                        if !ok {
                            let hint = e
                                .name()
                                .and_then(|n| did_you_mean(n.value(), ["field-height-mm", "value"]))
                                .map(|s| format!("did you mean '{s}'?"));
                            return Err(Error::from(
                                Located::at_offset(
                                    path,
                                    text,
                                    e.span().offset(),
                                    e.span().len(),
                                    "'point' takes field-height-mm=… value=…",
                                )
                                .with_help_opt(hint),
                            ));
                        }
                    }
                    h.push(get("field-height-mm")?);
                    v.push(get("value")?);
                }
                table(h, v).map_err(|m| loc(path, text, node.span(), m))
            } else {
                let e = prop("file").ok_or_else(|| {
                    loc(
                        path,
                        text,
                        node.span(),
                        "table needs file=\"ri.csv\" or point children".into(),
                    )
                })?;
                let f = e.value().as_string().ok_or_else(|| {
                    loc(path, text, e.span(), "'file' expects a path string".into())
                })?;
                let p = base.join(f);
                let (h, v) = read_ri_csv(&p).map_err(|m| loc(path, text, e.span(), m))?;
                table(h, v).map_err(|m| loc(path, text, e.span(), format!("{}: {m}", p.display())))
            }
        }
    }
}

fn table(h: Vec<f64>, v: Vec<f64>) -> Result<RelativeIllumination, String> {
    if h.is_empty() {
        return Err("relative-illumination table is empty".into());
    }
    for i in 1..h.len() {
        if h[i] <= h[i - 1] {
            return Err(format!(
                "field heights must increase ({} then {} mm)",
                h[i - 1],
                h[i]
            ));
        }
    }
    if h.iter().chain(&v).any(|x| !x.is_finite()) || v.iter().any(|&x| x < 0.0) || h[0] < 0.0 {
        return Err("relative-illumination values must be finite and ≥ 0".into());
    }
    Ok(RelativeIllumination::Table {
        field_height_mm: h,
        value: v,
    })
}

/// Read `field_height_mm,relative_illumination` CSV (the output of `camsim lens ri`;
/// `#` comment lines allowed).
pub fn read_ri_csv(p: &Path) -> Result<(Vec<f64>, Vec<f64>), String> {
    let t = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
    let mut lines = t
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let header = lines
        .next()
        .ok_or_else(|| format!("{}: empty file", p.display()))?;
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    // `y_field_mm` is Zemax's name for the same column (its RI export).
    let hi = cols
        .iter()
        .position(|c| *c == "field_height_mm" || *c == "y_field_mm");
    let vi = cols.iter().position(|c| *c == "relative_illumination");
    let (Some(hi), Some(vi)) = (hi, vi) else {
        return Err(format!(
            "{}: header must name field_height_mm and relative_illumination, found '{header}'",
            p.display()
        ));
    };
    let (mut h, mut v) = (vec![], vec![]);
    for (n, l) in lines.enumerate() {
        let f: Vec<&str> = l.split(',').map(str::trim).collect();
        let g = |i: usize| -> Result<f64, String> {
            f.get(i)
                .and_then(|s| s.parse::<f64>().ok())
                .ok_or_else(|| format!("{}: data row {}: bad number in '{l}'", p.display(), n + 1))
        };
        h.push(g(hi)?);
        v.push(g(vi)?);
    }
    Ok((h, v))
}

/// A located error in a sensor file.
fn loc(path: &Path, text: &str, span: miette::SourceSpan, msg: String) -> crate::diag::Error {
    crate::diag::Located::at_offset(path, text, span.offset(), span.len(), msg).into()
}

#[cfg(test)]
mod tests {
    use crate::sensor::SensorConfig;
    use std::path::Path;

    fn parse(s: &str) -> crate::Result<SensorConfig> {
        SensorConfig::parse(s, Path::new("t.kdl"))
    }

    #[test]
    fn relative_illumination_models() {
        let c = parse("relative-illumination \"cos-n\" n=4 distance-mm=4.0\n").unwrap();
        let ri = &c.relative_illumination;
        assert_eq!(ri.at(0.0), 1.0);
        let expect = (4.0f64 / (16.0f64 + 9.0).sqrt()).powi(4);
        assert!((ri.at(3.0) - expect).abs() < 1e-12);
        let c = parse("relative-illumination \"table\" {\n point field-height-mm=0 value=1\n point field-height-mm=2 value=0.5\n}\n").unwrap();
        assert!((c.relative_illumination.at(1.0) - 0.75).abs() < 1e-12);
        assert_eq!(c.relative_illumination.at(5.0), 0.5);
        let e = parse("relative-illumination \"cos-n\" n=4 distance=4.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("distance-mm"), "{e}");
    }

    /// Linear between uneven points, held at both ends.
    #[test]
    fn table_interpolates_and_holds_its_ends() {
        let t = super::table(vec![0.5, 1.0, 3.0], vec![1.0, 0.9, 0.5]).unwrap();
        for (h, want) in [
            (0.0, 1.0),
            (0.5, 1.0),
            (0.75, 0.95),
            (1.0, 0.9),
            (2.0, 0.7),
            (3.0, 0.5),
            (9.0, 0.5),
        ] {
            assert!((t.at(h) - want).abs() < 1e-12, "{h}: {}", t.at(h));
        }
        let c = super::RelativeIllumination::CosN {
            n: 2.5,
            distance_mm: 2.0,
        };
        assert!((c.at(1.0) - (2.0 / 5.0f64.sqrt()).powf(2.5)).abs() < 1e-15);
        assert_eq!(super::RelativeIllumination::None.at(7.0), 1.0);
        assert!(super::table(vec![], vec![]).is_err());
        assert!(super::table(vec![0.0, 0.0], vec![1.0, 1.0]).is_err());
        assert!(super::table(vec![1.0, 0.5], vec![1.0, 1.0]).is_err());
        assert!(super::table(vec![-0.1, 0.5], vec![1.0, 1.0]).is_err());
        assert!(super::table(vec![0.0, 0.5], vec![1.0, -0.1]).is_err());
        assert!(super::table(vec![0.0, f64::NAN], vec![1.0, 1.0]).is_err());
        assert!(super::table(vec![0.0, 0.5], vec![1.0, f64::INFINITY]).is_err());
        assert!(super::table(vec![0.0], vec![0.0]).is_ok());
    }

    /// Each mistake in the block is refused at its place with what was expected.
    #[test]
    fn malformed_blocks_are_refused_with_the_reason() {
        let refuse = |s: &str, expect: &str| {
            let e = parse(s).unwrap_err().to_string();
            assert!(e.contains("t.kdl") && e.contains(expect), "{s} → {e}");
        };
        refuse("relative-illumination\n", "one model name");
        refuse(
            "relative-illumination \"none\" \"cos-n\"\n",
            "one model name",
        );
        refuse("relative-illumination 4\n", "model is a string");
        refuse(
            "relative-illumination \"cosn\" n=4\n",
            "unknown relative-illumination model",
        );
        refuse(
            "relative-illumination \"none\" n=4\n",
            "not a property of model 'none'",
        );
        refuse(
            "relative-illumination \"cos-n\" distance-mm=4\n",
            "needs n=",
        );
        refuse(
            "relative-illumination \"cos-n\" n=4\n",
            "needs distance-mm=",
        );
        refuse(
            "relative-illumination \"cos-n\" n=\"4\" distance-mm=4\n",
            "expects a number",
        );
        refuse(
            "relative-illumination \"cos-n\" n=-1 distance-mm=4\n",
            "n ≥ 0",
        );
        refuse(
            "relative-illumination \"cos-n\" n=4 distance-mm=0\n",
            "distance-mm > 0",
        );
        refuse("relative-illumination \"table\"\n", "needs file=");
        refuse("relative-illumination \"table\" file=3\n", "path string");
        refuse(
            "relative-illumination \"table\" file=\"ri.csv\" {\n point field-height-mm=0 value=1\n}\n",
            "not both",
        );
        refuse(
            "relative-illumination \"table\" {\n pt field-height-mm=0 value=1\n}\n",
            "found 'pt'",
        );
        refuse(
            "relative-illumination \"table\" {\n point field-height-mm=0\n}\n",
            "needs value=",
        );
        refuse(
            "relative-illumination \"table\" {\n point field-height-mm=0 valu=1\n}\n",
            "takes field-height-mm",
        );
        refuse(
            "relative-illumination \"table\" {\n point field-height-mm=0 value=\"1\"\n}\n",
            "expects a number",
        );
        refuse(
            "relative-illumination \"table\" {\n point field-height-mm=1 value=1\n point field-height-mm=0 value=1\n}\n",
            "must increase",
        );
        // Non-finite numbers (KDL's #inf, #nan) are not numbers here.
        refuse(
            "relative-illumination \"cos-n\" n=#inf distance-mm=4\n",
            "expects a number",
        );
        refuse(
            "relative-illumination \"table\" {\n point field-height-mm=0 value=#nan\n}\n",
            "expects a number",
        );
        // n = 0 is allowed: no fall-off.
        let c = parse("relative-illumination \"cos-n\" n=0 distance-mm=4\n").unwrap();
        assert_eq!(c.relative_illumination.at(3.0), 1.0);
        let c = parse("relative-illumination \"none\"\n").unwrap();
        assert_eq!(c.relative_illumination, super::RelativeIllumination::None);
    }

    /// The CSV `camsim lens ri` writes (or Zemax's `y_field_mm` export),
    /// comments and blank lines skipped, columns found by name.
    #[test]
    fn tables_are_read_from_csv() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("ri.csv");
        std::fs::write(
            &f,
            "# from lens ri\n\nrelative_illumination, y_field_mm\n1.0, 0\n0.5, 2\n",
        )
        .unwrap();
        assert_eq!(
            super::read_ri_csv(&f).unwrap(),
            (vec![0.0, 2.0], vec![1.0, 0.5])
        );
        let kdl = dir.path().join("s.kdl");
        let c =
            SensorConfig::parse("relative-illumination \"table\" file=\"ri.csv\"\n", &kdl).unwrap();
        assert!((c.relative_illumination.at(1.0) - 0.75).abs() < 1e-12);
        for (text, expect) in [
            ("", "empty file"),
            ("# only a comment\n", "empty file"),
            ("h,v\n0,1\n", "header must name"),
            (
                "field_height_mm,relative_illumination\n0,1\n1,x\n",
                "data row 2",
            ),
            ("field_height_mm,relative_illumination\n0\n", "data row 1"),
        ] {
            std::fs::write(&f, text).unwrap();
            let e = super::read_ri_csv(&f).unwrap_err();
            assert!(e.contains("ri.csv") && e.contains(expect), "{text:?} → {e}");
        }
        std::fs::write(&f, "field_height_mm,relative_illumination\n1,1\n0,1\n").unwrap();
        let e = SensorConfig::parse("relative-illumination \"table\" file=\"ri.csv\"\n", &kdl)
            .unwrap_err()
            .to_string();
        assert!(e.contains("s.kdl") && e.contains("must increase"), "{e}");
        assert!(super::read_ri_csv(&dir.path().join("none.csv")).is_err());
    }
}
