//! Macbeth ColorChecker patch means per channel, with patch regions taken
//! from the renderer's object labels `<chart>/patch01` … `<chart>/patch24`
//! (no hand-typed pixel boxes).
//!
//! Each patch's label region is eroded — a pixel is kept only when every pixel
//! within `r` px (a (2r+1)² square) carries the same label — with
//! `r = max(1, round(erode_fraction · min(bbox width, bbox height)))`, so
//! edges, blur and the chart's black gaps stay out. Per channel the mean over
//! the kept pixels is reported with standard error std/√n (pixel noise and
//! render noise, assumed independent between pixels).
//!
//! **Clipped pixels.** A pixel at the ADC's white level (or at its floor) no
//! longer follows the light: the patch mean is biased and std/√n measures the
//! clipping, not the noise — it collapses as the noise falls below the margin
//! to the clip level (a 4× spp step then shrinks it 4–∞× instead of 2×). With
//! the clip range known (sensor images), every patch channel with clipped
//! pixels gets a figure `patchNN/<ch>_clipped_fraction`, and `convergence`
//! leaves such figures out of its fits ([`clipped_flag`]).

use super::plane::ChannelView;
use super::stats::{mean, std_dev};
use super::{Curve, Measured};
use crate::figure::Figure;
use crate::optical_image::Rect;
use crate::params::{Kind, ParamError, ParamSpec};
use crate::{Error, Result};

#[derive(Clone, Debug)]
pub struct Patch {
    /// 1-based patch number.
    pub number: usize,
    pub name: String,
    /// Bounding box of the eroded region.
    pub rect: Rect,
    pub pixels: usize,
    /// (channel, mean, stderr) per channel.
    pub means: Vec<(String, f64, f64)>,
    /// Fraction of the kept pixels at or beyond the clip range, per channel
    /// (parallel to `means`; all 0 when the range is unknown).
    pub clipped: Vec<f64>,
}

/// The quantity that flags `quantity` (a `patchNN/<ch>_mean`) as clipped:
/// `patchNN/<ch>_clipped_fraction`.
pub fn clipped_flag(quantity: &str) -> Option<String> {
    quantity
        .strip_suffix("_mean")
        .map(|s| format!("{s}_clipped_fraction"))
}

/// Patch labels of `chart`: (patch number, label id), sorted by number.
pub fn patch_labels(label_names: &[String], chart: &str) -> Result<Vec<(usize, u32)>> {
    let prefix = format!("{chart}/patch");
    let mut v: Vec<(usize, u32)> = label_names
        .iter()
        .enumerate()
        .filter_map(|(i, n)| {
            n.strip_prefix(&prefix)
                .and_then(|s| s.parse::<usize>().ok())
                .map(|k| (k, i as u32))
        })
        .collect();
    if v.is_empty() {
        let charts: Vec<&str> = label_names
            .iter()
            .filter_map(|n| n.split_once("/patch").map(|p| p.0))
            .collect();
        let hint = crate::diag::did_you_mean(chart, charts.iter().copied())
            .map(|c| format!("; did you mean '{c}'?"))
            .unwrap_or_default();
        return Err(Error::invalid(format!(
            "no objects labelled '{chart}/patchNN' in the image{hint}"
        )));
    }
    v.sort();
    Ok(v)
}

/// `measure "mcc"`: how much of each patch's border is left out.
#[derive(Clone, Debug)]
pub struct MccRequest {
    /// Fraction of each patch's size eroded from every side (0 < x < 0.5;
    /// at least 1 pixel).
    pub inset_fraction: f64,
    pub input: Option<String>,
}

impl Default for MccRequest {
    fn default() -> Self {
        Self {
            inset_fraction: 0.25,
            input: None,
        }
    }
}

/// The properties of `measure "mcc"`.
pub static SCHEMA: crate::params::Schema = crate::params::Schema {
    node: "measure \"mcc\"",
    params: &[
        super::shared_params::name_param(),
        super::shared_params::of_param(
            "the chart object whose patches (`<chart>/patch-1` … `-24`) are read; default \"mcc\"",
            "\"chart-far\"",
        ),
        super::shared_params::input_param(),
        ParamSpec {
            name: "inset-fraction",
            kind: Kind::Number,
            default: "0.25",
            doc: "fraction of each patch's size left out along every side before averaging (0 < x < 0.5; at least 1 pixel), keeping blur and edges out of the means",
            example: "0.1",
        },
    ],
};

/// Read `measure "mcc"` (see [`SCHEMA`]).
pub fn from_params(d: &crate::params::ParamDict) -> std::result::Result<MccRequest, ParamError> {
    let mut r = MccRequest::default();
    if let Some(x) = d.f64("inset-fraction")? {
        if !(x > 0.0 && x < 0.5) {
            return Err(ParamError::value(
                "inset-fraction",
                format!("'inset-fraction' = {x} is out of range; expected 0 < x < 0.5"),
            ));
        }
        r.inset_fraction = x;
    }
    r.input = super::shared_params::nonempty(d, "input")?;
    Ok(r)
}

/// Means of every patch of `chart`.
pub fn patch_means(
    views: &[ChannelView],
    labels: &[u32],
    label_names: &[String],
    chart: &str,
    erode_fraction: f64,
) -> Result<Vec<Patch>> {
    patch_means_clipped(views, labels, label_names, chart, erode_fraction, None)
}

/// [`patch_means`], counting the pixels outside the unclipped range
/// `(low, high)` (values ≤ low or ≥ high are clipped).
pub fn patch_means_clipped(
    views: &[ChannelView],
    labels: &[u32],
    label_names: &[String],
    chart: &str,
    erode_fraction: f64,
    clip: Option<(f64, f64)>,
) -> Result<Vec<Patch>> {
    let plane = views
        .first()
        .ok_or_else(|| Error::invalid("mcc: no channels"))?
        .plane;
    let (w, h) = (plane.width, plane.height);
    if labels.len() != w * h {
        return Err(Error::invalid(
            "MCC patch means need per-pixel object labels (the image carries none)",
        ));
    }
    let mut out = vec![];
    for (num, id) in patch_labels(label_names, chart)? {
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for y in 0..h {
            for x in 0..w {
                if labels[y * w + x] == id {
                    (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
                }
            }
        }
        let name = label_names[id as usize].clone();
        if x0 == usize::MAX {
            return Err(Error::invalid(format!(
                "patch '{name}' is not visible in the image"
            )));
        }
        let r =
            ((erode_fraction * ((x1 - x0 + 1).min(y1 - y0 + 1)) as f64).round() as usize).max(1);
        let same = |x: usize, y: usize| labels[y * w + x] == id;
        // Separable erosion: horizontal runs, then vertical.
        let (bw, bh) = (x1 - x0 + 1, y1 - y0 + 1);
        let mut hrun = vec![false; bw * bh];
        for y in y0..=y1 {
            for x in x0..=x1 {
                hrun[(y - y0) * bw + x - x0] =
                    x >= r && x + r < w && (x - r..=x + r).all(|xx| same(xx, y));
            }
        }
        let mut kept = vec![];
        for y in y0..=y1 {
            for x in x0..=x1 {
                if y >= y0 + r
                    && y + r <= y1
                    && (y - r..=y + r).all(|yy| hrun[(yy - y0) * bw + x - x0])
                {
                    kept.push((x, y));
                }
            }
        }
        if kept.is_empty() {
            return Err(Error::invalid(format!(
                "patch '{name}' vanishes after eroding {r} px; is it partly hidden?"
            )));
        }
        let (kx0, ky0) = (
            kept.iter().map(|p| p.0).min().unwrap_or(0),
            kept.iter().map(|p| p.1).min().unwrap_or(0),
        );
        let (kx1, ky1) = (
            kept.iter().map(|p| p.0).max().unwrap_or(0),
            kept.iter().map(|p| p.1).max().unwrap_or(0),
        );
        let mut means = vec![];
        let mut clipped = vec![];
        for v in views {
            let vals: Vec<f64> = kept.iter().filter_map(|&(x, y)| v.value(x, y)).collect();
            if vals.len() < 2 {
                return Err(Error::invalid(format!(
                    "patch '{name}': fewer than 2 '{}' pixels after erosion",
                    v.name
                )));
            }
            means.push((
                v.name.to_string(),
                mean(&vals),
                std_dev(&vals) / (vals.len() as f64).sqrt(),
            ));
            let n_clipped = clip.map_or(0, |(lo, hi)| {
                vals.iter().filter(|&&x| x <= lo || x >= hi).count()
            });
            clipped.push(n_clipped as f64 / vals.len() as f64);
        }
        out.push(Patch {
            number: num,
            name,
            rect: Rect::new(
                kx0 as u32,
                ky0 as u32,
                (kx1 - kx0 + 1) as u32,
                (ky1 - ky0 + 1) as u32,
            ),
            pixels: kept.len(),
            means,
            clipped,
        });
    }
    Ok(out)
}

/// Patch means of `chart` in a sensor image (black level subtracted, DV).
pub fn patch_means_of_sensor(
    img: &crate::image::SensorImage,
    chart: &str,
    erode_fraction: f64,
) -> Result<Vec<Patch>> {
    let plane = super::plane::Plane::from_sensor(img)?;
    let views = super::plane::channel_views(&plane, "y");
    // DV 0 and the white level are the ADC's clip levels (black subtracted here).
    let clip = (-img.black_level_dv, img.white_level_dv - img.black_level_dv);
    let patches = patch_means_clipped(
        &views,
        &img.labels,
        &img.label_names,
        chart,
        erode_fraction,
        Some(clip),
    )?;
    check_not_dark(&patches, chart, img.exposure_s)?;
    Ok(patches)
}

/// Refuse a chart with no signal: when no patch channel's mean rises above
/// 1 DV and 3 standard errors, the figures would be 0 DV of noise. Says what
/// to check instead (session 1 met "0 DV MCC means" without a word).
pub fn check_not_dark(patches: &[Patch], chart: &str, exposure_s: f64) -> Result<()> {
    let brightest = patches
        .iter()
        .flat_map(|p| p.means.iter().map(move |m| (p, m)))
        .max_by(|a, b| a.1.1.total_cmp(&b.1.1));
    let Some((p, (c, v, se))) = brightest else {
        return Ok(());
    };
    let lit = patches
        .iter()
        .flat_map(|p| &p.means)
        .any(|(_, v, se)| *v > 1.0 && *v > 3.0 * se);
    if lit {
        return Ok(());
    }
    Err(Error::invalid(format!(
        "chart '{chart}' is dark: its brightest patch ({}, channel {c}) reads {v:.3} ± {se:.3} DV above black at an exposure of {exposure_s:.3e} s; \
         no patch rises above 1 DV and its noise. Expose longer (sensor exposure-s=…), check the light's emission units (radiance in W/(sr·m²·nm)) \
         and that the chart faces the camera and is lit",
        p.name
    )))
}

/// Figures `patchNN/<ch>_mean` (DV), `patchNN/<ch>_clipped_fraction` where
/// pixels are clipped, and one curve per channel (mean vs patch number).
pub fn measured(patches: &[Patch], measurement: &str) -> Measured {
    let mut m = Measured::default();
    for p in patches {
        for (i, (c, v, se)) in p.means.iter().enumerate() {
            let q = format!("patch{:02}/{c}_mean", p.number);
            let clipped = p.clipped.get(i).copied().unwrap_or(0.0);
            let flag = clipped_flag(&q).filter(|_| clipped > 0.0);
            m.figures.push(Figure::new(measurement, q, "DV", *v, *se));
            if let Some(f) = flag {
                m.figures
                    .push(Figure::new(measurement, f, "1", clipped, 0.0));
            }
        }
        m.pixels_read.push(p.rect);
    }
    if let Some(first) = patches.first() {
        for (i, (c, _, _)) in first.means.iter().enumerate() {
            m.curves.push(Curve::new(
                &format!("patch_means/{c}"),
                ("patch", "1"),
                (c, "DV"),
                patches.iter().map(|p| p.number as f64).collect(),
                patches.iter().map(|p| p.means[i].1).collect(),
                patches.iter().map(|p| p.means[i].2).collect(),
            ));
        }
    }
    m
}
