//! Error-driven sampling: render until every figure reaches its target
//! standard error (`render target-stderr=…`, `target "MEASUREMENT" stderr=…`),
//! or a budget is spent (`max-s`, `max-spp`).
//!
//! The render goes in rounds. Round 0 is the `render` node's `spp` with its
//! seed (so a variant whose first round already meets its targets gives the
//! same numbers as a plain render); round k ≥ 1 adds samples with seed
//! [`round_seed`]`(seed, k)`, independent of the earlier rounds. After each
//! round the optical images so far are combined
//! ([`crate::optical_image::OpticalImage::combine`]: the spp-weighted mean
//! and its standard error), the sensor and the measurements run again, and
//! every figure is checked against its target.
//!
//! How many samples the next round adds is decided from the standard errors
//! only ([`next_total`]), so for a fixed seed and thread count the rounds, and
//! the results, are the same on every run — unless the time budget stops the
//! run, which the record says (`stopped: "time-budget"`; such a result depends
//! on the machine's speed). The stopping reasons:
//! - `target`: every figure meets its target;
//! - `spp-budget`: `max-spp` samples per pixel are spent;
//! - `time-budget`: the next round would end after `max-s` seconds;
//! - `stalled`: two rounds in a row that at least 1.5× the samples each
//!   reduced the worst figure's stderr/target by less than a third of the
//!   1/√n fall a Monte Carlo error would show (a floor that samples do not
//!   lower, e.g. the sensor's own noise). Two rounds, because an 8-batch
//!   standard error is itself uncertain by ≈ 25 %: one round would stall
//!   falsely about one time in five.
//!
//! Figures that do not depend on the render (sensor-only measurements,
//! `convergence`, which renders its own runs, `compare` of captures) are not
//! targeted.

use super::spec::{RenderSettings, StderrTarget};
use crate::figure::Figure;
use serde::{Deserialize, Serialize};

/// Why the rounds stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Stop {
    Target,
    SppBudget,
    TimeBudget,
    Stalled,
}

impl Stop {
    /// Did a budget (or a floor) stop the run before every target was met?
    pub fn budget_reached(self) -> bool {
        self != Stop::Target
    }
    pub fn as_str(self) -> &'static str {
        match self {
            Stop::Target => "target",
            Stop::SppBudget => "spp-budget",
            Stop::TimeBudget => "time-budget",
            Stop::Stalled => "stalled",
        }
    }
}

/// One targeted figure at the end of the rounds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FigureRecord {
    pub measurement: String,
    pub quantity: String,
    pub unit: String,
    pub value: f64,
    pub stderr: f64,
    /// The target as written (`0.5` or `1%`).
    pub target: String,
    /// The largest standard error that meets it, in the figure's unit.
    pub allowed: f64,
    pub met: bool,
}

/// What error-driven sampling did for one variant (in the manifest).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SamplingRecord {
    /// Samples per pixel reached (all rounds).
    pub spp: u64,
    pub rounds: u32,
    /// Render time of all rounds, s.
    pub render_s: f64,
    /// Wall time of all rounds (render, sensor and measurements), s.
    pub wall_s: f64,
    pub stopped: Stop,
    pub budget_reached: bool,
    pub figures: Vec<FigureRecord>,
}

/// Do the figures of measurement `name` depend on the render? Rendered and
/// sensor-image measurements do; `compare`/`compare-curve` do when one of
/// the measurements they compare does; `convergence` (its own renders),
/// sensor-only measurements and measurements of captures do not.
pub fn depends_on_render(spec: &super::spec::ResolvedExperiment, name: &str) -> bool {
    fn go(spec: &super::spec::ResolvedExperiment, name: &str, depth: usize) -> bool {
        let Some(m) = spec.measures.iter().find(|m| m.name == name) else {
            return false;
        };
        match m.kind.as_str() {
            "convergence" => false,
            "compare" | "compare-curve" if m.params.get("input").is_none() => {
                depth < 8 && m.of.iter().any(|o| go(spec, o, depth + 1))
            }
            _ => {
                let n = super::measured::needs_of(m);
                n.optical_image || n.sensor_image
            }
        }
    }
    go(spec, name, 0)
}

/// Seed of round `k` (round 0 keeps the variant's seed).
pub fn round_seed(seed: u64, k: u32) -> u64 {
    if k == 0 {
        return seed;
    }
    // SplitMix64 of (seed, k): rounds draw independent sample streams.
    let mut z = seed ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x524F_554E_4400_0000;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The target of figure (`measurement`, `quantity`): a `target` child naming
/// the quantity, else one naming the measurement, else `target-stderr`.
pub fn target_of(r: &RenderSettings, measurement: &str, quantity: &str) -> Option<StderrTarget> {
    let specific = r
        .targets
        .iter()
        .find(|t| t.quantity.is_some() && t.applies(measurement, quantity));
    let whole = r
        .targets
        .iter()
        .find(|t| t.quantity.is_none() && t.applies(measurement, quantity));
    // A measurement with a quantity-specific target leaves its other figures untargeted.
    let measurement_has_specific = r
        .targets
        .iter()
        .any(|t| t.measurement == measurement && t.quantity.is_some());
    match (specific, whole) {
        (Some(t), _) | (None, Some(t)) => Some(t.stderr),
        (None, None) if measurement_has_specific => None,
        (None, None) => r.target_stderr,
    }
}

/// Each targeted figure against its target. `targeted(measurement)` says
/// whether a measurement's figures depend on the render.
pub fn assess(
    r: &RenderSettings,
    figures: &[Figure],
    targeted: impl Fn(&str) -> bool,
) -> Vec<FigureRecord> {
    figures
        .iter()
        .filter(|f| targeted(&f.measurement))
        .filter_map(|f| {
            let t = target_of(r, &f.measurement, &f.quantity)?;
            let allowed = t.allowed(f.value);
            Some(FigureRecord {
                measurement: f.measurement.clone(),
                quantity: f.quantity.clone(),
                unit: f.unit.clone(),
                value: f.value,
                stderr: f.stderr,
                target: t.to_string(),
                allowed,
                met: f.stderr <= allowed,
            })
        })
        .collect()
}

/// The worst figure's stderr / allowed (∞ when a figure with a standard
/// error is allowed none); 0 when all are met exactly.
pub fn worst_ratio(recs: &[FigureRecord]) -> f64 {
    recs.iter()
        .filter(|r| !r.met)
        .map(|r| {
            if r.allowed > 0.0 {
                r.stderr / r.allowed
            } else {
                f64::INFINITY
            }
        })
        .fold(0.0, f64::max)
}

/// The total samples per pixel after the next round, from `n` now: enough
/// for the worst figure at 1/√n (with 10 % to spare), at least n + max(8,
/// n/2) (every round has ≥ 8 samples, one per standard-error batch), at most
/// 4n, and within `max_spp`. Depends on the standard errors only.
pub fn next_total(n: u64, worst: f64, max_spp: Option<u64>) -> u64 {
    let lo = n + (n / 2).max(8);
    let hi = n.saturating_mul(4).max(lo);
    let want = if worst.is_finite() {
        (n as f64 * worst * worst * 1.1).ceil().min(hi as f64) as u64
    } else {
        hi
    };
    let t = want.clamp(lo, hi);
    max_spp.map_or(t, |m| t.min(m))
}

/// Has the worst ratio stopped falling? `prev` = (n, worst) of the round
/// before, `now` = this round's. See the module docs.
pub fn stalled_round(prev: (u64, f64), now: (u64, f64)) -> bool {
    let g = now.0 as f64 / prev.0 as f64;
    if g < 1.5 || !(prev.1.is_finite() && now.1.is_finite()) || prev.1 <= 0.0 {
        return false;
    }
    let expected_fall = 1.0 - 1.0 / g.sqrt();
    now.1 / prev.1 > 1.0 - expected_fall / 3.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::spec::FigureTarget;

    fn fig(m: &str, q: &str, v: f64, se: f64) -> Figure {
        Figure::new(m, q, "1", v, se)
    }

    #[test]
    fn targets_resolve_specific_before_whole_before_experiment() {
        let r = RenderSettings {
            target_stderr: Some(StderrTarget::Relative(0.01)),
            targets: vec![
                FigureTarget {
                    measurement: "sfr".into(),
                    quantity: Some("mtf50".into()),
                    stderr: StderrTarget::Absolute(0.5),
                    span: Default::default(),
                },
                FigureTarget {
                    measurement: "mcc".into(),
                    quantity: None,
                    stderr: StderrTarget::Absolute(2.0),
                    span: Default::default(),
                },
            ],
            ..Default::default()
        };
        assert_eq!(
            target_of(&r, "sfr", "edge/mtf50"),
            Some(StderrTarget::Absolute(0.5))
        );
        // The sfr's other figures are left alone (a specific target was given).
        assert_eq!(target_of(&r, "sfr", "mtf@0.25"), None);
        assert_eq!(
            target_of(&r, "mcc", "patch01/g_mean"),
            Some(StderrTarget::Absolute(2.0))
        );
        assert_eq!(
            target_of(&r, "ri", "max"),
            Some(StderrTarget::Relative(0.01))
        );
        let recs = assess(
            &r,
            &[
                fig("ri", "max", 2.0, 0.01),
                fig("ri", "min", 1.0, 0.02),
                fig("conv", "x", 1.0, 9.0),
            ],
            |m| m != "conv",
        );
        assert_eq!(recs.len(), 2);
        assert!(recs[0].met && !recs[1].met);
        assert_eq!(recs[1].target, "1%");
        assert!((worst_ratio(&recs) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn next_round_sizes_follow_the_inverse_square_law_within_bounds() {
        // worst ratio 1.5 → 1.5²·1.1 = 2.475× the samples.
        assert_eq!(next_total(100, 1.5, None), 248);
        // at least n + n/2, at most 4n, within the budget
        assert_eq!(next_total(100, 1.01, None), 150);
        assert_eq!(next_total(100, 10.0, None), 400);
        assert_eq!(next_total(100, f64::INFINITY, Some(300)), 300);
        assert_eq!(next_total(4, 1.2, None), 12);
    }

    #[test]
    fn a_floor_stalls_and_monte_carlo_error_does_not() {
        // 1/√n fall over 4× samples: 2 → 1.
        assert!(!stalled_round((100, 2.0), (400, 1.0)));
        // No fall at all over 4×: a floor.
        assert!(stalled_round((100, 2.0), (400, 1.95)));
        // Too small a step to judge.
        assert!(!stalled_round((100, 2.0), (120, 2.0)));
    }

    #[test]
    fn round_seeds_are_distinct_and_round_zero_keeps_the_seed() {
        assert_eq!(round_seed(7, 0), 7);
        let s: std::collections::BTreeSet<u64> = (0..100).map(|k| round_seed(7, k)).collect();
        assert_eq!(s.len(), 100);
        assert_ne!(round_seed(7, 1), round_seed(8, 1));
    }
}
