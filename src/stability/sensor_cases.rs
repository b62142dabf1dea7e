//! Stability cases of the sensor pipeline ([`crate::sensor::simulate_flat`]
//! on the experiment's sensor): a saturated and a zero-light frame, and
//! extreme exposure times and analog gains. References are the pipeline's
//! closed forms: the ADC maximum 2^bits − 1, the full well, the black level
//! plus dark signal, and for the noise the read/reset/dark-shot variance
//! (+1/12 DV² of rounding) or the normal probability of a clip at 0 DV.
//! Fixed-pattern sources (PRNU, DSNU, column FPN) and pixel vignetting are
//! switched off in the case's copy of the sensor so the closed forms are
//! exact; every temporal source, the well and the ADC stay as configured.

use super::Check;
use crate::image::SensorImage;
use crate::measure::noise::{NoiseOptions, measure_with};
use crate::measure::plane::Plane;
use crate::optical_image::Rect;
use crate::sensor::config::{Exposure, SensorConfig};
use crate::sensor::pipeline::{flat_rate_e_per_s, simulate_flat};
use crate::spectrum::{Spectrum, WavelengthGrid};
use crate::{Error, Result};

/// Side of the simulated window (pixels): n = 4096 samples per frame.
const SIDE: u32 = 64;

fn grid() -> WavelengthGrid {
    WavelengthGrid::new(400.0, 700.0, 10.0).unwrap_or_default()
}

/// The case's copy of the sensor: fixed patterns and vignetting off,
/// exposure `t` seconds, analog gain `gain`; with rows/cols if it had none.
fn sensor(cfg: &SensorConfig, t: f64, gain: f64) -> SensorConfig {
    let mut c = cfg.clone();
    c.sources.prnu = false;
    c.sources.dsnu = false;
    c.sources.column_fpn = false;
    c.sources.pixel_vignetting = false;
    c.exposure = Exposure::Seconds(t);
    c.analog_gain = gain;
    c.rows = Some(c.rows.unwrap_or(SIDE).max(SIDE));
    c.cols = Some(c.cols.unwrap_or(SIDE).max(SIDE));
    c
}

fn window(c: &SensorConfig) -> Rect {
    let (cols, rows) = (c.cols.unwrap_or(SIDE), c.rows.unwrap_or(SIDE));
    Rect::new((cols - SIDE) / 2, (rows - SIDE) / 2, SIDE, SIDE)
}

fn frame(c: &SensorConfig, irradiance: f64, seed: u64) -> Result<SensorImage> {
    let e = Spectrum::constant("flat", irradiance);
    Ok(simulate_flat(c, &e, &grid(), window(c), seed)?.image)
}

/// Temporal noise in DV² at zero signal: read and reset noise, dark-current
/// shot noise, and 1/12 DV² of rounding (Sheppard; exact to < 1 % for
/// σ ≥ 0.5 DV, see `saturated_dark`).
fn dark_variance_dv2(c: &SensorConfig, t: f64) -> f64 {
    let s = c.sources;
    let cg = c.conversion_gain_v_per_e();
    let dv_per_v = c.analog_gain / c.quantization_step_v();
    let mut v2 = 0.0;
    if s.read_noise {
        v2 += c.read_noise_v.powi(2);
    }
    if s.reset_noise {
        v2 += c.reset_noise_v.powi(2);
    }
    if s.dark_current && s.photon_noise {
        v2 += c.dark_voltage_v_per_s * t / cg * cg * cg;
    }
    v2 * dv_per_v * dv_per_v + if s.quantization { 1.0 / 12.0 } else { 0.0 }
}

/// Mean DV of the dark signal above the black level.
fn dark_signal_dv(c: &SensorConfig, t: f64) -> f64 {
    if c.sources.dark_current {
        c.dark_voltage_v_per_s * t * c.analog_gain / c.quantization_step_v()
    } else {
        0.0
    }
}

fn mean_sd(v: &[f32]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().map(|&x| x as f64).sum::<f64>() / n;
    let s2 = v.iter().map(|&x| (x as f64 - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, s2.sqrt())
}

fn fraction(v: &[f32], f: impl Fn(f32) -> bool) -> f64 {
    v.iter().filter(|&&x| f(x)).count() as f64 / v.len() as f64
}

/// A noise measurement on a flat frame must give finite figures or a clear
/// error: the count of non-finite figures (0 on an error with a message).
fn noise_measure_check(si: &SensorImage, tag: &str) -> Check {
    let at = format!("measure \"noise\" on the {tag} frame");
    let plane = match Plane::from_sensor(si) {
        Ok(p) => p,
        Err(e) => {
            return Check::count(
                &format!("{tag}/noise_measure_nonfinite"),
                0,
                0,
                &format!("{at}: {e}"),
            );
        }
    };
    let opts = NoiseOptions {
        conversion_gain_dv_per_e: si.conversion_gain_dv_per_e,
        regions: 20,
        ..Default::default()
    };
    match measure_with(&plane, &opts, None, "noise") {
        Ok((m, _)) => {
            let bad = m
                .figures
                .iter()
                .filter(|f| !(f.value.is_finite() && f.stderr.is_finite()))
                .count();
            Check::count(&format!("{tag}/noise_measure_nonfinite"), bad, 0, &at)
        }
        // a refusal must say why
        Err(e) => Check::count(
            &format!("{tag}/noise_measure_nonfinite"),
            e.to_string().trim().is_empty() as usize,
            0,
            &format!("{at} refused: {e}"),
        ),
    }
}

/// `sensor-saturated-dark`: a frame 10⁴× over full well and a frame with no
/// light, at the sensor's exposure and gain.
///
/// Saturated: every DV at the ADC maximum (exact count; the charge clips at
/// the well and full well × conversion gain reaches the ADC swing).
/// Dark: mean DV = black level + dark signal within 5 standard errors
/// (σ/√n, n = 4096); sample standard deviation within 5·σ/√(2(n−1)) + 1 %
/// of the predicted √(read² + reset² + dark shot + 1/12) DV (the 1 % covers
/// Sheppard's rounding correction, whose error is ≈ exp(−2π²σ²) ≤ 0.7 % for
/// σ ≥ 0.5 DV); no pixel at 0 or at the maximum. A noise measurement on
/// each frame gives finite figures or an error that says why.
pub fn saturated_dark(cfg: &SensorConfig, seed: u64) -> Result<Vec<Check>> {
    let t = match cfg.exposure {
        Exposure::Seconds(t) => t,
        _ => 0.01,
    };
    let c = sensor(cfg, t, cfg.analog_gain);
    let white = c.white_level_dv() as f32;
    // irradiance for 10⁴ full wells in the exposure (the weakest channel)
    let r1 = flat_rate_e_per_s(&c, &Spectrum::constant("1", 1.0), &grid());
    let weakest = r1.iter().copied().fold(f64::INFINITY, f64::min);
    if weakest.is_nan() || weakest <= 0.0 {
        return Err(Error::invalid(
            "sensor-saturated-dark: a channel collects no light",
        ));
    }
    let e_sat = 1e4 * c.full_well_e() / (weakest * t);
    let sat = frame(&c, e_sat, seed)?;
    let n = sat.dv.len();
    let mut checks = vec![
        Check::count(
            "saturated/nonfinite",
            super::nonfinite(&sat.dv),
            0,
            "the saturated frame's DVs",
        ),
        Check::new(
            "saturated/fraction_at_adc_max",
            fraction(&sat.dv, |d| d == white),
            1.0,
            0.0,
            &format!("{n} pixels, ADC maximum {white} DV"),
        ),
        noise_measure_check(&sat, "saturated"),
    ];
    let dark = frame(&c, 0.0, seed)?;
    let (m, sd) = mean_sd(&dark.dv);
    let mean0 = c.black_level_dv + dark_signal_dv(&c, t);
    let s0 = dark_variance_dv2(&c, t).sqrt();
    let nf = n as f64;
    let at = format!(
        "{n} pixels of the zero-light frame, black level {} DV",
        c.black_level_dv
    );
    checks.extend([
        Check::count("dark/nonfinite", super::nonfinite(&dark.dv), 0, &at),
        Check::new(
            "dark/mean_ratio",
            m / mean0,
            1.0,
            5.0 * s0 / nf.sqrt() / mean0,
            &at,
        )
        .with_stderr(sd / nf.sqrt() / mean0),
        Check::new(
            "dark/sd_ratio",
            sd / s0,
            1.0,
            5.0 / (2.0 * (nf - 1.0)).sqrt() + 0.01,
            &format!("{at}, predicted σ {s0:.4} DV"),
        ),
        Check::new(
            "dark/fraction_clipped",
            fraction(&dark.dv, |d| d <= 0.0 || d >= white),
            0.0,
            0.0,
            &at,
        ),
        noise_measure_check(&dark, "dark"),
    ]);
    Ok(checks)
}

/// Standard normal lower tail Φ(z), from erfc (Abramowitz–Stegun 7.1.26,
/// absolute error < 1.5·10⁻⁷).
fn phi(z: f64) -> f64 {
    let x = -z / std::f64::consts::SQRT_2;
    let ax = x.abs();
    let t = 1.0 / (1.0 + 0.3275911 * ax);
    let y = t
        * (0.254829592
            + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
    let erfc_ax = y * (-ax * ax).exp();
    let erfc = if x >= 0.0 { erfc_ax } else { 2.0 - erfc_ax };
    0.5 * erfc
}

/// `exposure-gain`: exposures of 1 µs and 100 s at analog gains 0.1 and
/// 100, under a flat field of 10⁻³ W/(m²·nm). Checks per setting: finite
/// DVs, and the clipping the pipeline's closed form predicts, counted:
/// - 100 s × 100: every DV at the ADC maximum (exact);
/// - 100 s × 0.1: every pixel's charge at the full well (exact), and the
///   mean DV at black + well × conversion gain × gain (± ½ DV rounding
///   + 5 standard errors);
/// - 1 µs × 0.1: mean DV at black + signal + dark (same tolerance), none
///   clipped;
/// - 1 µs × 100: the read noise ×100 clips the low tail at 0 DV; the
///   clipped fraction equals Φ((½ − black − signal)/σ) within
///   5·√(p(1 − p)/n) (binomial standard error) + 10⁻³ (the normal tail of
///   rounded values; Φ's own error is 1.5·10⁻⁷).
pub fn exposure_gain(cfg: &SensorConfig, seed: u64) -> Result<Vec<Check>> {
    const E: f64 = 1e-3;
    let mut checks = vec![];
    for (t, gain, tag) in [
        (100.0, 100.0, "100s-x100"),
        (100.0, 0.1, "100s-x0.1"),
        (1e-6, 0.1, "1us-x0.1"),
        (1e-6, 100.0, "1us-x100"),
    ] {
        let c = sensor(cfg, t, gain);
        let si = frame(&c, E, seed)?;
        let n = si.dv.len() as f64;
        let white = c.white_level_dv() as f32;
        let at = format!(
            "{} pixels at {t} s, analog gain {gain}, {E} W/(m²·nm)",
            si.dv.len()
        );
        checks.push(Check::count(
            &format!("{tag}/nonfinite"),
            super::nonfinite(&si.dv) + super::nonfinite(&si.electrons),
            0,
            &at,
        ));
        let dv_per_e = c.conversion_gain_dv_per_e();
        let sigma = dark_variance_dv2(&c, t).sqrt();
        let rates = flat_rate_e_per_s(&c, &Spectrum::constant("flat", E), &grid());
        let w = window(&c);
        // mean signal electrons over the window's CFA pixels
        let mut sig = 0.0;
        for y in 0..w.h {
            for x in 0..w.w {
                sig += rates[c.cfa.channel_at(w.x + x, w.y + y)] * t;
            }
        }
        sig /= n;
        let dark = dark_signal_dv(&c, t);
        let (m, sd) = mean_sd(&si.dv);
        match tag {
            "100s-x100" => checks.push(Check::new(
                &format!("{tag}/fraction_at_adc_max"),
                fraction(&si.dv, |d| d == white),
                1.0,
                0.0,
                &at,
            )),
            "100s-x0.1" => {
                let fw = c.full_well_e() as f32;
                checks.push(Check::new(
                    &format!("{tag}/fraction_at_full_well"),
                    fraction(&si.electrons, |e| e >= fw),
                    1.0,
                    0.0,
                    &at,
                ));
                let m0 = c.black_level_dv + c.full_well_e() * dv_per_e;
                checks.push(
                    Check::new(
                        &format!("{tag}/mean_ratio"),
                        m / m0,
                        1.0,
                        (0.5 + 5.0 * sigma / n.sqrt()) / m0,
                        &at,
                    )
                    .with_stderr(sd / n.sqrt() / m0),
                );
            }
            "1us-x0.1" => {
                let m0 = c.black_level_dv + sig * dv_per_e + dark;
                let s_tot = (sigma * sigma + sig * dv_per_e * dv_per_e).sqrt();
                checks.push(
                    Check::new(
                        &format!("{tag}/mean_ratio"),
                        m / m0,
                        1.0,
                        (0.5 + 5.0 * s_tot / n.sqrt()) / m0,
                        &at,
                    )
                    .with_stderr(sd / n.sqrt() / m0),
                );
                checks.push(Check::new(
                    &format!("{tag}/fraction_clipped"),
                    fraction(&si.dv, |d| d <= 0.0 || d >= white),
                    0.0,
                    0.0,
                    &at,
                ));
            }
            _ => {
                let mu = c.black_level_dv + sig * dv_per_e + dark;
                let s_tot = (sigma * sigma + sig * dv_per_e * dv_per_e).sqrt();
                let p = phi((0.5 - mu) / s_tot);
                let got = fraction(&si.dv, |d| d <= 0.0);
                checks.push(
                    Check::new(
                        &format!("{tag}/fraction_at_zero"),
                        got,
                        p,
                        5.0 * (p * (1.0 - p) / n).sqrt() + 1e-3,
                        &format!("{at}, σ {s_tot:.2} DV"),
                    )
                    .with_stderr((p * (1.0 - p) / n).sqrt()),
                );
            }
        }
    }
    Ok(checks)
}

#[cfg(test)]
mod tests {
    #[test]
    fn phi_matches_known_values() {
        assert!((super::phi(0.0) - 0.5).abs() < 1e-7);
        assert!((super::phi(-1.0) - 0.158_655_25).abs() < 2e-7);
        assert!((super::phi(1.959_964) - 0.975).abs() < 2e-7);
    }
}
