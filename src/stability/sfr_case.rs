//! Stability case of the slanted-edge SFR ([`crate::measure::sfr::sfr`]):
//! a region too noisy for ISO 12233 must be refused (an error naming the
//! noise), not turned into an MTF50; the same edge with little noise must
//! still be measured, at the closed-form MTF50 of an ideal edge.

use super::Check;
use crate::measure::plane::Plane;
use crate::measure::sfr::{SfrOptions, sfr};
use crate::sensor::rng::PixelRng;
use crate::{Error, Result};
use std::f64::consts::PI;

const SIDE: usize = 64;
const ANGLE_DEG: f64 = 5.0;
const DARK: f64 = 0.1;
const BRIGHT: f64 = 0.9;
/// Sub-samples per pixel side for the pixel aperture.
const SUB: usize = 16;

/// A sharp slanted edge (5° from vertical through the centre) integrated over
/// square pixels of fill 1, plus white noise of `sigma` (in units of the
/// levels, seeded).
fn edge(sigma: f64, seed: u64) -> Result<Plane> {
    let t = ANGLE_DEG.to_radians().tan();
    let c = SIDE as f64 / 2.0;
    let key = PixelRng::stream_key(seed, 0x5AB1);
    let mut v = Vec::with_capacity(SIDE * SIDE);
    for y in 0..SIDE {
        for x in 0..SIDE {
            let mut bright = 0usize;
            for j in 0..SUB {
                for i in 0..SUB {
                    let px = x as f64 + (i as f64 + 0.5) / SUB as f64;
                    let py = y as f64 + (j as f64 + 0.5) / SUB as f64;
                    if px - c > (py - c) * t {
                        bright += 1;
                    }
                }
            }
            let f = bright as f64 / (SUB * SUB) as f64;
            let n = PixelRng::keyed(key, (y * SIDE + x) as u64).normal();
            v.push(DARK + (BRIGHT - DARK) * f + sigma * n);
        }
    }
    Plane::new(SIDE, SIDE, v)
}

fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-12 {
        1.0
    } else {
        (PI * x).sin() / (PI * x)
    }
}

/// MTF of the ideal edge as the method measures it (see the sfr module):
/// the pixel aperture projected on the edge normal, sinc(f cos θ)·sinc(f sin θ),
/// times the ¼-px binning box sinc(f/4). (The edge's aperture is sub-sampled
/// at SUB points per pixel side; that differs from a continuous box by
/// < 10⁻³ below 1 cy/px, inside the case's tolerance.)
fn mtf(f: f64) -> f64 {
    let th = ANGLE_DEG.to_radians();
    sinc(f * th.cos()) * sinc(f * th.sin()) * sinc(f / 4.0)
}

/// The frequency where [`mtf`] = ½ (bisection; it falls monotonically on 0…1).
fn mtf50() -> f64 {
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let m = 0.5 * (lo + hi);
        if mtf(m) > 0.5 { lo = m } else { hi = m }
    }
    0.5 * (lo + hi)
}

/// `sfr-noisy`: the 64×64 slanted edge with noise σ = 0.5 of its contrast
/// (0.8) must be refused with an error that names the noise; with σ = 10⁻³
/// it must give an MTF50 at the ideal edge's closed form.
///
/// Tolerance of the clean MTF50: 1 % relative + 5 jackknife standard
/// errors. The method's own deviation from the closed form on noise-free
/// edges is < 1 % (tests/measure_sfr.rs, Gaussian-blurred edges); a
/// 16-point sub-sampled aperture differs from a continuous one by
/// 1 − sinc(f/16) ≈ 2·10⁻⁴ at f ≈ 0.6 cy/px.
pub fn noisy_roi(seed: u64) -> Result<Vec<Check>> {
    let opts = SfrOptions::default();
    let noisy = edge(0.5 * (BRIGHT - DARK), seed)?;
    let (refused, why) = match sfr(&noisy, &opts) {
        Err(e) => {
            let m = e.to_string();
            (m.contains("noise") as usize, format!("refused: {m}"))
        }
        Ok(r) => (
            0,
            format!(
                "measured an MTF50 of {:?} cy/px on noise σ = 0.4",
                r.mtf50_cy_per_px
            ),
        ),
    };
    let mut checks = vec![Check::new(
        "noisy/refused_for_noise",
        refused as f64,
        1.0,
        0.0,
        &format!("64×64 edge, contrast 0.8, noise σ 0.4: {why}"),
    )];
    let clean = edge(1e-3, seed)?;
    let r = sfr(&clean, &opts)
        .map_err(|e| Error::invalid(format!("sfr-noisy: the clean edge was refused: {e}")))?;
    let f50 = mtf50();
    let m50 = r.mtf50_cy_per_px.unwrap_or(f64::NAN);
    checks.push(
        Check::new(
            "clean/mtf50_ratio",
            m50 / f50,
            1.0,
            0.01 + 5.0 * r.mtf50_stderr / f50,
            &format!("64×64 edge, noise σ 0.001, closed-form MTF50 {f50:.5} cy/px"),
        )
        .with_stderr(r.mtf50_stderr / f50),
    );
    Ok(checks)
}
