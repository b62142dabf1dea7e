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
use crate::{Error, Result};

#[derive(Clone, Debug)]
pub struct ProfileOptions {
    pub band_px: usize,
    pub vertical: bool,
    /// Channel ratios to report, (numerator, denominator), e.g. ("g", "r").
    pub ratios: Vec<(String, String)>,
    /// Samples grouped along the line, px (2 for a Bayer mosaic, 1 otherwise).
    pub step_px: usize,
}

impl Default for ProfileOptions {
    fn default() -> Self {
        Self {
            band_px: 4,
            vertical: false,
            ratios: vec![("g".into(), "r".into())],
            step_px: 2,
        }
    }
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
