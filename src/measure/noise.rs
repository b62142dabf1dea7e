//! Uniform-region noise after the paper's Appendix IV.
//!
//! Many `region_px`×`region_px` squares (10×10 in the paper) are drawn at
//! random (seeded). For each, the pixels of one channel (green: 50 pixels of a
//! Bayer 10×10) are tested:
//! 1. **Outliers (dead pixels).** The channel median is converted to electrons
//!    with the conversion gain; Poisson statistics give σ = √median (plus the
//!    read noise, if given, in quadrature; on a simulated image also the
//!    rendering's Monte Carlo variance of the region's pixels, which the paper
//!    names as the cause of rejections in simulated data). A region with any pixel more than
//!    `outlier_sigma` (3) σ from the median is rejected. The paper says "from
//!    the mean"; we use the median it converted, which a dead pixel cannot drag.
//! 2. **Non-uniformity.** The paper holds out 20 % of the values, fits a
//!    second-order spatial polynomial (1, x, y, x², xy, y²) to the rest and
//!    compares the held-out RMSE of the polynomial with that of a constant (the
//!    mean of the fitted values); the region is non-uniform if the constant's
//!    RMSE exceeds the polynomial's by more than 2 %. A single 20 % split of 50
//!    values leaves 10 held-out values and a very noisy verdict, so we use all
//!    five disjoint 20 % hold-out folds (5-fold cross-validation, folds drawn
//!    at random) and pool the held-out squared errors: the same test, each value
//!    held out once.
//!
//! Accepted regions give (mean, standard deviation) of the channel in DV; the
//! figures are the number accepted and the line `variance_dv = a + b·mean_dv`
//! (b estimates the conversion gain in DV/e⁻ for a photon-noise-limited
//! sensor, a the read-noise variance).

use super::plane::Plane;
use super::stats::{SplitMix64, least_squares, line_fit, mean, median, std_dev};
use super::{Curve, Measured};
use crate::figure::Figure;
use crate::optical_image::Rect;
use crate::params::{Kind, ParamError, ParamSpec};
use crate::{Error, Result};

#[derive(Clone, Debug)]
pub struct NoiseOptions {
    pub region_px: usize,
    pub regions: usize,
    pub seed: u64,
    pub conversion_gain_dv_per_e: f64,
    pub read_noise_e: f64,
    pub outlier_sigma: f64,
    /// Non-uniform when RMSE(constant) > `nonuniform_ratio`·RMSE(polynomial).
    pub nonuniform_ratio: f64,
    pub folds: usize,
    /// Channel name on a mosaic ("g"); ignored on a single-channel plane.
    pub channel: String,
}

impl Default for NoiseOptions {
    fn default() -> Self {
        Self {
            region_px: 10,
            regions: 500,
            seed: 1,
            conversion_gain_dv_per_e: 1.0,
            read_noise_e: 0.0,
            outlier_sigma: 3.0,
            nonuniform_ratio: 1.02,
            folds: 5,
            channel: "g".into(),
        }
    }
}

/// `measure "noise"`: the region test's options and what the image supplies
/// unless written (the seed, the conversion gain).
#[derive(Clone, Debug)]
pub struct NoiseRequest {
    /// Region size/count, thresholds and channel (`seed` and the conversion
    /// gain in here are replaced by the fields below or the image's).
    pub options: NoiseOptions,
    /// `seed`: None = the variant's render seed.
    pub seed: Option<u64>,
    /// `conversion-gain-dv-e`: None = the sensor's (required on a capture).
    pub conversion_gain_dv_per_e: Option<f64>,
    /// `roi-px`: the part of the image regions are drawn from.
    pub roi_px: Option<Rect>,
    pub input: Option<String>,
    /// `band-percent` as a fraction: the noise model's band (simulated images).
    pub band: f64,
}

/// The properties of `measure "noise"`.
pub static SCHEMA: crate::params::Schema = crate::params::Schema {
    node: "measure \"noise\"",
    params: &[
        super::shared_params::name_param(),
        super::shared_params::input_param(),
        ParamSpec {
            name: "channel",
            kind: Kind::Choice(&["r", "g", "b"]),
            default: "g",
            doc: "CFA channel whose pixels each region tests (ignored on a single-channel image)",
            example: "\"b\"",
        },
        ParamSpec {
            name: "roi-px",
            kind: Kind::Numbers,
            default: "",
            doc: "part (x y w h) of the image the regions are drawn from, full-frame sensor pixels (of a captured image: its pixels); default the whole image",
            example: "(2 4 60 50)",
        },
        ParamSpec {
            name: "region-px",
            kind: Kind::Integer,
            default: "10",
            doc: "side of each square region, pixels (4 … 4096; the paper's 10×10)",
            example: "12",
        },
        ParamSpec {
            name: "region-count",
            kind: Kind::Integer,
            default: "500",
            doc: "regions drawn at random (1 … 1000000)",
            example: "300",
        },
        ParamSpec {
            name: "seed",
            kind: Kind::Integer,
            default: "the render seed",
            doc: "seed of the region positions and cross-validation folds",
            example: "77",
        },
        ParamSpec {
            name: "conversion-gain-dv-e",
            kind: Kind::Number,
            default: "the sensor's",
            doc: "conversion gain, DV per electron, of the Poisson outlier test (> 0; required on a captured image)",
            example: "0.37",
        },
        ParamSpec {
            name: "read-noise-e",
            kind: Kind::Number,
            default: "0",
            doc: "read noise, electrons rms, added in quadrature to the Poisson σ of the outlier test (≥ 0)",
            example: "2.5",
        },
        ParamSpec {
            name: "outlier-sigma",
            kind: Kind::Number,
            default: "3",
            doc: "a region with a pixel farther than this many σ from its median is rejected (> 0)",
            example: "4",
        },
        ParamSpec {
            name: "nonuniform-ratio",
            kind: Kind::Number,
            default: "1.02",
            doc: "a region is non-uniform when the held-out RMSE of a constant exceeds this times that of the quadratic surface (≥ 1)",
            example: "1.05",
        },
        ParamSpec {
            name: "fold-count",
            kind: Kind::Integer,
            default: "5",
            doc: "cross-validation folds of the uniformity test (2 … 20)",
            example: "4",
        },
        ParamSpec {
            name: "band-percent",
            kind: Kind::Number,
            default: "95",
            doc: "on a simulated image: the noise model's band (sensor noise + the render's Monte Carlo noise) that holds this share of regions' standard deviations; reports fraction_in_band (50 ≤ x < 100)",
            example: "90",
        },
    ],
};

/// Read `measure "noise"` (see [`SCHEMA`]).
pub fn from_params(d: &crate::params::ParamDict) -> std::result::Result<NoiseRequest, ParamError> {
    let mut o = NoiseOptions::default();
    if let Some(c) = d.choice("channel")? {
        o.channel = c.to_string();
    }
    if let Some(k) = d.int("region-px", 4, 4096)? {
        o.region_px = k as usize;
    }
    if let Some(k) = d.int("region-count", 1, 1_000_000)? {
        o.regions = k as usize;
    }
    if let Some(x) = d.nonneg("read-noise-e")? {
        o.read_noise_e = x;
    }
    if let Some(x) = d.positive("outlier-sigma")? {
        o.outlier_sigma = x;
    }
    if let Some(x) = d.f64("nonuniform-ratio")? {
        if x < 1.0 {
            return Err(ParamError::value(
                "nonuniform-ratio",
                format!("'nonuniform-ratio' = {x} is out of range; expected ≥ 1"),
            ));
        }
        o.nonuniform_ratio = x;
    }
    if let Some(k) = d.int("fold-count", 2, 20)? {
        o.folds = k as usize;
    }
    let band = match d.f64("band-percent")? {
        None => 0.95,
        Some(x) if (50.0..100.0).contains(&x) => x / 100.0,
        Some(x) => {
            return Err(ParamError::value(
                "band-percent",
                format!("'band-percent' = {x} is out of range; expected 50 ≤ x < 100"),
            ));
        }
    };
    Ok(NoiseRequest {
        band,
        options: o,
        seed: d.int("seed", 0, 1 << 53)?,
        conversion_gain_dv_per_e: d.positive("conversion-gain-dv-e")?,
        roi_px: super::shared_params::roi_px(d, "roi-px")?,
        input: super::shared_params::nonempty(d, "input")?,
    })
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    Accepted,
    /// A pixel beyond `outlier_sigma` Poisson σ of the median.
    Outlier,
    /// The polynomial predicts held-out values better than a constant.
    NonUniform,
    /// Too few pixels of the channel or a non-positive median.
    Unusable,
}

#[derive(Clone, Debug)]
pub struct Region {
    pub rect: Rect,
    pub verdict: Verdict,
    pub mean_dv: f64,
    pub std_dv: f64,
    pub n: usize,
    pub rmse_const: f64,
    pub rmse_poly: f64,
}

impl NoiseOptions {
    /// Defaults with the sensor image's conversion gain.
    pub fn for_sensor(img: &crate::image::SensorImage) -> Self {
        Self {
            conversion_gain_dv_per_e: img.conversion_gain_dv_per_e,
            ..Default::default()
        }
    }
}

/// Classify one region (pixels of the channel inside `rect`). `extra`: a
/// per-pixel variance (DV²) known to be in the values beyond Poisson and read
/// noise (a simulation's rendering noise), added to the outlier test's σ.
pub fn classify(
    plane: &Plane,
    rect: Rect,
    opts: &NoiseOptions,
    rng: &mut SplitMix64,
    extra: Option<&Plane>,
) -> Result<Region> {
    let ch = if plane.is_mosaic() {
        Some(plane.channel_index(&opts.channel).ok_or_else(|| {
            Error::invalid(format!(
                "channel '{}' is not in the CFA ({})",
                opts.channel,
                plane.channel_names.join(", ")
            ))
        })?)
    } else {
        None
    };
    let mut xs = vec![];
    let mut ys = vec![];
    let mut vs = vec![];
    let mut extra_sum = 0.0;
    for y in rect.y as usize..(rect.y + rect.h) as usize {
        for x in rect.x as usize..(rect.x + rect.w) as usize {
            if ch.is_none() || plane.channel_at(x, y) == ch {
                xs.push(x as f64 - rect.x as f64);
                ys.push(y as f64 - rect.y as f64);
                vs.push(plane.get(x, y));
                extra_sum += extra.map_or(0.0, |e| e.get(x, y));
            }
        }
    }
    let n = vs.len();
    let mut r = Region {
        rect,
        verdict: Verdict::Unusable,
        mean_dv: mean(&vs),
        std_dv: std_dev(&vs),
        n,
        rmse_const: 0.0,
        rmse_poly: 0.0,
    };
    let med_e = median(&vs) / opts.conversion_gain_dv_per_e;
    if n < 6 * opts.folds.max(2) || med_e <= 0.0 {
        return Ok(r);
    }
    let k = opts.conversion_gain_dv_per_e;
    let extra_e2 = extra_sum / n as f64 / (k * k);
    let sigma_e = (med_e + opts.read_noise_e * opts.read_noise_e + extra_e2).sqrt();
    if vs
        .iter()
        .any(|v| (v / opts.conversion_gain_dv_per_e - med_e).abs() > opts.outlier_sigma * sigma_e)
    {
        r.verdict = Verdict::Outlier;
        return Ok(r);
    }
    let fold = fold_assignment(n, opts.folds, rng);
    let s = opts.region_px.max(2) as f64 / 2.0;
    let basis = |x: f64, y: f64| {
        let (u, v) = ((x - s) / s, (y - s) / s);
        [1.0, u, v, u * u, u * v, v * v]
    };
    let (mut se_c, mut se_p, mut cnt) = (0.0, 0.0, 0usize);
    for k in 0..opts.folds {
        let train: Vec<usize> = (0..n).filter(|&i| fold[i] != k).collect();
        let a: Vec<f64> = train.iter().flat_map(|&i| basis(xs[i], ys[i])).collect();
        let b: Vec<f64> = train.iter().map(|&i| vs[i]).collect();
        let c = least_squares(&a, train.len(), 6, &b)
            .ok_or_else(|| Error::invalid("degenerate region geometry"))?;
        let m = mean(&b);
        for i in (0..n).filter(|&i| fold[i] == k) {
            let p: f64 = basis(xs[i], ys[i]).iter().zip(&c).map(|(a, b)| a * b).sum();
            se_p += (vs[i] - p).powi(2);
            se_c += (vs[i] - m).powi(2);
            cnt += 1;
        }
    }
    r.rmse_const = (se_c / cnt as f64).sqrt();
    r.rmse_poly = (se_p / cnt as f64).sqrt();
    r.verdict = if r.rmse_const > opts.nonuniform_ratio * r.rmse_poly {
        Verdict::NonUniform
    } else {
        Verdict::Accepted
    };
    Ok(r)
}

/// Random fold assignment for cross-validation: a shuffled round-robin, so
/// each of the `folds` folds holds ⌊n/folds⌋ or ⌈n/folds⌉ of the `n` pixels.
fn fold_assignment(n: usize, folds: usize, rng: &mut SplitMix64) -> Vec<usize> {
    let mut fold: Vec<usize> = (0..n).map(|i| i % folds).collect();
    for i in (1..n).rev() {
        let j = rng.below(i as u64 + 1) as usize;
        fold.swap(i, j);
    }
    fold
}

/// Draw `opts.regions` random squares and classify each (`extra`: see [`classify`]).
pub fn uniform_regions(
    plane: &Plane,
    opts: &NoiseOptions,
    extra: Option<&Plane>,
) -> Result<Vec<Region>> {
    let s = opts.region_px;
    if s < 2 || plane.width < s || plane.height < s {
        return Err(Error::invalid(format!(
            "noise regions of {s} px do not fit a {}×{} image",
            plane.width, plane.height
        )));
    }
    if opts.conversion_gain_dv_per_e.is_nan() || opts.conversion_gain_dv_per_e <= 0.0 {
        return Err(Error::invalid("conversion gain must be > 0 DV/e-"));
    }
    let mut rng = SplitMix64(opts.seed);
    (0..opts.regions)
        .map(|_| {
            let x = rng.below((plane.width - s + 1) as u64) as u32;
            let y = rng.below((plane.height - s + 1) as u64) as u32;
            classify(
                plane,
                Rect::new(x, y, s as u32, s as u32),
                opts,
                &mut rng,
                extra,
            )
        })
        .collect()
}

/// Figures, the std-vs-mean scatter and the accepted regions.
pub fn measure(
    plane: &Plane,
    opts: &NoiseOptions,
    measurement: &str,
) -> Result<(Measured, Vec<Region>)> {
    measure_with(plane, opts, None, measurement)
}

/// [`measure`] with a known extra per-pixel variance (DV²) in the outlier
/// test (see [`classify`]).
pub fn measure_with(
    plane: &Plane,
    opts: &NoiseOptions,
    extra: Option<&Plane>,
    measurement: &str,
) -> Result<(Measured, Vec<Region>)> {
    if let Some(e) = extra
        && (e.width, e.height) != (plane.width, plane.height)
    {
        return Err(Error::invalid(
            "extra variance plane differs in size from the image",
        ));
    }
    let regions = uniform_regions(plane, opts, extra)?;
    let acc: Vec<&Region> = regions
        .iter()
        .filter(|r| r.verdict == Verdict::Accepted)
        .collect();
    // Binomial standard error of the accepted count.
    let p_acc = acc.len() as f64 / regions.len().max(1) as f64;
    let se_count = (regions.len() as f64 * p_acc * (1.0 - p_acc)).sqrt();
    let mut figures = vec![Figure::new(
        measurement,
        "regions_accepted",
        "1",
        acc.len() as f64,
        se_count,
    )];
    let means: Vec<f64> = acc.iter().map(|r| r.mean_dv).collect();
    let stds: Vec<f64> = acc.iter().map(|r| r.std_dv).collect();
    if let Some((a, b, sa, sb)) = line_fit(&means, &stds.iter().map(|s| s * s).collect::<Vec<_>>())
    {
        figures.push(Figure::new(measurement, "variance_slope", "DV/e-", b, sb));
        figures.push(Figure::new(
            measurement,
            "variance_intercept",
            "DV^2",
            a,
            sa,
        ));
    }
    if !acc.is_empty() {
        figures.push(Figure::new(
            measurement,
            "std_mean",
            "DV",
            mean(&stds),
            if stds.len() > 1 {
                std_dev(&stds) / (stds.len() as f64).sqrt()
            } else {
                0.0
            },
        ));
    }
    let curves = vec![Curve::new(
        "std_vs_mean",
        ("mean", "DV"),
        ("std", "DV"),
        means,
        stds,
        vec![],
    )];
    let pixels_read = acc.iter().map(|r| r.rect).collect();
    Ok((
        Measured {
            figures,
            curves,
            pixels_read,
        },
        regions,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{ParamDict, Params, Value};

    fn request(props: &[(&str, f64)]) -> std::result::Result<NoiseRequest, ParamError> {
        let mut p = Params::new();
        for &(k, v) in props {
            p.set(k, Value::Number(v));
        }
        from_params(&ParamDict::new(&p, &SCHEMA))
    }

    /// Each range's boundary: the first value allowed is accepted with its
    /// value, the last refused is refused.
    #[test]
    fn ranges_are_closed_where_the_schema_says() {
        assert_eq!(
            request(&[("nonuniform-ratio", 1.0)])
                .unwrap()
                .options
                .nonuniform_ratio,
            1.0
        );
        assert!(request(&[("nonuniform-ratio", 0.999)]).is_err());
        assert_eq!(
            request(&[("nonuniform-ratio", 1.5)])
                .unwrap()
                .options
                .nonuniform_ratio,
            1.5
        );
        assert_eq!(request(&[]).unwrap().band, 0.95);
        assert_eq!(request(&[("band-percent", 50.0)]).unwrap().band, 0.5);
        assert_eq!(request(&[("band-percent", 90.0)]).unwrap().band, 0.9);
        assert!(request(&[("band-percent", 100.0)]).is_err());
        assert!(request(&[("band-percent", 49.0)]).is_err());
        assert_eq!(request(&[("seed", 12345.0)]).unwrap().seed, Some(12345));
        let max = (1u64 << 53) as f64;
        assert_eq!(request(&[("seed", max)]).unwrap().seed, Some(1 << 53));
    }

    /// The rendering-noise variance widens the outlier test's σ: a pixel
    /// 40 DV above a flat 100 DV region (1 DV/e⁻, no read noise) is beyond
    /// 3σ = 30 DV of Poisson noise alone, and inside 3·√(100 + 100) = 42.4 DV
    /// once a known 100 DV² of extra variance is added.
    #[test]
    fn extra_variance_widens_the_outlier_test() {
        let mut v = vec![100.0; 100];
        v[55] = 140.0;
        let plane = Plane::new(10, 10, v).unwrap();
        let extra = Plane::new(10, 10, vec![100.0; 100]).unwrap();
        let rect = Rect::new(0, 0, 10, 10);
        let opts = NoiseOptions::default();
        let without = classify(&plane, rect, &opts, &mut SplitMix64(1), None).unwrap();
        assert_eq!(without.verdict, Verdict::Outlier);
        let with = classify(&plane, rect, &opts, &mut SplitMix64(1), Some(&extra)).unwrap();
        assert_ne!(with.verdict, Verdict::Outlier);
        assert_ne!(with.verdict, Verdict::Unusable);
    }

    /// Every pixel is held out exactly once, the folds balanced to one pixel.
    #[test]
    fn folds_are_balanced_and_cover_every_pixel() {
        let f = fold_assignment(103, 5, &mut SplitMix64(7));
        assert_eq!(f.len(), 103);
        let mut count = [0usize; 5];
        for &k in &f {
            count[k] += 1; // panics if a label is ≥ 5
        }
        assert_eq!(count.iter().filter(|&&c| c == 21).count(), 3);
        assert_eq!(count.iter().filter(|&&c| c == 20).count(), 2);
        // Shuffled, not the round-robin order itself.
        assert!(f.iter().enumerate().any(|(i, &k)| k != i % 5));
    }

    /// The held-out prediction is a full quadratic in x and y: on a
    /// noise-free quadratic surface it is exact (to rounding), the constant
    /// is not, and the region is non-uniform.
    #[test]
    fn quadratic_model_predicts_a_quadratic_surface_exactly() {
        let mut v = vec![];
        for y in 0..10 {
            for x in 0..10 {
                let (x, y) = (x as f64, y as f64);
                v.push(100.0 + 3.0 * x + 2.0 * y + 0.5 * x * y - 0.2 * x * x + 0.1 * y * y);
            }
        }
        let plane = Plane::new(10, 10, v).unwrap();
        let opts = NoiseOptions {
            outlier_sigma: 100.0,
            ..Default::default()
        };
        let r = classify(
            &plane,
            Rect::new(0, 0, 10, 10),
            &opts,
            &mut SplitMix64(1),
            None,
        )
        .unwrap();
        assert!(r.rmse_poly < 1e-9, "{}", r.rmse_poly);
        // The constant's held-out error is the values' spread, inflated by
        // the training means' own error: by a factor √(1 + 1/80) ≈ 1.006
        // on average for 80 training pixels (a 5 % band holds any fold draw).
        let ratio = r.rmse_const / r.std_dv;
        assert!((ratio - 1.0).abs() < 0.05, "{ratio}");
        assert_eq!(r.verdict, Verdict::NonUniform);
    }

    /// The non-uniformity threshold is a ratio of the two errors: a noise-free
    /// ramp of 0.1 DV/px (constant's error ≈ 0.29 DV, the polynomial's 0)
    /// is non-uniform however small the ramp.
    #[test]
    fn a_gentle_noise_free_ramp_is_non_uniform() {
        let v: Vec<f64> = (0..100).map(|i| 100.0 + 0.1 * (i % 10) as f64).collect();
        let plane = Plane::new(10, 10, v).unwrap();
        let opts = NoiseOptions::default();
        let r = classify(
            &plane,
            Rect::new(0, 0, 10, 10),
            &opts,
            &mut SplitMix64(1),
            None,
        )
        .unwrap();
        assert!(r.rmse_const > 0.2 && r.rmse_const < 0.4, "{}", r.rmse_const);
        assert_eq!(r.verdict, Verdict::NonUniform);
    }

    /// An outlier lies beyond `outlier_sigma`·σ: a pixel exactly at 3σ
    /// (130 DV over a 100 DV median, σ = 10 DV) is not one, 131 DV is.
    #[test]
    fn outliers_lie_strictly_beyond_the_threshold() {
        let rect = Rect::new(0, 0, 10, 10);
        let opts = NoiseOptions::default();
        for (bump, outlier) in [(130.0, false), (131.0, true)] {
            let mut v = vec![100.0; 100];
            v[55] = bump;
            let plane = Plane::new(10, 10, v).unwrap();
            let r = classify(&plane, rect, &opts, &mut SplitMix64(1), None).unwrap();
            assert_eq!(r.verdict == Verdict::Outlier, outlier, "{bump} DV");
        }
    }

    /// Read noise widens it the same way: 10 e⁻ of read noise at 1 DV/e⁻
    /// make σ = √(100 + 100) DV, so the 40 DV pixel is inside 3σ.
    #[test]
    fn read_noise_widens_the_outlier_test() {
        let mut v = vec![100.0; 100];
        v[55] = 140.0;
        let plane = Plane::new(10, 10, v).unwrap();
        let rect = Rect::new(0, 0, 10, 10);
        let opts = NoiseOptions {
            read_noise_e: 10.0,
            ..Default::default()
        };
        let r = classify(&plane, rect, &opts, &mut SplitMix64(1), None).unwrap();
        assert_ne!(r.verdict, Verdict::Outlier);
        assert_ne!(r.verdict, Verdict::Unusable);
    }

    /// Fewer pixels than the folds need (6 per fold), or a median at or
    /// below zero, leave a region unusable; each condition alone suffices.
    #[test]
    fn too_few_pixels_or_a_dark_median_is_unusable() {
        let opts = NoiseOptions::default();
        let bright = Plane::new(10, 10, vec![100.0; 100]).unwrap();
        let small = classify(
            &bright,
            Rect::new(0, 0, 5, 5),
            &opts,
            &mut SplitMix64(1),
            None,
        );
        assert_eq!(small.unwrap().verdict, Verdict::Unusable);
        let whole = classify(
            &bright,
            Rect::new(0, 0, 10, 10),
            &opts,
            &mut SplitMix64(1),
            None,
        );
        assert_eq!(whole.unwrap().verdict, Verdict::Accepted);
        // Exactly 6 per fold (30 pixels) is enough.
        let thirty = classify(
            &bright,
            Rect::new(0, 0, 6, 5),
            &opts,
            &mut SplitMix64(1),
            None,
        );
        assert_eq!(thirty.unwrap().verdict, Verdict::Accepted);
        let dark = Plane::new(10, 10, vec![0.0; 100]).unwrap();
        let dark = classify(
            &dark,
            Rect::new(0, 0, 10, 10),
            &opts,
            &mut SplitMix64(1),
            None,
        );
        assert_eq!(dark.unwrap().verdict, Verdict::Unusable);
    }

    /// Regions must be ≥ 2 px and fit the image in each direction (an image
    /// exactly one region wide and high has one place for it); the
    /// conversion gain must be a positive number. Each condition alone fails.
    #[test]
    fn region_size_and_conversion_gain_are_checked() {
        let run = |w: usize, h: usize, region_px: usize, k: f64| {
            let plane = Plane::new(w, h, vec![100.0; w * h]).unwrap();
            let opts = NoiseOptions {
                region_px,
                regions: 3,
                conversion_gain_dv_per_e: k,
                ..Default::default()
            };
            uniform_regions(&plane, &opts, None)
        };
        let exact = run(6, 6, 6, 1.0).unwrap();
        assert_eq!(exact.len(), 3);
        assert!(exact.iter().all(|r| r.rect == Rect::new(0, 0, 6, 6)));
        assert!(run(8, 8, 2, 1.0).is_ok());
        assert!(run(8, 8, 1, 1.0).is_err());
        assert!(run(5, 6, 6, 1.0).is_err());
        assert!(run(6, 5, 6, 1.0).is_err());
        assert!(run(8, 8, 6, f64::NAN).is_err());
        assert!(run(8, 8, 6, 0.0).is_err());
        assert!(run(8, 8, 6, -1.0).is_err());
    }

    /// Every placement is drawn: a 6 px region in a 7×7 image starts at 0 or
    /// 1 in each direction, and 200 draws see both (each is missed with
    /// probability 2⁻²⁰⁰).
    #[test]
    fn regions_reach_the_last_placement() {
        let plane = Plane::new(7, 7, vec![100.0; 49]).unwrap();
        let opts = NoiseOptions {
            region_px: 6,
            regions: 200,
            ..Default::default()
        };
        let r = uniform_regions(&plane, &opts, None).unwrap();
        for pick in [|r: &Region| r.rect.x, |r: &Region| r.rect.y] {
            let starts: std::collections::BTreeSet<u32> = r.iter().map(pick).collect();
            assert_eq!(starts.into_iter().collect::<Vec<_>>(), vec![0, 1]);
        }
    }

    /// Gaussian noise of σ = 10 DV on a flat 100 DV field (Poisson's σ at
    /// 1 DV/e⁻), `regions` squares of 10×10 px in a 200×200 image.
    fn flat_noisy(seed: u64) -> Plane {
        let mut rng = SplitMix64(seed);
        let v = (0..200 * 200).map(|_| 100.0 + 10.0 * rng.gauss()).collect();
        Plane::new(200, 200, v).unwrap()
    }

    /// On pure noise the quadratic's held-out error is the noise itself,
    /// inflated by its six fitted coefficients: on average by
    /// √(1 + 6/n_train) ≈ 1.037 over the constant's √(1 + 1/n_train) for
    /// 80 training pixels. The band [0.98, 1.12] holds that plus the ratio's
    /// spread over one 100 px region (≈ 2 %, the two errors sharing their noise).
    #[test]
    fn on_pure_noise_the_quadratic_errs_by_the_noise() {
        let plane = flat_noisy(3);
        for (i, x0) in [0u32, 40, 80, 120].into_iter().enumerate() {
            let r = classify(
                &plane,
                Rect::new(x0, x0, 10, 10),
                &NoiseOptions {
                    outlier_sigma: 100.0,
                    ..Default::default()
                },
                &mut SplitMix64(i as u64),
                None,
            )
            .unwrap();
            let ratio = r.rmse_poly / r.rmse_const;
            assert!((0.98..1.12).contains(&ratio), "region {i}: {ratio}");
            assert!((r.rmse_const / r.std_dv - 1.0).abs() < 0.05);
        }
    }

    /// The figures of a flat noisy image: the accepted count with its
    /// binomial standard error √(N·p·(1−p)); `std_mean`, the accepted
    /// regions' mean standard deviation, against the true σ = 10 DV (lowered
    /// 1.3 % by the 3σ outlier cut, which truncates the accepted regions'
    /// values; its standard error ≈ 0.1 %, so a 3 % band), and its standard
    /// error against the spread of a 100-pixel sample σ, σ/√(2·99), over
    /// √N_accepted regions (the estimate's own relative error is
    /// 1/√(2(N−1)) ≈ 10 % for ~50 regions: a 40 % band).
    #[test]
    fn figures_of_a_flat_noisy_image() {
        let plane = flat_noisy(5);
        let opts = NoiseOptions {
            regions: 100,
            ..Default::default()
        };
        let (m, regions) = measure(&plane, &opts, "noise").unwrap();
        let fig = |q: &str| {
            m.figures
                .iter()
                .find(|f| f.quantity == q)
                .unwrap_or_else(|| panic!("no {q}"))
                .clone()
        };
        let n = regions.len() as f64;
        let acc = regions
            .iter()
            .filter(|r| r.verdict == Verdict::Accepted)
            .count() as f64;
        let p = acc / n;
        assert!(p > 0.2 && p < 0.95, "accepted fraction {p}");
        let count = fig("regions_accepted");
        assert_eq!(count.value, acc);
        assert!((count.stderr - (n * p * (1.0 - p)).sqrt()).abs() < 1e-12);
        let s = fig("std_mean");
        assert!((s.value / 10.0 - 1.0).abs() < 0.03, "{}", s.value);
        let expected = 10.0 / (2.0 * 99.0f64).sqrt() / acc.sqrt();
        assert!(
            (s.stderr / expected - 1.0).abs() < 0.4,
            "{} vs {expected}",
            s.stderr
        );
    }

    /// The sensor image's conversion gain is the one the classification uses.
    #[test]
    fn for_sensor_takes_the_images_conversion_gain() {
        let cfa = crate::image::CfaPattern::bayer("rggb").unwrap();
        let mut img = crate::image::SensorImage::from_raw_dv(4, 4, &cfa, &[64; 16], 64.0, 1023.0);
        img.conversion_gain_dv_per_e = 0.37;
        let o = NoiseOptions::for_sensor(&img);
        assert_eq!(o.conversion_gain_dv_per_e, 0.37);
        assert_eq!(o.region_px, NoiseOptions::default().region_px);
    }
}
