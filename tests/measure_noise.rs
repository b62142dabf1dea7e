//! Appendix IV uniform-region selection on a synthetic Bayer image whose
//! uniform, non-uniform and dead-pixel areas are known.

use camsim::image::CfaPattern;
use camsim::measure::noise::{NoiseOptions, Verdict, measure};
use camsim::measure::plane::Plane;
use camsim::measure::stats::SplitMix64;

const P: usize = 40; // patch size, px
const N: usize = 6; // patches per side
const CG: f64 = 0.17; // DV per electron

#[derive(Clone, Copy, PartialEq)]
enum Kind {
    Uniform(f64),
    RampX(f64),
    Bump(f64),
}

fn kind(px: usize, py: usize) -> Kind {
    let level = 600.0 * 1.18f64.powi((py * N + px) as i32 % 11); // neighbours differ ≥ 18 %
    match (px + 2 * py) % 4 {
        0 | 1 => Kind::Uniform(level),
        2 => Kind::RampX(level),
        _ => Kind::Bump(level),
    }
}

fn electrons(x: usize, y: usize) -> f64 {
    let (u, v) = ((x % P) as f64 / P as f64, (y % P) as f64 / P as f64);
    match kind(x / P, y / P) {
        Kind::Uniform(l) => l,
        // 100 % across the patch: 25 % across a 10-px region.
        Kind::RampX(l) => l * (0.5 + u),
        // Quadratic bowl, 60 % deep at the patch corners.
        Kind::Bump(l) => l * (1.0 - 1.2 * ((u - 0.5).powi(2) + (v - 0.5).powi(2))),
    }
}

fn dead(x: usize, y: usize) -> bool {
    // Dead green pixels (x + y odd in RGGB) inside some uniform patches.
    (x + y) % 2 == 1
        && x % 23 == 7
        && y % 29 == 12
        && matches!(kind(x / P, y / P), Kind::Uniform(_))
}

#[test]
fn appendix_iv_selection_agrees_with_truth() {
    let w = P * N;
    let cfa = CfaPattern::bayer("rggb").unwrap();
    let mut rng = SplitMix64(42);
    let mut data = Vec::with_capacity(w * w);
    for y in 0..w {
        for x in 0..w {
            let e = electrons(x, y);
            // Photon noise: Gaussian with variance = mean (Poisson at ≥ 250 e⁻), DV quantised.
            let v = if dead(x, y) {
                0.0
            } else {
                ((e + e.sqrt() * rng.gauss()) * CG).round()
            };
            data.push(v);
        }
    }
    let mut plane = Plane::new(w, w, data).unwrap();
    plane.channel = (0..w)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| cfa.channel_at(x as u32, y as u32) as u8)
        .collect();
    plane.channel_names = cfa.channels.clone();
    let opts = NoiseOptions {
        regions: 1500,
        conversion_gain_dv_per_e: CG,
        seed: 7,
        ..Default::default()
    };
    let (m, regions) = measure(&plane, &opts, "noise").unwrap();
    let (mut uni, mut uni_acc, mut nonuni, mut nonuni_acc, mut deadn, mut dead_out) =
        (0, 0, 0, 0, 0, 0);
    for r in &regions {
        let (x0, y0) = (r.rect.x as usize, r.rect.y as usize);
        let one_patch = x0 / P == (x0 + 9) / P && y0 / P == (y0 + 9) / P;
        let has_dead = (y0..y0 + 10).any(|y| (x0..x0 + 10).any(|x| dead(x, y)));
        let is_uniform = one_patch && matches!(kind(x0 / P, y0 / P), Kind::Uniform(_));
        if has_dead {
            deadn += 1;
            dead_out += (r.verdict == Verdict::Outlier) as usize;
        } else if is_uniform {
            uni += 1;
            uni_acc += (r.verdict == Verdict::Accepted) as usize;
        } else {
            nonuni += 1;
            nonuni_acc += (r.verdict == Verdict::Accepted) as usize;
        }
    }
    let fu = uni_acc as f64 / uni as f64;
    let fn_ = nonuni_acc as f64 / nonuni as f64;
    println!(
        "uniform {uni_acc}/{uni} accepted ({fu:.3}); non-uniform {nonuni_acc}/{nonuni} accepted ({fn_:.4}); dead {dead_out}/{deadn} rejected as outliers"
    );
    assert!(
        deadn > 20 && uni > 200 && nonuni > 200,
        "test geometry gives too few regions of a kind"
    );
    // Every region with a dead pixel is rejected by the 3σ test (0 e⁻ is ≥ 24σ below the median).
    assert_eq!(dead_out, deadn);
    // Uniform regions: false rejections are expected from the 3σ test on 50 pixels
    // (1 − 0.9973⁵⁰ ≈ 13 %) and from hold-out noise in the 2 % rule (~5–10 %).
    assert!(fu > 0.7, "too many uniform regions rejected: {fu}");
    // Non-uniform regions (25 % ramps, 60 % bowls, patch boundaries ≥ 18 % steps):
    // the signal is ≥ 2× the photon noise, so almost none may pass.
    assert!(fn_ < 0.02, "non-uniform regions accepted: {fn_}");
    // The accepted regions are photon-noise limited: var = CG·mean (+ 1/12 DV² quantisation).
    let slope = m
        .figures
        .iter()
        .find(|f| f.quantity == "variance_slope")
        .unwrap();
    println!(
        "variance slope {} ± {} DV/e- (true {CG})",
        slope.value, slope.stderr
    );
    assert!(
        (slope.value - CG).abs() < 4.0 * slope.stderr + 0.01,
        "slope {} ± {}",
        slope.value,
        slope.stderr
    );
}
