//! Conversion gain from flat frames, after the paper's Appendix III (Eq. 12):
//! `measure "conversion-gain"` needs no scene. It synthesises `frame-count`
//! integrating-sphere frames through the variant's sensor
//! ([`crate::sensor::flatfield::flat_sequence`], the full sensor pipeline:
//! shot noise, PRNU, DSNU, dark current, read noise, ADC) at the flat
//! irradiance that gives the channel a mean of `mean-dv` above black in
//! `exposure-s`, pools the channel's pixels of the crop `roi-px` over all
//! frames, and estimates α = (V − E²σ_p²) / (E (1 + σ_p²))
//! ([`crate::sensor::calibrate::conversion_gain_appendix3`], delta-method
//! standard error) with the sensor's PRNU (or `prnu-percent`).
//!
//! With `reference-mean-dv` and `reference-variance-dv2` (a published
//! capture's moments, e.g. Fig. 11's caption: 320.7 DV, 57.8 DV²) Eq. 12 is
//! also applied to them: `reference_conversion_gain` (exact arithmetic).
//!
//! Curves (the two histograms of the paper's Fig. 11), drawn on one chart
//! each (`<chart>#<series>` names, see the report):
//! - `dv_histogram#counts`: pooled DV above black, one bin per DV, and
//!   `dv_histogram#poisson`: the Poisson pmf with the same mean (× the number of
//!   values): the DVs are far narrower than a Poisson count of that mean;
//! - `electrons_histogram#counts`: the same values divided by α (estimated
//!   electrons; one bin per DV, 1/α e⁻ wide), and `electrons_histogram#poisson`:
//!   the Poisson pmf of their mean × values × bin width, which they follow.

use super::{Curve, Measured};
use crate::figure::Figure;
use crate::optical_image::Rect;
use crate::params::{Kind, ParamDict, ParamError, ParamSpec, Schema};
use crate::sensor::SensorConfig;
use crate::sensor::calibrate::conversion_gain_appendix3;
use crate::sensor::flatfield::{flat_for_signal, flat_sequence};
use crate::{Error, Result};

/// `measure "conversion-gain"` options.
#[derive(Clone, Debug, PartialEq)]
pub struct ConversionGainOptions {
    pub mean_dv: f64,
    pub frames: usize,
    pub exposure_s: f64,
    /// Crop, full-frame sensor pixels; None = the centred 20×10 window ([`window`]).
    pub roi_px: Option<Rect>,
    pub channel: String,
    /// PRNU of Eq. 12 as a fraction; None = the sensor's.
    pub prnu: Option<f64>,
    /// A published (mean DV, variance DV²) to put through Eq. 12 as well.
    pub reference: Option<(f64, f64)>,
}

impl Default for ConversionGainOptions {
    fn default() -> Self {
        Self {
            mean_dv: 320.0,
            frames: 15,
            exposure_s: 0.1,
            roi_px: None,
            channel: "g".into(),
            prnu: None,
            reference: None,
        }
    }
}

/// The properties of `measure "conversion-gain"`.
pub static SCHEMA: Schema = Schema {
    node: "measure \"conversion-gain\"",
    params: &[
        super::shared_params::name_param(),
        ParamSpec::new(
            "mean-dv",
            Kind::Number,
            "320",
            "mean digital value of the channel above black the flat field is set to (the paper's Fig. 11: 320.7)",
            "250",
        ),
        ParamSpec::new(
            "frame-count",
            Kind::Integer,
            "15",
            "flat frames simulated (2 … 10000; the paper's 15)",
            "9",
        ),
        ParamSpec::new(
            "exposure-s",
            Kind::Number,
            "0.1",
            "exposure time of each frame, s (> 0; the paper's 1/10 s)",
            "0.05",
        ),
        ParamSpec::new(
            "roi-px",
            Kind::Numbers,
            "20×10 at the sensor centre",
            "crop (x y w h) whose channel pixels are pooled, full-frame sensor pixels (a 20×10 Bayer crop holds 100 green pixels: the paper's 1500 values over 15 frames)",
            "(100 60 16 12)",
        ),
        ParamSpec::new(
            "channel",
            Kind::Choice(&["r", "g", "b"]),
            "g",
            "CFA channel whose pixels are pooled",
            "\"b\"",
        ),
        ParamSpec::new(
            "prnu-percent",
            Kind::Number,
            "the sensor's",
            "PRNU (% rms) Eq. 12 corrects for (0 ≤ x < 100)",
            "0.61",
        ),
        ParamSpec::new(
            "reference-mean-dv",
            Kind::Number,
            "none",
            "a published capture's mean above black, put through Eq. 12 with reference-variance-dv2 and the PRNU used: reference_conversion_gain (needs reference-variance-dv2)",
            "320.7",
        ),
        ParamSpec::new(
            "reference-variance-dv2",
            Kind::Number,
            "none",
            "that capture's variance, DV² (needs reference-mean-dv)",
            "57.8",
        ),
    ],
};

/// Read `measure "conversion-gain"` (see [`SCHEMA`]).
pub fn from_params(d: &ParamDict) -> std::result::Result<ConversionGainOptions, ParamError> {
    let mut o = ConversionGainOptions::default();
    if let Some(x) = d.positive("mean-dv")? {
        o.mean_dv = x;
    }
    if let Some(k) = d.int("frame-count", 2, 10_000)? {
        o.frames = k as usize;
    }
    if let Some(x) = d.positive("exposure-s")? {
        o.exposure_s = x;
    }
    o.roi_px = super::shared_params::roi_px(d, "roi-px")?;
    if let Some(c) = d.choice("channel")? {
        o.channel = c.to_string();
    }
    if let Some(x) = d.in_range("prnu-percent", 0.0, 100.0)? {
        if x >= 100.0 {
            return Err(ParamError::value(
                "prnu-percent",
                format!("'prnu-percent' = {x} is out of range; expected 0 ≤ x < 100"),
            ));
        }
        o.prnu = Some(x / 100.0);
    }
    let m = d.positive("reference-mean-dv")?;
    let v = d.positive("reference-variance-dv2")?;
    // Each may be probed alone; measure() insists on both.
    o.reference = match (m, v) {
        (None, None) => None,
        (m, v) => Some((m.unwrap_or(f64::NAN), v.unwrap_or(f64::NAN))),
    };
    Ok(o)
}

/// The sensor's full size (cols, rows), required for flat frames.
pub fn sensor_size(cfg: &SensorConfig, what: &str) -> Result<(u32, u32)> {
    match (cfg.cols, cfg.rows) {
        (Some(c), Some(r)) => Ok((c, r)),
        _ => Err(Error::invalid(format!(
            "{what}: sensor '{}' has no rows and cols; flat frames need the sensor's size (add rows=… cols=… to the sensor)",
            cfg.name
        ))),
    }
}

/// A `w`×`h` window at the centre of the sensor, even origin (keeps the CFA phase).
pub fn centred(cols: u32, rows: u32, w: u32, h: u32) -> Rect {
    let (w, h) = (w.min(cols), h.min(rows));
    Rect::new(((cols - w) / 2) & !1, ((rows - h) / 2) & !1, w, h)
}

/// `roi` checked inside the sensor, or the centred default `w`×`h`.
pub fn window(roi: Option<Rect>, cfg: &SensorConfig, w: u32, h: u32, what: &str) -> Result<Rect> {
    let (cols, rows) = sensor_size(cfg, what)?;
    match roi {
        None => Ok(centred(cols, rows, w, h)),
        Some(r)
            if r.x as u64 + r.w as u64 <= cols as u64 && r.y as u64 + r.h as u64 <= rows as u64 =>
        {
            Ok(r)
        }
        Some(r) => Err(Error::invalid(format!(
            "{what}: roi-px (x {} y {} w {} h {}) is not inside the {cols}×{rows} sensor",
            r.x, r.y, r.w, r.h
        ))),
    }
}

/// The CFA channel index of `name` on `cfg` (a mono sensor has one).
pub fn channel_index(cfg: &SensorConfig, name: &str, what: &str) -> Result<usize> {
    if cfg.cfa.channels.len() == 1 {
        return Ok(0);
    }
    cfg.cfa.channel_index(name).ok_or_else(|| {
        Error::invalid(format!(
            "{what}: channel '{name}' is not in the sensor's CFA ({})",
            cfg.cfa.channels.join(", ")
        ))
    })
}

/// ln k! (exact sum below 30, Stirling's series above; error < 1e-10).
pub fn ln_factorial(k: u64) -> f64 {
    if k < 30 {
        return (2..=k).map(|i| (i as f64).ln()).sum();
    }
    let x = k as f64;
    x * x.ln() - x + 0.5 * (2.0 * std::f64::consts::PI * x).ln() + 1.0 / (12.0 * x)
        - 1.0 / (360.0 * x.powi(3))
}

/// Poisson probability of `k` for mean `mu` (> 0).
pub fn poisson_pmf(k: u64, mu: f64) -> f64 {
    (k as f64 * mu.ln() - mu - ln_factorial(k)).exp()
}

/// Run `measure "conversion-gain"` on the sensor `cfg`; frames seeded by `seed`.
pub fn measure(
    cfg: &SensorConfig,
    o: &ConversionGainOptions,
    seed: u64,
    name: &str,
) -> Result<Measured> {
    let what = format!("measurement '{name}'");
    let win = window(o.roi_px, cfg, 20, 10, &what)?;
    let ch = channel_index(cfg, &o.channel, &what)?;
    let k_sensor = cfg.conversion_gain_dv_per_e();
    let signal_e = o.mean_dv / k_sensor;
    let flat = flat_for_signal(cfg, ch, signal_e, o.exposure_s)?;
    let seq = flat_sequence(cfg, Some(&flat), o.exposure_s, win, o.frames, seed, ch)?;
    let black = cfg.black_level_dv;
    let vals: Vec<f64> = seq.frames.iter().flatten().map(|v| v - black).collect();
    let white = cfg.white_level_dv() - black;
    if vals.iter().any(|&v| v >= white || v <= -black) {
        return Err(Error::invalid(format!(
            "{what}: some pixels clip at the ADC range (mean-dv={} with black {black} and white {}); lower mean-dv",
            o.mean_dv,
            cfg.white_level_dv()
        )));
    }
    let prnu = o.prnu.unwrap_or(cfg.prnu);
    if let Some((rm, rv)) = o.reference
        && (rm.is_nan() || rv.is_nan())
    {
        return Err(Error::invalid(format!(
            "{what}: reference-mean-dv and reference-variance-dv2 go together"
        )));
    }
    let a = conversion_gain_appendix3(&vals, prnu)
        .map_err(|e| Error::invalid(format!("{what}: {e}")))?;
    if a.value <= 0.0 || a.value.is_nan() {
        return Err(Error::invalid(format!(
            "{what}: Eq. 12 gives α = {} ≤ 0 (variance below the PRNU term); raise mean-dv or check prnu-percent",
            a.value
        )));
    }
    let n = vals.len() as f64;
    let mean = vals.iter().sum::<f64>() / n;
    let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let m4 = vals.iter().map(|v| (v - mean).powi(4)).sum::<f64>() / n;
    let var_se = ((m4 - var * var) / n).max(0.0).sqrt();
    let f = |q: &str, u: &str, v: f64, se: f64| Figure::new(name, q, u, v, se);
    let figures = vec![
        f("conversion_gain", "DV/e-", a.value, a.stderr),
        f("sensor_conversion_gain", "DV/e-", k_sensor, 0.0),
        f(
            "conversion_gain_error",
            "%",
            (a.value / k_sensor - 1.0) * 100.0,
            a.stderr / k_sensor * 100.0,
        ),
        f("mean", "DV", mean, (var / n).sqrt()),
        f("variance", "DV^2", var, var_se),
        f(
            "mean_electrons",
            "e-",
            mean / a.value,
            (var / n).sqrt() / a.value,
        ),
        f(
            "variance_electrons",
            "e-^2",
            var / (a.value * a.value),
            var_se / (a.value * a.value),
        ),
        f("prnu_used", "%", prnu * 100.0, 0.0),
        f("values", "1", n, 0.0),
    ];
    let mut figures = figures;
    if let Some((rm, rv)) = o.reference {
        // Eq. 12 on the published moments: exact arithmetic, no sampling.
        figures.push(f(
            "reference_conversion_gain",
            "DV/e-",
            crate::sensor::calibrate::alpha_eq12(rm, rv, prnu),
            0.0,
        ));
    }
    // Fig. 11 (a): one bin per DV, and a Poisson count of the same mean.
    let lo = vals.iter().cloned().fold(f64::INFINITY, f64::min).floor() as i64;
    let hi = vals
        .iter()
        .cloned()
        .fold(f64::NEG_INFINITY, f64::max)
        .ceil() as i64;
    let mut counts = vec![0.0; (hi - lo + 1) as usize];
    for v in &vals {
        counts[(v.round() as i64 - lo) as usize] += 1.0;
    }
    let xs: Vec<f64> = (lo..=hi).map(|k| k as f64).collect();
    let pois_dv: Vec<f64> = (lo..=hi)
        .map(|k| {
            if k >= 0 {
                n * poisson_pmf(k as u64, mean)
            } else {
                0.0
            }
        })
        .collect();
    // Fig. 11 (b): the same bins in estimated electrons (width 1/α), and the
    // Poisson pmf of their mean × values × bin width, per whole electron.
    let xe: Vec<f64> = xs.iter().map(|x| x / a.value).collect();
    let mean_e = mean / a.value;
    let (e0, e1) = (
        (lo as f64 / a.value).floor().max(0.0) as u64,
        (hi as f64 / a.value).ceil() as u64,
    );
    let ke: Vec<f64> = (e0..=e1).map(|k| k as f64).collect();
    let pois_e: Vec<f64> = (e0..=e1)
        .map(|k| n * poisson_pmf(k, mean_e) / a.value)
        .collect();
    let c = |nm: &str, x: (&str, &str), xs: Vec<f64>, ys: Vec<f64>| {
        Curve::new(nm, x, ("count", "1"), xs, ys, vec![])
    };
    let curves = vec![
        c(
            "dv_histogram#counts",
            ("digital value above black", "DV"),
            xs.clone(),
            counts.clone(),
        ),
        c(
            "dv_histogram#poisson",
            ("digital value above black", "DV"),
            xs,
            pois_dv,
        ),
        c(
            "electrons_histogram#counts",
            ("estimated electrons", "e-"),
            xe,
            counts,
        ),
        c(
            "electrons_histogram#poisson",
            ("estimated electrons", "e-"),
            ke,
            pois_e,
        ),
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

    #[test]
    fn poisson_pmf_sums_to_one_and_matches_small_k() {
        // exact: P(2; 3) = 9/2 e^-3
        assert!((poisson_pmf(2, 3.0) - 4.5 * (-3.0f64).exp()).abs() < 1e-14);
        // Stirling branch against the exact sum at k = 30, 40
        for k in [30u64, 40, 100] {
            let exact: f64 = (2..=k).map(|i| (i as f64).ln()).sum();
            assert!((ln_factorial(k) - exact).abs() < 1e-9, "{k}");
        }
        let s: f64 = (0..4000).map(|k| poisson_pmf(k, 1875.0)).sum();
        assert!((s - 1.0).abs() < 1e-9, "{s}");
    }
}
