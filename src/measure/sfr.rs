//! Slanted-edge e-SFR after ISO 12233:2017 (the `sfrmat` family of methods).
//!
//! Steps, on a region holding one near-vertical (or near-horizontal, then the
//! region is transposed) edge:
//! 1. Edge location per row: derivative `[−1, +1]` along the row, Hamming
//!    window, centroid; first pass with the window centred in the row, second
//!    pass with the window centred on the first-pass fitted edge.
//! 2. Edge fit `x_e(y)`: least-squares polynomial (degree 1 by default, up
//!    to 5) through the row centroids (QR on a centred, scaled basis).
//! 3. Whole phase cycles: only `round(floor(h·|slope|)/|slope|)` rows (centred
//!    in the region) are used, so every quarter-pixel bin gets the same share
//!    of phases.
//! 4. 4× oversampled ESF: every pixel's signed distance **normal to the edge**
//!    `(x − x_e(y))·cos θ` is binned at 1/4 px; empty bins are filled by linear
//!    interpolation. Frequencies are therefore measured normal to the edge and
//!    need no later cos θ correction. Deviation from the standard (documented):
//!    each bin's mean is attributed to the mean position of its samples and
//!    linearly interpolated back to the bin centre. With a finite number of rows
//!    the sample phases inside a bin are not exactly centred (offsets up to
//!    ~½/rows px), which the plain bin mean turns into deterministic ESF errors
//!    (≈0.01 MTF near Nyquist for a sharp edge); the correction removes them
//!    to first order and keeps the ¼-px box average.
//! 5. LSF by the 3-tap central difference `[−½, 0, +½]`, Hamming window
//!    centred on the LSF centroid (asymmetric, as in ISO 12233:2017 Annex),
//!    DFT, normalised at zero frequency.
//! 6. Derivative correction: division by the central-difference response
//!    `sin(2πf·Δ)/(2πf·Δ)`, Δ = ¼ px (capped at 10 as in sfrmat). The ¼-px
//!    binning itself (a box of ¼ px, `sinc(f/4)`) is part of the method and is
//!    *not* corrected, as in the standard.
//!
//! The measured MTF of a Gaussian PSF σ sampled by square pixels of fill 1 is
//! then `exp(−2π²σ²f²) · sinc(f cos θ) · sinc(f sin θ) · sinc(f/4)`: the pixel
//! aperture projected on the edge normal is the convolution of two boxes of
//! widths cos θ and sin θ (the "sinc²(pixel)" of the acceptance criterion).
//!
//! **CFA mosaics.** The edge is located on the 2×2 sliding mean of the mosaic
//! (every 2×2 window holds each Bayer colour in the same proportion; its
//! samples sit at half-pixel positions, accounted for). With `channel = r|g|b`
//! only that channel's pixels enter the ESF, at their true positions. With
//! `lum` on a mosaic, each channel's samples are normalised to 0…1 by their
//! own dark and bright plateau medians (outer quarters of the region), then all
//! are binned together: a luminance ESF for a neutral edge without demosaicing.
//!
//! **Standard errors.** Delete-a-group jackknife: the used rows are split into
//! `G` (default 8) contiguous blocks; the whole estimate (edge fit, ESF, MTF,
//! MTF50, angle) is repeated without each block, and
//! `se = sqrt((G−1)/G Σ(θ_g − θ̄)²)`. It captures image noise, edge-fit error
//! and binning (phase) variation; it assumes rows are independent.
//!
//! **Noise floor.** From the spread of the samples in each ¼-px ESF bin the
//! RMS MTF that pixel noise alone produces is propagated analytically through
//! the LSF and DFT (`noise_floor`); its value at 0.5 cy/px is reported as
//! `mtf_noise@0.5cy/px`, and a region whose floor exceeds
//! [`MAX_NOISE_FLOOR`] (edge contrast too low for its noise) is refused with
//! an error naming the region, instead of reporting noise as MTF (> 1).

use super::plane::Plane;
use super::stats::{jackknife_se, least_squares, median};
use super::{Curve, Measured};
use crate::figure::Figure;
use crate::optical_image::Rect;
use crate::params::{Kind, ParamError, ParamSpec};
use crate::{Error, Result};

/// Largest RMS MTF that pixel noise alone may produce at 0.5 cy/px before an
/// edge region is refused. A sharp edge's MTF there is ≈0.6 (pixel
/// aperture); a noise floor of 0.5 is as large as that signal, so the
/// high-frequency MTF would be noise and values > 1 common (session 1 saw
/// 1.06 and 1.36 on an 8-spp pinhole render, floor 1.0). Below the limit the
/// floor is reported with the figures (`mtf_noise@0.5cy/px`) so a reader can
/// judge each one.
pub const MAX_NOISE_FLOOR: f64 = 0.5;

/// Which pixels form the edge-spread function.
#[derive(Clone, Debug, PartialEq)]
pub enum SfrChannel {
    /// All pixels (per-channel normalised on a mosaic).
    Lum,
    /// Only pixels of this CFA channel ("r", "g", "b").
    Named(String),
}

impl SfrChannel {
    pub fn parse(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "lum" | "y" | "luminance" => Ok(SfrChannel::Lum),
            c @ ("r" | "g" | "b" | "w") => Ok(SfrChannel::Named(c.to_string())),
            _ => Err(Error::invalid(format!(
                "unknown channel '{s}': expected lum, r, g or b"
            ))),
        }
    }
}

#[derive(Clone, Debug)]
pub struct SfrOptions {
    pub channel: SfrChannel,
    /// Degree of the edge polynomial x_e(y): 1 (straight edge) … 5.
    pub fit_degree: usize,
    /// Pixel pitch for cy/mm figures.
    pub pixel_pitch_m: Option<f64>,
    /// Jackknife groups (≥ 4).
    pub jackknife_groups: usize,
    /// Highest frequency reported, cy/px (the 4× ESF supports up to 2).
    pub max_freq_cy_per_px: f64,
    /// Largest RMS MTF that pixel noise alone may produce at 0.5 cy/px before
    /// the region is refused (default [`MAX_NOISE_FLOOR`]).
    pub max_noise_floor: f64,
}

impl Default for SfrOptions {
    fn default() -> Self {
        Self {
            channel: SfrChannel::Lum,
            fit_degree: 1,
            pixel_pitch_m: None,
            jackknife_groups: 8,
            max_freq_cy_per_px: 1.0,
            max_noise_floor: MAX_NOISE_FLOOR,
        }
    }
}

/// The e-SFR of one edge region.
#[derive(Clone, Debug)]
pub struct Sfr {
    pub freq_cy_per_px: Vec<f64>,
    pub mtf: Vec<f64>,
    pub mtf_stderr: Vec<f64>,
    /// ESF abscissa: distance normal to the edge, px (bin centres, ¼ px apart).
    pub esf_x_px: Vec<f64>,
    pub esf: Vec<f64>,
    /// LSF, normalised to unit area (1/px), same abscissa as the ESF.
    pub lsf: Vec<f64>,
    pub mtf50_cy_per_px: Option<f64>,
    pub mtf50_stderr: f64,
    /// Edge angle from the row direction's normal (from vertical; from
    /// horizontal when `transposed`), degrees.
    pub edge_angle_deg: f64,
    pub edge_angle_stderr_deg: f64,
    pub lsf_fwhm_stderr_px: f64,
    pub rows_used: usize,
    /// RMS MTF from pixel noise alone at 0.5 cy/px (see `noise_floor`).
    pub noise_floor_nyquist: f64,
    /// RMS MTF from pixel noise alone at each of `freq_cy_per_px`.
    pub noise_floor: Vec<f64>,
    /// Its jackknife standard error.
    pub noise_floor_stderr: f64,
    pub transposed: bool,
    pub pixel_pitch_m: Option<f64>,
}

impl Sfr {
    /// MTF (and its standard error) at `f` cy/px by linear interpolation.
    pub fn mtf_at(&self, f: f64) -> Option<(f64, f64)> {
        let fs = &self.freq_cy_per_px;
        let i = fs.iter().position(|&x| x >= f)?;
        if i == 0 {
            return Some((self.mtf[0], self.mtf_stderr[0]));
        }
        let t = (f - fs[i - 1]) / (fs[i] - fs[i - 1]);
        let lerp = |v: &[f64]| v[i - 1] + t * (v[i] - v[i - 1]);
        Some((lerp(&self.mtf), lerp(&self.mtf_stderr)))
    }

    pub fn freq_cy_per_mm(&self) -> Option<Vec<f64>> {
        let p_mm = self.pixel_pitch_m? * 1e3;
        Some(self.freq_cy_per_px.iter().map(|f| f / p_mm).collect())
    }

    /// Figures and curves for `results.csv` / `curves/`.
    pub fn measured(&self, measurement: &str, roi: Rect) -> Measured {
        let mut figures = vec![];
        if let Some(m50) = self.mtf50_cy_per_px {
            figures.push(Figure::new(
                measurement,
                "mtf50",
                "cy/px",
                m50,
                self.mtf50_stderr,
            ));
            if let Some(p) = self.pixel_pitch_m {
                let p_mm = p * 1e3;
                figures.push(Figure::new(
                    measurement,
                    "mtf50_mm",
                    "cy/mm",
                    m50 / p_mm,
                    self.mtf50_stderr / p_mm,
                ));
            }
        }
        for f in [0.125, 0.25, 0.5] {
            if let Some((m, se)) = self.mtf_at(f) {
                figures.push(Figure::new(
                    measurement,
                    format!("mtf@{f}cy/px"),
                    "1",
                    m,
                    se,
                ));
            }
        }
        figures.push(Figure::new(
            measurement,
            "mtf_noise@0.5cy/px",
            "1",
            self.noise_floor_nyquist,
            self.noise_floor_stderr,
        ));
        figures.push(Figure::new(
            measurement,
            "edge_angle",
            "deg",
            self.edge_angle_deg,
            self.edge_angle_stderr_deg,
        ));
        figures.push(Figure::new(
            measurement,
            "lsf_fwhm",
            "px",
            self.lsf_fwhm_px(),
            self.lsf_fwhm_stderr_px,
        ));
        let curves = self.curves();
        Measured {
            figures,
            curves,
            pixels_read: vec![roi],
        }
    }

    /// The curves as the paper plots them (Fig. 7): the ESF (px); the LSF
    /// over the span where it is not negligible ([`Sfr::lsf_span`]), in µm
    /// when the pixel pitch is known; the MTF up to the Nyquist frequency
    /// (0.5 cy/px) in cy/mm when the pitch is known, with the RMS MTF that
    /// pixel noise alone gives drawn beside it (`mtf#noise floor`), so a
    /// reader sees where the curve is blur and where it is noise.
    pub fn curves(&self) -> Vec<Curve> {
        let (lo, hi) = self.lsf_span();
        let um = self.pixel_pitch_m.map(|p| p * 1e6);
        let keep: Vec<usize> = (0..self.esf_x_px.len())
            .filter(|&i| self.esf_x_px[i] >= lo && self.esf_x_px[i] <= hi)
            .collect();
        let (lsf_x, lsf_y, x_unit, y_unit) = match um {
            Some(u) => (
                keep.iter().map(|&i| self.esf_x_px[i] * u).collect(),
                keep.iter().map(|&i| self.lsf[i] / u).collect(),
                "µm",
                "1/µm",
            ),
            None => (
                keep.iter().map(|&i| self.esf_x_px[i]).collect(),
                keep.iter().map(|&i| self.lsf[i]).collect(),
                "px",
                "1/px",
            ),
        };
        let nyq: Vec<usize> = (0..self.freq_cy_per_px.len())
            .filter(|&i| self.freq_cy_per_px[i] <= 0.5 + 1e-9)
            .collect();
        let (f_scale, f_unit) = match self.pixel_pitch_m {
            Some(p) => (1.0 / (p * 1e3), "cy/mm"),
            None => (1.0, "cy/px"),
        };
        let f: Vec<f64> = nyq
            .iter()
            .map(|&i| self.freq_cy_per_px[i] * f_scale)
            .collect();
        let pick = |v: &[f64]| {
            nyq.iter()
                .map(|&i| v.get(i).copied().unwrap_or(0.0))
                .collect()
        };
        vec![
            Curve::new(
                "esf",
                ("distance", "px"),
                ("esf", "input"),
                self.esf_x_px.clone(),
                self.esf.clone(),
                vec![],
            ),
            Curve::new(
                "lsf",
                ("distance", x_unit),
                ("lsf", y_unit),
                lsf_x,
                lsf_y,
                vec![],
            ),
            Curve::new(
                "mtf",
                ("frequency", f_unit),
                ("mtf", "1"),
                f.clone(),
                pick(&self.mtf),
                pick(&self.mtf_stderr),
            ),
            Curve::new(
                "mtf#noise floor",
                ("frequency", f_unit),
                ("mtf", "1"),
                f,
                pick(&self.noise_floor),
                vec![],
            ),
        ]
    }

    /// The span of the LSF that is not negligible, px: around the edge's
    /// 10–90 % rise (the ESF normalised by its plateaus and smoothed over
    /// 4 px; from its first crossing of ½ outward until it passes 10 % and
    /// 90 %; the smoothing widens the rise by at most 4 px), widened by twice
    /// the rise distance plus 4 px on each side, so the plot shows the blur
    /// and its tails, not ±150 px of plateau noise.
    pub fn lsf_span(&self) -> (f64, f64) {
        let n = self.esf.len();
        let x = &self.esf_x_px;
        if n < 8 {
            return (
                x.first().copied().unwrap_or(0.0),
                x.last().copied().unwrap_or(0.0),
            );
        }
        let q = n / 8;
        let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
        let (a, b) = (mean(&self.esf[..q]), mean(&self.esf[n - q..]));
        let step = b - a;
        // The ESF normalised to its plateaus (0 → 1), smoothed over 17 bins
        // (4 px) so plateau noise cannot pass for the edge.
        let norm: Vec<f64> = self
            .esf
            .iter()
            .map(|v| if step == 0.0 { 0.5 } else { (v - a) / step })
            .collect();
        let half = 8usize;
        let frac: Vec<f64> = (0..n)
            .map(|i| {
                let (lo, hi) = (i.saturating_sub(half), (i + half + 1).min(n));
                mean(&norm[lo..hi])
            })
            .collect();
        // the edge: the first crossing of ½
        let mid = (0..n).find(|&i| frac[i] >= 0.5).unwrap_or(n / 2);
        let mut l = mid;
        while l > 0 && frac[l] > 0.1 {
            l -= 1;
        }
        let mut r = mid;
        while r + 1 < n && frac[r] < 0.9 {
            r += 1;
        }
        let rise = x[r] - x[l];
        let pad = 2.0 * rise + 4.0;
        ((x[l] - pad).max(x[0]), (x[r] + pad).min(x[n - 1]))
    }

    /// Full width at half maximum of the LSF, px (linear interpolation).
    pub fn lsf_fwhm_px(&self) -> f64 {
        fwhm(&self.esf_x_px, &self.lsf)
    }
}

/// Full width at half maximum of `y(x)`, linear interpolation between samples.
fn fwhm(x: &[f64], y: &[f64]) -> f64 {
    let (imax, &peak) = y
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .unwrap_or((0, &0.0));
    let half = 0.5 * peak;
    let mut left = x[0];
    for i in (1..=imax).rev() {
        if y[i - 1] < half {
            left = x[i - 1] + (half - y[i - 1]) / (y[i] - y[i - 1]) * (x[i] - x[i - 1]);
            break;
        }
    }
    let mut right = x[x.len() - 1];
    for i in imax..y.len() - 1 {
        if y[i + 1] < half {
            right = x[i] + (y[i] - half) / (y[i] - y[i + 1]) * (x[i + 1] - x[i]);
            break;
        }
    }
    right - left
}

/// Asymmetric Hamming window of `n` points peaking at `mid` (sfrmat `ahamming`).
fn ahamming(n: usize, mid: f64) -> Vec<f64> {
    let wid = mid.max(n as f64 - 1.0 - mid).max(1.0);
    (0..n)
        .map(|i| 0.54 + 0.46 * (std::f64::consts::PI * (i as f64 - mid) / wid).cos())
        .collect()
}

/// A polynomial x(y) in the scaled variable t = (y − y0)/ys.
#[derive(Clone, Debug)]
struct EdgeFit {
    c: Vec<f64>,
    y0: f64,
    ys: f64,
}

impl EdgeFit {
    fn fit(ys_: &[f64], xs: &[f64], degree: usize) -> Option<Self> {
        let n = ys_.len();
        if n < degree + 2 {
            return None;
        }
        let y0 = ys_.iter().sum::<f64>() / n as f64;
        let ys = ys_
            .iter()
            .map(|y| (y - y0).abs())
            .fold(0.0, f64::max)
            .max(1.0);
        let a: Vec<f64> = ys_
            .iter()
            .flat_map(|y| (0..=degree).map(move |k| ((y - y0) / ys).powi(k as i32)))
            .collect();
        let c = least_squares(&a, n, degree + 1, xs)?;
        Some(Self { c, y0, ys })
    }
    fn x(&self, y: f64) -> f64 {
        let t = (y - self.y0) / self.ys;
        self.c.iter().rev().fold(0.0, |acc, &c| acc * t + c)
    }
    /// dx/dy.
    fn slope(&self, y: f64) -> f64 {
        let t = (y - self.y0) / self.ys;
        let d = self
            .c
            .iter()
            .enumerate()
            .skip(1)
            .rev()
            .fold(0.0, |acc, (k, &c)| acc * t + k as f64 * c);
        d / self.ys
    }
}

/// Edge-location plane: the plane itself, or the 2×2 sliding mean of a mosaic
/// (sample (x, y) then sits at (x + ½, y + ½)).
fn locate_plane(p: &Plane) -> (usize, usize, Vec<f64>, f64) {
    if !p.is_mosaic() {
        return (p.width, p.height, p.data.clone(), 0.0);
    }
    let (w, h) = (p.width - 1, p.height - 1);
    let mut d = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            d.push(0.25 * (p.get(x, y) + p.get(x + 1, y) + p.get(x, y + 1) + p.get(x + 1, y + 1)));
        }
    }
    (w, h, d, 0.5)
}

/// Mean |horizontal| and |vertical| first differences.
fn gradient_energy(w: usize, h: usize, d: &[f64]) -> (f64, f64) {
    let (mut gx, mut gy) = (0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            if x + 1 < w {
                gx += (d[y * w + x + 1] - d[y * w + x]).abs();
            }
            if y + 1 < h {
                gy += (d[(y + 1) * w + x] - d[y * w + x]).abs();
            }
        }
    }
    (gx / ((w - 1) * h) as f64, gy / (w * (h - 1)) as f64)
}

/// Windowed centroid of a row derivative (positions of the derivative samples
/// are `i + ½ + off`); `mid` is the window centre in derivative-index units.
fn row_centroid(row: &[f64], sign: f64, mid: Option<f64>, off: f64) -> Option<f64> {
    let n = row.len() - 1;
    let mid = mid.unwrap_or((n as f64 - 1.0) / 2.0);
    let win = ahamming(n, mid);
    let (mut s, mut sx) = (0.0, 0.0);
    for i in 0..n {
        let d = sign * (row[i + 1] - row[i]) * win[i];
        s += d;
        sx += d * (i as f64 + 0.5 + off);
    }
    (s > 0.0).then(|| sx / s)
}

struct Estimate {
    mtf: Vec<f64>,
    /// RMS MTF that the pixel noise alone gives at each frequency (see [`noise_floor`]).
    noise_floor: Vec<f64>,
    /// RMS per-pixel noise of the ESF samples and the ESF's edge contrast (input units).
    pixel_noise: f64,
    contrast: f64,
    mtf50: Option<f64>,
    angle_deg: f64,
    esf: Vec<f64>,
    lsf: Vec<f64>,
}

struct Prepared<'a> {
    plane: &'a Plane,
    /// Row centroids of the locate plane: (y, x) in plane coordinates.
    centroids: Vec<(f64, f64)>,
    degree: usize,
    nbins: usize,
    nfreq: usize,
    /// Which pixels enter the ESF and their affine normalisation (gain, offset) per channel.
    select: Vec<Option<(f64, f64)>>,
}

impl Prepared<'_> {
    fn value(&self, x: usize, y: usize) -> Option<f64> {
        let ch = self.plane.channel_at(x, y).unwrap_or(0) as usize;
        self.select
            .get(ch)
            .copied()
            .flatten()
            .map(|(g, o)| (self.plane.get(x, y) - o) * g)
    }

    fn estimate(&self, rows: &[usize]) -> Option<Estimate> {
        let (lo, hi) = (*rows.first()? as f64, *rows.last()? as f64 + 1.0);
        let keep: Vec<&(f64, f64)> = self
            .centroids
            .iter()
            .filter(|(y, _)| {
                *y >= lo && *y <= hi && rows.binary_search(&(y.floor() as usize)).is_ok()
            })
            .collect();
        let fit = EdgeFit::fit(
            &keep.iter().map(|c| c.0).collect::<Vec<_>>(),
            &keep.iter().map(|c| c.1).collect::<Vec<_>>(),
            self.degree,
        )?;
        let ymid = 0.5 * (lo + hi - 1.0);
        let angle_deg = fit.slope(ymid).atan().to_degrees();
        let n = self.nbins;
        let half_px = n as f64 / 8.0;
        let (mut sum, mut sum_d, mut cnt) = (vec![0.0; n], vec![0.0; n], vec![0u32; n]);
        let mut sum2 = vec![0.0; n];
        for &y in rows {
            let xe = fit.x(y as f64);
            let cos = 1.0 / (1.0 + fit.slope(y as f64).powi(2)).sqrt();
            for x in 0..self.plane.width {
                let Some(v) = self.value(x, y) else { continue };
                let d = (x as f64 - xe) * cos;
                let b = ((d + half_px) * 4.0).floor();
                if b >= 0.0 && (b as usize) < n {
                    sum[b as usize] += v;
                    sum2[b as usize] += v * v;
                    sum_d[b as usize] += (d + half_px) * 4.0 - b - 0.5;
                    cnt[b as usize] += 1;
                }
            }
        }
        let esf = fill_bins(&sum, &sum_d, &cnt)?;
        // LSF: 3-tap central difference, per px (Δ = ¼ px).
        let mut lsf = vec![0.0; n];
        for i in 1..n - 1 {
            lsf[i] = (esf[i + 1] - esf[i - 1]) * 2.0;
        }
        lsf[0] = lsf[1];
        lsf[n - 1] = lsf[n - 2];
        let total: f64 = lsf.iter().sum();
        if total == 0.0 || !total.is_finite() {
            return None;
        }
        let sign = total.signum();
        lsf.iter_mut().for_each(|v| *v *= sign);
        let area: f64 = lsf.iter().sum::<f64>() * 0.25;
        let centroid = lsf
            .iter()
            .enumerate()
            .map(|(i, v)| i as f64 * v)
            .sum::<f64>()
            / lsf.iter().sum::<f64>();
        let win = ahamming(n, centroid.clamp(0.0, n as f64 - 1.0));
        let lw: Vec<f64> = lsf.iter().zip(&win).map(|(a, b)| a * b).collect();
        let mut mtf = Vec::with_capacity(self.nfreq);
        let mut dc = 0.0;
        for m in 0..self.nfreq {
            let (mut re, mut im) = (0.0, 0.0);
            let w = 2.0 * std::f64::consts::PI * m as f64 / n as f64;
            for (k, v) in lw.iter().enumerate() {
                let a = w * k as f64;
                re += v * a.cos();
                im -= v * a.sin();
            }
            let mag = (re * re + im * im).sqrt();
            if m == 0 {
                dc = mag;
            }
            // Derivative correction: central difference over ±1 bin responds sin(w)/w.
            let corr = if m == 0 {
                1.0
            } else {
                (w / w.sin()).abs().min(10.0)
            };
            mtf.push(mag / dc * corr);
        }
        let mtf50 = crossing(&mtf, 0.5).map(|i| i * 4.0 / n as f64);
        let bin_var = bin_variances(&sum, &sum2, &cnt);
        let noise_floor = noise_floor(&win, &cnt, &bin_var, dc, self.nfreq);
        let pixel_noise = (bin_var.iter().sum::<f64>() / n as f64).sqrt();
        let contrast = edge_contrast(&esf);
        let lsf = lsf.iter().map(|v| v / area).collect();
        Some(Estimate {
            mtf,
            noise_floor,
            pixel_noise,
            contrast,
            mtf50,
            angle_deg,
            esf,
            lsf,
        })
    }
}

/// Per-bin variance of the ESF samples (0 for bins with < 2 samples).
/// Samples of one ¼-px bin sit at the same distance from the edge, so their
/// spread is pixel noise (plus row-to-row shading); on a steep edge the ¼-px
/// phase spread adds a little signal (conservative). Per bin, not pooled:
/// noise differs across the edge (photon noise, clipped plateaus).
fn bin_variances(sum: &[f64], sum2: &[f64], cnt: &[u32]) -> Vec<f64> {
    (0..sum.len())
        .map(|i| {
            let k = cnt[i] as f64;
            if cnt[i] < 2 {
                0.0
            } else {
                ((sum2[i] - sum[i] * sum[i] / k) / (k - 1.0)).max(0.0)
            }
        })
        .collect()
}

/// Edge contrast of an ESF: mean of its last eighth minus mean of its first.
fn edge_contrast(esf: &[f64]) -> f64 {
    let k = (esf.len() / 8).max(1);
    let m = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    (m(&esf[esf.len() - k..]) - m(&esf[..k])).abs()
}

/// RMS of the MTF that independent pixel noise (variance `var[j]` in bin j) alone produces, per
/// frequency bin m (same normalisation as the MTF: derivative correction,
/// divided by the zero-frequency LSF sum `dc`). The LSF is 2(e₊ − e₋) of ESF
/// bins e_j with variance σ_j²/n_j, so the windowed DFT's noise is
/// Σ_j a_j e_j with a_j = 2(w_{j−1}·z^{j−1} − w_{j+1}·z^{j+1}), z = e^{−iω}:
/// E|N|² = Σ_j |a_j|² σ_j²/n_j.
fn noise_floor(win: &[f64], cnt: &[u32], var_j: &[f64], dc: f64, nfreq: usize) -> Vec<f64> {
    let n = win.len();
    // (sin, cos) of ω·k for k = 0…n−1: each term j − 1 and j + 1 takes its
    // angle from here (the same product ω·k, so the same values as computing it
    // per term, with half the trigonometric calls).
    let mut sc = vec![(0.0f64, 0.0f64); n];
    (0..nfreq)
        .map(|m| {
            if m == 0 || dc <= 0.0 {
                return 0.0;
            }
            let w = 2.0 * std::f64::consts::PI * m as f64 / n as f64;
            for (k, t) in sc.iter_mut().enumerate() {
                *t = (w * k as f64).sin_cos();
            }
            let mut var = 0.0;
            for j in 0..n {
                let (mut re, mut im) = (0.0, 0.0);
                if j >= 2 && j - 1 < n - 1 {
                    let (sin, cos) = sc[j - 1];
                    re += win[j - 1] * cos;
                    im -= win[j - 1] * sin;
                }
                if j + 1 < n - 1 {
                    let (sin, cos) = sc[j + 1];
                    re -= win[j + 1] * cos;
                    im += win[j + 1] * sin;
                }
                var += 4.0 * (re * re + im * im) * var_j[j] / cnt[j].max(1) as f64;
            }
            let corr = (w / w.sin()).abs().min(10.0);
            var.sqrt() * corr / dc
        })
        .collect()
}

/// Fractional index where `v` first falls below `level`.
fn crossing(v: &[f64], level: f64) -> Option<f64> {
    (1..v.len())
        .find(|&i| v[i] < level && v[i - 1] >= level)
        .map(|i| (i - 1) as f64 + (v[i - 1] - level) / (v[i - 1] - v[i]))
}

/// Bin means, moved from the mean sample position of each bin to the bin
/// centre by linear interpolation with the neighbouring bin (phase-quantisation
/// correction, see module docs); empty bins linearly interpolated, constant
/// beyond the ends. `sum_d` holds each sample's offset from its bin centre, in bins.
fn fill_bins(sum: &[f64], sum_d: &[f64], cnt: &[u32]) -> Option<Vec<f64>> {
    let full: Vec<usize> = (0..sum.len()).filter(|&i| cnt[i] > 0).collect();
    if full.len() < 2 {
        return None;
    }
    // (position in bins, mean value) of every non-empty bin.
    let pts: Vec<(f64, f64)> = full
        .iter()
        .map(|&i| (i as f64 + sum_d[i] / cnt[i] as f64, sum[i] / cnt[i] as f64))
        .collect();
    let interp = |x: f64| -> f64 {
        let j = pts.partition_point(|p| p.0 < x);
        if j == 0 {
            pts[0].1
        } else if j == pts.len() {
            pts[j - 1].1
        } else {
            let (a, b) = (pts[j - 1], pts[j]);
            a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0)
        }
    };
    Some((0..sum.len()).map(|i| interp(i as f64)).collect())
}

/// e-SFR of the edge in `plane` (the whole plane is the region of interest).
pub fn sfr(plane: &Plane, opts: &SfrOptions) -> Result<Sfr> {
    if plane.width < 8 || plane.height < 8 {
        return Err(Error::invalid(format!(
            "SFR region {}×{} px is too small (at least 8×8, ideally ≥ 32×32)",
            plane.width, plane.height
        )));
    }
    if !(1..=5).contains(&opts.fit_degree) {
        return Err(Error::invalid(format!(
            "edge fit degree {} not in 1…5",
            opts.fit_degree
        )));
    }
    let (lw, lh, ld, _) = locate_plane(plane);
    let (gx, gy) = gradient_energy(lw, lh, &ld);
    let transposed = gy > gx;
    let tp;
    let p: &Plane = if transposed {
        tp = plane.transpose();
        &tp
    } else {
        plane
    };
    let (lw, lh, ld, off) = locate_plane(p);
    let total: f64 = (0..lh).map(|y| ld[y * lw + lw - 1] - ld[y * lw]).sum();
    if total == 0.0 {
        return Err(Error::invalid(
            "no edge in the SFR region: dark and bright sides have the same level".to_string(),
        ));
    }
    let sign = total.signum();
    let rows: Vec<&[f64]> = (0..lh).map(|y| &ld[y * lw..(y + 1) * lw]).collect();
    // Pass 1: window centred in the row; fit; pass 2: window centred on the fit.
    let pass1: Vec<(f64, f64)> = rows
        .iter()
        .enumerate()
        .filter_map(|(y, r)| row_centroid(r, sign, None, off).map(|c| (y as f64 + off, c)))
        .collect();
    let fit_of = |c: &[(f64, f64)], deg| {
        EdgeFit::fit(
            &c.iter().map(|v| v.0).collect::<Vec<_>>(),
            &c.iter().map(|v| v.1).collect::<Vec<_>>(),
            deg,
        )
    };
    let no_edge = || {
        Error::invalid(
            "could not locate the edge in the SFR region (too few rows with an edge response)"
                .to_string(),
        )
    };
    let fit1 = fit_of(&pass1, opts.fit_degree).ok_or_else(no_edge)?;
    let centroids: Vec<(f64, f64)> = rows
        .iter()
        .enumerate()
        .filter_map(|(y, r)| {
            let yc = y as f64 + off;
            let mid = (fit1.x(yc) - 0.5 - off).clamp(0.0, (lw - 2) as f64);
            row_centroid(r, sign, Some(mid), off).map(|c| (yc, c))
        })
        .collect();
    let lin = fit_of(&centroids, 1).ok_or_else(no_edge)?;
    let slope = lin.slope(lin.y0).abs();
    let h = p.height;
    let cycles = h as f64 * slope;
    if cycles < 1.0 {
        return Err(Error::invalid(format!(
            "edge angle {:.2}° is too close to the pixel grid: {cycles:.2} phase cycles in {h} rows (need ≥ 1; tilt the edge ~5°)",
            slope.atan().to_degrees()
        )));
    }
    let nlin = ((cycles.floor() / slope).round() as usize).clamp(1, h);
    let start = (h - nlin) / 2;
    let used: Vec<usize> = (start..start + nlin).collect();
    let cos = 1.0 / (1.0 + slope * slope).sqrt();
    let nbins = ((p.width as f64 * cos * 4.0) as usize / 2 * 2).max(16);
    let fmax = opts.max_freq_cy_per_px.clamp(0.01, 2.0);
    let nfreq = ((fmax * nbins as f64 / 4.0).floor() as usize + 1).min(nbins / 2 + 1);
    let nch = p.channel_names.len().max(1);
    let mut prep = Prepared {
        plane: p,
        centroids,
        degree: opts.fit_degree,
        nbins,
        nfreq,
        select: vec![Some((1.0, 0.0)); nch],
    };
    match (&opts.channel, p.is_mosaic()) {
        (SfrChannel::Named(c), true) => {
            let ci = p.channel_index(c).ok_or_else(|| {
                Error::invalid(format!(
                    "channel '{c}' is not in the CFA (channels: {})",
                    p.channel_names.join(", ")
                ))
            })? as usize;
            prep.select = (0..nch).map(|i| (i == ci).then_some((1.0, 0.0))).collect();
        }
        (SfrChannel::Named(c), false) if c != "w" && c != "g" => {
            return Err(Error::invalid(format!(
                "channel '{c}' asked of a single-channel image; use --channel lum"
            )));
        }
        (SfrChannel::Lum, true) => {
            // Per-channel plateau normalisation from the outer quarters of the region.
            let fit = EdgeFit::fit(
                &prep.centroids.iter().map(|v| v.0).collect::<Vec<_>>(),
                &prep.centroids.iter().map(|v| v.1).collect::<Vec<_>>(),
                opts.fit_degree,
            )
            .ok_or_else(no_edge)?;
            let q = p.width as f64 / 4.0;
            let mut sel = vec![];
            for ch in 0..nch as u8 {
                let (mut lo, mut hi) = (vec![], vec![]);
                for &y in &used {
                    let xe = fit.x(y as f64);
                    for x in 0..p.width {
                        if p.channel_at(x, y) == Some(ch) {
                            let d = (x as f64 - xe) * sign;
                            if d < -q {
                                lo.push(p.get(x, y));
                            } else if d > q {
                                hi.push(p.get(x, y));
                            }
                        }
                    }
                }
                let (l, hgh) = (median(&lo), median(&hi));
                sel.push(
                    (lo.len() >= 4 && hi.len() >= 4 && (hgh - l).abs() > 0.0)
                        .then(|| (1.0 / (hgh - l), l)),
                );
            }
            if sel.iter().all(|s| s.is_none()) {
                return Err(Error::invalid(
                    "no CFA channel shows both edge plateaus; widen the SFR region".to_string(),
                ));
            }
            prep.select = sel;
        }
        _ => {}
    }
    let full = prep.estimate(&used).ok_or_else(no_edge)?;
    // Refuse an edge whose contrast is too low for its noise: the MTF at
    // 0.5 cy/px (the highest reported figure) would be noise.
    let f_check = 0.5f64.min(fmax);
    let i_check = ((f_check * nbins as f64 / 4.0).round() as usize).min(full.noise_floor.len() - 1);
    let floor_check = full.noise_floor[i_check];
    if floor_check > opts.max_noise_floor {
        return Err(Error::invalid(format!(
            "edge contrast {:.4} is too low for its noise ({:.4} rms per pixel, contrast/noise {:.1}): noise alone gives MTF ≈ {:.3} at {f_check} cy/px (limit {}); render more samples per pixel, expose longer or use a taller region",
            full.contrast,
            full.pixel_noise,
            full.contrast / full.pixel_noise.max(f64::MIN_POSITIVE),
            floor_check,
            opts.max_noise_floor
        )));
    }
    // Jackknife over contiguous row blocks.
    let g = opts.jackknife_groups.max(4).min(nlin / 2);
    let (mut se_mtf, mut se50, mut se_ang, mut se_fwhm, mut se_floor) =
        (vec![0.0; full.mtf.len()], 0.0, 0.0, 0.0, 0.0);
    let esf_x_px: Vec<f64> = (0..nbins)
        .map(|i| (i as f64 + 0.5) / 4.0 - nbins as f64 / 8.0)
        .collect();
    if g >= 4 {
        let reps: Vec<Estimate> = (0..g)
            .filter_map(|k| {
                let (a, b) = (k * nlin / g, (k + 1) * nlin / g);
                let rows: Vec<usize> = used
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| *i < a || *i >= b)
                    .map(|(_, &r)| r)
                    .collect();
                prep.estimate(&rows)
            })
            .collect();
        if reps.len() == g {
            for (i, s) in se_mtf.iter_mut().enumerate() {
                *s = jackknife_se(&reps.iter().map(|r| r.mtf[i]).collect::<Vec<_>>());
            }
            se_ang = jackknife_se(&reps.iter().map(|r| r.angle_deg).collect::<Vec<_>>());
            se_floor = jackknife_se(
                &reps
                    .iter()
                    .map(|r| r.noise_floor[i_check])
                    .collect::<Vec<_>>(),
            );
            se_fwhm = jackknife_se(
                &reps
                    .iter()
                    .map(|r| fwhm(&esf_x_px, &r.lsf))
                    .collect::<Vec<_>>(),
            );
            let m50: Vec<f64> = reps.iter().filter_map(|r| r.mtf50).collect();
            se50 = if m50.len() == g {
                jackknife_se(&m50)
            } else {
                f64::INFINITY
            };
        }
    }
    Ok(Sfr {
        freq_cy_per_px: (0..full.mtf.len())
            .map(|m| m as f64 * 4.0 / nbins as f64)
            .collect(),
        mtf: full.mtf,
        mtf_stderr: se_mtf,
        esf_x_px,
        esf: full.esf,
        lsf: full.lsf,
        mtf50_cy_per_px: full.mtf50,
        mtf50_stderr: if se50.is_finite() { se50 } else { 0.0 },
        edge_angle_deg: full.angle_deg,
        edge_angle_stderr_deg: se_ang,
        lsf_fwhm_stderr_px: se_fwhm,
        rows_used: nlin,
        noise_floor_nyquist: floor_check,
        noise_floor: full.noise_floor,
        noise_floor_stderr: se_floor,
        transposed,
        pixel_pitch_m: opts.pixel_pitch_m,
    })
}

/// SFR of a labelled edge in a sensor image: the ROI is the bounding box of
/// the label, shrunk to its central half, so both plateaus and the edge are inside.
pub fn sfr_of_region(plane: &Plane, roi: Rect, opts: &SfrOptions) -> Result<(Sfr, Rect)> {
    let sub = plane.crop(roi)?;
    let s = sfr(&sub, opts).map_err(|e| {
        Error::invalid(format!(
            "SFR region (x {} y {} w {} h {}): {e}",
            roi.x, roi.y, roi.w, roi.h
        ))
    })?;
    Ok((s, roi))
}

/// SFR of a labelled slanted-edge object in a sensor image. The region of
/// interest is the object's bounding box inset by 15 % per side, shrunk further
/// (in 5 % steps, up to 40 %) until every pixel in it carries the object's
/// label, so neither the background nor the target's own outline enters.
/// Returns the SFR and the region read (window pixel coordinates).
pub fn sfr_of_object(
    img: &crate::image::SensorImage,
    object: &str,
    opts: &SfrOptions,
) -> Result<(Sfr, Rect)> {
    let plane = Plane::from_sensor(img)?;
    let roi = object_roi(
        &img.labels,
        &img.label_names,
        plane.width,
        plane.height,
        object,
    )?;
    let mut o = opts.clone();
    if o.pixel_pitch_m.is_none() && img.pixel_pitch_m > 0.0 {
        o.pixel_pitch_m = Some(img.pixel_pitch_m);
    }
    sfr_of_region(&plane, roi, &o)
}

/// Interior rectangle of a labelled object (see [`sfr_of_object`]).
pub fn object_roi(
    labels: &[u32],
    names: &[String],
    w: usize,
    h: usize,
    object: &str,
) -> Result<Rect> {
    if labels.len() != w * h {
        return Err(Error::invalid(
            "the image carries no per-pixel object labels",
        ));
    }
    let id = super::plane::label_ids(names, &[object.to_string()])?[0];
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for y in 0..h {
        for x in 0..w {
            if labels[y * w + x] == id {
                (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
            }
        }
    }
    if x0 == usize::MAX {
        return Err(Error::invalid(format!(
            "object '{object}' is not visible in the image"
        )));
    }
    let (bw, bh) = ((x1 - x0 + 1) as f64, (y1 - y0 + 1) as f64);
    for inset in [0.15, 0.2, 0.25, 0.3, 0.35, 0.4] {
        let (ax, ay) = (
            x0 + (bw * inset).round() as usize,
            y0 + (bh * inset).round() as usize,
        );
        let (bx, by) = (
            x1 - (bw * inset).round() as usize,
            y1 - (bh * inset).round() as usize,
        );
        if bx <= ax + 8 || by <= ay + 8 {
            break;
        }
        if (ay..=by).all(|y| (ax..=bx).all(|x| labels[y * w + x] == id)) {
            return Ok(Rect::new(
                ax as u32,
                ay as u32,
                (bx - ax + 1) as u32,
                (by - ay + 1) as u32,
            ));
        }
    }
    Err(Error::invalid(format!(
        "object '{object}' has no solid interior of at least 8×8 px for an SFR region"
    )))
}

/// `measure "sfr"`: the slanted-edge options, the region and the input.
#[derive(Clone, Debug, Default)]
pub struct SfrRequest {
    pub options: SfrOptions,
    /// `roi-px`: the region holding the edge (full-frame pixels of the
    /// sensor, or pixels of a captured image); None = each `of` object's strip.
    pub roi_px: Option<Rect>,
    /// `input`: the captured image read instead of the sensor image.
    pub input: Option<String>,
}

/// The properties of `measure "sfr"`.
pub static SCHEMA: crate::params::Schema = crate::params::Schema {
    node: "measure \"sfr\"",
    params: &[
        super::shared_params::name_param(),
        super::shared_params::of_param(
            "the slanted-edge object whose edge is measured (more as arguments: `\"edge-near\" \"edge-far\"`); figures are prefixed `<object>/` (`roi/` with roi-px alone, the input's name on a capture)",
            "\"edge-far\"",
        ),
        super::shared_params::input_param(),
        ParamSpec {
            name: "channel",
            kind: Kind::Choice(&["lum", "r", "g", "b"]),
            default: "lum",
            doc: "pixels forming the edge-spread function: \"lum\" = all of them (each CFA channel normalised to its own plateaus), or one CFA channel",
            example: "\"g\"",
        },
        ParamSpec {
            name: "roi-px",
            kind: Kind::Numbers,
            default: "",
            doc: "region (x y w h) holding the edge, in full-frame sensor pixels (of a captured image: its pixels); default: the central strip of each `of` object",
            example: "(4 6 40 48)",
        },
        ParamSpec {
            name: "fit-degree",
            kind: Kind::Integer,
            default: "1",
            doc: "degree of the polynomial x_e(y) fitted through the row centroids: 1 (straight edge) … 5",
            example: "2",
        },
        ParamSpec {
            name: "jackknife-count",
            kind: Kind::Integer,
            default: "8",
            doc: "row blocks of the delete-a-group jackknife giving the standard errors, 4 … 64 (at most half the rows used)",
            example: "12",
        },
        ParamSpec {
            name: "max-freq-cy-px",
            kind: Kind::Number,
            default: "1",
            doc: "highest frequency of the MTF curve, cycles/pixel (0 < f ≤ 2; the 4× oversampled ESF is fixed by ISO 12233)",
            example: "1.5",
        },
        ParamSpec {
            name: "max-noise-fraction",
            kind: Kind::Number,
            default: "0.5",
            doc: "largest RMS MTF that pixel noise alone may give at 0.5 cy/px (0 < x ≤ 1); a region whose edge contrast is too low for its noise is refused, not reported as MTF",
            example: "0.3",
        },
    ],
};

/// Read `measure "sfr"` (see [`SCHEMA`]).
pub fn from_params(d: &crate::params::ParamDict) -> std::result::Result<SfrRequest, ParamError> {
    let mut o = SfrOptions::default();
    if let Some(c) = d.choice("channel")? {
        o.channel =
            SfrChannel::parse(c).map_err(|e| ParamError::value("channel", e.to_string()))?;
    }
    if let Some(k) = d.int("fit-degree", 1, 5)? {
        o.fit_degree = k as usize;
    }
    if let Some(k) = d.int("jackknife-count", 4, 64)? {
        o.jackknife_groups = k as usize;
    }
    if let Some(f) = d.positive("max-freq-cy-px")? {
        if f > 2.0 {
            return Err(ParamError::value(
                "max-freq-cy-px",
                format!(
                    "'max-freq-cy-px' = {f} is out of range; expected 0 < f ≤ 2 (the 4× ESF reaches 2 cy/px)"
                ),
            ));
        }
        o.max_freq_cy_per_px = f;
    }
    if let Some(x) = d.positive("max-noise-fraction")? {
        if x > 1.0 {
            return Err(ParamError::value(
                "max-noise-fraction",
                format!("'max-noise-fraction' = {x} is out of range; expected 0 < x ≤ 1"),
            ));
        }
        o.max_noise_floor = x;
    }
    Ok(SfrRequest {
        options: o,
        roi_px: super::shared_params::roi_px(d, "roi-px")?,
        input: super::shared_params::nonempty(d, "input")?,
    })
}

/// The part of a slanted-edge plate's box that the SFR reads: the central half
/// of its width (both plateaus and the edge) and at most 128 rows about its
/// centre (≥ 11 rows make one phase cycle at 5°).
pub fn edge_strip(b: Rect) -> Rect {
    let h = (b.h / 2).clamp(8.min(b.h), 128);
    Rect::new(
        b.x + b.w / 4,
        b.y + (b.h - h) / 2,
        (b.w / 2).max(8.min(b.w)),
        h,
    )
}

/// `measure "sfr"` on a simulated sensor image: per `of` object, the strip the
/// render stage chose for it (else the strip of its label box), or `roi-px`.
pub fn run_on_sensor(
    name: &str,
    of: &[String],
    r: &SfrRequest,
    si: &crate::image::SensorImage,
    inp: &super::inputs::Inputs,
) -> Result<Measured> {
    let plane = Plane::from_sensor(si)?;
    let opts = SfrOptions {
        pixel_pitch_m: Some(si.pixel_pitch_m),
        ..r.options.clone()
    };
    let mut regions = vec![];
    if let Some(roi) = r.roi_px {
        if of.len() > 1 {
            return Err(Error::invalid(format!(
                "measurement '{name}': roi-px names one region but of= names {} objects",
                of.len()
            )));
        }
        let label = of.first().map(String::as_str).unwrap_or("roi");
        regions.push((
            label.to_string(),
            super::inputs::to_window(roi, si.window, "roi-px")?,
        ));
    } else {
        if of.is_empty() {
            return Err(Error::invalid(format!(
                "measurement '{name}': sfr needs of=\"<edge object>\" or roi-px=(x y w h)"
            )));
        }
        for obj in of {
            // The edge strip chosen for this plate by the render stage (full-frame
            // pixels → window pixels); without one, the strip of its label box.
            let roi = match inp.object_rects.get(obj) {
                Some(rect) => {
                    super::inputs::to_window(*rect, si.window, &format!("object '{obj}'"))?
                }
                None => edge_strip(
                    super::inputs::label_box(
                        &si.labels,
                        &si.label_names,
                        si.width(),
                        si.height(),
                        obj,
                    )
                    .ok_or_else(|| {
                        Error::invalid(format!("object '{obj}' is not in the measured image"))
                    })?,
                ),
            };
            regions.push((obj.clone(), roi));
        }
    }
    let mut out = Measured::default();
    for (obj, roi) in regions {
        let (sfr, roi) = sfr_of_region(&plane, roi, &opts)
            .map_err(|e| Error::invalid(format!("measurement '{name}', edge '{obj}': {e}")))?;
        let m = sfr.measured(name, roi).prefixed(&obj);
        out.figures.extend(m.figures);
        out.curves.extend(m.curves);
        out.pixels_read.extend(m.pixels_read);
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
