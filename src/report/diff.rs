//! Compare two results sets (directories or git revisions) figure by figure.
//!
//! Figures are matched on (experiment, variant, measurement, quantity). For
//! values a, b with standard errors sa, sb the significance is
//! `z = |b − a| / √(sa² + sb²)`. A change is **significant** when
//! `z > z_N` **and** `|b − a| > rel_floor · max(|a|, |b|)` (default 0.1 %).
//!
//! *Threshold.* `--threshold t` (default 3) names a false-alarm rate, that of
//! one two-sided t-σ test, P = P(|Z| > t) = 0.27 % for t = 3. A results set
//! holds hundreds of figures; testing each at 3σ would flag about N·0.27 % of
//! them on every re-seeded run (half a false alarm for 190 figures), so by
//! default the rate is held for the whole comparison (Šidák correction): each
//! figure is tested at `z_N` with P(|Z| > z_N) = 1 − (1 − P)^(1/N) (z ≈ 4.5 for
//! N = 190). `per_figure = true` (`--per-figure`) tests each at t itself.
//! The relative floor keeps exact figures (standard error 0, e.g. a geometric
//! constant) from flagging float-level noise, and very precise figures from
//! flagging changes no engineer would act on. Figures present on one side
//! only are listed but do not count as significant, and neither do figures
//! of wall time (a convergence run's `…/wall_s`, its time slope, efficiency
//! and fixed cost: [`crate::measure::convergence::depends_on_wall_time`]),
//! which follow the machine's load, not the inputs.
//!
//! A side is a directory (one experiment's `results.csv`, or a results root
//! holding `<experiment>/results.csv`) or, when no such directory exists, a
//! git revision: `git ls-tree`/`git show REV:<path>/…/results.csv` in the
//! current repository, `<path>` defaulting to `results`.

use super::html::{css, fmt_num, fmt_se, js, render};
use super::results::{ResultRow, parse_results, read_results};
use crate::{Error, Result};
use serde::Serialize;
use std::path::Path;
use std::process::Command;

#[derive(Clone, Debug)]
pub struct DiffOptions {
    pub threshold_sigma: f64,
    pub rel_floor: f64,
    /// Test every figure at `threshold_sigma` (no family-wise correction).
    pub per_figure: bool,
}

impl Default for DiffOptions {
    fn default() -> Self {
        Self {
            threshold_sigma: 3.0,
            rel_floor: 1e-3,
            per_figure: false,
        }
    }
}

impl DiffOptions {
    /// Per-figure z threshold for `n` compared figures.
    pub fn z_threshold(&self, n: usize) -> f64 {
        if self.per_figure || n <= 1 {
            return self.threshold_sigma;
        }
        let p = two_sided_tail(self.threshold_sigma);
        // 1 − (1 − p)^(1/n), computed stably.
        let pn = -((-p).ln_1p() / n as f64).exp_m1();
        let (mut lo, mut hi) = (0.0, 40.0);
        for _ in 0..200 {
            let m = 0.5 * (lo + hi);
            if two_sided_tail(m) > pn {
                lo = m
            } else {
                hi = m
            }
        }
        0.5 * (lo + hi)
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Change {
    pub experiment: String,
    pub variant: String,
    pub measurement: String,
    pub quantity: String,
    pub unit: String,
    pub a: f64,
    pub se_a: f64,
    pub b: f64,
    pub se_b: f64,
    /// (b − a)/|a| (NaN when a = 0).
    pub rel: f64,
    /// |b − a| / √(se_a² + se_b²) (∞ when both are exact and differ).
    pub z: f64,
    pub significant: bool,
}

#[derive(Clone, Debug, Default)]
pub struct DiffResult {
    pub compared: usize,
    /// The per-figure z threshold applied.
    pub z_threshold: f64,
    /// Figures whose value differs, most significant first.
    pub changes: Vec<Change>,
    pub only_a: Vec<String>,
    pub only_b: Vec<String>,
}

impl DiffResult {
    pub fn significant(&self) -> usize {
        self.changes.iter().filter(|c| c.significant).count()
    }
}

fn key_str(r: &ResultRow) -> String {
    format!(
        "{}/{} {}.{}",
        r.experiment, r.variant, r.measurement, r.quantity
    )
}

pub fn diff_rows(a: &[ResultRow], b: &[ResultRow], opts: &DiffOptions) -> DiffResult {
    let mut out = DiffResult::default();
    let n = a
        .iter()
        .filter(|ra| b.iter().any(|rb| rb.key() == ra.key()))
        .count();
    let zt = opts.z_threshold(n);
    out.z_threshold = zt;
    for ra in a {
        match b.iter().find(|rb| rb.key() == ra.key()) {
            None => out.only_a.push(key_str(ra)),
            Some(rb) => {
                out.compared += 1;
                let d = rb.value - ra.value;
                if d == 0.0 {
                    continue;
                }
                let se = (ra.stderr.powi(2) + rb.stderr.powi(2)).sqrt();
                let z = if se > 0.0 {
                    d.abs() / se
                } else {
                    f64::INFINITY
                };
                let floor = opts.rel_floor * ra.value.abs().max(rb.value.abs());
                out.changes.push(Change {
                    experiment: ra.experiment.clone(),
                    variant: ra.variant.clone(),
                    measurement: ra.measurement.clone(),
                    quantity: ra.quantity.clone(),
                    unit: ra.unit.clone(),
                    a: ra.value,
                    se_a: ra.stderr,
                    b: rb.value,
                    se_b: rb.stderr,
                    rel: if ra.value != 0.0 {
                        d / ra.value.abs()
                    } else {
                        f64::NAN
                    },
                    z,
                    significant: z > zt
                        && d.abs() > floor
                        && !crate::measure::convergence::depends_on_wall_time(&ra.quantity),
                });
            }
        }
    }
    out.only_b = b
        .iter()
        .filter(|rb| !a.iter().any(|ra| ra.key() == rb.key()))
        .map(key_str)
        .collect();
    out.changes.sort_by(|x, y| y.z.total_cmp(&x.z));
    out
}

/// Rows of a results directory (one experiment or a root of experiments).
pub fn read_dir_results(dir: &Path) -> Result<Vec<ResultRow>> {
    let direct = dir.join("results.csv");
    if direct.exists() {
        return read_results(&direct);
    }
    let mut subs: Vec<_> = std::fs::read_dir(dir)
        .map_err(|e| Error::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    subs.sort();
    let mut rows = vec![];
    for s in subs {
        let p = s.join("results.csv");
        if p.exists() {
            rows.extend(read_results(&p)?);
        }
    }
    if rows.is_empty() {
        return Err(Error::io(
            dir,
            "no results.csv here or in its sub-directories",
        ));
    }
    Ok(rows)
}

fn git(args: &[&str]) -> Result<String> {
    let o = Command::new("git")
        .args(args)
        .output()
        .map_err(|e| Error::invalid(format!("cannot run git: {e}")))?;
    if !o.status.success() {
        return Err(Error::invalid(format!(
            "git {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&o.stderr).trim()
        )));
    }
    Ok(String::from_utf8_lossy(&o.stdout).into_owned())
}

/// Rows of all `results.csv` under `path` at git revision `rev`.
pub fn read_git_results(rev: &str, path: &str) -> Result<Vec<ResultRow>> {
    let commit = git(&[
        "rev-parse",
        "--verify",
        "--quiet",
        &format!("{rev}^{{commit}}"),
    ])
    .map_err(|_| {
        Error::invalid(format!(
            "'{rev}' is neither a results directory nor a git revision"
        ))
    })?;
    let commit = commit.trim();
    let list = git(&[
        "ls-tree",
        "-r",
        "--full-tree",
        "--name-only",
        commit,
        "--",
        path,
    ])?;
    let mut rows = vec![];
    for f in list
        .lines()
        .filter(|l| *l == "results.csv" || l.ends_with("/results.csv"))
    {
        let text = git(&["show", &format!("{commit}:{f}")])?;
        rows.extend(parse_results(&text, &format!("{rev}:{f}"))?);
    }
    if rows.is_empty() {
        return Err(Error::invalid(format!(
            "no results.csv under '{path}' at revision {rev}"
        )));
    }
    Ok(rows)
}

/// A side given on the command line: a directory if it exists, else a git revision.
pub fn load_side(spec: &str, git_path: &str) -> Result<Vec<ResultRow>> {
    let p = Path::new(spec);
    if p.is_dir() {
        read_dir_results(p)
    } else {
        read_git_results(spec, git_path)
    }
}

/// Human-readable lines for the terminal.
pub fn summary(d: &DiffResult, opts: &DiffOptions) -> String {
    let mut s = String::new();
    for c in &d.changes {
        let rel = if c.rel.is_finite() {
            format!("{:+.3}%", 100.0 * c.rel)
        } else {
            "n/a".into()
        };
        s.push_str(&format!(
            "{} {}/{} {}.{}: {} ± {} → {} ± {} {} (Δ {rel}, |Δ|/σ = {})\n",
            if c.significant {
                "SIGNIFICANT"
            } else {
                "changed    "
            },
            c.experiment,
            c.variant,
            c.measurement,
            c.quantity,
            fmt_num(c.a),
            fmt_num(c.se_a),
            fmt_num(c.b),
            fmt_num(c.se_b),
            c.unit,
            if c.z.is_finite() {
                format!("{:.2}", c.z)
            } else {
                "inf".into()
            }
        ));
    }
    for k in &d.only_a {
        s.push_str(&format!("only in A   {k}\n"));
    }
    for k in &d.only_b {
        s.push_str(&format!("only in B   {k}\n"));
    }
    s.push_str(&format!(
        "{} figures compared, {} changed, {} significant (|Δ|/σ > {:.2}{} and |Δ| > {}%)\n",
        d.compared,
        d.changes.len(),
        d.significant(),
        d.z_threshold,
        if opts.per_figure {
            String::new()
        } else {
            format!(
                ": {} σ false-alarm rate for the whole set",
                opts.threshold_sigma
            )
        },
        100.0 * opts.rel_floor,
    ));
    s
}

/// Two-sided normal tail probability P(|Z| > t) (Abramowitz–Stegun 7.1.26, |error| < 1.5e-7).
fn two_sided_tail(t: f64) -> f64 {
    let x = t / std::f64::consts::SQRT_2;
    let k = 1.0 / (1.0 + 0.3275911 * x);
    let poly = k
        * (0.254829592
            + k * (-0.284496736 + k * (1.421413741 + k * (-1.453152027 + k * 1.061405429))));
    poly * (-x * x).exp()
}

#[derive(Serialize)]
struct RowOut {
    experiment: String,
    variant: String,
    measurement: String,
    quantity: String,
    unit: String,
    a: String,
    b: String,
    rel: String,
    z: String,
    significant: bool,
}

/// Write the HTML diff.
pub fn write_html(path: &Path, a: &str, b: &str, d: &DiffResult, opts: &DiffOptions) -> Result<()> {
    let fmt_pm = |v: f64, se: f64| {
        let s = fmt_se(se);
        if s.is_empty() {
            fmt_num(v)
        } else {
            format!("{} ± {s}", fmt_num(v))
        }
    };
    let rows: Vec<RowOut> = d
        .changes
        .iter()
        .map(|c| RowOut {
            experiment: c.experiment.clone(),
            variant: c.variant.clone(),
            measurement: c.measurement.clone(),
            quantity: c.quantity.clone(),
            unit: c.unit.clone(),
            a: fmt_pm(c.a, c.se_a),
            b: fmt_pm(c.b, c.se_b),
            rel: if c.rel.is_finite() {
                format!("{:+.3}%", 100.0 * c.rel)
            } else {
                "n/a".into()
            },
            z: if c.z.is_finite() {
                format!("{:.2}", c.z)
            } else {
                "∞".into()
            },
            significant: c.significant,
        })
        .collect();
    let only: Vec<String> = d
        .only_a
        .iter()
        .map(|k| format!("A only: {k}"))
        .chain(d.only_b.iter().map(|k| format!("B only: {k}")))
        .collect();
    let ctx = minijinja::context! {
        a => a, b => b, threshold => format!("{:.2}", d.z_threshold), rel_floor_pct => 100.0 * opts.rel_floor,
        n_compared => d.compared, n_significant => d.significant(), rows => rows, only => only,
        css => css(), js => js(),
    };
    let html = render("diff.html", super::html::DIFF, ctx)?;
    crate::diag::write_atomic(path, html.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    fn row(v: &str, q: &str, value: f64, se: f64) -> ResultRow {
        ResultRow {
            experiment: "e".into(),
            variant: v.into(),
            params: vec![],
            measurement: "m".into(),
            quantity: q.into(),
            unit: "DV".into(),
            value,
            stderr: se,
            render_s: 0.0,
            total_s: 0.0,
        }
    }
    #[test]
    fn significance_and_floor() {
        let a = vec![
            row("v", "x", 100.0, 1.0),
            row("v", "exact", 5.0, 0.0),
            row("v", "gone", 1.0, 0.1),
        ];
        let b = vec![
            row("v", "x", 105.0, 1.0),
            row("v", "exact", 5.0 + 1e-9, 0.0),
            row("v", "new", 1.0, 0.1),
        ];
        let d = diff_rows(&a, &b, &DiffOptions::default());
        assert_eq!(d.compared, 2);
        assert_eq!(d.significant(), 1);
        let x = d.changes.iter().find(|c| c.quantity == "x").unwrap();
        assert!((x.z - 5.0 / 2f64.sqrt()).abs() < 1e-12 && x.significant);
        let exact = d.changes.iter().find(|c| c.quantity == "exact").unwrap();
        assert!(
            exact.z.is_infinite() && !exact.significant,
            "float noise on an exact figure is below the floor"
        );
        assert_eq!((d.only_a.len(), d.only_b.len()), (1, 1));
        assert!((two_sided_tail(3.0) - 0.0026998).abs() < 1e-6);
        // Šidák: 190 figures at a 3σ family-wise rate → per-figure P = 1.42e-5 → z ≈ 4.34.
        let z = DiffOptions::default().z_threshold(190);
        assert!(
            (two_sided_tail(z) - (1.0 - (1.0 - 0.0026998f64).powf(1.0 / 190.0))).abs() < 1e-8,
            "{z}"
        );
        assert_eq!(
            DiffOptions {
                per_figure: true,
                ..Default::default()
            }
            .z_threshold(190),
            3.0
        );
    }

    #[test]
    fn wall_time_figures_are_listed_but_never_significant() {
        let a = [row("v", "mcc/spp16/wall_s", 2.0, 0.0)];
        let b = [row("v", "mcc/spp16/wall_s", 9.0, 0.0)];
        let d = diff_rows(&a, &b, &DiffOptions::default());
        assert_eq!(d.changes.len(), 1);
        assert!(!d.changes[0].significant);
        // the same change on a reproducible figure is significant
        let a = [row("v", "mcc/spp16/mean", 2.0, 0.0)];
        let b = [row("v", "mcc/spp16/mean", 9.0, 0.0)];
        assert!(diff_rows(&a, &b, &DiffOptions::default()).changes[0].significant);
    }
}
