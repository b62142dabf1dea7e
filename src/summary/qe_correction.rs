//! `summary "qe-correction"`: the paper's QE correction matrix (Eq. 2–3)
//! fitted across variants. The patch means of a "measured" set of variants
//! (a capture, or a simulation standing in for one) are paired with the
//! "nominal" predictions of the variants that differ from them only in
//! `axis` (e.g. `tag.qe` = "corrected" / "nominal"; every other swept value —
//! illuminant, position — must match), and the non-negative n×n matrix M with
//! measured ≈ nominal · M is fitted by NNLS (`sensor::nnls`), one column per
//! output channel. Row r of M is the nominal channel r, column c the
//! corrected channel c (as `qe-matrix` in a sensor file).
//!
//! Figures (unit 1 unless said): `M_<r>_<c>` for every entry with its
//! jackknife standard error (leave one patch-pair out; k pairs:
//! se² = (k−1)/k · Σ (M₋ᵢ − M̄)²), `fit_error_percent` =
//! 100·‖nominal·M − measured‖/‖measured‖ (Frobenius, over the fitted pairs)
//! and `nominal_error_percent` the same with M = I (before correction), with
//! jackknife standard errors, and `pairs` (patch pairs fitted). Curves:
//! `scatter-before/<ch>` (nominal vs measured, Fig 3a), `scatter-after/<ch>`
//! (nominal·M vs measured, Fig 3b) and, with `sensor=`, the sensor's QE
//! (QE × IR cut) `qe-nominal/<ch>` and `qe-corrected/<ch>` = nominal·M
//! (Fig 3c–d), 400–700 nm in 5 nm steps.

use super::pairing::{patch_channel, points_of, split_by_axis};
use crate::figure::Figure;
use crate::measure::{Curve, Measured};
use crate::params::{Kind, ParamDict, ParamError, ParamSpec};
use crate::report::results::ResultRow;
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Options of `summary "qe-correction"`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct QeCorrectionOptions {
    pub axis: Option<String>,
    pub measured: Option<String>,
    pub nominal: Option<String>,
    /// 1-based patch numbers left out of the fit.
    pub exclude: Vec<usize>,
    /// The nominal sensor file (for the QE curves), resolved.
    pub sensor: Option<PathBuf>,
    /// Shown with the summary in the report.
    pub note: Option<String>,
}

/// The properties of `summary "qe-correction"`.
pub static SCHEMA: crate::params::Schema = crate::params::Schema {
    node: "summary \"qe-correction\"",
    params: &[
        super::name_param(),
        super::of_param(),
        super::note_param(),
        super::axis_param(
            "the swept path whose values tell the measured variants from the nominal ones, e.g. \"tag.qe\" (required); variants pair when every other swept value agrees",
        ),
        ParamSpec::new(
            "measured",
            Kind::Text,
            "",
            "the axis value of the measured (or standing-in) variants (required)",
            "\"m-probe\"",
        ),
        ParamSpec::new(
            "nominal",
            Kind::Text,
            "",
            "the axis value of the nominal-QE predictions (required)",
            "\"n-probe\"",
        ),
        ParamSpec::new(
            "exclude-patch-number",
            Kind::Numbers,
            "none",
            "patch numbers (1-based) left out of the fit; the paper left out the fluorescent patches (3 6 10 11 14 19)",
            "(3 6 10)",
        ),
        ParamSpec::new(
            "sensor",
            Kind::File,
            "none",
            "the nominal sensor file: its QE × IR cut and that times M are drawn as the before/after QE curves",
            "\"sensors/imx363-nominal.kdl\"",
        ),
    ],
};

/// Find `written` in `dir` or one of its parents (as experiment files do).
pub fn find_file(written: &str, dir: &Path) -> Option<PathBuf> {
    let p = Path::new(written);
    if p.is_absolute() {
        return p.exists().then(|| p.to_path_buf());
    }
    dir.ancestors().map(|d| d.join(p)).find(|c| c.exists())
}

/// Read `summary "qe-correction"` (see [`SCHEMA`]).
pub fn from_params(
    d: &ParamDict,
    base_dir: &Path,
) -> std::result::Result<QeCorrectionOptions, ParamError> {
    let nonempty = |k: &str| -> std::result::Result<Option<String>, ParamError> {
        match d.str(k)? {
            Some("") => Err(ParamError::value(k, format!("'{k}' must not be empty"))),
            o => Ok(o.map(str::to_string)),
        }
    };
    let mut o = QeCorrectionOptions {
        axis: nonempty("axis")?,
        measured: nonempty("measured")?,
        nominal: nonempty("nominal")?,
        ..Default::default()
    };
    o.note = d.str("note")?.map(str::to_string);
    if let Some(v) = d.f64s("exclude-patch-number")? {
        for x in v {
            if !(x >= 1.0 && x.fract() == 0.0 && x <= 1e6) {
                return Err(ParamError::value(
                    "exclude-patch-number",
                    format!("'exclude-patch-number': {x} is not a patch number (1, 2, …)"),
                ));
            }
            o.exclude.push(x as usize);
        }
    }
    if let Some(w) = d.str("sensor")? {
        let p = find_file(w, base_dir).ok_or_else(|| {
            ParamError::value(
                "sensor",
                format!(
                    "sensor file '{w}' not found (looked in {} and its parents)",
                    base_dir.display()
                ),
            )
        })?;
        crate::sensor::sensor_config(Some(&p), &Default::default())
            .map_err(|e| ParamError::value("sensor", format!("sensor '{w}': {}", e.message)))?;
        o.sensor = Some(p);
    }
    if let (Some(m), Some(n)) = (&o.measured, &o.nominal)
        && m == n
    {
        return Err(ParamError::value(
            "nominal",
            format!("'measured' and 'nominal' are both \"{m}\"; they name two values of the axis"),
        ));
    }
    Ok(o)
}

impl QeCorrectionOptions {
    /// The properties a run cannot do without.
    pub fn require_complete(&self) -> std::result::Result<(), ParamError> {
        if self.axis.is_none() || self.measured.is_none() || self.nominal.is_none() {
            return Err(ParamError::section(
                "qe-correction needs axis=\"…\", measured=\"…\" and nominal=\"…\"",
            )
            .with_help("e.g. axis=\"tag.qe\" measured=\"corrected\" nominal=\"nominal\""));
        }
        Ok(())
    }
}

/// Channel order: r, g, b first (in that order), then others by name.
pub fn channel_order(mut chans: Vec<String>) -> Vec<String> {
    chans.sort_by_key(|c| {
        (
            match c.as_str() {
                "r" => 0,
                "g" => 1,
                "b" => 2,
                _ => 3,
            },
            c.clone(),
        )
    });
    chans.dedup();
    chans
}

/// 100·‖P·M − B‖/‖B‖ over rows.
fn error_percent(pred: &[Vec<f64>], m: &[Vec<f64>], meas: &[Vec<f64>]) -> f64 {
    let n = m.len();
    let (mut num, mut den) = (0.0, 0.0);
    for (p, b) in pred.iter().zip(meas) {
        for c in 0..n {
            let f: f64 = (0..n).map(|r| p[r] * m[r][c]).sum();
            num += (f - b[c]).powi(2);
            den += b[c] * b[c];
        }
    }
    100.0 * (num / den.max(f64::MIN_POSITIVE)).sqrt()
}

fn identity(n: usize) -> Vec<Vec<f64>> {
    (0..n)
        .map(|r| (0..n).map(|c| if r == c { 1.0 } else { 0.0 }).collect())
        .collect()
}

/// Jackknife standard error of a statistic computed leave-one-out.
fn jackknife_se(loo: &[f64]) -> f64 {
    let k = loo.len() as f64;
    if loo.len() < 2 {
        return 0.0;
    }
    let mean = loo.iter().sum::<f64>() / k;
    ((k - 1.0) / k * loo.iter().map(|x| (x - mean).powi(2)).sum::<f64>()).sqrt()
}

/// Fit M on the measurement's rows (see the module docs).
pub fn run(
    name: &str,
    o: &QeCorrectionOptions,
    axes: &[String],
    rows: &[&ResultRow],
) -> Result<Measured> {
    o.require_complete()
        .map_err(|e| Error::invalid(format!("summary '{name}': {}", e.message)))?;
    let (axis, mv, nv) = (
        o.axis.as_deref().unwrap_or_default(),
        o.measured.as_deref().unwrap_or_default(),
        o.nominal.as_deref().unwrap_or_default(),
    );
    let split = split_by_axis(name, axis, axes, rows)?;
    let meas = points_of(name, axis, &split, mv)?;
    let nom = points_of(name, axis, &split, nv)?;
    // (group, patch) → channel → value
    let mut by_patch: BTreeMap<(String, usize), BTreeMap<String, (f64, String)>> = BTreeMap::new();
    let mut chans = vec![];
    for ((g, q), p) in meas {
        let Some((patch, ch)) = patch_channel(q) else {
            continue;
        };
        if o.exclude.contains(&patch) {
            continue;
        }
        by_patch
            .entry((g.clone(), patch))
            .or_default()
            .insert(ch.clone(), (p.value, q.clone()));
        chans.push(ch);
    }
    let chans = channel_order(chans);
    if by_patch.is_empty() {
        return Err(Error::invalid(format!(
            "summary '{name}': measurement rows hold no patch means (quantities patchNN/<channel>_mean)"
        )));
    }
    let n = chans.len();
    let (mut pred, mut obs) = (vec![], vec![]);
    for ((g, patch), vals) in &by_patch {
        let mut prow = vec![];
        let mut orow = vec![];
        for ch in &chans {
            let b = vals.get(ch);
            let a = b.and_then(|(_, q)| nom.get(&(g.clone(), q.clone())));
            let (Some((b, _)), Some(a)) = (b, a) else {
                let which = if vals.contains_key(ch) { nv } else { mv };
                return Err(Error::invalid(format!(
                    "summary '{name}': patch {patch} channel {ch} ({g}) has no value with {axis}={which}"
                )));
            };
            prow.push(a.value);
            orow.push(*b);
        }
        pred.push(prow);
        obs.push(orow);
    }
    let k = pred.len();
    if k < n {
        return Err(Error::invalid(format!(
            "summary '{name}': {k} patch pairs cannot determine a {n}×{n} matrix"
        )));
    }
    let fit = |p: &[Vec<f64>], b: &[Vec<f64>]| {
        crate::sensor::nnls::qe_correction_matrix(p, b)
            .map(|r| r.0)
            .map_err(|e| Error::invalid(format!("summary '{name}': {e}")))
    };
    let m = fit(&pred, &obs)?;
    let err_after = error_percent(&pred, &m, &obs);
    let err_before = error_percent(&pred, &identity(n), &obs);
    // Jackknife: leave one patch pair out.
    let mut loo_m = vec![vec![vec![]; n]; n];
    let (mut loo_after, mut loo_before) = (vec![], vec![]);
    if k > n {
        for i in 0..k {
            let p: Vec<Vec<f64>> = (0..k)
                .filter(|&j| j != i)
                .map(|j| pred[j].clone())
                .collect();
            let b: Vec<Vec<f64>> = (0..k).filter(|&j| j != i).map(|j| obs[j].clone()).collect();
            let mi = fit(&p, &b)?;
            for r in 0..n {
                for c in 0..n {
                    loo_m[r][c].push(mi[r][c]);
                }
            }
            loo_after.push(error_percent(&p, &mi, &b));
            loo_before.push(error_percent(&p, &identity(n), &b));
        }
    }
    let mut out = Measured::default();
    for r in 0..n {
        for c in 0..n {
            out.figures.push(Figure::new(
                name,
                format!("M_{}_{}", chans[r], chans[c]),
                "1",
                m[r][c],
                jackknife_se(&loo_m[r][c]),
            ));
        }
    }
    out.figures.push(Figure::new(
        name,
        "fit_error_percent",
        "%",
        err_after,
        jackknife_se(&loo_after),
    ));
    out.figures.push(Figure::new(
        name,
        "nominal_error_percent",
        "%",
        err_before,
        jackknife_se(&loo_before),
    ));
    out.figures
        .push(Figure::new(name, "pairs", "1", k as f64, 0.0));
    for (c, ch) in chans.iter().enumerate() {
        let after: Vec<f64> = pred
            .iter()
            .map(|p| (0..n).map(|r| p[r] * m[r][c]).sum())
            .collect();
        out.curves.push(Curve::new(
            &format!("scatter-before/{ch}"),
            ("nominal", "DV"),
            ("measured", "DV"),
            pred.iter().map(|p| p[c]).collect(),
            obs.iter().map(|b| b[c]).collect(),
            vec![],
        ));
        out.curves.push(Curve::new(
            &format!("scatter-after/{ch}"),
            ("nominal·M", "DV"),
            ("measured", "DV"),
            after,
            obs.iter().map(|b| b[c]).collect(),
            vec![],
        ));
    }
    if let Some(path) = &o.sensor {
        let cfg = crate::sensor::sensor_config(Some(path), &Default::default())
            .map_err(|e| Error::invalid(format!("summary '{name}': sensor: {}", e.message)))?;
        let names = &cfg.cfa.channels;
        let lambdas: Vec<f64> = (0..=60).map(|i| 400.0 + 5.0 * i as f64).collect();
        let qe: Vec<Vec<f64>> = lambdas.iter().map(|&l| cfg.effective_qe(l)).collect();
        // Sensor channel index of each fitted channel.
        let idx: Vec<usize> = chans
            .iter()
            .map(|ch| {
                names.iter().position(|s| s == ch).ok_or_else(|| {
                    Error::invalid(format!(
                        "summary '{name}': the sensor has channels {names:?}, no '{ch}'"
                    ))
                })
            })
            .collect::<Result<_>>()?;
        for (c, ch) in chans.iter().enumerate() {
            out.curves.push(Curve::new(
                &format!("qe-nominal/{ch}"),
                ("wavelength", "nm"),
                ("QE", "1"),
                lambdas.clone(),
                qe.iter().map(|q| q[idx[c]]).collect(),
                vec![],
            ));
        }
        for (c, ch) in chans.iter().enumerate() {
            out.curves.push(Curve::new(
                &format!("qe-corrected/{ch}"),
                ("wavelength", "nm"),
                ("QE", "1"),
                lambdas.clone(),
                qe.iter()
                    .map(|q| (0..n).map(|r| q[idx[r]] * m[r][c]).sum())
                    .collect(),
                vec![],
            ));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows of `measure "mcc"` for patches 1…24 under 3 lights, nominal values
    /// from a fixed pseudo-random sequence and measured = nominal·M (+ noise).
    fn rows(m: &[[f64; 3]; 3], noise: f64) -> Vec<ResultRow> {
        let mut out = vec![];
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let ch = ["r", "g", "b"];
        for light in ["a", "cwf", "day"] {
            for patch in 1..=24 {
                let nom: Vec<f64> = (0..3).map(|_| 20.0 + 500.0 * rnd()).collect();
                for (qe, vals) in [
                    ("nominal", nom.clone()),
                    (
                        "corrected",
                        (0..3)
                            .map(|c| {
                                (0..3).map(|r| nom[r] * m[r][c]).sum::<f64>()
                                    + noise * (rnd() - 0.5)
                            })
                            .collect(),
                    ),
                ] {
                    for c in 0..3 {
                        out.push(ResultRow {
                            experiment: "e".into(),
                            variant: format!("{light},{qe}"),
                            params: vec![
                                ("light".into(), light.into()),
                                ("tag.qe".into(), qe.into()),
                            ],
                            measurement: "mcc".into(),
                            quantity: format!("patch{patch:02}/{}_mean", ch[c]),
                            unit: "DV".into(),
                            value: vals[c],
                            stderr: 0.1,
                            render_s: 0.0,
                            total_s: 0.0,
                        });
                    }
                }
            }
        }
        out
    }

    fn opts() -> QeCorrectionOptions {
        QeCorrectionOptions {
            axis: Some("tag.qe".into()),
            measured: Some("corrected".into()),
            nominal: Some("nominal".into()),
            exclude: vec![3, 6, 10, 11, 14, 19],
            ..Default::default()
        }
    }

    const M: [[f64; 3]; 3] = [
        [0.5636, 0.0807, 0.0069],
        [0.0, 0.5917, 0.0],
        [0.0, 0.247, 0.7098],
    ];

    #[test]
    fn nnls_recovers_m_from_paired_rows() {
        let rows = rows(&M, 0.0);
        let r: Vec<&ResultRow> = rows.iter().collect();
        let axes = vec!["light".to_string(), "tag.qe".to_string()];
        let out = run("qe", &opts(), &axes, &r).unwrap();
        let fig = |q: &str| out.figures.iter().find(|f| f.quantity == q).unwrap();
        let ch = ["r", "g", "b"];
        for (i, a) in ch.iter().enumerate() {
            for (j, b) in ch.iter().enumerate() {
                let f = fig(&format!("M_{a}_{b}"));
                assert!((f.value - M[i][j]).abs() < 1e-9, "{f:?}");
                assert!(f.value >= 0.0);
            }
        }
        assert_eq!(fig("pairs").value, 54.0, "3 lights × 18 patches");
        assert!(fig("fit_error_percent").value < 1e-9);
        // QE curves need sensor=; the scatters are there
        assert!(out.curves.iter().any(|c| c.name == "scatter-after/g"));
    }

    #[test]
    fn noise_gives_jackknife_errors_that_cover_the_truth() {
        // ±2.5 DV uniform noise (σ = 5/√12 ≈ 1.44 DV) on values 20…520 DV.
        let rows = rows(&M, 5.0);
        let r: Vec<&ResultRow> = rows.iter().collect();
        let axes = vec!["light".to_string(), "tag.qe".to_string()];
        let out = run("qe", &opts(), &axes, &r).unwrap();
        for f in out.figures.iter().filter(|f| f.quantity.starts_with("M_")) {
            let (a, b) = f.quantity[2..].split_once('_').unwrap();
            let idx = |c: &str| ["r", "g", "b"].iter().position(|x| *x == c).unwrap();
            let truth = M[idx(a)][idx(b)];
            // 4 jackknife standard errors, or the NNLS bound at 0 (a true 0 entry
            // is pinned to ≥ 0, its estimate within a few se of it).
            assert!(
                (f.value - truth).abs() <= 4.0 * f.stderr + 1e-12,
                "{f:?} vs {truth}"
            );
            if truth > 0.0 {
                assert!(f.stderr > 0.0, "{f:?}");
            }
        }
    }

    #[test]
    fn unpaired_or_unswept_axes_are_errors() {
        let rows = rows(&M, 0.0);
        let r: Vec<&ResultRow> = rows.iter().collect();
        let e = run("qe", &opts(), &["light".to_string()], &r).unwrap_err();
        assert!(e.to_string().contains("not swept"), "{e}");
        let o = QeCorrectionOptions {
            measured: Some("capture".into()),
            ..opts()
        };
        let axes = vec!["light".to_string(), "tag.qe".to_string()];
        let e = run("qe", &o, &axes, &r).unwrap_err();
        assert!(
            e.to_string().contains("values present: nominal, corrected"),
            "{e}"
        );
    }
}
