//! Self-contained HTML reports: `results/<experiment>/report.html` and
//! `results/index.html`, rendered with minijinja from templates embedded in
//! the binary. Plots are inline SVG (plotters), images inline PNG data URIs;
//! a strict Content-Security-Policy forbids any network access.
//!
//! Plots: every curve name of a measurement becomes one chart with one
//! series per variant (curves named `*_vs_time` on log–log axes; `scatter`
//! with the identity line; `std_vs_mean` as points). Curves named
//! `<chart>#<series>` share the chart `<chart>` (an overlay: simulated,
//! reference, noise floor, a model curve), one series each (per variant when
//! there are several; a series equal to one already drawn, such as a
//! reference every variant repeats, is drawn once), styled by the series
//! name: `counts` as histogram bars, `points…`/`regions…`/`levels…` as
//! points, anything else as a line. When the variants sweep a
//! numeric parameter, each figure of a measurement with at most 10 figures is
//! also plotted against it, with ±1 se. Tables have a row per variant, or a
//! row per quantity when a measurement has more than 10 (e.g. MCC means).

use super::plot::{PlotSpec, Series, Style, drawable_points, plot_svg};
use super::results::{ResultRow, read_curves, read_results};
use crate::{Error, Result};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

const CSS: &str = include_str!("templates/style.css");
const JS: &str = include_str!("templates/check.js");
const REPORT: &str = include_str!("templates/report.html");
const INDEX: &str = include_str!("templates/index.html");
pub(crate) const DIFF: &str = include_str!("templates/diff.html");

/// Render one of the embedded templates with `ctx`.
pub(crate) fn render(name: &str, src: &str, ctx: minijinja::Value) -> Result<String> {
    let mut env = minijinja::Environment::new();
    env.add_template(name, src)
        .map_err(|e| Error::invalid(format!("template {name}: {e}")))?;
    let t = env
        .get_template(name)
        .map_err(|e| Error::invalid(format!("template {name}: {e}")))?;
    t.render(ctx)
        .map_err(|e| Error::invalid(format!("template {name}: {e}")))
}

pub(crate) fn css() -> &'static str {
    CSS
}
pub(crate) fn js() -> &'static str {
    JS
}

/// A number with 5 significant digits (scientific outside 1e-3…1e6).
pub fn fmt_num(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if (1e-3..1e6).contains(&a) {
        let dec = (4 - a.log10().floor() as i32).clamp(0, 8) as usize;
        let s = format!("{v:.dec$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{v:.4e}")
    }
}

/// A standard error with 2 significant digits ("" when 0).
pub fn fmt_se(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return String::new();
    }
    let a = v.abs();
    if (1e-3..1e6).contains(&a) {
        let dec = (1 - a.log10().floor() as i32).clamp(0, 8) as usize;
        format!("{v:.dec$}")
    } else {
        format!("{v:.1e}")
    }
}

fn base64(bytes: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(T[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

#[derive(Serialize)]
struct VariantRow {
    name: String,
    params: Vec<String>,
    render_s: String,
    total_s: String,
    /// `hit`, `miss`, `off` (optical-image cache) or `—`.
    oi_cache: String,
}

#[derive(Serialize)]
struct Cell {
    value: String,
    stderr: String,
    /// `budget reached`: error-driven sampling stopped before this figure
    /// met its target (empty otherwise).
    flag: String,
}

#[derive(Serialize)]
struct MRow {
    variant: String,
    cells: Vec<Cell>,
}

#[derive(Serialize)]
struct PlotOut {
    id: String,
    svg: String,
    points: usize,
}

/// A figure table: `head` column titles after the first (label) column.
#[derive(Serialize)]
struct MeasOut {
    name: String,
    /// Flagged convergence slopes, with their likely reason.
    notes: Vec<String>,
    corner: String,
    head: Vec<String>,
    rows: Vec<MRow>,
    plots: Vec<PlotOut>,
}

#[derive(Serialize)]
struct ImageOut {
    svg: String,
    caption: String,
    /// Files saved beside the pictures (`save "dng"`): (relative link, name).
    files: Vec<(String, String)>,
}

fn read_manifest(dir: &Path) -> Result<Option<serde_json::Value>> {
    let p = dir.join("manifest.json");
    if !p.exists() {
        return Ok(None);
    }
    let t = std::fs::read_to_string(&p).map_err(|e| Error::io(&p, e))?;
    serde_json::from_str(&t)
        .map(Some)
        .map_err(|e| Error::io(&p, format!("line {} column {}: {e}", e.line(), e.column())))
}

fn scalar(v: &serde_json::Value) -> Option<String> {
    match v {
        serde_json::Value::String(s) => Some(s.clone()),
        serde_json::Value::Number(n) => {
            Some(n.as_f64().map(fmt_num).unwrap_or_else(|| n.to_string()))
        }
        serde_json::Value::Bool(b) => Some(b.to_string()),
        _ => None,
    }
}

fn status_class(s: &str) -> &'static str {
    match s.to_ascii_lowercase().as_str() {
        "ok" | "done" | "passed" | "success" => "ok",
        "failed" | "error" => "bad",
        _ => "warn",
    }
}

/// Variants in first-appearance order.
fn variant_order(rows: &[ResultRow]) -> Vec<String> {
    let mut v: Vec<String> = vec![];
    for r in rows {
        if !v.contains(&r.variant) {
            v.push(r.variant.clone());
        }
    }
    v
}

fn plot_for(id: String, spec: PlotSpec, series: Vec<Series>) -> Option<PlotOut> {
    let points = drawable_points(&spec, &series);
    if points == 0 {
        return None;
    }
    plot_svg(&spec, &series)
        .ok()
        .map(|svg| PlotOut { id, svg, points })
}

fn png_size(bytes: &[u8]) -> Option<(u32, u32)> {
    if bytes.len() < 24 || !bytes.starts_with(b"\x89PNG") {
        return None;
    }
    Some((
        u32::from_be_bytes(bytes[16..20].try_into().ok()?),
        u32::from_be_bytes(bytes[20..24].try_into().ok()?),
    ))
}

/// Preview images with ROI overlays, as inline SVG.
fn images(dir: &Path, variants: &[String]) -> Result<Vec<ImageOut>> {
    let mut out = vec![];
    for v in variants {
        let d = dir.join("previews").join(v);
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        let mut files: Vec<PathBuf> = rd
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "png"))
            .collect();
        files.sort();
        // Saved raw files (DNG) are linked from the first picture of their variant.
        let mut saved: Vec<(String, String)> = std::fs::read_dir(&d)
            .map_err(|e| Error::io(&d, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "dng"))
            .map(|p| {
                let name = p
                    .file_name()
                    .map(|s| s.to_string_lossy().to_string())
                    .unwrap_or_default();
                let href = format!(
                    "previews/{}/{}",
                    url_path_segment(v),
                    url_path_segment(&name)
                );
                (href, format!("{v}: {name} (raw mosaic, DNG)"))
            })
            .collect();
        saved.sort();
        for f in files {
            let bytes = std::fs::read(&f).map_err(|e| Error::io(&f, e))?;
            let (w, h) = png_size(&bytes).ok_or_else(|| Error::io(&f, "not a PNG file"))?;
            let mut svg = format!(
                "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" viewBox=\"0 0 {w} {h}\"><image width=\"{w}\" height=\"{h}\" href=\"data:image/png;base64,{}\"/>",
                w.clamp(160, 480),
                base64(&bytes)
            );
            let rois = f.with_extension("rois.json");
            if rois.exists() {
                let t = std::fs::read_to_string(&rois).map_err(|e| Error::io(&rois, e))?;
                let list: Vec<serde_json::Value> =
                    serde_json::from_str(&t).map_err(|e| Error::io(&rois, e))?;
                for r in list {
                    let g = |k: &str| r.get(k).and_then(|x| x.as_f64()).unwrap_or(0.0);
                    let label = r.get("label").and_then(|x| x.as_str()).unwrap_or("");
                    let sw = (w.max(h) as f64 / 300.0).max(1.0);
                    svg.push_str(&format!(
                        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#ffd000\" stroke-width=\"{sw}\"><title>{}</title></rect>",
                        g("x"),
                        g("y"),
                        g("w"),
                        g("h"),
                        html_escape(label)
                    ));
                }
            }
            svg.push_str("</svg>");
            let name = f
                .file_stem()
                .map(|s| s.to_string_lossy().to_string())
                .unwrap_or_default();
            out.push(ImageOut {
                svg,
                caption: format!("{v}: {name}"),
                files: std::mem::take(&mut saved),
            });
        }
    }
    Ok(out)
}

/// Percent-encode a path segment for an href (variant ids hold spaces, `(`, `=`, `,`).
fn url_path_segment(s: &str) -> String {
    s.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The style of series `<chart>#<name>` (see the module docs).
fn series_style(name: &str) -> Style {
    if name == "counts" {
        Style::Bars
    } else if ["points", "regions", "levels"]
        .iter()
        .any(|p| name.starts_with(p))
    {
        Style::Points
    } else {
        Style::Line
    }
}

fn curve_spec(measurement: &str, name: &str, c: &crate::measure::Curve) -> PlotSpec {
    let lbl = |n: &str, u: &str| {
        if u.is_empty() || u == "1" {
            n.to_string()
        } else {
            format!("{n} ({u})")
        }
    };
    PlotSpec {
        title: format!("{measurement}: {name}"),
        x_label: lbl(&c.x_name, &c.x_unit),
        y_label: lbl(&c.y_name, &c.y_unit),
        log_x: name.ends_with("_vs_time"),
        log_y: name.ends_with("_vs_time"),
        scatter: name == "scatter" || name == "std_vs_mean",
        identity: name == "scatter",
    }
}

/// One variant's error-driven sampling, as the report shows it (read from
/// the manifest's `sampling` record as JSON, like the rest of the manifest).
#[derive(Serialize)]
struct SamplingOut {
    variant: String,
    spp: u64,
    rounds: u64,
    render_s: String,
    wall_s: String,
    stopped: String,
    budget_reached: bool,
    met: usize,
    targeted: usize,
    /// The figures that did not meet their target.
    unmet: Vec<UnmetFigure>,
    /// The worst figure: `measurement/quantity ± stderr unit (target …)`.
    worst: String,
}

/// A figure above its target.
#[derive(Serialize)]
struct UnmetFigure {
    measurement: String,
    quantity: String,
    value: String,
    stderr: String,
    target: String,
    allowed: String,
}

/// Each variant's sampling record from the manifest (empty when no variant
/// samples to a target).
fn sampling_out(manifest: Option<&serde_json::Value>) -> Vec<SamplingOut> {
    let Some(vs) = manifest
        .and_then(|m| m.get("variants"))
        .and_then(|v| v.as_array())
    else {
        return vec![];
    };
    let text = |v: &serde_json::Value, k: &str| {
        v.get(k).and_then(|x| x.as_str()).unwrap_or("").to_string()
    };
    let num =
        |v: &serde_json::Value, k: &str| v.get(k).and_then(|x| x.as_f64()).unwrap_or(f64::NAN);
    vs.iter()
        .filter_map(|v| {
            let id = v.get("id")?.as_str()?.to_string();
            let r = v.get("sampling")?;
            let figs = r.get("figures")?.as_array()?;
            let met = |f: &serde_json::Value| f.get("met").and_then(|m| m.as_bool()) == Some(true);
            // stderr / allowed: how far a figure is from its target
            let ratio = |f: &serde_json::Value| {
                let (se, al) = (num(f, "stderr"), num(f, "allowed"));
                if al > 0.0 {
                    se / al
                } else if se > 0.0 {
                    f64::INFINITY
                } else {
                    0.0
                }
            };
            let worst = figs
                .iter()
                .max_by(|a, b| ratio(a).total_cmp(&ratio(b)))
                .map(|f| {
                    format!(
                        "{}/{}: ± {} {} (target {})",
                        text(f, "measurement"),
                        text(f, "quantity"),
                        fmt_se(num(f, "stderr")),
                        text(f, "unit"),
                        text(f, "target")
                    )
                })
                .unwrap_or_default();
            let budget_reached = r
                .get("budget_reached")
                .and_then(|b| b.as_bool())
                .unwrap_or(false);
            Some(SamplingOut {
                variant: id,
                spp: r.get("spp").and_then(|x| x.as_u64()).unwrap_or(0),
                rounds: r.get("rounds").and_then(|x| x.as_u64()).unwrap_or(0),
                render_s: fmt_num(num(r, "render_s")),
                wall_s: fmt_num(num(r, "wall_s")),
                stopped: if budget_reached {
                    format!("{}: budget reached", text(r, "stopped"))
                } else {
                    "target met".into()
                },
                budget_reached,
                met: figs.iter().filter(|f| met(f)).count(),
                targeted: figs.len(),
                unmet: figs
                    .iter()
                    .filter(|f| !met(f))
                    .map(|f| UnmetFigure {
                        measurement: text(f, "measurement"),
                        quantity: text(f, "quantity"),
                        value: fmt_num(num(f, "value")),
                        stderr: fmt_se(num(f, "stderr")),
                        target: text(f, "target"),
                        allowed: fmt_num(num(f, "allowed")),
                    })
                    .collect(),
                worst,
            })
        })
        .collect()
}

/// The declared calibration of each variant, as the report states it: the
/// sensor's `illuminance-scale-factor` (the paper's per-figure mean-illuminance
/// factors) from the variant's resolved sensor overrides in the manifest;
/// "none (1)" where it is not set. Empty when no variant declares one.
fn calibration_lines(manifest: Option<&serde_json::Value>) -> Vec<(String, String)> {
    let Some(vs) = manifest
        .and_then(|m| m.get("variants"))
        .and_then(|v| v.as_array())
    else {
        return vec![];
    };
    let lines: Vec<(String, Option<f64>)> = vs
        .iter()
        .map(|v| {
            let id = v
                .get("id")
                .and_then(|x| x.as_str())
                .unwrap_or("")
                .to_string();
            let k = v
                .pointer("/spec/sensor/overrides/illuminance-scale-factor")
                .and_then(|x| x.as_f64());
            (id, k)
        })
        .collect();
    if lines.iter().all(|l| l.1.is_none()) {
        return vec![];
    }
    lines
        .into_iter()
        .map(|(id, k)| {
            (
                id,
                match k {
                    Some(k) => format!("illuminance-scale-factor = {}", fmt_num(k)),
                    None => "none (1)".into(),
                },
            )
        })
        .collect()
}

/// Render `dir/report.html` from `dir/results.csv`, `manifest.json`, `curves/`, `previews/`.
pub fn write_report(dir: &Path) -> Result<()> {
    let rows = read_results(&dir.join("results.csv"))?;
    let manifest = read_manifest(dir)?;
    let experiment = rows
        .first()
        .map(|r| r.experiment.clone())
        .unwrap_or_else(|| {
            dir.file_name()
                .map(|s| s.to_string_lossy().to_string())
                .unwrap_or_default()
        });
    // Rows of the cross-variant stage (`summary` nodes) get their own section.
    let summary_v = super::results::SUMMARY_VARIANT;
    let variants: Vec<String> = variant_order(&rows)
        .into_iter()
        .filter(|v| v != summary_v)
        .collect();
    let param_names: Vec<String> = rows
        .first()
        .map(|r| r.params.iter().map(|p| p.0.clone()).collect())
        .unwrap_or_default();
    let vrows: Vec<VariantRow> = variants
        .iter()
        .map(|v| {
            let rs: Vec<&ResultRow> = rows.iter().filter(|r| &r.variant == v).collect();
            VariantRow {
                name: v.clone(),
                params: rs[0].params.iter().map(|p| p.1.clone()).collect(),
                render_s: fmt_num(rs.iter().map(|r| r.render_s).fold(0.0, f64::max)),
                total_s: fmt_num(rs.iter().map(|r| r.total_s).fold(0.0, f64::max)),
                oi_cache: manifest
                    .as_ref()
                    .and_then(|m| m.get("variants"))
                    .and_then(|vs| vs.as_array())
                    .and_then(|vs| {
                        vs.iter()
                            .find(|x| x.get("id").and_then(|i| i.as_str()) == Some(v.as_str()))
                    })
                    .and_then(|x| x.get("oi_cache"))
                    .and_then(|c| c.as_str())
                    .unwrap_or("—")
                    .to_string(),
            }
        })
        .collect();
    // A numeric swept parameter to plot figures against.
    let sweep_param: Option<(usize, String)> = param_names.iter().enumerate().find_map(|(i, n)| {
        let vals: Vec<f64> = vrows
            .iter()
            .filter_map(|v| v.params.get(i).and_then(|s| s.parse::<f64>().ok()))
            .collect();
        let distinct = vals.iter().fold(Vec::<f64>::new(), |mut a, x| {
            if !a.contains(x) {
                a.push(*x)
            }
            a
        });
        (vals.len() == vrows.len() && distinct.len() >= 2).then(|| (i, n.clone()))
    });
    let mut measurements: Vec<String> = vec![];
    for r in &rows {
        if !measurements.contains(&r.measurement) {
            measurements.push(r.measurement.clone());
        }
    }
    let mut mouts = vec![];
    let mut souts = vec![];
    let mut pid = 0;
    let sampling = sampling_out(manifest.as_ref());
    let unmet: std::collections::BTreeSet<(String, String, String)> = sampling
        .iter()
        .flat_map(|s| {
            s.unmet
                .iter()
                .map(|f| (s.variant.clone(), f.measurement.clone(), f.quantity.clone()))
        })
        .collect();
    for m in &measurements {
        let mr: Vec<&ResultRow> = rows.iter().filter(|r| &r.measurement == m).collect();
        if mr.iter().all(|r| r.variant == summary_v) {
            souts.push(summary_out(dir, m, &mr, manifest.as_ref(), &mut pid)?);
            continue;
        }
        let mut quants: Vec<(String, String)> = vec![];
        for r in &mr {
            if !quants.iter().any(|q| q.0 == r.quantity) {
                quants.push((r.quantity.clone(), r.unit.clone()));
            }
        }
        let mvars: Vec<&String> = variants
            .iter()
            .filter(|v| mr.iter().any(|r| &r.variant == *v))
            .collect();
        let cell =
            |v: &String, q: &str| match mr.iter().find(|r| &r.variant == v && r.quantity == q) {
                Some(r) => Cell {
                    value: fmt_num(r.value),
                    stderr: fmt_se(r.stderr),
                    flag: if unmet.contains(&(v.to_string(), m.clone(), q.to_string())) {
                        "budget reached".into()
                    } else {
                        String::new()
                    },
                },
                None => Cell {
                    value: "—".into(),
                    stderr: String::new(),
                    flag: String::new(),
                },
            };
        let qtitle = |q: &(String, String)| {
            if q.1.is_empty() {
                q.0.clone()
            } else {
                format!("{} ({})", q.0, q.1)
            }
        };
        // Few quantities: a row per variant; many (e.g. 72 MCC means): a row per quantity.
        let wide = quants.len() <= 10;
        let (corner, head, table_rows): (String, Vec<String>, Vec<MRow>) = if wide {
            (
                "variant".into(),
                quants.iter().map(qtitle).collect(),
                mvars
                    .iter()
                    .map(|v| MRow {
                        variant: (*v).clone(),
                        cells: quants.iter().map(|q| cell(v, &q.0)).collect(),
                    })
                    .collect(),
            )
        } else {
            (
                "quantity".into(),
                mvars.iter().map(|v| v.to_string()).collect(),
                quants
                    .iter()
                    .map(|q| MRow {
                        variant: qtitle(q),
                        cells: mvars.iter().map(|v| cell(v, &q.0)).collect(),
                    })
                    .collect(),
            )
        };
        let mut plots = vec![];
        // Curves: one chart per curve name, a series per variant.
        let mut by_name: BTreeMap<String, (PlotSpec, Vec<Series>)> = BTreeMap::new();
        let mut order: Vec<String> = vec![];
        for v in &variants {
            let p = dir.join("curves").join(v).join(format!("{m}.csv"));
            if !p.exists() {
                continue;
            }
            for c in read_curves(&p)? {
                // `chart#series` curves share one chart (an overlay)
                let (chart, part) = match c.name.split_once('#') {
                    Some((a, b)) => (a.to_string(), Some(b.to_string())),
                    None => (c.name.clone(), None),
                };
                let e = by_name.entry(chart.clone()).or_insert_with(|| {
                    order.push(chart.clone());
                    (curve_spec(m, &chart, &c), vec![])
                });
                let points: Vec<(f64, f64)> =
                    c.x.iter().copied().zip(c.y.iter().copied()).collect();
                let (name, style) = match &part {
                    None => (v.clone(), None),
                    Some(sn) => (
                        if variants.len() > 1 {
                            format!("{v} · {sn}")
                        } else {
                            sn.clone()
                        },
                        Some(series_style(sn)),
                    ),
                };
                if let Some(t) = &part {
                    // drawn already (a reference repeated by every variant): once, by its tag
                    let suffix = format!(" · {t}");
                    if let Some(s) = e
                        .1
                        .iter_mut()
                        .find(|s| (s.name == *t || s.name.ends_with(&suffix)) && s.points == points)
                    {
                        s.name = t.clone();
                        continue;
                    }
                }
                e.1.push(Series {
                    name,
                    points,
                    stderr: c.stderr.clone(),
                    style,
                });
            }
        }
        for n in &order {
            if let Some((spec, series)) = by_name.remove(n) {
                pid += 1;
                plots.extend(plot_for(format!("plot{pid}"), spec, series));
            }
        }
        // Figures against the swept parameter (for measurements with few figures).
        if let Some((pi, pname)) = sweep_param.as_ref().filter(|_| quants.len() <= 10) {
            for (q, unit) in &quants {
                let mut pts: Vec<(f64, f64, f64)> = mr
                    .iter()
                    .filter(|r| &r.quantity == q)
                    .filter_map(|r| {
                        r.params
                            .get(*pi)
                            .and_then(|p| p.1.parse::<f64>().ok())
                            .map(|x| (x, r.value, r.stderr))
                    })
                    .collect();
                pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                if pts.len() < 2 {
                    continue;
                }
                let spec = PlotSpec {
                    title: format!("{m}: {q} vs {pname}"),
                    x_label: pname.clone(),
                    y_label: if unit.is_empty() || unit == "1" {
                        q.clone()
                    } else {
                        format!("{q} ({unit})")
                    },
                    scatter: false,
                    ..Default::default()
                };
                let s = Series {
                    name: q.clone(),
                    points: pts.iter().map(|p| (p.0, p.1)).collect(),
                    stderr: pts.iter().map(|p| p.2).collect(),
                    style: None,
                };
                pid += 1;
                plots.extend(plot_for(format!("plot{pid}"), spec, vec![s]));
            }
        }
        // Convergence: a slope that is not −½ within its uncertainty, named.
        let mut notes = vec![];
        for v in &mvars {
            let vr: Vec<(String, f64, f64)> = mr
                .iter()
                .filter(|r| &r.variant == *v)
                .map(|r| (r.quantity.clone(), r.value, r.stderr))
                .collect();
            for n in crate::measure::convergence::flag_notes(&vr) {
                notes.push(if mvars.len() > 1 {
                    format!("{v}: {n}")
                } else {
                    n
                });
            }
        }
        mouts.push(MeasOut {
            name: m.clone(),
            notes,
            corner,
            head,
            rows: table_rows,
            plots,
        });
    }
    let calibration = calibration_lines(manifest.as_ref());
    let manifest_kv: Vec<(String, String)> = manifest
        .as_ref()
        .and_then(|m| m.as_object())
        .map(|o| {
            o.iter()
                .filter_map(|(k, v)| scalar(v).map(|s| (k.clone(), s)))
                .collect()
        })
        .unwrap_or_default();
    let status = manifest
        .as_ref()
        .and_then(|m| m.get("status"))
        .and_then(|s| s.as_str())
        .unwrap_or("ok")
        .to_string();
    let total_s = manifest
        .as_ref()
        .and_then(|m| m.get("total_s"))
        .and_then(|s| s.as_f64())
        .or_else(|| (!rows.is_empty()).then(|| rows.iter().map(|r| r.total_s).fold(0.0, f64::max)))
        .map(fmt_num);
    let ctx = minijinja::context! {
        experiment => experiment,
        status_class => status_class(&status),
        status => status,
        total_s => total_s,
        n_variants => variants.len(),
        n_figures => rows.len(),
        manifest => manifest_kv,
        calibration => calibration,
        sampling => sampling,
        param_names => param_names,
        variants => vrows,
        measurements => mouts,
        summaries => souts,
        images => images(dir, &variants)?,
        version => crate::version(),
        css => CSS,
        js => JS,
    };
    let html = render("report.html", REPORT, ctx)?;
    crate::diag::write_atomic(&dir.join("report.html"), html.as_bytes())
}

/// A summary's section: its figures (a row each) and its curves, one chart
/// per curve-name prefix (`scatter-before/r`, `…/g`, `…/b` → one chart,
/// series r, g, b); its `note=` from the manifest.
#[derive(Serialize)]
struct SummaryOut {
    name: String,
    kind: String,
    note: String,
    rows: Vec<MRow>,
    plots: Vec<PlotOut>,
}

fn summary_out(
    dir: &Path,
    name: &str,
    rows: &[&ResultRow],
    manifest: Option<&serde_json::Value>,
    pid: &mut usize,
) -> Result<SummaryOut> {
    let node = manifest
        .and_then(|m| m.get("summaries"))
        .and_then(|s| s.as_array())
        .and_then(|a| {
            a.iter()
                .find(|x| x.get("name").and_then(|n| n.as_str()) == Some(name))
        });
    let field = |k: &str| {
        node.and_then(|n| n.get(k))
            .and_then(|v| v.as_str())
            .unwrap_or("")
            .to_string()
    };
    let note = node
        .and_then(|n| n.get("params"))
        .and_then(|p| p.get("note"))
        .and_then(|v| v.as_str())
        .unwrap_or("")
        .to_string();
    let table = rows
        .iter()
        .map(|r| MRow {
            variant: if r.unit.is_empty() || r.unit == "1" {
                r.quantity.clone()
            } else {
                format!("{} ({})", r.quantity, r.unit)
            },
            cells: vec![Cell {
                value: fmt_num(r.value),
                stderr: fmt_se(r.stderr),
                flag: String::new(),
            }],
        })
        .collect();
    let mut plots = vec![];
    let p = dir
        .join("curves")
        .join(super::results::SUMMARY_VARIANT)
        .join(format!("{name}.csv"));
    if p.exists() {
        let mut by: Vec<(String, PlotSpec, Vec<Series>)> = vec![];
        for c in read_curves(&p)? {
            let (chart, series) = c.name.rsplit_once('/').unwrap_or((&c.name, &c.name));
            let (chart, series) = (chart.to_string(), series.to_string());
            let i = match by.iter().position(|b| b.0 == chart) {
                Some(i) => i,
                None => {
                    let mut spec = curve_spec(name, &chart, &c);
                    spec.scatter = chart.starts_with("scatter");
                    spec.identity = spec.scatter;
                    by.push((chart.clone(), spec, vec![]));
                    by.len() - 1
                }
            };
            by[i].2.push(Series {
                name: series,
                points: c.x.iter().copied().zip(c.y.iter().copied()).collect(),
                stderr: c.stderr.clone(),
                style: None,
            });
        }
        for (_, spec, series) in by {
            *pid += 1;
            plots.extend(plot_for(format!("plot{pid}"), spec, series));
        }
    }
    Ok(SummaryOut {
        name: name.to_string(),
        kind: field("kind"),
        note,
        rows: table,
        plots,
    })
}

#[derive(Serialize)]
struct IndexRow {
    name: String,
    report: Option<String>,
    status: String,
    status_class: &'static str,
    variants: usize,
    total_s: String,
    /// The run's `--quality` (`quick`: the render nodes' own settings).
    quality: String,
    headline: Vec<String>,
}

/// Render `root/index.html` listing every experiment directory under `root`.
pub fn write_index(root: &Path) -> Result<()> {
    let mut total_all = 0.0f64;
    let rd = std::fs::read_dir(root).map_err(|e| Error::io(root, e))?;
    let mut dirs: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    let mut exps = vec![];
    for d in dirs {
        let has_results = d.join("results.csv").exists();
        if !has_results && !d.join("manifest.json").exists() {
            continue;
        }
        let name = d
            .file_name()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        let manifest = read_manifest(&d).unwrap_or(None);
        let (rows, err) = if has_results {
            match read_results(&d.join("results.csv")) {
                Ok(r) => (r, None),
                Err(e) => (vec![], Some(e.to_string())),
            }
        } else {
            (vec![], None)
        };
        let status = match (
            &err,
            manifest
                .as_ref()
                .and_then(|m| m.get("status"))
                .and_then(|s| s.as_str()),
        ) {
            (Some(_), _) => "unreadable results".to_string(),
            (None, Some(s)) => s.to_string(),
            (None, None) if has_results => "ok".into(),
            _ => "no results".into(),
        };
        // The experiment's own run time: the manifest's wall time of its last
        // run, else the slowest variant's.
        let total = manifest
            .as_ref()
            .and_then(|m| m.get("wall_s").or_else(|| m.get("total_s")))
            .and_then(|s| s.as_f64())
            .or_else(|| {
                (!rows.is_empty()).then(|| rows.iter().map(|r| r.total_s).fold(0.0, f64::max))
            });
        total_all += total.unwrap_or(0.0);
        // Rows of the cross-variant stage (`summary` nodes) get their own section.
        let summary_v = super::results::SUMMARY_VARIANT;
        let variants: Vec<String> = variant_order(&rows)
            .into_iter()
            .filter(|v| v != summary_v)
            .collect();
        let mut headline = vec![];
        let mut seen: Vec<(String, String)> = vec![];
        for r in rows.iter().filter(|r| Some(&r.variant) == variants.first()) {
            let k = (r.measurement.clone(), r.quantity.clone());
            if seen.contains(&k) || seen.len() >= 3 {
                continue;
            }
            seen.push(k);
            let se = fmt_se(r.stderr);
            headline.push(format!(
                "{} {} = {}{} {}",
                r.measurement,
                r.quantity,
                fmt_num(r.value),
                if se.is_empty() {
                    String::new()
                } else {
                    format!(" ± {se}")
                },
                r.unit
            ));
        }
        if variants.len() > 1 && !headline.is_empty() {
            headline[0] = format!("{} (variant {})", headline[0], variants[0]);
        }
        let report = d
            .join("report.html")
            .exists()
            .then(|| format!("{name}/report.html"));
        exps.push(IndexRow {
            name,
            report,
            status_class: status_class(&status),
            status,
            variants: variants.len(),
            total_s: total.map(fmt_num).unwrap_or_else(|| "—".into()),
            quality: manifest
                .as_ref()
                .and_then(|m| m.get("quality"))
                .and_then(|q| q.as_str())
                .unwrap_or("quick")
                .to_string(),
            headline,
        });
    }
    let ctx = minijinja::context! {
        experiments => exps,
        total_s => fmt_num(total_all),
        version => crate::version(),
        css => CSS,
        js => JS
    };
    let html = render("index.html", INDEX, ctx)?;
    crate::diag::write_atomic(&root.join("index.html"), html.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn convergence_curves_are_drawn_log_log() {
        let c = crate::measure::Curve::new(
            "stderr_vs_time#q",
            ("wall time", "s"),
            ("standard error", "DV"),
            vec![1.0, 4.0],
            vec![0.2, 0.1],
            vec![],
        );
        for name in ["stderr_vs_time", "error_vs_time"] {
            let s = curve_spec("conv", name, &c);
            assert!(s.log_x && s.log_y, "{name}");
        }
        assert!(!curve_spec("sfr", "mtf", &c).log_y);
    }

    #[test]
    fn number_formatting_and_base64() {
        assert_eq!(fmt_num(0.219384), "0.21938");
        assert_eq!(fmt_num(1234.5678), "1234.6");
        assert_eq!(fmt_num(2.0), "2");
        assert_eq!(fmt_num(1.5e-7), "1.5000e-7");
        assert_eq!(fmt_se(0.00123), "0.0012");
        assert_eq!(fmt_se(0.0), "");
        assert_eq!(base64(b"Man"), "TWFu");
        assert_eq!(base64(b"Ma"), "TWE=");
        assert_eq!(base64(b"M"), "TQ==");
    }
}
