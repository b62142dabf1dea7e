//! Plots for the HTML report, drawn with plotters' SVG backend: line charts
//! (optionally log–log, with a ±1 standard-error band) and scatter plots
//! (optionally with the identity line). Axis labels carry units. A series may
//! set its own style ([`Style`]): points, a line or histogram bars, so one
//! chart holds e.g. a histogram with its model curve.

use crate::{Error, Result};
use plotters::prelude::*;

#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Standard error per point (empty: none).
    pub stderr: Vec<f64>,
    /// How the series is drawn; None: the chart's (`PlotSpec::scatter`).
    pub style: Option<Style>,
}

/// How one series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    Points,
    Line,
    /// Histogram bars centred on each x, as wide as the x spacing.
    Bars,
}

#[derive(Clone, Debug, Default)]
pub struct PlotSpec {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub log_x: bool,
    pub log_y: bool,
    /// Points instead of lines.
    pub scatter: bool,
    /// Draw y = x (scatter of simulated against reference).
    pub identity: bool,
}

const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// A series' colour: channel series named r, g, b in their own colours,
/// others by position.
fn series_color(i: usize, name: &str) -> RGBColor {
    match name {
        "r" => COLORS[1],
        "g" => COLORS[2],
        "b" => COLORS[0],
        _ => COLORS[i % COLORS.len()],
    }
}

fn range(v: impl Iterator<Item = f64>, log: bool) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in v.filter(|x| x.is_finite() && (!log || *x > 0.0)) {
        lo = lo.min(x);
        hi = hi.max(x);
    }
    if lo > hi {
        return None;
    }
    Some(if log {
        if hi / lo < 8.0 {
            // at least a decade around the data: a log axis labels only
            // powers of ten, so a narrower one would carry no numbers
            let c = (hi * lo).sqrt();
            let k = (hi / lo).sqrt().max(10f64.sqrt()) * 1.1;
            (c / k, c * k)
        } else {
            (lo / (hi / lo).powf(0.03), hi * (hi / lo).powf(0.03))
        }
    } else if hi - lo < 1e-300_f64.max(hi.abs() * 1e-12) {
        (lo - 0.5 * lo.abs().max(1.0), hi + 0.5 * hi.abs().max(1.0))
    } else {
        (lo - 0.04 * (hi - lo), hi + 0.04 * (hi - lo))
    })
}

/// Number of finite points that a plot would draw.
pub fn drawable_points(spec: &PlotSpec, series: &[Series]) -> usize {
    series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|(x, y)| {
            x.is_finite() && y.is_finite() && (!spec.log_x || *x > 0.0) && (!spec.log_y || *y > 0.0)
        })
        .count()
}

/// Render to an SVG string. Errors when there is nothing to draw.
pub fn plot_svg(spec: &PlotSpec, series: &[Series]) -> Result<String> {
    let ok = |x: f64, y: f64| {
        x.is_finite() && y.is_finite() && (!spec.log_x || x > 0.0) && (!spec.log_y || y > 0.0)
    };
    let pts = || {
        series
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|&(x, y)| ok(x, y))
    };
    let nodata = || Error::invalid(format!("plot '{}' has no finite data", spec.title));
    let (mut x0, mut x1) = range(pts().map(|p| p.0), spec.log_x).ok_or_else(nodata)?;
    let (mut y0, mut y1) = range(
        pts().map(|p| p.1).chain(series.iter().flat_map(|s| {
            s.points
                .iter()
                .zip(&s.stderr)
                .filter(|(p, _)| ok(p.0, p.1))
                .flat_map(|(p, e)| [p.1 - e, p.1 + e])
        })),
        spec.log_y,
    )
    .ok_or_else(nodata)?;
    if spec.identity {
        let (a, b) = (x0.min(y0), x1.max(y1));
        (x0, x1, y0, y1) = (a, b, a, b);
    }
    let mut out = String::new();
    let e = |e: &dyn std::fmt::Display| Error::invalid(format!("plot '{}': {e}", spec.title));
    {
        // The legend goes below the chart (one line per series), where long
        // variant names cannot cover the data.
        let legend = series.len() > 1 || !series.first().is_none_or(|s| s.name.is_empty());
        let legend_h = if legend {
            8 + 16 * series.len() as u32
        } else {
            0
        };
        let canvas = SVGBackend::with_string(&mut out, (640, 400 + legend_h)).into_drawing_area();
        canvas.fill(&WHITE).map_err(|x| e(&x))?;
        let (root, below) = canvas.split_vertically(400);
        if legend {
            for (i, s) in series.iter().enumerate() {
                let c = series_color(i, &s.name);
                let y = 8 + 16 * i as i32;
                below
                    .draw(&PathElement::new(vec![(70, y), (92, y)], c.stroke_width(2)))
                    .map_err(|x| e(&x))?;
                below
                    .draw(&Text::new(
                        s.name.clone(),
                        (98, y - 6),
                        ("sans-serif", 12).into_font().color(&BLACK),
                    ))
                    .map_err(|x| e(&x))?;
            }
        }
        macro_rules! draw {
            ($xr:expr, $yr:expr) => {{
                let mut chart = ChartBuilder::on(&root)
                    .caption(&spec.title, ("sans-serif", 18))
                    .margin(12)
                    .x_label_area_size(42)
                    .y_label_area_size(64)
                    .build_cartesian_2d($xr, $yr)
                    .map_err(|x| e(&x))?;
                chart
                    .configure_mesh()
                    .x_desc(&spec.x_label)
                    .y_desc(&spec.y_label)
                    .light_line_style(RGBColor(235, 235, 235))
                    .draw()
                    .map_err(|x| e(&x))?;
                if spec.identity {
                    chart
                        .draw_series(LineSeries::new(vec![(x0, x0), (x1, x1)], BLACK.mix(0.5)))
                        .map_err(|x| e(&x))?;
                }
                for (i, s) in series.iter().enumerate() {
                    let c = series_color(i, &s.name);
                    let p: Vec<(f64, f64)> = s
                        .points
                        .iter()
                        .copied()
                        .filter(|&(x, y)| ok(x, y))
                        .collect();
                    let style = s.style.unwrap_or(if spec.scatter {
                        Style::Points
                    } else {
                        Style::Line
                    });
                    if s.stderr.len() == s.points.len() && style == Style::Line {
                        let band: Vec<(f64, f64)> = s
                            .points
                            .iter()
                            .zip(&s.stderr)
                            .filter(|(q, _)| ok(q.0, q.1))
                            .map(|(q, se)| (q.0, q.1 + se))
                            .chain(
                                s.points
                                    .iter()
                                    .zip(&s.stderr)
                                    .rev()
                                    .filter(|(q, _)| ok(q.0, q.1))
                                    .map(|(q, se)| (q.0, q.1 - se)),
                            )
                            .filter(|&(x, y)| ok(x, y))
                            .collect();
                        if band.len() > 2 {
                            chart
                                .draw_series(std::iter::once(Polygon::new(band, c.mix(0.18))))
                                .map_err(|x| e(&x))?;
                        }
                    }
                    match style {
                        Style::Points => chart
                            .draw_series(p.iter().map(|&q| Circle::new(q, 3, c.filled())))
                            .map_err(|x| e(&x))
                            .map(|_| ())?,
                        Style::Line => chart
                            .draw_series(LineSeries::new(p.clone(), c.stroke_width(2)))
                            .map_err(|x| e(&x))
                            .map(|_| ())?,
                        Style::Bars => {
                            let w = p
                                .windows(2)
                                .map(|q| (q[1].0 - q[0].0).abs())
                                .filter(|d| *d > 0.0)
                                .fold(f64::INFINITY, f64::min);
                            let w = if w.is_finite() { w } else { 1.0 };
                            let base = if spec.log_y { y0 } else { 0.0f64.max(y0) };
                            chart
                                .draw_series(p.iter().map(|&(x, y)| {
                                    Rectangle::new(
                                        [(x - 0.45 * w, base), (x + 0.45 * w, y)],
                                        c.mix(0.55).filled(),
                                    )
                                }))
                                .map_err(|x| e(&x))?;
                        }
                    }
                }
            }};
        }
        match (spec.log_x, spec.log_y) {
            (false, false) => draw!(x0..x1, y0..y1),
            (true, false) => draw!((x0..x1).log_scale(), y0..y1),
            (false, true) => draw!(x0..x1, (y0..y1).log_scale()),
            (true, true) => draw!((x0..x1).log_scale(), (y0..y1).log_scale()),
        }
        root.present().map_err(|x| e(&x))?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn svg_has_axes_labels_and_data() {
        let s = Series {
            name: "a".into(),
            points: vec![(1.0, 1.0), (10.0, 0.1), (100.0, 0.01)],
            stderr: vec![0.1, 0.01, 0.001],
            style: None,
        };
        let spec = PlotSpec {
            title: "err".into(),
            x_label: "time (s)".into(),
            y_label: "error (1)".into(),
            log_x: true,
            log_y: true,
            ..Default::default()
        };
        let svg = plot_svg(&spec, &[s]).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.contains("time (s)") && svg.contains("<polyline"),
            "{}",
            &svg[..200.min(svg.len())]
        );
        // a log axis spans at least a decade (labelled powers of ten)
        let (lo, hi) = range([0.2, 0.3].into_iter(), true).unwrap();
        assert!(hi / lo >= 10.0 && lo < 0.2 && hi > 0.3, "{lo} {hi}");
        let empty = Series {
            name: "b".into(),
            points: vec![(f64::NAN, 1.0)],
            stderr: vec![],
            style: None,
        };
        assert!(plot_svg(&PlotSpec::default(), &[empty]).is_err());
    }
}
