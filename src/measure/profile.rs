//! Line profiles through named objects, per channel, and channel ratios
//! (e.g. G/R along the MCC achromatic row, paper Fig. 9).
//!
//! The line is horizontal (or vertical) through the centroid of the union of
//! the named objects' pixels, `band_px` rows (columns) thick (rounded up to a
//! whole CFA tile so every channel is present), spanning the union's bounding
//! box. Along the line, samples are grouped per CFA tile column (2 px on a
//! Bayer mosaic). Per object, the channel means over its pixels inside the
//! band are figures (standard error std/√n) and so are the requested ratios
//! (error propagated assuming independent means).

use super::plane::{ChannelView, label_ids};
use super::stats::{mean, std_dev};
use super::{Curve, Measured};
use crate::figure::Figure;
use crate::optical_image::Rect;
use crate::params::{Kind, ParamError, ParamSpec};
use crate::{Error, Result};

#[derive(Clone, Debug)]
pub struct ProfileOptions {
    pub band_px: usize,
    pub vertical: bool,
    /// Channel ratios to report, (numerator, denominator), e.g. ("g", "r").
    pub ratios: Vec<(String, String)>,
    /// Samples grouped along the line, px (2 for a Bayer mosaic, 1 otherwise).
    pub step_px: usize,
    /// Channels profiled (empty = every channel of the image).
    pub channels: Vec<String>,
}

impl Default for ProfileOptions {
    fn default() -> Self {
        Self {
            band_px: 4,
            vertical: false,
            ratios: vec![("g".into(), "r".into())],
            step_px: 2,
            channels: vec![],
        }
    }
}

/// `measure "profile"`: the line and what is reported along it.
#[derive(Clone, Debug, Default)]
pub struct ProfileRequest {
    /// `step_px` is set from the image (its CFA tile width).
    pub options: ProfileOptions,
    pub input: Option<String>,
}

/// The properties of `measure "profile"`.
pub static SCHEMA: crate::params::Schema = crate::params::Schema {
    node: "measure \"profile\"",
    params: &[
        super::shared_params::name_param(),
        super::shared_params::of_param(
            "the object(s) the line runs through (more as arguments); the line crosses the centroid of their pixels and spans their bounding box",
            "\"mcc/patch-19\"",
        ),
        super::shared_params::input_param(),
        ParamSpec {
            name: "band-px",
            kind: Kind::Integer,
            default: "4",
            doc: "thickness of the line, pixels (1 … 10000; rounded up to whole CFA tiles)",
            example: "6",
        },
        ParamSpec {
            name: "vertical",
            kind: Kind::Bool,
            default: "#false",
            doc: "run the line down a column instead of along a row",
            example: "#true",
        },
        ParamSpec {
            name: "channels",
            kind: Kind::Text,
            default: "all",
            doc: "the channels profiled, space-separated (e.g. \"r g\"); each must be in the image",
            example: "\"g b\"",
        },
        ParamSpec {
            name: "ratios",
            kind: Kind::Text,
            default: "g/r",
            doc: "channel ratios reported, space-separated numerator/denominator pairs (\"\" = none), e.g. the paper's G/R of Fig. 9",
            example: "\"b/g r/g\"",
        },
    ],
};

/// Read `measure "profile"` (see [`SCHEMA`]).
pub fn from_params(
    d: &crate::params::ParamDict,
) -> std::result::Result<ProfileRequest, ParamError> {
    let mut o = ProfileOptions::default();
    if let Some(k) = d.int("band-px", 1, 10_000)? {
        o.band_px = k as usize;
    }
    if let Some(v) = d.bool("vertical")? {
        o.vertical = v;
    }
    let name_ok = |n: &str| !n.is_empty() && n.chars().all(|c| c.is_ascii_alphanumeric());
    if let Some(s) = d.str("channels")? {
        let v: Vec<String> = s.split_whitespace().map(str::to_string).collect();
        if v.is_empty() || !v.iter().all(|c| name_ok(c)) {
            return Err(ParamError::value(
                "channels",
                format!(
                    "'channels' = \"{s}\": expected channel names separated by spaces, e.g. \"r g b\""
                ),
            ));
        }
        o.channels = v;
    }
    if let Some(s) = d.str("ratios")? {
        let mut v = vec![];
        for p in s.split_whitespace() {
            match p.split_once('/') {
                Some((a, b)) if name_ok(a) && name_ok(b) => v.push((a.to_string(), b.to_string())),
                _ => {
                    return Err(ParamError::value(
                        "ratios",
                        format!(
                            "'ratios': '{p}' is not a ratio; expected numerator/denominator pairs such as \"g/r b/g\""
                        ),
                    ));
                }
            }
        }
        o.ratios = v;
    }
    Ok(ProfileRequest {
        options: o,
        input: super::shared_params::nonempty(d, "input")?,
    })
}

/// Profiles through `objects` of a sensor image (black level subtracted, DV;
/// samples grouped per CFA tile column).
pub fn profile_of_sensor(
    img: &crate::image::SensorImage,
    objects: &[String],
    opts: &ProfileOptions,
    measurement: &str,
) -> Result<Measured> {
    let plane = super::plane::Plane::from_sensor(img)?;
    let views = super::plane::channel_views(&plane, "y");
    let mut o = opts.clone();
    o.step_px = img.cfa.width.max(1) as usize;
    profile(
        &views,
        &img.labels,
        &img.label_names,
        objects,
        &o,
        measurement,
    )
}

/// Profiles through `objects` (names in `label_names`; `labels` per pixel, row-major).
pub fn profile(
    views: &[ChannelView],
    labels: &[u32],
    label_names: &[String],
    objects: &[String],
    opts: &ProfileOptions,
    measurement: &str,
) -> Result<Measured> {
    let selected: Vec<ChannelView>;
    let views = if opts.channels.is_empty() {
        views
    } else {
        selected = opts
            .channels
            .iter()
            .map(|c| {
                views.iter().find(|v| v.name == c).copied().ok_or_else(|| {
                    Error::invalid(format!(
                        "profile: no channel '{c}' in the image (has {})",
                        views.iter().map(|v| v.name).collect::<Vec<_>>().join(", ")
                    ))
                })
            })
            .collect::<Result<_>>()?;
        &selected
    };
    let plane = views
        .first()
        .ok_or_else(|| Error::invalid("profile: no channels"))?
        .plane;
    let (w, h) = (plane.width, plane.height);
    if labels.len() != w * h {
        return Err(Error::invalid(
            "profile needs per-pixel object labels (the image carries none)",
        ));
    }
    let ids = label_ids(label_names, objects)?;
    // Coordinates along (s) and across (t) the line.
    let (ns, nt) = if opts.vertical { (h, w) } else { (w, h) };
    let at = |s: usize, t: usize| if opts.vertical { (t, s) } else { (s, t) };
    let (mut s0, mut s1, mut tsum, mut cnt) = (usize::MAX, 0, 0.0, 0usize);
    for t in 0..nt {
        for s in 0..ns {
            let (x, y) = at(s, t);
            if ids.contains(&labels[y * w + x]) {
                s0 = s0.min(s);
                s1 = s1.max(s);
                tsum += t as f64 + 0.5;
                cnt += 1;
            }
        }
    }
    if cnt == 0 {
        return Err(Error::invalid(format!(
            "objects {} cover no pixel of the image",
            objects.join(", ")
        )));
    }
    let step = opts.step_px.max(1);
    let band = opts.band_px.max(1).div_ceil(step) * step;
    let tc = tsum / cnt as f64;
    let t0 = ((tc - band as f64 / 2.0).round().max(0.0) as usize / step * step)
        .min(nt.saturating_sub(band));
    let t1 = (t0 + band).min(nt);
    let s0 = s0 / step * step;
    let mut curves = vec![];
    let mut series: Vec<Vec<f64>> = vec![];
    let mut xs = vec![];
    for s in (s0..=s1).step_by(step) {
        xs.push(s as f64 + step as f64 / 2.0);
    }
    for v in views {
        let mut ys = vec![];
        let mut ses = vec![];
        for s in (s0..=s1).step_by(step) {
            let vals: Vec<f64> = (t0..t1)
                .flat_map(|t| (s..(s + step).min(ns)).map(move |ss| (ss, t)))
                .filter_map(|(ss, t)| {
                    let (x, y) = at(ss, t);
                    v.value(x, y)
                })
                .collect();
            ys.push(if vals.is_empty() {
                f64::NAN
            } else {
                mean(&vals)
            });
            ses.push(if vals.len() > 1 {
                std_dev(&vals) / (vals.len() as f64).sqrt()
            } else {
                0.0
            });
        }
        series.push(ys.clone());
        curves.push(Curve::new(
            &format!("profile/{}", v.name),
            ("position", "px"),
            (v.name, "DV"),
            xs.clone(),
            ys,
            ses,
        ));
    }
    let idx = |n: &str| views.iter().position(|v| v.name == n);
    for (a, b) in &opts.ratios {
        if let (Some(ia), Some(ib)) = (idx(a), idx(b)) {
            let r: Vec<f64> = series[ia]
                .iter()
                .zip(&series[ib])
                .map(|(p, q)| p / q)
                .collect();
            curves.push(Curve::new(
                &format!("ratio/{a}/{b}"),
                ("position", "px"),
                (&format!("{a}/{b}"), "1"),
                xs.clone(),
                r,
                vec![],
            ));
        }
    }
    // Per-object channel means inside the band.
    let mut figures = vec![];
    for (o, id) in objects.iter().zip(&ids) {
        let mut means = vec![];
        for v in views {
            let vals: Vec<f64> = (t0..t1)
                .flat_map(|t| (0..ns).map(move |s| (s, t)))
                .filter_map(|(s, t)| {
                    let (x, y) = at(s, t);
                    (labels[y * w + x] == *id).then(|| v.value(x, y)).flatten()
                })
                .collect();
            if vals.len() < 2 {
                return Err(Error::invalid(format!(
                    "object '{o}' has fewer than 2 '{}' pixels on the profile band",
                    v.name
                )));
            }
            let (m, se) = (mean(&vals), std_dev(&vals) / (vals.len() as f64).sqrt());
            figures.push(Figure::new(
                measurement,
                format!("{o}/{}_mean", v.name),
                "DV",
                m,
                se,
            ));
            means.push((v.name.to_string(), m, se));
        }
        for (a, b) in &opts.ratios {
            let fa = means.iter().find(|m| &m.0 == a);
            let fb = means.iter().find(|m| &m.0 == b);
            if let (Some(fa), Some(fb)) = (fa, fb) {
                let r = fa.1 / fb.1;
                let se = r.abs() * ((fa.2 / fa.1).powi(2) + (fb.2 / fb.1).powi(2)).sqrt();
                figures.push(Figure::new(measurement, format!("{o}/{a}/{b}"), "1", r, se));
            }
        }
    }
    let rect = if opts.vertical {
        Rect::new(t0 as u32, s0 as u32, (t1 - t0) as u32, (s1 + 1 - s0) as u32)
    } else {
        Rect::new(s0 as u32, t0 as u32, (s1 + 1 - s0) as u32, (t1 - t0) as u32)
    };
    Ok(Measured {
        figures,
        curves,
        pixels_read: vec![rect],
    })
}
