//! The sensor noise model's prediction for Appendix IV's uniform regions
//! (paper Fig. 8 b), with the rendering's own Monte Carlo noise added.
//!
//! For a pixel whose mean signal (dark current included) is μ electrons, the
//! sensor model ([`crate::sensor::pipeline`]) gives, in DV² above black,
//!
//! σ² = K² [ μ(1 + σ_p²) + μ²σ_p² + σ²_read + σ²_reset + σ²_DSNU + σ²_col.off + μ²σ²_col.gain
//!          + (1 + σ_p²) σ²_MC ] + 1/12
//!
//! with K the system gain (DV/e⁻), σ_p the PRNU, noise voltages in electrons
//! (÷ the sense-node gain), the quantisation step's 1/12 DV², and σ²_MC the
//! optical image's Monte Carlo variance of that pixel's electron count:
//! (exposure × relative illumination × the standard error of the pixel's
//! channel-weighted irradiance, from the render's batches —
//! `OpticalImage::weighted_stderr`; the bands of one path are correlated, so
//! it is not formed from the per-band errors). Shot noise and the PRNU gain
//! are Eq. 8 of Appendix III; the fixed-pattern terms are spatial and so part
//! of a region's spread.
//!
//! A region's predicted variance is the mean of its channel pixels' σ² at the
//! region's mean (μ = mean DV / K). Its sample standard deviation s over n
//! pixels then lies, for normal noise, in σ·√(χ²_{(1∓b)/2, n−1}/(n−1)) with
//! probability b (`band-percent`); χ² quantiles by Wilson–Hilferty (relative
//! error < 10⁻³ for n − 1 ≥ 20), normal quantiles by Acklam's rational
//! approximation (relative error < 1.2·10⁻⁹). Regions with a pixel at the
//! ADC's white level or floor are left out (clipping breaks the model) and
//! counted. Scene structure a region keeps after the uniformity test is not
//! in the model: it can only push s above the band.

use super::noise::{Region, Verdict};
use super::plane::Plane;
use super::{Curve, Measured};
use crate::figure::Figure;
use crate::image::SensorImage;
use crate::optical_image::OpticalImage;
use crate::sensor::SensorConfig;
use crate::{Error, Result};

/// The standard normal quantile (Acklam's algorithm), 0 < p < 1.
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e+01,
        2.209460984245205e+02,
        -2.759285104469687e+02,
        1.383_577_518_672_69e2,
        -3.066479806614716e+01,
        2.506628277459239e+00,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e+01,
        1.615858368580409e+02,
        -1.556989798598866e+02,
        6.680131188771972e+01,
        -1.328068155288572e+01,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-03,
        -3.223964580411365e-01,
        -2.400758277161838e+00,
        -2.549732539343734e+00,
        4.374664141464968e+00,
        2.938163982698783e+00,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-03,
        3.224671290700398e-01,
        2.445134137142996e+00,
        3.754408661907416e+00,
    ];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// The `p` quantile of χ² with `k` degrees of freedom (Wilson–Hilferty).
pub fn chi2_quantile(p: f64, k: f64) -> f64 {
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + normal_quantile(p) * a.sqrt()).powi(3).max(0.0)
}

/// Factors (low, high) on σ bounding the sample standard deviation of `n`
/// normal values with probability `b`.
pub fn std_band(n: usize, b: f64) -> (f64, f64) {
    let k = (n as f64 - 1.0).max(1.0);
    let lo = (chi2_quantile((1.0 - b) / 2.0, k) / k).sqrt();
    let hi = (chi2_quantile((1.0 + b) / 2.0, k) / k).sqrt();
    (lo, hi)
}

/// The sensor model's variance (DV²) of a pixel with mean `mean_dv` above
/// black, without rendering noise (see the module docs).
pub fn sensor_variance_dv2(cfg: &SensorConfig, mean_dv: f64) -> f64 {
    let k = cfg.conversion_gain_dv_per_e();
    let cg = cfg.conversion_gain_v_per_e();
    let s = cfg.sources;
    let mu = (mean_dv / k).max(0.0);
    let p2 = if s.prnu { cfg.prnu * cfg.prnu } else { 0.0 };
    let mut e2 = if s.photon_noise { mu * (1.0 + p2) } else { 0.0 };
    e2 += mu * mu * p2;
    let v2e = |v: f64, on: bool| if on { (v / cg).powi(2) } else { 0.0 };
    e2 += v2e(cfg.read_noise_v, s.read_noise) + v2e(cfg.reset_noise_v, s.reset_noise);
    e2 += v2e(cfg.dsnu_v, s.dsnu) + v2e(cfg.column_fpn_offset_v, s.column_fpn);
    if s.column_fpn {
        e2 += (mu * cfg.column_fpn_gain).powi(2);
    }
    k * k * e2 + if s.quantization { 1.0 / 12.0 } else { 0.0 }
}

/// Per pixel of the sensor image's window, the Monte Carlo variance of its
/// electron count in DV² (× (1 + σ_p²)), as a plane shaped like
/// [`Plane::from_sensor`]. Needs the optical image on the sensor's pixel grid
/// with channel-weighted standard errors.
pub fn mc_variance_plane(
    cfg: &SensorConfig,
    si: &SensorImage,
    oi: &OpticalImage,
    name: &str,
) -> Result<Plane> {
    let nch = cfg.cfa.channels.len();
    let same_grid = (oi.pixel_pitch_m / si.pixel_pitch_m - 1.0).abs() < 1e-9
        && oi.full_width == si.full_width
        && oi.full_height == si.full_height;
    if !same_grid {
        return Err(Error::invalid(format!(
            "measurement '{name}': the noise model needs the optical image on the sensor's pixel grid (the optical image is {}×{} at {} µm, the sensor {}×{} at {} µm)",
            oi.full_width,
            oi.full_height,
            oi.pixel_pitch_m * 1e6,
            si.full_width,
            si.full_height,
            si.pixel_pitch_m * 1e6
        )));
    }
    if oi.weighted_stderr.len() != oi.window.area() as usize * nch {
        return Err(Error::invalid(format!(
            "measurement '{name}': the noise model needs the rendering's per-pixel standard error of each sensor channel (render with spp ≥ 2)"
        )));
    }
    let k = cfg.conversion_gain_dv_per_e();
    let p2 = if cfg.sources.prnu {
        cfg.prnu * cfg.prnu
    } else {
        0.0
    };
    let t = si.exposure_s;
    let (w, h) = (si.width() as usize, si.height() as usize);
    let mut data = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let (fx, fy) = (si.window.x + x as u32, si.window.y + y as u32);
            if !oi.window.contains(fx, fy) {
                return Err(Error::invalid(format!(
                    "measurement '{name}': sensor pixel ({fx}, {fy}) was not rendered"
                )));
            }
            let oidx =
                (fy - oi.window.y) as usize * oi.window.w as usize + (fx - oi.window.x) as usize;
            let c = cfg.cfa.channel_at(fx, fy);
            let ri = crate::sensor::pipeline::relative_illumination_at(
                cfg,
                (si.full_width, si.full_height),
                fx,
                fy,
            );
            let se_e = oi.weighted_stderr[oidx * nch + c] as f64 * t * ri;
            data[y * w + x] = k * k * se_e * se_e * (1.0 + p2);
        }
    }
    let mut p = Plane::new(w, h, data)?;
    p.channel = Plane::from_sensor(si)?.channel;
    p.channel_names = cfg.cfa.channels.clone();
    Ok(p)
}

/// Add the model's figures and curves to a noise measurement's result.
/// `plane` holds the DVs above black the regions were drawn from, `mc` the
/// matching Monte Carlo variances (DV²), `white_above_black` the clip.
#[allow(clippy::too_many_arguments)]
pub fn add_model(
    out: &mut Measured,
    regions: &[Region],
    plane: &Plane,
    mc: &Plane,
    cfg: &SensorConfig,
    channel: &str,
    band: f64,
    name: &str,
) -> Result<()> {
    let ch = plane.channel_index(channel);
    let white = cfg.white_level_dv() - cfg.black_level_dv;
    let floor = -cfg.black_level_dv;
    let (mut used, mut inside, mut clipped) = (0usize, 0usize, 0usize);
    let mut inside_sensor_only = 0usize;
    let (mut mc_frac, mut ratios) = (vec![], vec![]);
    let (mut mx, mut my_meas, mut my_pred) = (vec![], vec![], vec![]);
    for r in regions.iter().filter(|r| r.verdict == Verdict::Accepted) {
        let (mut vals, mut mcs) = (vec![], vec![]);
        for y in r.rect.y as usize..(r.rect.y + r.rect.h) as usize {
            for x in r.rect.x as usize..(r.rect.x + r.rect.w) as usize {
                if ch.is_none() || plane.channel_at(x, y) == ch {
                    vals.push(plane.get(x, y));
                    mcs.push(mc.get(x, y));
                }
            }
        }
        if vals.iter().any(|&v| v >= white || v <= floor) {
            clipped += 1;
            continue;
        }
        let n = vals.len();
        let sensor = sensor_variance_dv2(cfg, r.mean_dv);
        let mcv = mcs.iter().sum::<f64>() / n as f64;
        let sigma = (sensor + mcv).sqrt();
        let (lo, hi) = std_band(n, band);
        used += 1;
        if r.std_dv >= lo * sigma && r.std_dv <= hi * sigma {
            inside += 1;
        }
        let s0 = sensor.sqrt();
        if r.std_dv >= lo * s0 && r.std_dv <= hi * s0 {
            inside_sensor_only += 1;
        }
        mc_frac.push(mcv / (sensor + mcv));
        ratios.push(r.std_dv / sigma);
        mx.push(r.mean_dv);
        my_meas.push(r.std_dv);
        my_pred.push(sigma);
    }
    if used == 0 {
        return Err(Error::invalid(format!(
            "measurement '{name}': no accepted region below the clip to compare with the noise model ({clipped} clipped)"
        )));
    }
    let f = used as f64;
    let frac = inside as f64 / f;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let sem = |v: &[f64]| {
        let m = mean(v);
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>()
            / (v.len().max(2) - 1) as f64
            / v.len() as f64)
            .sqrt()
    };
    out.figures.extend([
        Figure::new(name, "model_regions", "1", f, 0.0),
        Figure::new(name, "regions_clipped", "1", clipped as f64, 0.0),
        Figure::new(
            name,
            "fraction_in_band",
            "1",
            frac,
            (frac * (1.0 - frac) / f).sqrt(),
        ),
        Figure::new(name, "band_percent", "%", band * 100.0, 0.0),
        Figure::new(
            name,
            "fraction_in_band_sensor_only",
            "1",
            inside_sensor_only as f64 / f,
            {
                let q = inside_sensor_only as f64 / f;
                (q * (1.0 - q) / f).sqrt()
            },
        ),
        Figure::new(name, "std_over_model", "1", mean(&ratios), sem(&ratios)),
        Figure::new(
            name,
            "mc_variance_fraction",
            "1",
            mean(&mc_frac),
            sem(&mc_frac),
        ),
    ]);
    // The chart: measured and predicted σ per region, and the sensor-only
    // model (no rendering noise) with its band for a typical region size.
    let n_typ = regions
        .iter()
        .filter(|r| r.verdict == Verdict::Accepted)
        .map(|r| r.n)
        .max()
        .unwrap_or(2);
    let (lo, hi) = std_band(n_typ, band);
    let top = mx.iter().cloned().fold(0.0, f64::max);
    let gx: Vec<f64> = (0..=100).map(|i| top * i as f64 / 100.0).collect();
    let gs: Vec<f64> = gx
        .iter()
        .map(|&m| sensor_variance_dv2(cfg, m).sqrt())
        .collect();
    let c = |n: &str, x: Vec<f64>, y: Vec<f64>| {
        Curve::new(n, ("mean", "DV"), ("std", "DV"), x, y, vec![])
    };
    out.curves.retain(|c| c.name != "std_vs_mean");
    out.curves.extend([
        c("std_vs_mean#regions", mx.clone(), my_meas),
        c("std_vs_mean#regions_model_with_mc", mx, my_pred),
        c("std_vs_mean#sensor_model", gx.clone(), gs.clone()),
        c(
            "std_vs_mean#sensor_band_low",
            gx.clone(),
            gs.iter().map(|s| s * lo).collect(),
        ),
        c(
            "std_vs_mean#sensor_band_high",
            gx,
            gs.iter().map(|s| s * hi).collect(),
        ),
    ]);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_match_tables() {
        // z_{0.975} = 1.959963985; z_{0.001} = −3.090232306 (tables)
        assert!((normal_quantile(0.975) - 1.959963985).abs() < 1e-8);
        assert!((normal_quantile(0.001) + 3.090232306).abs() < 1e-8);
        // χ²_{0.025, 49} = 31.5549, χ²_{0.975, 49} = 70.2224 (tables; WH < 1e-3 rel.)
        assert!((chi2_quantile(0.025, 49.0) / 31.5549 - 1.0).abs() < 1e-3);
        assert!((chi2_quantile(0.975, 49.0) / 70.2224 - 1.0).abs() < 1e-3);
    }
}
