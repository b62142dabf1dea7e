//! A simulated curve against a reference curve from a CSV file: relative
//! illumination against Zemax's, an MTF against a measured one (paper Figs 5
//! and 7). One general measurement: `measure "compare-curve" of="<measurement>"
//! curve="<curve name>" reference-file="…csv"`.
//!
//! The simulated curve is interpolated linearly at the reference's abscissae
//! that lie inside both curves' spans (and inside `x-range-curve-unit`), and
//! the differences simulated − reference give `max_abs_diff`, `rmse`,
//! `mean_diff` and `pairs`. With `crossing-level=L` both curves' first
//! downward crossing of L is reported (`simulated_x@L`, `reference_x@L`: an
//! MTF50 when L = 0.5), so a figure's simulated and reference values stand
//! side by side.
//!
//! Standard errors come from the simulated curve's own per-point standard
//! errors (the reference is taken as exact): at the arg-max for
//! `max_abs_diff`; `√Σ(dᵢ·seᵢ)²/(n·rmse)` for the RMSE (delta method);
//! `√Σseᵢ²/n` for the mean difference (points treated as independent, which
//! RI annuli and MTF bins of one edge only approximately are); a crossing's
//! as half the distance between the crossings of the curve's ±1σ band (on a
//! straight stretch the delta method se(y)/|dy/dx|; on a flat or noisy MTF
//! the slope at the crossing would understate it many times over).
//!
//! The overlay is written as two curves named `<curve>#simulated` and
//! `<curve>#reference`, which the report draws as series of one chart.

use super::{Curve, Measured};
use crate::figure::Figure;
use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Schema};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// How each curve is scaled before the comparison.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Normalize {
    #[default]
    None,
    /// Each curve divided by its own maximum (relative illumination).
    Max,
}

/// The reference curve read from its CSV file.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceCurve {
    pub file: PathBuf,
    pub x_name: String,
    pub y_name: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
}

/// `measure "compare-curve"` options.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CompareCurveOptions {
    /// The curve of the `of` measurement (required), e.g. "ri" or "edge-near/mtf".
    pub curve: Option<String>,
    /// The reference (required), read and checked when the options are read.
    pub reference: Option<ReferenceCurve>,
    pub normalize: Normalize,
    pub x_range: Option<(f64, f64)>,
    pub crossing_level: Option<f64>,
    /// Unit the reference's abscissa is in, checked against the curve's.
    pub x_unit: Option<String>,
    /// The reference columns asked for (None: the first two).
    pub x_column: Option<String>,
    pub y_column: Option<String>,
    /// The rows kept: (column, value).
    pub reference_filter: Option<(String, f64)>,
    /// Factor applied to the reference ordinate.
    pub reference_y_scale: f64,
}

/// The properties of `measure "compare-curve"`.
pub static SCHEMA: Schema = Schema {
    node: "measure \"compare-curve\"",
    params: &[
        super::shared_params::name_param(),
        super::shared_params::of_param(
            "the measurement whose curve is compared (required; one)",
            "\"ri\"",
        ),
        ParamSpec::new(
            "curve",
            Kind::Text,
            "",
            "the curve of that measurement (required): its name in curves/<variant>/<measurement>.csv, e.g. \"ri\" or \"edge-near/mtf\"",
            "\"edge-far/mtf\"",
        ),
        ParamSpec::new(
            "reference-file",
            Kind::File,
            "",
            "CSV of the reference curve (required): '#' comment lines, a header row, numeric columns; looked up beside the experiment, then in its parents",
            "\"lenses/zemax-reference/zemax_p4a_geometric_mtf.csv\"",
        ),
        ParamSpec::new(
            "x-column",
            Kind::Text,
            "the first column",
            "reference column holding the abscissa, in the curve's x unit",
            "\"freq_cy_per_mm\"",
        ),
        ParamSpec::new(
            "y-column",
            Kind::Text,
            "the second column",
            "reference column holding the ordinate",
            "\"mtf_sagittal\"",
        ),
        ParamSpec::new(
            "reference-filter",
            Kind::Text,
            "all rows",
            "keep only reference rows whose column equals a number, \"column=value\" (e.g. one field of a Zemax table)",
            "\"field_mm=1.5\"",
        ),
        ParamSpec::new(
            "reference-y-scale-factor",
            Kind::Number,
            "1",
            "factor on the reference ordinate (0.01 for a curve in percent)",
            "0.037",
        ),
        ParamSpec::new(
            "x-unit",
            Kind::Text,
            "unchecked",
            "the unit of the reference's abscissa; must equal the simulated curve's x unit (e.g. \"mm\", \"cy/mm\")",
            "\"cy/mm\"",
        ),
        ParamSpec::new(
            "normalize",
            Kind::Choice(&["none", "max"]),
            "none",
            "\"max\" divides each curve by its own maximum first (relative illumination)",
            "\"max\"",
        ),
        ParamSpec::new(
            "x-range-curve-unit",
            Kind::Numbers,
            "both curves' common span",
            "(from to): compare only there, in the curve's x unit",
            "(0.25 2.75)",
        ),
        ParamSpec::new(
            "crossing-level",
            Kind::Number,
            "none",
            "also report where each curve first falls through this level (0.5: MTF50), in the x unit",
            "0.37",
        ),
    ],
};

/// Read `x_col`/`y_col` (default: the first two columns) of a CSV with `#`
/// comment lines and a header, keeping rows where `filter` holds.
pub fn read_reference(
    path: &Path,
    x_col: Option<&str>,
    y_col: Option<&str>,
    filter: Option<(&str, f64)>,
) -> std::result::Result<ReferenceCurve, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let (_, head) = lines
        .next()
        .ok_or_else(|| format!("{}: no header row", path.display()))?;
    let cols: Vec<&str> = head.split(',').map(str::trim).collect();
    let col = |name: Option<&str>, default: usize| -> std::result::Result<usize, String> {
        match name {
            None if default < cols.len() => Ok(default),
            None => Err(format!(
                "{}: needs at least two columns (header: {head})",
                path.display()
            )),
            Some(n) => cols.iter().position(|c| *c == n).ok_or_else(|| {
                format!(
                    "{}: no column '{n}'; its columns: {}",
                    path.display(),
                    cols.join(", ")
                )
            }),
        }
    };
    let (xi, yi) = (col(x_col, 0)?, col(y_col, 1)?);
    let fi = filter
        .map(|(c, v)| col(Some(c), 0).map(|i| (i, v)))
        .transpose()?;
    let (mut x, mut y) = (vec![], vec![]);
    for (ln, l) in lines {
        let f: Vec<&str> = l.split(',').map(str::trim).collect();
        let num = |i: usize| -> std::result::Result<f64, String> {
            f.get(i)
                .and_then(|s| s.parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    format!(
                        "{}:{}: column {} is not a finite number: '{l}'",
                        path.display(),
                        ln + 1,
                        i + 1
                    )
                })
        };
        if let Some((i, v)) = fi
            && num(i)? != v
        {
            continue;
        }
        x.push(num(xi)?);
        y.push(num(yi)?);
    }
    if x.len() < 2 {
        return Err(format!(
            "{}: fewer than 2 reference points{}",
            path.display(),
            if filter.is_some() {
                " after reference-filter"
            } else {
                ""
            }
        ));
    }
    let mut idx: Vec<usize> = (0..x.len()).collect();
    idx.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    Ok(ReferenceCurve {
        file: path.to_path_buf(),
        x_name: cols[xi].to_string(),
        y_name: cols[yi].to_string(),
        x: idx.iter().map(|&i| x[i]).collect(),
        y: idx.iter().map(|&i| y[i]).collect(),
    })
}

/// Read `measure "compare-curve"` (see [`SCHEMA`]); the reference file is read here,
/// so a missing file or column is an error at `check`.
pub fn from_params(
    d: &ParamDict,
    base_dir: &Path,
) -> std::result::Result<CompareCurveOptions, ParamError> {
    let curve = super::shared_params::nonempty(d, "curve")?;
    let x_col = super::shared_params::nonempty(d, "x-column")?;
    let y_col = super::shared_params::nonempty(d, "y-column")?;
    let filter = match super::shared_params::nonempty(d, "reference-filter")? {
        None => None,
        Some(s) => {
            let bad = || {
                ParamError::value(
                    "reference-filter",
                    format!("reference-filter '{s}': expected \"column=number\""),
                )
                .with_help("e.g. reference-filter=\"field_mm=0\"")
            };
            let (c, v) = s.split_once('=').ok_or_else(bad)?;
            let v: f64 = v.trim().parse().map_err(|_| bad())?;
            Some((c.trim().to_string(), v))
        }
    };
    let scale = d.f64("reference-y-scale-factor")?.unwrap_or(1.0);
    if !(scale.is_finite() && scale != 0.0) {
        return Err(ParamError::value(
            "reference-y-scale-factor",
            "reference-y-scale-factor must be a finite, non-zero number",
        ));
    }
    let x_unit = super::shared_params::nonempty(d, "x-unit")?;
    let normalize = match d.choice("normalize")? {
        Some("max") => Normalize::Max,
        _ => Normalize::None,
    };
    let x_range = match d.f64s("x-range-curve-unit")? {
        None => None,
        Some(v) if v.len() == 2 && v[0] < v[1] => Some((v[0], v[1])),
        Some(_) => {
            return Err(ParamError::value(
                "x-range-curve-unit",
                "x-range-curve-unit: expected (from to) with from < to",
            ));
        }
    };
    let crossing_level = d.f64("crossing-level")?;
    let reference = match super::shared_params::nonempty(d, "reference-file")? {
        None => None,
        Some(w) => {
            let p = crate::diag::find_up(&w, base_dir, Path::is_file).ok_or_else(|| {
                ParamError::value("reference-file", format!("reference file '{w}' not found"))
                    .with_help(format!(
                        "relative paths are looked up in {} and then in each parent directory",
                        base_dir.display()
                    ))
            })?;
            let mut r = read_reference(
                &p,
                x_col.as_deref(),
                y_col.as_deref(),
                filter.as_ref().map(|(c, v)| (c.as_str(), *v)),
            )
            .map_err(|e| ParamError::value("reference-file", e))?;
            for v in &mut r.y {
                *v *= scale;
            }
            Some(r)
        }
    };
    Ok(CompareCurveOptions {
        curve,
        reference,
        normalize,
        x_range,
        crossing_level,
        x_unit,
        x_column: x_col,
        y_column: y_col,
        reference_filter: filter,
        reference_y_scale: scale,
    })
}

/// Linear interpolation of (x, y) at `t` (x increasing), None outside.
fn interp(x: &[f64], y: &[f64], t: f64) -> Option<f64> {
    if x.is_empty() || t < x[0] || t > x[x.len() - 1] {
        return None;
    }
    let i = x.partition_point(|&v| v < t);
    if i == 0 {
        return Some(y[0]);
    }
    let (x0, x1) = (x[i - 1], x[i]);
    let w = if x1 > x0 { (t - x0) / (x1 - x0) } else { 0.0 };
    Some(y[i - 1] + w * (y[i] - y[i - 1]))
}

/// First downward crossing of `level`: its x.
fn crossing(x: &[f64], y: &[f64], level: f64) -> Option<f64> {
    (1..x.len()).find_map(|i| {
        (y[i - 1] >= level && y[i] < level).then(|| {
            let w = (y[i - 1] - level) / (y[i - 1] - y[i]);
            x[i - 1] + w * (x[i] - x[i - 1])
        })
    })
}

/// Standard error of the first downward crossing of `level`: half
/// the distance between the crossings of the curve's ±1σ band, y + se and
/// y − se (a band edge that never crosses stands at the end of the span it
/// would lie beyond). On a straight stretch this is se(y)/|dy/dx|, the delta
/// method; where the curve is flat, or noise makes an earlier dip the first
/// crossing, the slope at the crossing understates it by orders of magnitude
/// (an MTF near 0.5 over a plateau), while the band's crossings see it.
fn crossing_stderr(x: &[f64], y: &[f64], se: &[f64], level: f64) -> f64 {
    let band = |sign: f64| -> Vec<f64> { y.iter().zip(se).map(|(v, e)| v + sign * e).collect() };
    let (first, last) = (x[0], x[x.len() - 1]);
    let upper = crossing(x, &band(1.0), level).unwrap_or(last);
    let lower = crossing(x, &band(-1.0), level).unwrap_or(first);
    (upper - lower).abs() / 2.0
}

/// Compare `sim` with the options' reference (see the module docs).
pub fn compare_curve(
    sim: &Curve,
    opts: &CompareCurveOptions,
    measurement: &str,
) -> Result<Measured> {
    let reference = opts.reference.as_ref().ok_or_else(|| {
        Error::invalid(format!(
            "compare-curve '{measurement}' needs reference-file"
        ))
    })?;
    if let Some(u) = &opts.x_unit
        && *u != sim.x_unit
    {
        return Err(Error::invalid(format!(
            "compare-curve '{measurement}': the reference is in {u} (x-unit) but curve '{}' is in {}",
            sim.name, sim.x_unit
        )));
    }
    // The simulated curve, sorted by x, finite points only.
    let mut idx: Vec<usize> = (0..sim.x.len())
        .filter(|&i| sim.x[i].is_finite() && sim.y[i].is_finite())
        .collect();
    idx.sort_by(|&a, &b| sim.x[a].total_cmp(&sim.x[b]));
    let sx: Vec<f64> = idx.iter().map(|&i| sim.x[i]).collect();
    let mut sy: Vec<f64> = idx.iter().map(|&i| sim.y[i]).collect();
    let mut sse: Vec<f64> = idx
        .iter()
        .map(|&i| sim.stderr.get(i).copied().unwrap_or(0.0))
        .collect();
    let (rx, mut ry) = (reference.x.clone(), reference.y.clone());
    if opts.normalize == Normalize::Max {
        let m = sy.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let r = ry.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        if !(m > 0.0 && r > 0.0) {
            return Err(Error::invalid(format!(
                "compare-curve '{measurement}': normalize=\"max\" needs positive maxima (simulated {m}, reference {r})"
            )));
        }
        sy.iter_mut().for_each(|v| *v /= m);
        sse.iter_mut().for_each(|v| *v /= m);
        ry.iter_mut().for_each(|v| *v /= r);
    }
    let (lo, hi) = opts.x_range.unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
    let mut d = vec![];
    for (&x, &y) in rx.iter().zip(&ry) {
        if x < lo || x > hi {
            continue;
        }
        if let (Some(s), Some(se)) = (interp(&sx, &sy, x), interp(&sx, &sse, x)) {
            d.push((x, s - y, se));
        }
    }
    if d.len() < 2 {
        return Err(Error::invalid(format!(
            "compare-curve '{measurement}': fewer than 2 reference points of {} fall inside curve '{}' ({} … {} {}){}",
            reference.file.display(),
            sim.name,
            sx.first().copied().unwrap_or(f64::NAN),
            sx.last().copied().unwrap_or(f64::NAN),
            sim.x_unit,
            if opts.x_range.is_some() {
                " and x-range-curve-unit"
            } else {
                ""
            }
        )));
    }
    let n = d.len() as f64;
    let (imax, &(_, dmax, se_max)) = d
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.1.abs().total_cmp(&b.1.1.abs()))
        .expect("d is not empty");
    let _ = imax;
    let mse = d.iter().map(|p| p.1 * p.1).sum::<f64>() / n;
    let rmse = mse.sqrt();
    let se_rmse = if rmse > 0.0 {
        d.iter().map(|p| (p.1 * p.2).powi(2)).sum::<f64>().sqrt() / (n * rmse)
    } else {
        0.0
    };
    let mean_diff = d.iter().map(|p| p.1).sum::<f64>() / n;
    let se_mean = d.iter().map(|p| p.2 * p.2).sum::<f64>().sqrt() / n;
    let yu = if opts.normalize == Normalize::Max {
        "1".to_string()
    } else {
        sim.y_unit.clone()
    };
    let mut figures = vec![
        Figure::new(measurement, "max_abs_diff", &yu, dmax.abs(), se_max),
        Figure::new(measurement, "rmse", &yu, rmse, se_rmse),
        Figure::new(measurement, "mean_diff", &yu, mean_diff, se_mean),
        Figure::new(measurement, "pairs", "1", n, 0.0),
    ];
    if let Some(level) = opts.crossing_level {
        let s = crossing(&sx, &sy, level).ok_or_else(|| {
            Error::invalid(format!(
                "compare-curve '{measurement}': curve '{}' never falls through {level}",
                sim.name
            ))
        })?;
        let r = crossing(&rx, &ry, level).ok_or_else(|| {
            Error::invalid(format!(
                "compare-curve '{measurement}': the reference never falls through {level}"
            ))
        })?;
        let se_x = crossing_stderr(&sx, &sy, &sse, level);
        figures.push(Figure::new(
            measurement,
            format!("simulated_x@{level}"),
            &sim.x_unit,
            s,
            se_x,
        ));
        figures.push(Figure::new(
            measurement,
            format!("reference_x@{level}"),
            &sim.x_unit,
            r,
            0.0,
        ));
        figures.push(Figure::new(
            measurement,
            format!("diff_x@{level}"),
            &sim.x_unit,
            s - r,
            se_x,
        ));
    }
    let overlay = |tag: &str, x: Vec<f64>, y: Vec<f64>, se: Vec<f64>| {
        Curve::new(
            &format!("{}#{tag}", sim.name),
            (&sim.x_name, &sim.x_unit),
            (&sim.y_name, &yu),
            x,
            y,
            se,
        )
    };
    let curves = vec![
        overlay("simulated", sx, sy, sse),
        overlay("reference", rx, ry, vec![]),
    ];
    Ok(Measured {
        figures,
        curves,
        pixels_read: vec![],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(x: Vec<f64>, y: Vec<f64>) -> CompareCurveOptions {
        CompareCurveOptions {
            curve: Some("c".into()),
            reference: Some(ReferenceCurve {
                file: "ref.csv".into(),
                x_name: "x".into(),
                y_name: "y".into(),
                x,
                y,
            }),
            ..Default::default()
        }
    }

    /// A curve that hovers just above the level over a plateau before it
    /// falls: one standard error lower and it would cross at the plateau's
    /// start, so the crossing is uncertain by about half the plateau, not by
    /// se/|slope| at the final drop (0.03/0.31 ≈ 0.1).
    #[test]
    fn crossing_on_a_plateau_is_as_uncertain_as_the_plateau_is_long() {
        let x: Vec<f64> = (0..6).map(f64::from).collect();
        let y = [1.0, 0.52, 0.51, 0.52, 0.51, 0.2];
        let se = [0.03; 6];
        let c = crossing(&x, &y, 0.5).unwrap();
        assert!((c - (4.0 + 0.01 / 0.31)).abs() < 1e-12);
        // band crossings: y − 0.03 at 0 + 0.47/0.48, y + 0.03 at 4 + 0.04/0.31
        let want = ((4.0 + 0.04 / 0.31) - 0.47 / 0.48) / 2.0;
        assert!((crossing_stderr(&x, &y, &se, 0.5) - want).abs() < 1e-12);
        // a band edge that never crosses stands at the span's end
        let flat = [0.52; 6];
        assert_eq!(crossing_stderr(&x, &flat, &se, 0.5), (5.0 - 0.0) / 2.0);
    }

    #[test]
    fn differences_at_the_reference_points() {
        // simulated y = 1 − x/4 (exact at any x), reference y = 1 − x/5
        let sx: Vec<f64> = (0..=8).map(|i| i as f64 * 0.5).collect();
        let sim = Curve::new(
            "c",
            ("x", "mm"),
            ("y", "1"),
            sx.clone(),
            sx.iter().map(|x| 1.0 - x / 4.0).collect(),
            vec![0.01; sx.len()],
        );
        let rx = vec![0.0, 1.0, 2.0, 3.0, 10.0];
        let ry: Vec<f64> = rx.iter().map(|x| 1.0 - x / 5.0).collect();
        let mut o = opts(rx, ry);
        o.crossing_level = Some(0.5);
        let m = compare_curve(&sim, &o, "cmp").unwrap();
        let get = |q: &str| m.figures.iter().find(|f| f.quantity == q).unwrap();
        // x = 10 lies outside the simulated span: 4 pairs, d = −x/20
        assert_eq!(get("pairs").value, 4.0);
        assert!((get("max_abs_diff").value - 0.15).abs() < 1e-12);
        assert!((get("mean_diff").value - (-0.3 / 4.0)).abs() < 1e-12);
        // crossings of 0.5: x = 2 (simulated), 2.5 (reference)
        assert!((get("simulated_x@0.5").value - 2.0).abs() < 1e-12);
        assert!((get("reference_x@0.5").value - 2.5).abs() < 1e-12);
        // se of the crossing: se_y / |slope| = 0.01 / 0.25 on a straight line
        // (the ±1σ band crosses 0.5 at x = 2 ± 0.04)
        assert!((get("simulated_x@0.5").stderr - 0.04).abs() < 1e-12);
        assert_eq!(m.curves[0].name, "c#simulated");
        assert_eq!(m.curves[1].name, "c#reference");
    }

    #[test]
    fn normalize_max_and_range_and_unit_check() {
        let sim = Curve::new(
            "ri",
            ("field height", "mm"),
            ("ri", "1"),
            vec![0.0, 1.0, 2.0],
            vec![2.0, 1.8, 1.0],
            vec![],
        );
        let mut o = opts(vec![0.0, 1.0, 2.0], vec![1.0, 0.9, 0.6]);
        o.normalize = Normalize::Max;
        o.x_range = Some((0.5, 2.0));
        let m = compare_curve(&sim, &o, "cmp").unwrap();
        let get = |q: &str| m.figures.iter().find(|f| f.quantity == q).unwrap().value;
        assert_eq!(get("pairs"), 2.0);
        assert!((get("max_abs_diff") - 0.1).abs() < 1e-12);
        o.x_unit = Some("cy/mm".into());
        assert!(compare_curve(&sim, &o, "cmp").is_err());
    }

    #[test]
    fn reference_csv_columns_filter_and_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.csv");
        std::fs::write(
            &p,
            "# comment\nfield_mm,freq,mtf\n0,0,1\n0,10,0.9\n1,0,1\n1,10,0.7\n",
        )
        .unwrap();
        let r = read_reference(&p, Some("freq"), Some("mtf"), Some(("field_mm", 1.0))).unwrap();
        assert_eq!(r.y, vec![1.0, 0.7]);
        assert!(read_reference(&p, Some("nope"), None, None).is_err());
        std::fs::write(&p, "a,b\n0,1\n1,x\n").unwrap();
        let e = read_reference(&p, None, None, None).unwrap_err();
        assert!(e.contains(":3:"), "{e}");
    }
}
