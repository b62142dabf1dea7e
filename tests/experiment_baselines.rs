//! Baselines of the shipped experiments (`experiments/*.kdl`): each runs end to
//! end at a test quality (`camsim run --max-spp 64` for most, see [`max_spp`];
//! the files' own seeds), its report opens in headless Chromium (no console
//! message, every plot drawn, the pictures and curves its figure names:
//! [`report_must_show`]), and
//! its `results.csv` is compared with the committed baseline in
//! `tests/baselines/<experiment>/results.csv` by `camsim diff`'s rule: a figure
//! fails when it moved by more than the family-wise 3σ threshold of the
//! combined standard error *and* more than 0.1 % (`report::diff`), or when a
//! figure is missing on either side (a failed variant writes no rows).
//!
//! Same binary, inputs and seeds give bit-identical figures, so on an unchanged
//! tree every difference is 0; the statistical rule is what lets a change that
//! reorders floating-point sums pass while a physics or parameter change
//! (a dropped `materials="paper"`, a film distance in the wrong unit) fails.
//!
//! Regenerate after an intended change, then read the baseline's diff:
//!
//! ```sh
//! CAMSIM_BLESS=1 cargo test --release --test experiment_baselines
//! ```
//!
//! `CAMSIM_BASELINES=fig05-relative-illumination,fig09-interreflection` limits
//! a run (and a bless) to the experiments named.

mod common;

use camsim::report::diff::{DiffOptions, diff_rows};
use camsim::report::results::read_results;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The quality the baselines are run at: few enough samples that the whole
/// set runs in about two minutes on 2 cores, enough that every SFR region
/// clears its noise floor (ISO 12233 refuses an edge whose noise alone gives
/// MTF > 0.5 at Nyquist). The SFR experiments need their shipped counts:
/// `rtf-vs-prescription` (256 spp) sees a dim, bounce-lit edge (contrast/noise
/// 7 at 64 spp), `fig07-lsf-mtf` and `e2e-quick` (128 spp) edges lit by the
/// paper's lamp and spot fall below the floor at 64.
fn max_spp(experiment: &str) -> Option<&'static str> {
    match experiment {
        "rtf-vs-prescription" | "fig07-lsf-mtf" | "e2e-quick" => None,
        _ => Some("64"),
    }
}

fn experiments() -> Vec<(String, PathBuf)> {
    let mut v = vec![];
    for e in std::fs::read_dir("experiments").unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "kdl") {
            let text = std::fs::read_to_string(&p).unwrap();
            // setups (shared bases) are not run on their own
            let top = text
                .lines()
                .map(str::trim)
                .find(|l| !l.is_empty() && !l.starts_with("//"))
                .unwrap_or("");
            if top.starts_with("experiment") {
                let name = top.split('"').nth(1).unwrap().to_string();
                v.push((name, p));
            }
        }
    }
    v.sort();
    v
}

/// What a figure's report must show (besides opening in headless Chromium with
/// no console message and every plot drawn): text of its charts and pictures.
fn report_must_show(experiment: &str) -> &'static [&'static str] {
    match experiment {
        // both views: white-balanced preview, raw mosaic picture, DNG link
        "fig04-qualitative" => &[
            "illuminance-scale-factor = 0.57",
            "fig4_center",
            "fig4_left",
            "sensor-raw-mosaic",
            "sensor.dng\" download>",
        ],
        // the rendered RI against Zemax's in one chart
        "fig05-relative-illumination" => {
            &["ri-vs-zemax: ri", "\nreference\n</text>", "· simulated"]
        }
        // LSF in µm, MTF in cy/mm with its noise floor, measured and Zemax overlays
        "fig07-lsf-mtf" => &[
            "illuminance-scale-factor = 0.5",
            "sfr: edge-near/lsf",
            "distance (µm)",
            "frequency (cy/mm)",
            "noise floor",
            "near-vs-measured: edge-near/mtf",
            "far-vs-zemax: edge-far/mtf",
        ],
        // R, G, B along the achromatic row and the G/R ratios
        "fig09-interreflection" => &["profile: profile/r", "profile: ratio/g/r"],
        // the pass/fail table: a row per case, its passed and failed counts
        "stability" => &[
            "Measurement: stability",
            "<th>passed (1)</th>",
            "<th>failed_checks (1)</th>",
            "case=dynamic-range</td><td>1</td>",
            "case=grazing</td><td>1</td>",
            "case=scale</td><td>1</td>",
            "case=sensor-saturated-dark</td><td>1</td>",
            "case=rtf-beyond-field</td><td>1</td>",
            "case=rtf-singular-fit</td><td>1</td>",
            "case=sfr-noisy</td><td>1</td>",
            "case=exposure-gain</td><td>1</td>",
        ],
        // standard error and error against wall time (log–log) with the
        // fitted slopes in the legend, and the flagged figures' notes
        "convergence" => &[
            "conv-mtf50: stderr_vs_time",
            "conv-patch-means: error_vs_time",
            "conv-g-over-r: stderr_vs_time",
            "conv-noise-model: stderr_vs_time",
            "conv-alpha: stderr_vs_time",
            "per sample, ",
            "<p class=\"note flag\">Convergence: ",
        ],
        "convergence-ri" => &[
            "conv-ri-error: stderr_vs_time",
            "conv-ri-error: error_vs_time",
            "<p class=\"note flag\">Convergence: rmse",
        ],
        _ => &[],
    }
}

/// Fig. 4: the DNG of each view opens in dcraw (an independent raw reader) with
/// the sensor's size (672 × 504 at the declared 8.4 µm pitch), CFA pattern
/// (the IMX363 file's "grbg") and black level (64 DV).
fn check_fig04_dngs(dir: &Path) {
    let mut n = 0;
    for v in std::fs::read_dir(dir.join("previews")).unwrap() {
        let dng = v.unwrap().path().join("sensor.dng");
        assert!(dng.exists(), "no {}", dng.display());
        n += 1;
        common::dcraw_reads(&dng, (672, 504), "GR/BG", (64, 1023));
    }
    assert_eq!(n, 2, "one DNG per camera view");
}

fn check_report(name: &str, dir: &Path) {
    if name == "fig04-qualitative" {
        check_fig04_dngs(dir);
    }
    let page = dir.join("report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    for needle in report_must_show(name) {
        assert!(html.contains(needle), "{name}: the report lacks '{needle}'");
    }
    if let Some(dom) = common::chromium_dom(&page) {
        assert!(
            dom.contains("data-plots-ok=\"true\""),
            "{name}: a plot of the report is empty or missing"
        );
    }
}

fn run(name: &str, file: &Path, out: &Path) {
    let mut c = Command::new(env!("CARGO_BIN_EXE_camsim"));
    c.args(["run", "--threads", "2", "--out"]).arg(out);
    if let Some(n) = max_spp(name) {
        c.args(["--max-spp", n]);
    }
    let o = c.arg(file).output().unwrap();
    assert!(
        o.status.success(),
        "{}: camsim run failed ({}):\n{}",
        file.display(),
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn shipped_experiments_match_their_baselines() {
    let tmp = tempfile::tempdir().unwrap();
    let bless = std::env::var_os("CAMSIM_BLESS").is_some();
    let exps = experiments();
    assert!(
        exps.len() >= 4,
        "experiments/ holds {} experiments",
        exps.len()
    );
    let only: Option<Vec<String>> = std::env::var("CAMSIM_BASELINES")
        .ok()
        .map(|s| s.split(',').map(|x| x.trim().to_string()).collect());
    if let Some(o) = &only {
        for n in o {
            assert!(
                exps.iter().any(|e| &e.0 == n),
                "CAMSIM_BASELINES names '{n}', which is not an experiment in experiments/"
            );
        }
    }
    let exps: Vec<_> = exps
        .into_iter()
        .filter(|(n, _)| only.as_ref().is_none_or(|o| o.contains(n)))
        .collect();
    let mut failures = vec![];
    for (name, file) in &exps {
        run(name, file, tmp.path());
        check_report(name, &tmp.path().join(name));
        let got = tmp.path().join(name).join("results.csv");
        let base = Path::new("tests/baselines").join(name).join("results.csv");
        if bless {
            std::fs::create_dir_all(base.parent().unwrap()).unwrap();
            std::fs::copy(&got, &base).unwrap();
            eprintln!("blessed {}", base.display());
            continue;
        }
        assert!(
            base.exists(),
            "{name}: no baseline {}; create it with CAMSIM_BLESS=1 cargo test --release --test experiment_baselines",
            base.display()
        );
        // (Figures of wall time are listed by the diff but never significant.)
        let a = read_results(&base).unwrap();
        let b = read_results(&got).unwrap();
        let d = diff_rows(&a, &b, &DiffOptions::default());
        let sig: Vec<String> = d
            .changes
            .iter()
            .filter(|c| c.significant)
            .map(|c| {
                format!(
                    "{}/{} {}.{}: {} ± {} → {} ± {} (z = {:.1})",
                    c.experiment,
                    c.variant,
                    c.measurement,
                    c.quantity,
                    c.a,
                    c.se_a,
                    c.b,
                    c.se_b,
                    c.z
                )
            })
            .collect();
        if !sig.is_empty() || !d.only_a.is_empty() || !d.only_b.is_empty() {
            failures.push(format!(
                "{name}: {} significant change(s) of {} compared (z > {:.2}):\n  {}\n  only in the baseline: {:?}\n  only in this run: {:?}",
                sig.len(),
                d.compared,
                d.z_threshold,
                sig.join("\n  "),
                d.only_a,
                d.only_b
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{}\n(an intended change? regenerate with CAMSIM_BLESS=1 cargo test --release --test experiment_baselines and review the diff)",
        failures.join("\n")
    );
}
