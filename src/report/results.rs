//! Reading and writing `results.csv` rows and curve CSVs.

use crate::measure::Curve;
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::path::Path;

/// One row of `results.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct ResultRow {
    pub experiment: String,
    pub variant: String,
    /// Swept parameters of the variant, in column order.
    pub params: Vec<(String, String)>,
    pub measurement: String,
    pub quantity: String,
    pub unit: String,
    pub value: f64,
    pub stderr: f64,
    pub render_s: f64,
    pub total_s: f64,
}

impl ResultRow {
    /// Identity of a figure across runs.
    pub fn key(&self) -> (String, String, String, String) {
        (
            self.experiment.clone(),
            self.variant.clone(),
            self.measurement.clone(),
            self.quantity.clone(),
        )
    }
}

const FIXED: [&str; 9] = [
    "experiment",
    "variant",
    "measurement",
    "quantity",
    "unit",
    "value",
    "stderr",
    "render_s",
    "total_s",
];

/// Parse `results.csv` text; `origin` names the file in errors.
pub fn parse_results(text: &str, origin: &str) -> Result<Vec<ResultRow>> {
    let mut rd = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let header: Vec<String> = rd
        .headers()
        .map_err(|e| Error::invalid(format!("{origin}: {e}")))?
        .iter()
        .map(|s| s.to_string())
        .collect();
    let col = |n: &str| header.iter().position(|h| h == n);
    let mut idx = BTreeMap::new();
    for n in FIXED {
        let i = col(n).ok_or_else(|| {
            Error::invalid(format!(
                "{origin}:1: missing column '{n}' (have {})",
                header.join(",")
            ))
        })?;
        idx.insert(n, i);
    }
    let params: Vec<(usize, String)> = header
        .iter()
        .enumerate()
        .filter(|(_, h)| !FIXED.contains(&h.as_str()))
        .map(|(i, h)| (i, h.clone()))
        .collect();
    let mut rows = vec![];
    for (line, rec) in rd.records().enumerate() {
        let rec = rec.map_err(|e| Error::invalid(format!("{origin}: {e}")))?;
        let lineno = line + 2;
        let s = |n: &str| rec.get(idx[n]).unwrap_or("").to_string();
        let num = |n: &str| -> Result<f64> {
            let t = s(n);
            if t.is_empty() {
                return Ok(0.0);
            }
            t.parse::<f64>().map_err(|_| {
                Error::invalid(format!(
                    "{origin}:{lineno}: column '{n}': '{t}' is not a number"
                ))
            })
        };
        let value = num("value")?;
        if !value.is_finite() {
            return Err(Error::invalid(format!(
                "{origin}:{lineno}: value is not finite"
            )));
        }
        rows.push(ResultRow {
            experiment: s("experiment"),
            variant: s("variant"),
            params: params
                .iter()
                .map(|(i, h)| (h.clone(), rec.get(*i).unwrap_or("").to_string()))
                .collect(),
            measurement: s("measurement"),
            quantity: s("quantity"),
            unit: s("unit"),
            value,
            stderr: num("stderr")?,
            render_s: num("render_s")?,
            total_s: num("total_s")?,
        });
    }
    Ok(rows)
}

/// The `variant` column of the rows written by the cross-variant `summary` stage.
pub const SUMMARY_VARIANT: &str = "summary";

pub fn read_results(path: &Path) -> Result<Vec<ResultRow>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_results(&text, &path.display().to_string())
}

/// Write rows (all with the same parameter names) atomically.
pub fn write_results(path: &Path, rows: &[ResultRow]) -> Result<()> {
    let pnames: Vec<String> = rows
        .first()
        .map(|r| r.params.iter().map(|p| p.0.clone()).collect())
        .unwrap_or_default();
    let mut w = csv::Writer::from_writer(vec![]);
    let mut head = vec!["experiment".to_string(), "variant".into()];
    head.extend(pnames.iter().cloned());
    head.extend(
        [
            "measurement",
            "quantity",
            "unit",
            "value",
            "stderr",
            "render_s",
            "total_s",
        ]
        .map(String::from),
    );
    w.write_record(&head).map_err(|e| Error::io(path, e))?;
    for r in rows {
        let mut rec = vec![r.experiment.clone(), r.variant.clone()];
        for n in &pnames {
            rec.push(
                r.params
                    .iter()
                    .find(|p| &p.0 == n)
                    .map(|p| p.1.clone())
                    .unwrap_or_default(),
            );
        }
        rec.extend([
            r.measurement.clone(),
            r.quantity.clone(),
            r.unit.clone(),
            format!("{}", r.value),
            format!("{}", r.stderr),
            format!("{}", r.render_s),
            format!("{}", r.total_s),
        ]);
        w.write_record(&rec).map_err(|e| Error::io(path, e))?;
    }
    let bytes = w.into_inner().map_err(|e| Error::io(path, e))?;
    crate::diag::write_atomic(path, &bytes)
}

/// Write `dir/curves/<variant>/<measurement>.csv`.
pub fn write_curves(dir: &Path, variant: &str, measurement: &str, curves: &[Curve]) -> Result<()> {
    let path = dir
        .join("curves")
        .join(variant)
        .join(format!("{measurement}.csv"));
    let mut w = csv::Writer::from_writer(vec![]);
    w.write_record([
        "curve", "x_name", "x_unit", "y_name", "y_unit", "x", "y", "stderr",
    ])
    .map_err(|e| Error::io(&path, e))?;
    for c in curves {
        for i in 0..c.x.len() {
            let se = c.stderr.get(i).map(|s| format!("{s}")).unwrap_or_default();
            w.write_record([
                &c.name,
                &c.x_name,
                &c.x_unit,
                &c.y_name,
                &c.y_unit,
                &format!("{}", c.x[i]),
                &format!("{}", c.y[i]),
                &se,
            ])
            .map_err(|e| Error::io(&path, e))?;
        }
    }
    let bytes = w.into_inner().map_err(|e| Error::io(&path, e))?;
    crate::diag::write_atomic(&path, &bytes)
}

/// Read one curve CSV (points with a non-finite x or y are dropped).
pub fn read_curves(path: &Path) -> Result<Vec<Curve>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut rd = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let mut out: Vec<Curve> = vec![];
    for (i, rec) in rd.records().enumerate() {
        let rec = rec.map_err(|e| Error::io(path, e))?;
        if rec.len() < 7 {
            return Err(Error::io(
                path,
                format!(
                    "line {}: expected curve,x_name,x_unit,y_name,y_unit,x,y[,stderr]",
                    i + 2
                ),
            ));
        }
        let num = |k: usize| rec.get(k).and_then(|s| s.parse::<f64>().ok());
        let (Some(x), Some(y)) = (num(5), num(6)) else {
            return Err(Error::io(
                path,
                format!("line {}: x and y must be numbers", i + 2),
            ));
        };
        let name = &rec[0];
        if out.last().is_none_or(|c| c.name != name) {
            out.push(Curve::new(
                name,
                (&rec[1], &rec[2]),
                (&rec[3], &rec[4]),
                vec![],
                vec![],
                vec![],
            ));
        }
        if x.is_finite() && y.is_finite() {
            let c = out.last_mut().expect("pushed above");
            c.x.push(x);
            c.y.push(y);
            if let Some(s) = num(7) {
                c.stderr.push(s);
            }
        }
    }
    for c in &mut out {
        if c.stderr.len() != c.x.len() {
            c.stderr.clear();
        }
    }
    Ok(out)
}

/// Rows for `results.csv` from a variant's measured figures.
pub fn rows_from_figures(
    experiment: &str,
    variant: &str,
    params: &[(String, String)],
    figures: &[crate::figure::Figure],
    render_s: f64,
    total_s: f64,
) -> Vec<ResultRow> {
    figures
        .iter()
        .map(|f| ResultRow {
            experiment: experiment.into(),
            variant: variant.into(),
            params: params.to_vec(),
            measurement: f.measurement.clone(),
            quantity: f.quantity.clone(),
            unit: f.unit.clone(),
            value: f.value,
            stderr: f.stderr,
            render_s,
            total_s,
        })
        .collect()
}

/// Write `dir/previews/<variant>/<name>.png` (8-bit grey or RGB, `channels`
/// 1 or 3, row-major) and, when `rois` is not empty, `<name>.rois.json`
/// with the labelled rectangles (pixels of that image) the report overlays.
pub fn write_preview(
    dir: &Path,
    variant: &str,
    name: &str,
    (w, h, channels): (u32, u32, usize),
    pixels: &[u8],
    rois: &[(String, crate::optical_image::Rect)],
) -> Result<()> {
    let base = dir.join("previews").join(variant);
    let path = base.join(format!("{name}.png"));
    if pixels.len() != w as usize * h as usize * channels || !(channels == 1 || channels == 3) {
        return Err(Error::invalid(format!(
            "preview {}: {} bytes for {w}×{h}×{channels}",
            path.display(),
            pixels.len()
        )));
    }
    let mut buf = vec![];
    {
        let mut e = png::Encoder::new(&mut buf, w, h);
        e.set_color(if channels == 1 {
            png::ColorType::Grayscale
        } else {
            png::ColorType::Rgb
        });
        e.set_depth(png::BitDepth::Eight);
        let mut wr = e.write_header().map_err(|e| Error::io(&path, e))?;
        wr.write_image_data(pixels)
            .map_err(|e| Error::io(&path, e))?;
        wr.finish().map_err(|e| Error::io(&path, e))?;
    }
    crate::diag::write_atomic(&path, &buf)?;
    if !rois.is_empty() {
        let list: Vec<serde_json::Value> = rois
            .iter()
            .map(|(l, r)| serde_json::json!({"label": l, "x": r.x, "y": r.y, "w": r.w, "h": r.h}))
            .collect();
        let p = base.join(format!("{name}.rois.json"));
        let text = serde_json::to_string_pretty(&list).map_err(|e| Error::io(&p, e))?;
        crate::diag::write_atomic(&p, text.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn results_and_curves_roundtrip() {
        let dir = tempfile::tempdir().unwrap();
        let row = ResultRow {
            experiment: "e".into(),
            variant: "v1".into(),
            params: vec![("focus-m".into(), "0.3".into())],
            measurement: "sfr".into(),
            quantity: "mtf50".into(),
            unit: "cy/px".into(),
            value: 0.25,
            stderr: 0.001,
            render_s: 1.5,
            total_s: 2.0,
        };
        let p = dir.path().join("results.csv");
        write_results(&p, std::slice::from_ref(&row)).unwrap();
        assert_eq!(read_results(&p).unwrap(), vec![row]);
        let c = Curve::new(
            "mtf",
            ("frequency", "cy/px"),
            ("mtf", "1"),
            vec![0.0, 0.5],
            vec![1.0, 0.4],
            vec![0.0, 0.01],
        );
        write_curves(dir.path(), "v1", "sfr", std::slice::from_ref(&c)).unwrap();
        assert_eq!(
            read_curves(&dir.path().join("curves/v1/sfr.csv")).unwrap(),
            vec![c]
        );
        let e = parse_results("experiment,variant,value\n", "x.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.csv:1: missing column 'measurement'"), "{e}");
        let e = parse_results(
            "experiment,variant,measurement,quantity,unit,value,stderr,render_s,total_s\ne,v,m,q,u,abc,0,0,0\n",
            "y.csv",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("y.csv:2") && e.contains("abc"), "{e}");
    }
}
