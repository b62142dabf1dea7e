//! Sensor calibration from flat-field frames:
//!
//! - [`conversion_gain_appendix3`]: the paper's Appendix III estimator (Eq. 12),
//!   α = (V − E²σ_p²) / (E (1 + σ_p²)), from pooled DV (black subtracted) with a
//!   known PRNU, and its delta-method standard error;
//! - [`photon_transfer`]: the EMVA 1288 (release 3.1) photon-transfer analysis of
//!   flat-field sequences at several levels plus dark sequences: system gain K,
//!   temporal dark noise, DSNU₁₂₈₈, PRNU₁₂₈₈, saturation capacity, dark current, with
//!   standard errors.
//!
//! Standard errors: sample means and variances use their large-sample sampling
//! variances (for a variance s², Var(s²) ≈ (m₄ − s⁴)/n); K is a weighted
//! least-squares slope through the origin (weights from each point's variance SE),
//! inflated by √(χ²/(n−1)) when the points scatter more than their SEs; quantities in
//! electrons add K's relative error in quadrature. Saturation (the variance
//! maximum) adds the level spacing around it and the width of the plateau of
//! levels whose variance is within 2 SE of the maximum (each uniform, half-width / √3).

use crate::figure::Figure;

/// An estimate with its standard error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    pub value: f64,
    pub stderr: f64,
}

fn moments(v: &[f64]) -> (f64, f64, f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let (mut m2, mut m3, mut m4) = (0.0, 0.0, 0.0);
    for x in v {
        let d = x - m;
        m2 += d * d;
        m3 += d * d * d;
        m4 += d * d * d * d;
    }
    (m, m2 / (n - 1.0), m3 / n, m4 / n)
}

/// Eq. 12 of Appendix III on given moments: α = (V − E²σ_p²) / (E (1 + σ_p²)),
/// with E the mean and V the variance of the digital values above black, and
/// σ_p the PRNU as a fraction.
pub fn alpha_eq12(mean_dv: f64, variance_dv2: f64, prnu: f64) -> f64 {
    let p2 = prnu * prnu;
    (variance_dv2 - mean_dv * mean_dv * p2) / (mean_dv * (1.0 + p2))
}

/// Appendix III (Eq. 12). `dv_above_black`: pooled pixel values (all crops, all
/// frames) with the black level subtracted; `prnu`: PRNU as a fraction.
pub fn conversion_gain_appendix3(dv_above_black: &[f64], prnu: f64) -> Result<Estimate, String> {
    if dv_above_black.len() < 3 {
        return Err("Appendix III needs at least 3 values".into());
    }
    if dv_above_black.iter().any(|v| !v.is_finite()) || !prnu.is_finite() || prnu < 0.0 {
        return Err("Appendix III: values and PRNU must be finite (PRNU ≥ 0)".into());
    }
    let n = dv_above_black.len() as f64;
    let (m, v, m3, m4) = moments(dv_above_black);
    if m <= 0.0 {
        return Err(format!(
            "Appendix III: mean above black must be > 0, found {m}"
        ));
    }
    let p2 = prnu * prnu;
    let alpha = alpha_eq12(m, v, prnu);
    let da_dv = 1.0 / (m * (1.0 + p2));
    let da_dm = -(v + m * m * p2) / (m * m * (1.0 + p2));
    let var_m = v / n;
    let var_v = ((m4 - v * v) / n).max(0.0);
    let cov = m3 / n;
    let se = (da_dv * da_dv * var_v + da_dm * da_dm * var_m + 2.0 * da_dv * da_dm * cov)
        .max(0.0)
        .sqrt();
    Ok(Estimate {
        value: alpha,
        stderr: se,
    })
}

/// A sequence of frames of one flat-field level (or dark), same exposure.
#[derive(Clone, Debug)]
pub struct FlatSequence {
    pub exposure_s: f64,
    pub dark: bool,
    /// Frames of pixel values of the analysed channel (same pixels in every frame).
    pub frames: Vec<Vec<f64>>,
    /// Largest digital value (pixels at it are clipped).
    pub white_level_dv: f64,
}

/// Per-level statistics (EMVA 1288 §6).
#[derive(Clone, Debug)]
pub struct LevelStats {
    pub exposure_s: f64,
    pub dark: bool,
    /// μ_y: mean over pixels and frames.
    pub mean: f64,
    /// σ²_y: temporal variance from frame differences.
    pub temporal_var: f64,
    pub temporal_var_se: f64,
    /// s²_y: spatial variance of the frame average, temporal part removed.
    pub spatial_var: f64,
    pub spatial_var_se: f64,
    pub pixels: usize,
    /// Fraction of samples at the white level.
    pub clipped_fraction: f64,
}

/// Statistics of one sequence (needs ≥ 2 frames of equal size).
pub fn level_stats(s: &FlatSequence) -> Result<LevelStats, String> {
    let l = s.frames.len();
    if l < 2 {
        return Err(format!(
            "a sequence needs at least 2 frames for temporal noise, found {l}"
        ));
    }
    let n = s.frames[0].len();
    if n < 2 || s.frames.iter().any(|f| f.len() != n) {
        return Err("all frames of a sequence must have the same (≥ 2) pixels".into());
    }
    // temporal: pairs (0,1), (2,3), …; σ² = var(A − B)/2
    let mut diffs = vec![];
    for p in 0..l / 2 {
        let (a, b) = (&s.frames[2 * p], &s.frames[2 * p + 1]);
        let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
        diffs.push(d);
    }
    let mut tv = 0.0;
    let mut tv_var = 0.0;
    for d in &diffs {
        let (_, v, _, m4) = moments(d);
        tv += v / 2.0;
        tv_var += ((m4 - v * v) / d.len() as f64).max(0.0) / 4.0;
    }
    let np = diffs.len() as f64;
    let temporal_var = tv / np;
    let temporal_var_se = tv_var.sqrt() / np;
    let avg: Vec<f64> = (0..n)
        .map(|i| s.frames.iter().map(|f| f[i]).sum::<f64>() / l as f64)
        .collect();
    let (mean, sv, _, m4) = moments(&avg);
    let spatial_var = sv - temporal_var / l as f64;
    let spatial_var_se =
        (((m4 - sv * sv) / n as f64).max(0.0) + (temporal_var_se / l as f64).powi(2)).sqrt();
    let clipped = s
        .frames
        .iter()
        .flatten()
        .filter(|&&v| v >= s.white_level_dv)
        .count();
    Ok(LevelStats {
        exposure_s: s.exposure_s,
        dark: s.dark,
        mean,
        temporal_var,
        temporal_var_se,
        spatial_var,
        spatial_var_se,
        pixels: n,
        clipped_fraction: clipped as f64 / (n * l) as f64,
    })
}

/// EMVA 1288 results.
#[derive(Clone, Debug)]
pub struct PhotonTransfer {
    /// System gain K, DV/e⁻.
    pub k_dv_per_e: Estimate,
    /// Temporal dark noise at the shortest dark exposure, e⁻ (quantisation removed).
    pub dark_noise_e: Estimate,
    pub dark_noise_dv: Estimate,
    /// DSNU₁₂₈₈ (spatial std of the dark level), e⁻ and DV.
    pub dsnu_e: Estimate,
    pub dsnu_dv: Estimate,
    /// PRNU₁₂₈₈ as a fraction, from the level closest to 50 % of saturation.
    pub prnu: Estimate,
    /// Saturation capacity μ_e.sat, e⁻ (None when no level passed the variance maximum).
    pub saturation_e: Option<Estimate>,
    /// Dark current, e⁻/s (None with fewer than two dark exposures).
    pub dark_current_e_per_s: Option<Estimate>,
    /// Dark signal growth, DV/s: the slope behind `dark_current_e_per_s`, before
    /// the division by K (so its SE does not carry K's).
    pub dark_signal_dv_per_s: Option<Estimate>,
    /// Appendix III conversion gain from the brightest level of the K fit, using the
    /// PRNU measured here (its SE includes the PRNU estimate's SE).
    pub appendix3_dv_per_e: Option<Estimate>,
    pub levels: Vec<LevelStats>,
    /// Light levels used for the K fit (indices into `levels`).
    pub fit_levels: Vec<usize>,
}

impl PhotonTransfer {
    /// Results as figures (measurement "emva1288").
    pub fn figures(&self) -> Vec<Figure> {
        let f = |q: &str, u: &str, e: &Estimate| Figure::new("emva1288", q, u, e.value, e.stderr);
        let mut v = vec![
            f("system_gain_k", "DV/e-", &self.k_dv_per_e),
            f("read_noise", "e-", &self.dark_noise_e),
            f("read_noise", "DV", &self.dark_noise_dv),
            f("dsnu", "e-", &self.dsnu_e),
            f("dsnu", "DV", &self.dsnu_dv),
            Figure::new(
                "emva1288",
                "prnu",
                "%",
                self.prnu.value * 100.0,
                self.prnu.stderr * 100.0,
            ),
        ];
        if let Some(s) = &self.saturation_e {
            v.push(f("saturation_capacity", "e-", s));
        }
        if let Some(d) = &self.dark_current_e_per_s {
            v.push(f("dark_current", "e-/s", d));
        }
        if let Some(a) = &self.appendix3_dv_per_e {
            v.push(f("conversion_gain_appendix3", "DV/e-", a));
        }
        v
    }
}

fn rel(e: &Estimate) -> f64 {
    if e.value != 0.0 {
        e.stderr / e.value.abs()
    } else {
        0.0
    }
}

/// EMVA 1288 photon-transfer analysis. Needs at least one dark and one light sequence;
/// each light level is paired with the dark sequence of the nearest exposure time.
pub fn photon_transfer(seqs: &[FlatSequence]) -> Result<PhotonTransfer, String> {
    let levels: Vec<LevelStats> = seqs.iter().map(level_stats).collect::<Result<_, _>>()?;
    let darks: Vec<usize> = (0..levels.len()).filter(|&i| levels[i].dark).collect();
    let mut lights: Vec<usize> = (0..levels.len()).filter(|&i| !levels[i].dark).collect();
    if darks.is_empty() || lights.is_empty() {
        return Err(format!(
            "photon transfer needs dark and light sequences; found {} dark and {} light",
            darks.len(),
            lights.len()
        ));
    }
    let dark_for = |t: f64| -> &LevelStats {
        let i = *darks
            .iter()
            .min_by(|&&a, &&b| {
                (levels[a].exposure_s - t)
                    .abs()
                    .total_cmp(&(levels[b].exposure_s - t).abs())
            })
            .expect("non-empty");
        &levels[i]
    };
    // points (x = μ_y − μ_dark, y = σ²_y − σ²_dark), SE of y
    let pt = |i: usize| -> (f64, f64, f64) {
        let l = &levels[i];
        let d = dark_for(l.exposure_s);
        (
            l.mean - d.mean,
            l.temporal_var - d.temporal_var,
            (l.temporal_var_se.powi(2) + d.temporal_var_se.powi(2)).sqrt(),
        )
    };
    lights.sort_by(|&a, &b| pt(a).0.total_cmp(&pt(b).0));
    // saturation: the variance maximum, if a brighter level lies beyond it
    let (imax, _) = lights
        .iter()
        .enumerate()
        .fold((0, f64::MIN), |acc, (k, &i)| {
            if pt(i).1 > acc.1 { (k, pt(i).1) } else { acc }
        });
    let saturated = imax + 1 < lights.len();
    let sat_x = if saturated {
        Some(pt(lights[imax]).0)
    } else {
        None
    };
    // fit range: unclipped levels up to 70 % of saturation
    let mut fit: Vec<usize> = lights
        .iter()
        .copied()
        .filter(|&i| {
            levels[i].clipped_fraction == 0.0
                && sat_x.is_none_or(|s| pt(i).0 <= 0.7 * s)
                && pt(i).0 > 0.0
        })
        .collect();
    if fit.is_empty() {
        fit = lights
            .iter()
            .copied()
            .filter(|&i| pt(i).0 > 0.0 && levels[i].clipped_fraction < 0.001)
            .take(1)
            .collect();
    }
    if fit.is_empty() {
        return Err("no unclipped light level above the dark level to fit K".into());
    }
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for &i in &fit {
        let (x, y, se) = pt(i);
        let w = 1.0 / se.max(1e-12).powi(2);
        sxx += w * x * x;
        sxy += w * x * y;
    }
    let k = sxy / sxx;
    let mut k_se = (1.0 / sxx).sqrt();
    if fit.len() >= 3 {
        let chi2: f64 = fit
            .iter()
            .map(|&i| {
                let (x, y, se) = pt(i);
                ((y - k * x) / se.max(1e-12)).powi(2)
            })
            .sum::<f64>()
            / (fit.len() - 1) as f64;
        if chi2 > 1.0 {
            k_se *= chi2.sqrt();
        }
    }
    if !(k.is_finite() && k > 0.0) {
        return Err(format!(
            "photon transfer: system gain came out {k}; check the frames (are the light levels brighter than dark?)"
        ));
    }
    let kk = Estimate {
        value: k,
        stderr: k_se,
    };
    let rk = rel(&kk);
    // dark noise at the shortest dark exposure
    let d0 = darks
        .iter()
        .copied()
        .min_by(|&a, &b| levels[a].exposure_s.total_cmp(&levels[b].exposure_s))
        .expect("non-empty");
    let d = &levels[d0];
    let q = 1.0 / 12.0;
    let dn2 = (d.temporal_var - q).max(0.0);
    let dn_dv = dn2.sqrt();
    let dn_dv_se = if dn_dv > 0.0 {
        d.temporal_var_se / (2.0 * dn_dv)
    } else {
        d.temporal_var_se.sqrt()
    };
    let dark_noise_dv = Estimate {
        value: dn_dv,
        stderr: dn_dv_se,
    };
    let dark_noise_e = Estimate {
        value: dn_dv / k,
        stderr: dn_dv / k * (rel(&dark_noise_dv).powi(2) + rk * rk).sqrt(),
    };
    let ds = d.spatial_var.max(0.0).sqrt();
    let ds_se = if ds > 0.0 {
        d.spatial_var_se / (2.0 * ds)
    } else {
        d.spatial_var_se.sqrt()
    };
    let dsnu_dv = Estimate {
        value: ds,
        stderr: ds_se,
    };
    let dsnu_e = Estimate {
        value: ds / k,
        stderr: ds / k * (rel(&dsnu_dv).powi(2) + rk * rk).sqrt(),
    };
    // PRNU at the level closest to 50 % of saturation (or of the brightest unclipped level)
    let target = sat_x.unwrap_or_else(|| fit.iter().map(|&i| pt(i).0).fold(0.0, f64::max)) * 0.5;
    let ip = *fit
        .iter()
        .min_by(|&&a, &&b| {
            (pt(a).0 - target)
                .abs()
                .total_cmp(&(pt(b).0 - target).abs())
        })
        .expect("non-empty");
    let lp = &levels[ip];
    let dp = dark_for(lp.exposure_s);
    let (x50, _, _) = pt(ip);
    let s2 = (lp.spatial_var - dp.spatial_var).max(0.0);
    let s2_se = (lp.spatial_var_se.powi(2) + dp.spatial_var_se.powi(2)).sqrt();
    let prnu_v = s2.sqrt() / x50;
    let prnu_se = if s2 > 0.0 {
        s2_se / (2.0 * s2.sqrt()) / x50
    } else {
        s2_se.sqrt() / x50
    };
    let prnu = Estimate {
        value: prnu_v,
        stderr: prnu_se,
    };
    let saturation_e = if saturated {
        // EMVA's saturation is the level of largest variance. Near its
        // maximum the variance curve is flat, so its SE has two parts: the
        // level spacing around it (uniform, half-width / √3) and the plateau
        // of levels whose variance is within 2 SE of the largest, any of which
        // could be the maximum (its half-width / √3).
        let x = pt(lights[imax]).0;
        let lo = if imax > 0 { pt(lights[imax - 1]).0 } else { x };
        let hi = pt(lights[imax + 1]).0;
        let (ymax, semax) = (pt(lights[imax]).1, pt(lights[imax]).2);
        let near: Vec<f64> = lights
            .iter()
            .map(|&i| pt(i))
            .filter(|&(_, y, se)| ymax - y <= 2.0 * (se * se + semax * semax).sqrt())
            .map(|p| p.0)
            .collect();
        let (p0, p1) = near.iter().fold((x, x), |(a, b), &v| (a.min(v), b.max(v)));
        let spacing = ((hi - lo) / 2.0 / 3f64.sqrt()).hypot((p1 - p0) / 2.0 / 3f64.sqrt());
        let v = x / k;
        Some(Estimate {
            value: v,
            stderr: ((spacing / k).powi(2) + (v * rk).powi(2)).sqrt(),
        })
    } else {
        None
    };
    // dark current: slope of μ_dark vs exposure (unweighted LS with intercept)
    let dark_slope = if darks.len() >= 2 {
        let ts: Vec<f64> = darks.iter().map(|&i| levels[i].exposure_s).collect();
        let ms: Vec<f64> = darks.iter().map(|&i| levels[i].mean).collect();
        let n = ts.len() as f64;
        let tm = ts.iter().sum::<f64>() / n;
        let mm = ms.iter().sum::<f64>() / n;
        let stt: f64 = ts.iter().map(|t| (t - tm).powi(2)).sum();
        if stt > 0.0 {
            let slope = ts
                .iter()
                .zip(&ms)
                .map(|(t, m)| (t - tm) * (m - mm))
                .sum::<f64>()
                / stt;
            // SE from the per-level mean SEs (temporal + spatial variance over pixels)
            let var_means: f64 = darks
                .iter()
                .zip(&ts)
                .map(|(&i, t)| {
                    (t - tm).powi(2) * (levels[i].temporal_var + levels[i].spatial_var.max(0.0))
                        / levels[i].pixels as f64
                })
                .sum::<f64>();
            Some(Estimate {
                value: slope,
                stderr: var_means.sqrt() / stt,
            })
        } else {
            None
        }
    } else {
        None
    };
    let dark_current_e_per_s = dark_slope.map(|d| {
        let v = d.value / k;
        Estimate {
            value: v,
            stderr: ((d.stderr / k).powi(2) + (v * rk).powi(2)).sqrt(),
        }
    });
    // Appendix III on the brightest fitted level, pooled values minus the dark mean
    let appendix3_dv_per_e = fit
        .iter()
        .copied()
        .max_by(|&a, &b| pt(a).0.total_cmp(&pt(b).0))
        .and_then(|i| {
            let dm = dark_for(levels[i].exposure_s).mean;
            let vals: Vec<f64> = seqs[i].frames.iter().flatten().map(|v| v - dm).collect();
            conversion_gain_appendix3(&vals, prnu.value).ok()
        });
    Ok(PhotonTransfer {
        k_dv_per_e: kk,
        dark_noise_e,
        dark_noise_dv,
        dsnu_e,
        dsnu_dv,
        prnu,
        saturation_e,
        dark_current_e_per_s,
        dark_signal_dv_per_s: dark_slope,
        appendix3_dv_per_e,
        levels,
        fit_levels: fit,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::rng::PixelRng;

    #[test]
    fn appendix3_on_ideal_poisson_times_gain() {
        // DV = α·Poisson(μ) with no PRNU: Eq. 12 reduces to var/mean = α.
        let alpha = 0.2;
        let vals: Vec<f64> = (0..200_000u64)
            .map(|i| alpha * PixelRng::new(5, 1, i).poisson(1500.0))
            .collect();
        let e = conversion_gain_appendix3(&vals, 0.0).unwrap();
        assert!((e.value - alpha).abs() < 5.0 * e.stderr, "{e:?}");
        // SE ≈ α·sqrt(2/n) for a near-normal variance estimate
        assert!(
            (e.stderr / (alpha * (2.0f64 / 200_000.0).sqrt()) - 1.0).abs() < 0.1,
            "{e:?}"
        );
        assert!(conversion_gain_appendix3(&[1.0], 0.0).is_err());
        assert!(conversion_gain_appendix3(&[1.0, f64::NAN, 2.0], 0.0).is_err());
    }
}
